#include "vdbsurf/density/scene.h"

#include "vdbsurf/core/error.h"

#include <algorithm>
#include <cmath>

namespace vdbsurf {

namespace {
// One primitive's density bounds as signed fixed-point terms, rounded outwards: every
// contribution() within them rounds to a value inside (a subtraction's upper bound lowers the
// sum's lower one).
FixedInterval signedFixedBounds(double lo, double hi, DensityOp op) {
    const FixedDensity a = FixedDensity(std::floor(lo * kFixedPerUnit)), b = FixedDensity(std::ceil(hi * kFixedPerUnit));
    return op == DensityOp::Add ? FixedInterval{a, b} : FixedInterval{-b, -a};
}

Interval clampedInterval(const FixedInterval& sum) { return {clampDensity(fromFixed(sum.lo)), clampDensity(fromFixed(sum.hi))}; }

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
    if (mPrimitives.size() > (std::size_t(1) << 20)) // with weights ≤ kMaxWeight, fixed-point sums stay in 63 bits
        throw Error(mSource, "has " + std::to_string(mPrimitives.size()) + " primitives; at most 1048576 are supported");
    for (std::size_t i = 0; i < mPrimitives.size(); ++i)
        if (!(mPrimitives[i].weight > 0 && mPrimitives[i].weight <= kMaxWeight))
            throw Error(mSource, "primitive " + std::to_string(i) + ": weight must be positive and at most " +
                                     std::to_string(int(kMaxWeight)));
    // Only added density can reach 0.5: a scene of subtractions alone has no surface.
    if (!any) throw Error(mSource, "has no primitive with op \"add\", so it has no surface");
    buildIndex(true);
}

void DensityScene::buildIndex(bool grid) {
    std::vector<Box3> boxes;
    boxes.reserve(mPrepared.size());
    for (const PreparedPrimitive& p : mPrepared) boxes.push_back(p.influenceBox());
    mIndex = PrimitiveIndex(boxes, grid);
}

LatticeFrame DensityScene::naturalFrame(double h) const {
    // Nodes on the world lattice h·(i, j, k), as `vdbsurf rasterize` puts voxel centres, so a
    // mesh of the scene and a mesh of its rasterized grid share their nodes.
    return {Vec3d(std::floor(mDomain.min.x / h), std::floor(mDomain.min.y / h), std::floor(mDomain.min.z / h)) * h, h};
}

FixedDensity DensityScene::contribution(std::uint32_t i, const Vec3d& p) const {
    const FixedDensity c = toFixed(mPrepared[i].density(p));
    return mPrimitives[i].op == DensityOp::Add ? c : -c;
}

FixedDensity DensityScene::fixedSum(const Vec3d& p, const std::vector<std::uint32_t>& among) const {
    FixedDensity s = 0;
    for (std::uint32_t i : among) s += contribution(i, p);
    return s;
}

void DensityScene::addContributions(std::uint32_t i, const Vec3d* points, std::size_t count, bool takeOut, FixedDensity* sums) const {
    constexpr std::size_t kChunk = 64;
    double density[kChunk];
    const bool add = (mPrimitives[i].op == DensityOp::Add) != takeOut;
    for (std::size_t first = 0; first < count; first += kChunk) {
        const std::size_t n = std::min(kChunk, count - first);
        mPrepared[i].densities(points + first, n, density);
        for (std::size_t k = 0; k < n; ++k) {
            const FixedDensity c = toFixed(density[k]); // as contribution()
            sums[first + k] += add ? c : -c;
        }
    }
}

void DensityScene::fixedSums(const Vec3d* points, std::size_t count, const std::vector<std::uint32_t>& among, FixedDensity* sums) const {
    std::fill(sums, sums + count, FixedDensity(0));
    for (std::uint32_t i : among) addContributions(i, points, count, false, sums);
}

double DensityScene::sum(const Vec3d& p) const {
    FixedDensity s = 0;
    std::size_t count;
    const std::uint32_t* near = mIndex.at(p, count);
    for (std::size_t k = 0; k < count; ++k) s += contribution(near[k], p);
    return fromFixed(s);
}

double DensityScene::sum(const Vec3d& p, const std::vector<std::uint32_t>& among) const { return fromFixed(fixedSum(p, among)); }

FixedInterval DensityScene::contributionBounds(std::uint32_t i, const DensityAnchor& a, const Vec3d& centre, double halfWidth) const {
    double lo, hi;
    mPrepared[i].densityBoundsNear(a, centre, Neighbourhood{halfWidth, 0.0}, lo, hi);
    return signedFixedBounds(lo, hi, mPrimitives[i].op);
}

void DensityScene::accumulateBoundsNear(std::uint32_t i, const DensityAnchor& a, const Vec3d& first, double step,
                                        const Neighbourhood& around, bool takeOut, FixedInterval* sums) const {
    constexpr int n = kNearBlock, count = n * n * n;
    if (!a.hasNormal || !(a.lo < a.hi)) { // the same bounds over the whole ball
        const FixedInterval b = signedFixedBounds(a.lo, a.hi, mPrimitives[i].op);
        if (b.lo == 0 && b.hi == 0) return;
        for (int k = 0; k < count; ++k) takeOut ? sums[k] -= b : sums[k] += b;
        return;
    }
    double lo[count], hi[count];
    mPrepared[i].densityBoundsNearBlock(a, first, step, n, around, lo, hi);
    // Rounded outwards by truncation and a unit (floor and ceil without a libm call per voxel).
    const bool add = mPrimitives[i].op == DensityOp::Add;
    for (int k = 0; k < count; ++k) {
        const FixedDensity l = FixedDensity(lo[k] * kFixedPerUnit) - 1, h = FixedDensity(hi[k] * kFixedPerUnit) + 1;
        const FixedInterval b = add ? FixedInterval{l, h} : FixedInterval{-h, -l};
        takeOut ? sums[k] -= b : sums[k] += b;
    }
}

double DensityScene::value(const Vec3d& p) const { return clampDensity(sum(p)); }

void DensityScene::values(const Box3& box, const Vec3d* points, std::size_t n, double* out) const {
    // A primitive whose influence box misses a point adds exactly 0 there (density()'s first test),
    // so summing every primitive that touches the box gives each point value()'s sum.
    thread_local std::vector<std::uint32_t> among;
    thread_local std::vector<FixedDensity> sums;
    primitivesTouching(box, among);
    sums.resize(n);
    fixedSums(points, n, among, sums.data());
    for (std::size_t i = 0; i < n; ++i) out[i] = clampDensity(fromFixed(sums[i]));
}

Vec3d DensityScene::gradient(const Vec3d& p) const {
    const double s = sum(p);
    if (s <= 0 || s >= 1) return {}; // the clamp is flat there
    Vec3d g;
    std::size_t count;
    const std::uint32_t* near = mIndex.at(p, count);
    for (std::size_t k = 0; k < count; ++k) g += mPrepared[near[k]].densityGradient(p) * mPrepared[near[k]].sign();
    return g;
}

void DensityScene::primitivesTouching(const Box3& box, std::vector<std::uint32_t>& out) const {
    mIndex.over(box, out);
    out.erase(std::remove_if(out.begin(), out.end(), [&](std::uint32_t i) { return !overlaps(mPrepared[i].influenceBox(), box); }),
              out.end());
}

Interval DensityScene::bounds(const Box3& box, const std::vector<std::uint32_t>& among) const {
    FixedInterval sum;
    for (std::uint32_t i : among) {
        double lo, hi;
        mPrepared[i].densityBounds(box, lo, hi);
        sum += signedFixedBounds(lo, hi, mPrimitives[i].op);
    }
    return clampedInterval(sum);
}

Interval DensityScene::boundsReaching(const Box3& box, std::vector<std::uint32_t>& reaching) const {
    FixedInterval sum;
    auto consider = [&](std::uint32_t i) {
        double lo, hi;
        if (!mPrepared[i].reaches(box, lo, hi)) return false;
        sum += signedFixedBounds(lo, hi, mPrimitives[i].op);
        return true;
    };
    // A primitive reaches no box its influence box misses (densityBounds' first test), so the
    // index's candidates are all that can; in ascending order, as a scan of all lists them.
    mIndex.over(box, reaching);
    reaching.erase(std::remove_if(reaching.begin(), reaching.end(), [&](std::uint32_t i) { return !consider(i); }), reaching.end());
    return clampedInterval(sum);
}

Interval DensityScene::bounds(const Box3& box) const {
    std::vector<std::uint32_t> among;
    primitivesTouching(box, among);
    return bounds(box, among);
}

} // namespace vdbsurf
