// One density primitive of seed 003: a core (ellipsoid, box or capsule) where the density is its weight,
// falling off smoothly with the distance to the core's surface over the influence width, zero
// beyond. Owns the falloff function, exact distances to the cores, and per-primitive bounds over
// a box. Scenes (scene.h) sum primitives; the rasterizer and the mesher only see the scene.
#pragma once
#include "vdbsurf/core/vec3.h"

#include <algorithm>
#include <cstddef>
#include <string>

namespace vdbsurf {

enum class CoreShape { Ellipsoid, Box, Capsule };
enum class DensityOp { Add, Subtract };

// The falloff s(t) over t = distance / falloff: 1 - 3t² + 2t³ on [0, 1], 0 beyond. The cubic
// Hermite step is the lowest-degree polynomial with s(0) = 1, s(1) = 0 and zero slope at both
// ends, so the density is C1 where the core ends and where the influence ends; and s(1/2) = 1/2,
// so a lone primitive of weight 1 has its 0.5 surface exactly half the falloff outside its core.
// Inline, as the density of a sphere is: those two are an edit's work at every voxel it corrects.
inline double falloffValue(double t) {
    if (t <= 0) return 1.0;
    if (t >= 1) return 0.0;
    return 1.0 - t * t * (3.0 - 2.0 * t);
}
double falloffSlope(double t); // ds/dt

struct Primitive {
    std::string name;           // optional label, for messages
    CoreShape core = CoreShape::Ellipsoid;
    Vec3d center;
    // Radii (ellipsoid) or half extents (box), > 0; a capsule's (half length ≥ 0, radius > 0,
    // radius): the points within its radius of a segment along its local x axis.
    Vec3d size{1, 1, 1};
    Vec3d rotationDegrees;      // about x, then y, then z
    double falloff = 0.5;       // influence width beyond the core, > 0
    double weight = 1.0;        // density in the core, > 0
    DensityOp op = DensityOp::Add;
};

// What one exact distance at a point c tells about a primitive's density near c. Besides the
// bounds over a ball around c, the nearest core point x and the unit normal n = (c − x)/|c − x|
// bound the distance at every p, because the core is convex: it lies in the half-space
// n·(y − x) ≤ 0, so the distance is at least n·(p − x); and x is a core point, so it is at most
// |p − x|. Near c both are tight to second order (unlike c's distance ± |p − c|), which is
// what lets a block of voxels be decided voxel by voxel without a root per voxel.
struct DensityAnchor {
    double lo = 0, hi = 0; // the density's bounds over the ball
    bool hasNormal = false; // c is outside the core by enough that n is accurate
    Vec3d closest, normal;
};

// The points around v that a bound covers: the cubes of half width halfWidth centred at v and at
// v ± shift along each axis (shift 0: one cube). A voxel whose 3³ block the surface crosses is a
// corner of a crossed lattice cell; with shift one voxel, its axis neighbours' blocks too, whose
// central differences read it.
struct Neighbourhood {
    double halfWidth = 0, shift = 0;
};

// A primitive prepared for evaluation: its rotation as a matrix and its bounding boxes.
class PreparedPrimitive {
public:
    explicit PreparedPrimitive(const Primitive& p);

    const Primitive& primitive() const { return mP; }
    double sign() const { return mP.op == DensityOp::Add ? 1.0 : -1.0; }

    // Distance from p to the core (0 inside it), and its gradient (zero inside).
    double coreDistance(const Vec3d& p) const;
    double coreDistance(const Vec3d& p, Vec3d& gradient) const;
    bool inCore(const Vec3d& p) const;

