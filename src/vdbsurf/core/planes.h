// Where planes meet: the one small solve both the sharp pass and the surface fit need.
#pragma once
#include "vdbsurf/core/vec3.h"

#include <cmath>

namespace vdbsurf {

// The point where the three planes {x : n_i · x = rhs_i} meet, if the system is well conditioned.
// Cramer's rule by cross products: with unit normals the determinant is the volume they span,
// bounded below here, so the quotient loses at most three digits; the same answer as an LU solve
// to within rounding, for a fraction of its cost.
inline bool intersectPlanes(const Vec3d n[3], const double rhs[3], Vec3d& out) {
    const Vec3d c12 = cross(n[1], n[2]), c20 = cross(n[2], n[0]), c01 = cross(n[0], n[1]);
    const double det = dot(n[0], c12);
    if (!(std::fabs(det) >= 1e-3)) return false; // below this the point runs off
    out = (c12 * rhs[0] + c20 * rhs[1] + c01 * rhs[2]) / det;
    return std::isfinite(out.x) && std::isfinite(out.y) && std::isfinite(out.z);
}

} // namespace vdbsurf
