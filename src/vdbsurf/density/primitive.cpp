#include "vdbsurf/density/primitive.h"

#include <algorithm>
#include <cmath>

namespace vdbsurf {

namespace {
constexpr double kDegree = 3.14159265358979323846 / 180.0;

// falloffValue without branches, for loops over many points that the compiler runs two at a
// time (with the file's -fno-trapping-math): t clamped to [0, 1] gives its 1 and 0 at the ends
// exactly, and the cubic between is its own, so the values keep their bits (for any t but a NaN).
inline double falloffClamped(double t) {
    t = std::min(std::max(t, 0.0), 1.0);
    return 1.0 - t * t * (3.0 - 2.0 * t);
}

// Box3::contains without branches, for the same loops.
inline bool inBox(const Box3& b, const Vec3d& p) {
    return (p.x >= b.min.x) & (p.y >= b.min.y) & (p.z >= b.min.z) & (p.x <= b.max.x) & (p.y <= b.max.y) & (p.z <= b.max.z);
}
} // namespace

double falloffSlope(double t) {
    if (t <= 0 || t >= 1) return 0.0;
    return -6.0 * t * (1.0 - t);
}

namespace {

// Newton's steps for ellipsoidDistances, N lanes in lockstep until every lane has stopped: a lane
// stops where F or its slope has the wrong sign or the step does not climb (t kept), and after a
// step below 1e-9 of the scale (t taken) — convergence is quadratic, so that step leaves ~1e-18
// of the scale. Lanes go in pairs through GCC's vector extension (a pair's divisions are one
// instruction: the steps are chains of divisions), each lane's update selected rather than
// skipped; every lane does the scalar step's IEEE operations in its order, so the bits are a
// point's alone whatever N is. A lane that stopped computes on without effect.
using Pair = double __attribute__((vector_size(16)));
using PairMask = long long __attribute__((vector_size(16)));

struct StepTerms {
    double f, slope;
};

inline StepTerms stepTerms(const Vec3d& r2, const Vec3d& ry, double t) {
    double s = 0, ds = 0;
    for (int i = 0; i < 3; ++i) {
        const double inv = 1.0 / (t + r2[i]);
        const double q = ry[i] * inv;
        s += q * q;
        ds -= 2.0 * q * q * inv;
    }
    return {s - 1.0, ds};
}

template <int N> void newtonSteps(const Vec3d& r2, const Vec3d* ry, const bool* live, double* t) {
    if constexpr (N % 2 == 0) {
        constexpr int P = N / 2;
        const Pair one = {1.0, 1.0}, two = {2.0, 2.0}, zero = {0.0, 0.0}, tolerance = {1e-9, 1e-9};
        const Pair R[3] = {{r2[0], r2[0]}, {r2[1], r2[1]}, {r2[2], r2[2]}};
        Pair a[P][3], tp[P];
        PairMask on[P];
        for (int k = 0; k < P; ++k) {
            for (int i = 0; i < 3; ++i) a[k][i] = Pair{ry[2 * k][i], ry[2 * k + 1][i]};
            tp[k] = Pair{t[2 * k], t[2 * k + 1]};
            on[k] = PairMask{live[2 * k] ? -1LL : 0LL, live[2 * k + 1] ? -1LL : 0LL};
        }
        for (int step = 0; step < 100; ++step) {
            PairMask any = {0, 0};
            for (int k = 0; k < P; ++k) {
                const Pair t0 = tp[k];
                Pair s = zero, ds = zero;
                for (int i = 0; i < 3; ++i) {
                    const Pair inv = one / (t0 + R[i]);
                    const Pair q = a[k][i] * inv;
                    s += q * q;
                    ds -= two * q * q * inv;
                }
                const Pair f = s - one;
                const Pair next = t0 - f / ds;
                const PairMask climbs = on[k] & (f > zero) & (ds < zero) & (next > t0);
                const PairMask done = (next - t0) <= tolerance * (t0 + R[0] + R[1] + R[2]);
                tp[k] = climbs ? next : t0;
                on[k] = climbs & ~done;
                any |= on[k];
            }
            if (!(any[0] | any[1])) break;
        }
        for (int k = 0; k < P; ++k) t[2 * k] = tp[k][0], t[2 * k + 1] = tp[k][1];
    } else {
        bool on[N];
        for (int n = 0; n < N; ++n) on[n] = live[n];
        for (int step = 0; step < 100; ++step) {
            bool any = false;
            for (int n = 0; n < N; ++n) {
                const double t0 = t[n];
                const StepTerms st = stepTerms(r2, ry[n], t0);
                const double next = t0 - st.f / st.slope;
                const bool climbs = on[n] && st.f > 0 && st.slope < 0 && next > t0;
                const bool done = next - t0 <= 1e-9 * (t0 + r2[0] + r2[1] + r2[2]);
                t[n] = climbs ? next : t0;
                on[n] = climbs && !done;
                any = any || on[n];
            }
            if (!any) break;
        }
    }
}

// Distances from N points outside-or-in to an axis-aligned ellipsoid (radii r, not all equal)
// and their closest points. The closest point is x_i = r_i² y_i / (t + r_i²) (y = |p|, first
// octant; x keeps p's signs) where F(t) = Σ (r_i y_i / (t + r_i²))² − 1 = 0, t ≥ 0 outside. F is
// convex and decreasing for t ≥ 0, so Newton's method from a point below the root climbs to it
// monotonically (quadratically near it) and never overshoots but by rounding; each term alone
// bounds F from below, so max(r_i y_i − r_i²) is such a start. The N points are solved in
// lockstep, each stopping on its own test after exactly the steps it would take alone: their
// divisions overlap in the pipeline instead of waiting on one another (a point alone is a chain
// of ~5 dependent rounds of divisions), and every point gets the same bits whatever N is.
template <int N> void ellipsoidDistances(const Vec3d& r, const Vec3d* p, double* distance, Vec3d* closest) {
    const Vec3d r2(r.x * r.x, r.y * r.y, r.z * r.z);
    Vec3d y[N], ry[N];
    double t[N];
    bool outside[N], live[N];
    // F at t = 0 (the side): its reciprocals 1 / (0 + r_i²) are the same for every point.
    const Vec3d atZero(1.0 / (0.0 + r2[0]), 1.0 / (0.0 + r2[1]), 1.0 / (0.0 + r2[2]));
    for (int n = 0; n < N; ++n) {
        y[n] = Vec3d(std::fabs(p[n].x), std::fabs(p[n].y), std::fabs(p[n].z));
        ry[n] = Vec3d(r.x * y[n].x, r.y * y[n].y, r.z * y[n].z);
        double s = 0;
        for (int i = 0; i < 3; ++i) {
            const double q = ry[n][i] * atZero[i];
            s += q * q;
        }
        outside[n] = live[n] = s - 1.0 > 0; // else on or inside the surface
        t[n] = 0;
        for (int i = 0; i < 3; ++i) t[n] = std::max(t[n], ry[n][i] - r2[i]);
    }
    newtonSteps<N>(r2, ry, live, t);
    for (int n = 0; n < N; ++n) {
        if (!outside[n]) {
            closest[n] = p[n];
            distance[n] = 0.0;
            continue;
        }
        Vec3d x;
        for (int i = 0; i < 3; ++i) x[i] = std::copysign(r2[i] * y[n][i] / (t[n] + r2[i]), p[n][i]);
        closest[n] = x;
        distance[n] = length(p[n] - x);
    }
}

} // namespace

double ellipsoidDistance(const Vec3d& r, const Vec3d& p, Vec3d& closest) {
    if (r.x == r.y && r.y == r.z) { // a sphere: the closest point is along the radius
        const double len = length(p);
        if (len <= r.x) {
            closest = p;
            return 0.0;
        }
        closest = p * (r.x / len);
        return len - r.x;
    }
    double d;
    ellipsoidDistances<1>(r, &p, &d, &closest);
    return d;
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
        if (p.core == CoreShape::Capsule) { // the segment's ends, grown by the radius
            half[i] = std::fabs(mR[i][0]) * p.size.x + p.size.y;
            continue;
        }
        double h = 0;
        for (int j = 0; j < 3; ++j) {
            const double e = mR[i][j] * p.size[j];
            h += p.core == CoreShape::Box ? std::fabs(e) : e * e;
        }
        half[i] = p.core == CoreShape::Box ? h : std::sqrt(h);
    }
    mCoreBox = {p.center - half, p.center + half};
    mMinRadius = std::min({p.size.x, p.size.y, p.size.z});
    mMaxRadius = std::max({p.size.x, p.size.y, p.size.z});
    mInverseRadii = {1.0 / p.size.x, 1.0 / p.size.y, 1.0 / p.size.z};
    mSphere = p.core == CoreShape::Ellipsoid && p.size.x == p.size.y && p.size.y == p.size.z;
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

Vec3d PreparedPrimitive::boxExcess(const Vec3d& q) const {
    // Nearest face, edge or vertex: the excess over the half extents on each axis.
    return {std::max(std::fabs(q.x) - mP.size.x, 0.0), std::max(std::fabs(q.y) - mP.size.y, 0.0),
            std::max(std::fabs(q.z) - mP.size.z, 0.0)};
}

Vec3d PreparedPrimitive::offAxis(const Vec3d& q) const {
    return {q.x - std::clamp(q.x, -mP.size.x, mP.size.x), q.y, q.z};
}

double PreparedPrimitive::coreDistance(const Vec3d& p, Vec3d& gradient) const {
    const Vec3d q = toLocal(p);
    gradient = Vec3d();
    if (mP.core == CoreShape::Capsule) {
        const Vec3d v = offAxis(q);
        const double len = length(v), d = std::max(0.0, len - mP.size.y);
        if (d > 0) gradient = toWorld(v / len);
        return d;
    }
    if (mP.core == CoreShape::Box) {
        const Vec3d e = boxExcess(q);
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
    // As coreDistance(p, gradient) without the gradient: this one runs per voxel.
    if (mSphere) return std::max(0.0, length(p - mP.center) - mP.size.x);
    const Vec3d q = toLocal(p);
    if (mP.core == CoreShape::Box) return length(boxExcess(q));
    if (mP.core == CoreShape::Capsule) return std::max(0.0, length(offAxis(q)) - mP.size.y);
    Vec3d closest;
    return ellipsoidDistance(mP.size, q, closest);
}

bool PreparedPrimitive::inCore(const Vec3d& p) const {
    const Vec3d q = toLocal(p);
    if (mP.core == CoreShape::Box) return std::fabs(q.x) <= mP.size.x && std::fabs(q.y) <= mP.size.y && std::fabs(q.z) <= mP.size.z;
    if (mP.core == CoreShape::Capsule) return length(offAxis(q)) <= mP.size.y;
    const double s = (q.x / mP.size.x) * (q.x / mP.size.x) + (q.y / mP.size.y) * (q.y / mP.size.y) + (q.z / mP.size.z) * (q.z / mP.size.z);
    return s <= 1.0;
}

double PreparedPrimitive::scaledRadius(const Vec3d& q) const {
    return length(Vec3d(q.x * mInverseRadii.x, q.y * mInverseRadii.y, q.z * mInverseRadii.z));
}

double PreparedPrimitive::distanceLowerBound(double scaled) const {
    // With p = A·u (A the radii), every core point is A·x with |x| ≤ 1, so the distance is at
    // least r_min·(|u| - 1): a cheap test that spares the root finding in the influence box's
    // corners, far from the ellipsoid.
    return mMinRadius * (scaled - 1.0);
}

bool PreparedPrimitive::beyondFalloff(const Vec3d& p) const {
    if (!mInfluence.contains(p)) return true;
    if (mP.core != CoreShape::Ellipsoid) return false; // a box's or capsule's exact distance is as cheap as a bound
    return distanceLowerBound(scaledRadius(toLocal(p))) >= mP.falloff;
}

bool PreparedPrimitive::densityWithoutRoot(const Vec3d& q, double& density) const {
    const double u = scaledRadius(q);
    if (u <= 1.0) {
        density = mP.weight;
        return true;
    }
    if (distanceLowerBound(u) >= mP.falloff) {
        density = 0.0;
        return true;
    }
    return false;
}

double PreparedPrimitive::densityOfOtherCores(const Vec3d& p) const {
    double d;
    if (mP.core == CoreShape::Ellipsoid) {
        // The hot path of rasterization: the core and far tests before the root, on one toLocal.
        const Vec3d q = toLocal(p);
        double decided;
        if (densityWithoutRoot(q, decided)) return decided;
        Vec3d closest;
        d = ellipsoidDistance(mP.size, q, closest);
    } else {
        d = coreDistance(p); // boxes and capsules: the exact distance is as cheap as any test
    }
    return mP.weight * falloffValue(d / mP.falloff);
}

void PreparedPrimitive::densities(const Vec3d* points, std::size_t count, double* out) const {
    if (mSphere) {
        // density() without branches (falloffClamped, inBox), so that the compiler runs two points
        // at a time; the other operations are density()'s, so the values keep their bits (for
        // every point but a NaN, which no voxel is). An edit that moves a sphere corrects every
        // voxel near it by two of these.
        const double radius = mP.size.x, falloff = mP.falloff, weight = mP.weight;
        const Vec3d c = mP.center;
        const Box3 influence = mInfluence;
        for (std::size_t k = 0; k < count; ++k) {
            const Vec3d& p = points[k];
            const double dx = p.x - c.x, dy = p.y - c.y, dz = p.z - c.z;
            const double s = falloffClamped(std::max(0.0, std::sqrt(dx * dx + dy * dy + dz * dz) - radius) / falloff);
            out[k] = inBox(influence, p) ? weight * s : 0.0;
        }
        return;
    }
    if (mP.core == CoreShape::Box) { // the same for boxes (coreDistance's operations: toLocal, boxExcess)
        const double falloff = mP.falloff, weight = mP.weight;
        const Box3 influence = mInfluence;
        for (std::size_t k = 0; k < count; ++k) {
            const double s = falloffClamped(length(boxExcess(toLocal(points[k]))) / falloff);
            out[k] = inBox(influence, points[k]) ? weight * s : 0.0;
        }
        return;
    }
    if (mP.core == CoreShape::Capsule) { // and for capsules (toLocal, offAxis)
        const double radius = mP.size.y, falloff = mP.falloff, weight = mP.weight;
        const Box3 influence = mInfluence;
        for (std::size_t k = 0; k < count; ++k) {
            const double s = falloffClamped(std::max(0.0, length(offAxis(toLocal(points[k]))) - radius) / falloff);
            out[k] = inBox(influence, points[k]) ? weight * s : 0.0;
        }
        return;
    }
    // density() point by point but for the roots, which wait in fours (ellipsoidDistances<4>).
    constexpr int kLanes = 4;
    Vec3d local[kLanes], closest[kLanes];
    double d[kLanes];
    std::size_t waiting[kLanes];
    int lanes = 0;
    auto solve = [&] {
        for (int n = lanes; n < kLanes; ++n) local[n] = local[0]; // spare lanes repeat a point
        ellipsoidDistances<kLanes>(mP.size, local, d, closest);
        for (int n = 0; n < lanes; ++n) out[waiting[n]] = mP.weight * falloffValue(d[n] / mP.falloff);
        lanes = 0;
    };
    for (std::size_t k = 0; k < count; ++k) {
        // As density(): the influence box, then the core and the far test before the root.
        const Vec3d& p = points[k];
        if (!mInfluence.contains(p)) {
            out[k] = 0.0;
            continue;
        }
        const Vec3d q = toLocal(p);
        if (densityWithoutRoot(q, out[k])) continue;
        local[lanes] = q;
        waiting[lanes++] = k;
        if (lanes == kLanes) solve();
    }
    if (lanes > 0) solve();
}

Vec3d PreparedPrimitive::densityGradient(const Vec3d& p) const {
    if (beyondFalloff(p)) return {};
    Vec3d g;
    const double d = coreDistance(p, g);
    return g * (mP.weight * falloffSlope(d / mP.falloff) / mP.falloff);
}

int PreparedPrimitive::area(const Vec3d& p) const {
    if (beyondFalloff(p)) return 0;
    const double d = coreDistance(p);
    if (d <= 0) return 3;
    if (d >= mP.falloff) return 0;
    return mP.weight * falloffValue(d / mP.falloff) < 0.5 ? 1 : 2;
}

double PreparedPrimitive::densityUpperBound(const Box3& box) const {
    if (box.max.x < mInfluence.min.x || box.max.y < mInfluence.min.y || box.max.z < mInfluence.min.z ||
        box.min.x > mInfluence.max.x || box.min.y > mInfluence.max.y || box.min.z > mInfluence.max.z)
        return 0.0;
    const double halfDiagonal = 0.5 * length(box.extent());
    const double dmin = std::max(0.0, coreDistance(box.center()) - halfDiagonal * (1 + 1e-12) - 1e-12);
    return mP.weight * falloffValue(dmin / mP.falloff);
}

void PreparedPrimitive::densityBounds(const Box3& box, double& lo, double& hi) const {
    // The upper bound first: where it is 0 so is the lower one (every corner is at least as far),
    // and the eight corner distances are spared.
    lo = 0;
    hi = densityUpperBound(box);
    if (!(hi > 0)) return;
    Vec3d corners[8];
    for (int k = 0; k < 8; ++k)
        corners[k] = Vec3d(k & 1 ? box.max.x : box.min.x, k & 2 ? box.max.y : box.min.y, k & 4 ? box.max.z : box.min.z);
    double dmax = 0;
    if (mP.core == CoreShape::Ellipsoid && !mSphere) { // the eight roots in two fours (ellipsoidDistances)
        Vec3d local[8], closest[8];
        double d[8];
        for (int k = 0; k < 8; ++k) local[k] = toLocal(corners[k]);
        ellipsoidDistances<4>(mP.size, local, d, closest);
        ellipsoidDistances<4>(mP.size, local + 4, d + 4, closest + 4);
        for (int k = 0; k < 8; ++k) dmax = std::max(dmax, d[k]);
    } else {
        for (int k = 0; k < 8; ++k) dmax = std::max(dmax, coreDistance(corners[k]));
    }
    lo = mP.weight * falloffValue(dmax / mP.falloff);
}

double PreparedPrimitive::nearestCorePoint(const Vec3d& p, Vec3d& closest) const {
    // The distance exactly as coreDistance(p) computes it, so bounds from either agree bit for bit.
    closest = p;
    if (mSphere) {
        const Vec3d d = p - mP.center;
        const double len = length(d);
        if (len > mP.size.x) closest = mP.center + d * (mP.size.x / len);
        return std::max(0.0, len - mP.size.x);
    }
    const Vec3d q = toLocal(p);
    if (mP.core == CoreShape::Capsule) {
        const Vec3d v = offAxis(q);
        const double len = length(v), d = std::max(0.0, len - mP.size.y);
        if (d > 0) closest = mP.center + toWorld(q - v + v * (mP.size.y / len));
        return d;
    }
    if (mP.core == CoreShape::Box) {
        const double d = length(boxExcess(q));
        const Vec3d x(std::clamp(q.x, -mP.size.x, mP.size.x), std::clamp(q.y, -mP.size.y, mP.size.y),
                      std::clamp(q.z, -mP.size.z, mP.size.z));
        if (d > 0) closest = mP.center + toWorld(x);
        return d;
    }
    Vec3d x;
    const double d = ellipsoidDistance(mP.size, q, x);
    if (d > 0) closest = mP.center + toWorld(x);
    return d;
}

DensityAnchor PreparedPrimitive::anchorAround(const Vec3d& c, double radius) const {
    DensityAnchor a;
    if (c.x + radius < mInfluence.min.x || c.y + radius < mInfluence.min.y || c.z + radius < mInfluence.min.z ||
        c.x - radius > mInfluence.max.x || c.y - radius > mInfluence.max.y || c.z - radius > mInfluence.max.z)
        return a;
    const double slack = radius * (1 + 1e-12) + 1e-12; // the caller's ball is from rounded voxel positions
    if (mP.core == CoreShape::Ellipsoid && distanceLowerBound(scaledRadius(toLocal(c))) - slack >= mP.falloff) return a;
    Vec3d x;
    const double d = nearestCorePoint(c, x);
    a.lo = mP.weight * falloffValue((d + slack) / mP.falloff);
    a.hi = mP.weight * falloffValue(std::max(0.0, d - slack) / mP.falloff);
    // The normal's direction is the closest point's rounding error over the distance: trusted
    // only a millionth of the core's size out, where that error is far below densityBoundsNear's slack.
    if (d > 1e-6 * mMaxRadius) {
        const Vec3d n = c - x;
        const double len = length(n);
        if (len > 0) {
            a.hasNormal = true;
            a.closest = x;
            a.normal = n / len;
        }
    }
    return a;
}

void PreparedPrimitive::densityBoundsNear(const DensityAnchor& a, const Vec3d& v, const Neighbourhood& around, double& lo,
                                          double& hi) const {
    densityBoundsNearBlock(a, v, 0, 1, around, &lo, &hi);
}

namespace {

// densityBoundsNearBlock's loop over the n³ points (N = n where it is known at compile time: the
// 4³ blocks the rasterizer asks for, whose rows along z of 4 the compiler then turns into vector
// operations — every lane the same IEEE operations as the scalar loop, so the same bits). Its
// inputs are copied in, so that the outputs cannot alias them.
struct NearBlockTerms {
    double nx, ny, nz, cx, cy, cz, fx, fy, fz, step, spread, corner, slack, invFalloff, loCap, hiCap, weight;
};

template <int N>
void boundsNearBlock(const NearBlockTerms t, int runtimeN, double* __restrict lo, double* __restrict hi) {
    const int n = N > 0 ? N : runtimeN;
    int index = 0;
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j, index += n) {
            // Along a row only z changes: the x and y parts of the plane's distance and of |r|² are taken once.
            const double rx = t.fx + i * t.step - t.cx, ry = t.fy + j * t.step - t.cy;
            const double planeXY = t.nx * rx + t.ny * ry, lengthXY = rx * rx + ry * ry;
            for (int k = 0; k < n; ++k) {
                const double rz = t.fz + k * t.step - t.cz;
                const double len = std::sqrt(lengthXY + rz * rz);
                const double dmin = planeXY + t.nz * rz - t.spread - t.slack;
                const double dmax = len + t.corner + t.slack;
                lo[index + k] = std::max(t.loCap, t.weight * falloffClamped(dmax * t.invFalloff));
                hi[index + k] = std::min(t.hiCap, t.weight * falloffClamped(dmin * t.invFalloff));
            }
        }
}

} // namespace

void PreparedPrimitive::densityBoundsNearBlock(const DensityAnchor& a, const Vec3d& first, double step, int n,
                                               const Neighbourhood& around, double* lo, double* hi) const {
    // The neighbourhoods lie in the anchor's ball (the caller's promise), so the ball's bounds hold too.
    const int count = n * n * n;
    if (!a.hasNormal || !(a.lo < a.hi)) {
        std::fill(lo, lo + count, a.lo);
        std::fill(hi, hi + count, a.hi);
        return;
    }
    const Vec3d& nrm = a.normal;
    const double e = around.halfWidth, s = around.shift;
    NearBlockTerms t;
    t.nx = nrm.x, t.ny = nrm.y, t.nz = nrm.z;
    t.cx = a.closest.x, t.cy = a.closest.y, t.cz = a.closest.z;
    t.fx = first.x, t.fy = first.y, t.fz = first.z, t.step = step;
    // Over the neighbourhood, the plane's distance n·(p − x) falls at most this far below its value
    // at the centre, and |p − x| rises at most `corner` (the farthest point: a cube's corner, shifted).
    t.spread = e * (std::fabs(nrm.x) + std::fabs(nrm.y) + std::fabs(nrm.z)) +
               s * std::max({std::fabs(nrm.x), std::fabs(nrm.y), std::fabs(nrm.z)});
    t.corner = std::sqrt(3.0 * e * e + 2.0 * e * s + s * s);
    t.invFalloff = 1.0 / mP.falloff;
    // Rounding in the closest point, the normal and the sums below is ~1e-15 of the lengths
    // involved; one slack for the whole block, from its farthest point.
    const double reach = std::sqrt(3.0) * (n - 1) * step;
    t.slack = 1e-9 * (length(first - a.closest) + reach + mMaxRadius) +
              1e-14 * (std::fabs(first.x) + std::fabs(first.y) + std::fabs(first.z) + 3 * (n - 1) * step);
    t.loCap = a.lo, t.hiCap = a.hi, t.weight = mP.weight;
    if (n == 4) boundsNearBlock<4>(t, n, lo, hi); // (the rasterizer's blocks, DensityScene::kNearBlock)
    else boundsNearBlock<0>(t, n, lo, hi);
}

} // namespace vdbsurf
