#include "vdbsurf/density/primitive.h"

#include <algorithm>
#include <cmath>

namespace vdbsurf {

namespace {
constexpr double kDegree = 3.14159265358979323846 / 180.0;
}

double falloffValue(double t) {
    if (t <= 0) return 1.0;
    if (t >= 1) return 0.0;
    return 1.0 - t * t * (3.0 - 2.0 * t);
}

double falloffSlope(double t) {
    if (t <= 0 || t >= 1) return 0.0;
    return -6.0 * t * (1.0 - t);
}

double ellipsoidDistance(const Vec3d& r, const Vec3d& p, Vec3d& closest) {
    // Work in the first octant; the closest point keeps the point's signs. The closest point is
    // x_i = r_i² y_i / (t + r_i²) where F(t) = Σ (r_i y_i / (t + r_i²))² - 1 = 0, t ≥ 0 outside.
    const Vec3d y(std::fabs(p.x), std::fabs(p.y), std::fabs(p.z));
    const Vec3d r2(r.x * r.x, r.y * r.y, r.z * r.z);
    auto F = [&](double t) {
        double s = 0;
        for (int i = 0; i < 3; ++i) {
            const double q = r[i] * y[i] / (t + r2[i]);
            s += q * q;
        }
        return s - 1.0;
    };
    double lo = 0, hi = length(Vec3d(r.x * y.x, r.y * y.y, r.z * y.z)); // F(hi) <= 0
    if (!(F(0) > 0)) { // on or inside the surface
        closest = p;
        return 0.0;
    }
    for (int i = 0; i < 200 && hi - lo > 1e-15 * std::max(1.0, hi); ++i) {
        const double mid = 0.5 * (lo + hi);
        (F(mid) > 0 ? lo : hi) = mid;
    }
    const double t = 0.5 * (lo + hi);
    Vec3d x;
    for (int i = 0; i < 3; ++i) x[i] = std::copysign(r2[i] * y[i] / (t + r2[i]), p[i]);
    closest = x;
    return length(p - x);
}

PreparedPrimitive::PreparedPrimitive(const Primitive& p) : mP(p) {
    const double ax = p.rotationDegrees.x * kDegree, ay = p.rotationDegrees.y * kDegree, az = p.rotationDegrees.z * kDegree;
    const double cx = std::cos(ax), sx = std::sin(ax), cy = std::cos(ay), sy = std::sin(ay), cz = std::cos(az), sz = std::sin(az);
    // R = Rz · Ry · Rx: rotate about x first, then y, then z (fixed axes).
    const double Rx[3][3] = {{1, 0, 0}, {0, cx, -sx}, {0, sx, cx}};
    const double Ry[3][3] = {{cy, 0, sy}, {0, 1, 0}, {-sy, 0, cy}};
    const double Rz[3][3] = {{cz, -sz, 0}, {sz, cz, 0}, {0, 0, 1}};
    double RyRx[3][3];
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
            RyRx[i][j] = 0;
            for (int k = 0; k < 3; ++k) RyRx[i][j] += Ry[i][k] * Rx[k][j];
        }
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
            mR[i][j] = 0;
            for (int k = 0; k < 3; ++k) mR[i][j] += Rz[i][k] * RyRx[k][j];
        }
    Vec3d half;
    for (int i = 0; i < 3; ++i) {
        double h = 0;
        for (int j = 0; j < 3; ++j) {
            const double e = mR[i][j] * p.size[j];
            h += p.core == CoreShape::Box ? std::fabs(e) : e * e;
        }
        half[i] = p.core == CoreShape::Box ? h : std::sqrt(h);
    }
    mCoreBox = {p.center - half, p.center + half};
    const Vec3d grow(p.falloff, p.falloff, p.falloff);
    mInfluence = {mCoreBox.min - grow, mCoreBox.max + grow};
}

Vec3d PreparedPrimitive::toLocal(const Vec3d& p) const {
    const Vec3d d = p - mP.center;
    return {mR[0][0] * d.x + mR[1][0] * d.y + mR[2][0] * d.z, mR[0][1] * d.x + mR[1][1] * d.y + mR[2][1] * d.z,
            mR[0][2] * d.x + mR[1][2] * d.y + mR[2][2] * d.z};
}