    // This primitive's own density (weight · s(d / falloff)), unsigned.
    double density(const Vec3d& p) const {
        if (!mInfluence.contains(p)) return 0.0;
        if (mSphere) return mP.weight * falloffValue(std::max(0.0, length(p - mP.center) - mP.size.x) / mP.falloff);
        return densityOfOtherCores(p);
    }
    // density() at `count` points (the same bits), faster: ellipsoid roots are found four at a
    // time, spheres two points at a time.
    void densities(const Vec3d* points, std::size_t count, double* out) const;
    Vec3d densityGradient(const Vec3d& p) const;
    // 0: outside the influence, 1: 0 < ρ < 0.5, 2: 0.5 ≤ ρ < weight, 3: the core (seed 003's areas).
    int area(const Vec3d& p) const;

    // Conservative bounds of density() over a box: the distance to a convex core is convex, so
    // its maximum over the box is at a corner (exact); its minimum is bounded by the centre's
    // distance less the half diagonal (distance is 1-Lipschitz).
    void densityBounds(const Box3& box, double& lo, double& hi) const;
    // Whether the density can be non-zero in the box (its bounds there, as densityBounds).
    bool reaches(const Box3& box, double& lo, double& hi) const {
        densityBounds(box, lo, hi);
        return hi > 0;
    }
    bool reaches(const Box3& box) const { return densityUpperBound(box) > 0; } // the same answer, without lo
    double densityUpperBound(const Box3& box) const; // densityBounds' hi alone (one distance)
    // The same over a ball, from the centre's distance alone (cheaper and looser, for small
    // blocks), with what that distance found on the way; then bounds over a neighbourhood of v
    // inside the ball from the anchor alone — a few flops, no root.
    DensityAnchor anchorAround(const Vec3d& centre, double radius) const;
    void densityBoundsNear(const DensityAnchor& anchor, const Vec3d& v, const Neighbourhood& around, double& lo, double& hi) const;
    // The same for the n³ points first + step·(i, j, k), k fastest, into lo[] and hi[].
    void densityBoundsNearBlock(const DensityAnchor& anchor, const Vec3d& first, double step, int n, const Neighbourhood& around,
                                double* lo, double* hi) const;

    // Where the density can be non-zero (core grown by the falloff), and the core's own box.
    const Box3& influenceBox() const { return mInfluence; }
    const Box3& coreBox() const { return mCoreBox; }

private:
    double densityOfOtherCores(const Vec3d& p) const; // density() of boxes, capsules and ellipsoids other than spheres
    Vec3d toLocal(const Vec3d& p) const;
    Vec3d toWorld(const Vec3d& v) const;
    bool beyondFalloff(const Vec3d& p) const; // a cheap sufficient test for density 0
    double scaledRadius(const Vec3d& local) const; // ellipsoids: |local / radii|, ≤ 1 in the core
    double distanceLowerBound(double scaled) const; // ellipsoids: the distance is at least this
    // Ellipsoids, at a local point: the density when it needs no root (in the core, or beyond the
    // falloff by distanceLowerBound), and whether it did.
    bool densityWithoutRoot(const Vec3d& local, double& density) const;
    double nearestCorePoint(const Vec3d& p, Vec3d& closest) const; // coreDistance(p), and the point (world)
    Vec3d boxExcess(const Vec3d& local) const;  // box cores: how far past each face
    Vec3d offAxis(const Vec3d& local) const;    // capsule cores: from the nearest point of the segment
    Primitive mP;
    double mR[3][3]; // local -> world rotation (columns: the local axes in world)
    Box3 mInfluence, mCoreBox;
    double mMinRadius = 0, mMaxRadius = 0;
    Vec3d mInverseRadii;
    bool mSphere = false; // an ellipsoid with equal radii: distances without rotation or root
};

// Exact distance from a point to the surface of an axis-aligned ellipsoid (radii r, centred at
// the origin) for a point outside it, and the closest point; by Newton's method on the Lagrange
// multiplier, whose equation is convex and monotone outside (so the root is unique and the
// iteration climbs to it from below). Spheres take the radial shortcut.
double ellipsoidDistance(const Vec3d& radii, const Vec3d& p, Vec3d& closest);

} // namespace vdbsurf
