// A narrow-band level-set grid sampled from a signed distance function: how the tests and
// benchmarks make inputs with a known surface (thin plates, rods, shells, gaps at any
// orientation) that OpenVDB's own primitives (spheres, boxes) do not cover.
#pragma once
#include "vdbsurf/core/vec3.h"
#include "vdbsurf/vdb/openvdb_fwd.h"

#include <functional>

namespace vdbsurf {

// Voxels of spacing voxelSize whose centres lie in `box` and within `halfWidth` voxels of the
// surface hold sdf (negative inside); the rest is flood-filled to ±halfWidth·voxelSize. Named
// "surface", class level set.
GridBasePtr levelSetFromDistance(const std::function<double(const Vec3d&)>& sdf, const Box3& box, double voxelSize,
                                 double halfWidth = 3.0);

} // namespace vdbsurf