Vec3d PreparedPrimitive::toWorld(const Vec3d& v) const {
    return {mR[0][0] * v.x + mR[0][1] * v.y + mR[0][2] * v.z, mR[1][0] * v.x + mR[1][1] * v.y + mR[1][2] * v.z,
            mR[2][0] * v.x + mR[2][1] * v.y + mR[2][2] * v.z};
}

double PreparedPrimitive::coreDistance(const Vec3d& p, Vec3d& gradient) const {
    const Vec3d q = toLocal(p);
    gradient = Vec3d();
    if (mP.core == CoreShape::Box) {
        // Nearest face, edge or vertex: the excess over the half extents on each axis.
        const Vec3d e(std::max(std::fabs(q.x) - mP.size.x, 0.0), std::max(std::fabs(q.y) - mP.size.y, 0.0),
                      std::max(std::fabs(q.z) - mP.size.z, 0.0));
        const double d = length(e);
        if (d > 0) gradient = toWorld(Vec3d(std::copysign(e.x, q.x), std::copysign(e.y, q.y), std::copysign(e.z, q.z)) / d);
        return d;
    }
    Vec3d closest;
    const double d = ellipsoidDistance(mP.size, q, closest);
    if (d > 0) gradient = toWorld((q - closest) / d);
    return d;
}

double PreparedPrimitive::coreDistance(const Vec3d& p) const {
    Vec3d g;
    return coreDistance(p, g);
}

bool PreparedPrimitive::inCore(const Vec3d& p) const {
    const Vec3d q = toLocal(p);
    if (mP.core == CoreShape::Box) return std::fabs(q.x) <= mP.size.x && std::fabs(q.y) <= mP.size.y && std::fabs(q.z) <= mP.size.z;
    const double s = (q.x / mP.size.x) * (q.x / mP.size.x) + (q.y / mP.size.y) * (q.y / mP.size.y) + (q.z / mP.size.z) * (q.z / mP.size.z);
    return s <= 1.0;
}

double PreparedPrimitive::density(const Vec3d& p) const {
    if (!mInfluence.contains(p)) return 0.0;
    return mP.weight * falloffValue(coreDistance(p) / mP.falloff);
}

Vec3d PreparedPrimitive::densityGradient(const Vec3d& p) const {
    if (!mInfluence.contains(p)) return {};
    Vec3d g;
    const double d = coreDistance(p, g);
    return g * (mP.weight * falloffSlope(d / mP.falloff) / mP.falloff);
}

int PreparedPrimitive::area(const Vec3d& p) const {
    if (!mInfluence.contains(p)) return 0;
    const double d = coreDistance(p);
    if (d <= 0) return 3;
    if (d >= mP.falloff) return 0;
    return mP.weight * falloffValue(d / mP.falloff) < 0.5 ? 1 : 2;
}

void PreparedPrimitive::densityBounds(const Box3& box, double& lo, double& hi) const {
    lo = hi = 0;
    if (box.max.x < mInfluence.min.x || box.max.y < mInfluence.min.y || box.max.z < mInfluence.min.z ||
        box.min.x > mInfluence.max.x || box.min.y > mInfluence.max.y || box.min.z > mInfluence.max.z)
        return;
    double dmax = 0;
    for (int k = 0; k < 8; ++k) {
        const Vec3d c(k & 1 ? box.max.x : box.min.x, k & 2 ? box.max.y : box.min.y, k & 4 ? box.max.z : box.min.z);
        dmax = std::max(dmax, coreDistance(c));
    }
    const double halfDiagonal = 0.5 * length(box.extent());
    const double dmin = std::max(0.0, coreDistance(box.center()) - halfDiagonal * (1 + 1e-12) - 1e-12);
    lo = mP.weight * falloffValue(dmax / mP.falloff);
    hi = mP.weight * falloffValue(dmin / mP.falloff);
}

} // namespace vdbsurf
