// The transform of every grid vdbsurf writes: a uniform voxel size. OpenVDB refuses a scale whose
// determinant is below 3e-15 (voxels under about 1.44e-5 world units) with an ArithmeticError
// that names nothing; this refuses it first, saying which voxel size and why.
#pragma once
#include "vdbsurf/core/lattice_frame.h"
#include "vdbsurf/field/field.h"
#include "vdbsurf/vdb/openvdb_fwd.h"

#include <memory>
#include <string>

namespace vdbsurf {

// The smallest uniform voxel size OpenVDB stores (about 1.44e-5).
double smallestStorableVoxelSize();

// Throws Error naming `what` (the option or input the voxel size came from) when a .vdb grid
// cannot have voxels of this size.
std::shared_ptr<openvdb::math::Transform> voxelTransform(double voxelSize, const std::string& what);

// The transform whose voxel (i, j, k) is the lattice node `frame` puts at (i, j, k), mapped to
// world by `own` where not null (a lattice in a field's own frame — a rotated grid's, a frustum
// grid's — as world sees it). Throws Error naming `what` when OpenVDB cannot store it (voxels too
// small).
std::shared_ptr<openvdb::math::Transform> latticeTransform(const LatticeFrame& frame, const OwnFrame* own, const std::string& what);

} // namespace vdbsurf
