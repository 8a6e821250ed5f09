#include "vdbsurf/density/scene.h"

#include "vdbsurf/core/error.h"

#include <algorithm>
#include <cmath>

namespace vdbsurf {

namespace {
bool overlaps(const Box3& a, const Box3& b) {
    return a.min.x <= b.max.x && a.min.y <= b.max.y && a.min.z <= b.max.z && b.min.x <= a.max.x && b.min.y <= a.max.y &&
           b.min.z <= a.max.z;
}
} // namespace

DensityScene::DensityScene(std::vector<Primitive> primitives, std::string source, std::optional<double> voxelSize)
    : mPrimitives(std::move(primitives)), mSource(std::move(source)), mVoxelSize(voxelSize) {
    bool any = false;
    for (const Primitive& p : mPrimitives) {
        mPrepared.emplace_back(p);
        if (p.op != DensityOp::Add) continue;
        const Box3& b = mPrepared.back().influenceBox();
        mDomain = any ? Box3{vmin(mDomain.min, b.min), vmax(mDomain.max, b.max)} : b;
        any = true;
    }
    // Only added density can reach 0.5: a scene of subtractions alone has no surface.
    if (!any) throw Error(mSource, "has no primitive with op \"add\", so it has no surface");
}

LatticeFrame DensityScene::naturalFrame(double h) const {
    // Nodes on the world lattice h·(i, j, k), as `vdbsurf rasterize` puts voxel centres, so a
    // mesh of the scene and a mesh of its rasterized grid share their nodes.
    return {Vec3d(std::floor(mDomain.min.x / h), std::floor(mDomain.min.y / h), std::floor(mDomain.min.z / h)) * h, h};
}

double DensityScene::sum(const Vec3d& p) const {
    double s = 0;
    for (const PreparedPrimitive& q : mPrepared) s += q.sign() * q.density(p);
    return s;
}

double DensityScene::sum(const Vec3d& p, const std::vector<std::uint32_t>& among) const {
    double s = 0;
    for (std::uint32_t i : among) s += mPrepared[i].sign() * mPrepared[i].density(p);
    return s;
}

double DensityScene::value(const Vec3d& p) const { return clampDensity(sum(p)); }

Vec3d DensityScene::gradient(const Vec3d& p) const {
    const double s = sum(p);
    if (s <= 0 || s >= 1) return {}; // the clamp is flat there
    Vec3d g;
    for (const PreparedPrimitive& q : mPrepared) g += q.densityGradient(p) * q.sign();
    return g;
}

void DensityScene::primitivesTouching(const Box3& box, std::vector<std::uint32_t>& out) const {
    out.clear();
    for (std::uint32_t i = 0; i < mPrepared.size(); ++i)
        if (overlaps(mPrepared[i].influenceBox(), box)) out.push_back(i);
}

namespace {
// Signed sum of per-primitive density bounds: a subtraction's upper bound lowers the sum's lower.
template <class PrimitiveBounds>
Interval sumBounds(const std::vector<PreparedPrimitive>& prepared, const std::vector<std::uint32_t>& among, PrimitiveBounds&& of) {
    double lo = 0, hi = 0;
    for (std::uint32_t i : among) {
        double a, b;
        of(prepared[i], a, b);
        if (prepared[i].primitive().op == DensityOp::Add) {
            lo += a;
            hi += b;
        } else {
            lo -= b;
            hi -= a;
        }
    }
    return {clampDensity(lo), clampDensity(hi)};
}
} // namespace

Interval DensityScene::bounds(const Box3& box, const std::vector<std::uint32_t>& among) const {
    return sumBounds(mPrepared, among, [&](const PreparedPrimitive& p, double& lo, double& hi) { p.densityBounds(box, lo, hi); });
}

Interval DensityScene::boundsAround(const Vec3d& centre, double radius, const std::vector<std::uint32_t>& among) const {
    return sumBounds(mPrepared, among,
                     [&](const PreparedPrimitive& p, double& lo, double& hi) { p.densityBoundsAround(centre, radius, lo, hi); });
}

Interval DensityScene::bounds(const Box3& box) const {
    std::vector<std::uint32_t> among;
    primitivesTouching(box, among);
    return bounds(box, among);
}

} // namespace vdbsurf
