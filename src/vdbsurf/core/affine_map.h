// An affine map of 3-space, p -> A p + t: how a field's own frame (where a grid's voxels lie on
// an axis-aligned lattice) sits in world space, for grids whose transform rotates, mirrors,
// shears or scales its axes unequally. Kept free of OpenVDB so the mesh side can apply it.
#pragma once
#include "vdbsurf/core/vec3.h"

namespace vdbsurf {

struct AffineMap {
    double a[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}; // a[row][column]
    Vec3d t;

    Vec3d linear(const Vec3d& v) const {
        return {a[0][0] * v.x + a[0][1] * v.y + a[0][2] * v.z, a[1][0] * v.x + a[1][1] * v.y + a[1][2] * v.z,
                a[2][0] * v.x + a[2][1] * v.y + a[2][2] * v.z};
    }
    Vec3d apply(const Vec3d& p) const { return linear(p) + t; }
    double determinant() const {
        return a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0]) +
               a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
    }
    // A mirroring map turns outward-facing polygons inward: their vertex order must be reversed.
    bool mirrors() const { return determinant() < 0; }
};

} // namespace vdbsurf
