// OpenVDB's own mesher, tools::volumeToMesh (adaptivity 0), as the peer vdbsurf is measured
// against in `vdbsurf compare` and the benchmarks. When a lattice spacing other than the grid's
// is asked for, the grid is first resampled onto that lattice with tools::resampleToMatch (level
// sets are rebuilt, as vdb_tool's -resample does), so both meshers see nodes at the same places.
#pragma once
#include "vdbsurf/core/lattice_frame.h"
#include "vdbsurf/field/field.h"
#include "vdbsurf/mesh/mesh.h"
#include "vdbsurf/vdb/openvdb_fwd.h"

namespace vdbsurf {

struct PeerMesh {
    Mesh mesh;                  // volumeToMesh's quads and triangles, its vertex order kept
    bool resampled = false;
    double secondsResample = 0; // resampling onto the lattice, when needed
    double secondsMesh = 0;     // volumeToMesh itself
};

// frame: the lattice to mesh on (node (i,j,k) at origin + h (i,j,k), mapped to world by `own`
// where not null: a lattice in a rotated or frustum grid's own frame); null: the grid's own
// voxels. Throws Error when the grid is not a float or double grid.
PeerMesh volumeToMeshPeer(const GridBaseCPtr& grid, double iso, const LatticeFrame* frame, const OwnFrame* own = nullptr);

} // namespace vdbsurf
