// Where the mesh lattice's nodes sit in world space: node (i, j, k) is at origin + h * (i, j, k),
// and cell (i, j, k) spans nodes (i, j, k) to (i+1, j+1, k+1).
#pragma once
#include "vdbsurf/core/vec3.h"

namespace vdbsurf {

struct LatticeFrame {
    Vec3d origin;
    double h = 1.0;

    Vec3d nodeWorld(const Vec3i& n) const { return origin + Vec3d(n) * h; }
    Vec3d nodeWorld(double i, double j, double k) const { return origin + Vec3d(i, j, k) * h; }
    Box3 cellBox(const Vec3i& c) const { return {nodeWorld(c), nodeWorld(c + Vec3i(1, 1, 1))}; }
    // Box spanning the nodes first .. last (inclusive).
    Box3 nodeBox(const Vec3i& first, const Vec3i& last) const { return {nodeWorld(first), nodeWorld(last)}; }
};

} // namespace vdbsurf
