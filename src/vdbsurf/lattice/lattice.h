// Lattice: the cells of a uniform lattice of spacing h that may hold surface, as the active
// voxels of a sparse OpenVDB mask tree (vdb/sparse_tree.h) in lattice index space (voxel
// (i,j,k) = cell (i,j,k)). Found top-down from the field's conservative bounds, one VDB node at a time: a node (4096^3, 128^3 or
// 8^3 cells) whose bounds do not straddle the iso value is skipped whole, so work grows with
// the surface, never with the bounding box.
#pragma once
#include "vdbsurf/core/lattice_frame.h"
#include "vdbsurf/field/field.h"
#include "vdbsurf/vdb/sparse_tree.h"

#include <cstdint>
#include <vector>

namespace vdbsurf {

class CancelToken;

struct LatticeStats {
    std::uint64_t upperNodesTested = 0; // 4096^3 and 128^3 blocks whose bounds were asked
    std::uint64_t leafBlocksTested = 0; // 8^3 blocks whose bounds were asked
    std::uint64_t leafBlocksVisited = 0; // 8^3 blocks whose cells were examined one by one
    std::uint64_t cellsExamined = 0;
    std::uint64_t cellsActive = 0;
    // Active cells whose every value is what the field calls no data (Field::dropCellsWithoutData):
    // they stay among the cells, which must hold the owner of every edge a meshed cell crosses,
    // and when there are any the mesher leaves out the polygons on no data.
    std::uint64_t cellsWithoutData = 0;
    double seconds = 0;
};

struct Lattice {
    LatticeFrame frame;
    openvdb::CoordBBox cellRange;   // cells considered (from the field's domain)
    CellTree::Ptr cells;           // active voxel = cell that may hold surface
    // Where the corner values decide the cells (CellTest::CornerSigns, or a field whose cell
    // bounds are its corners' range): the nodes inside whose six neighbours all lie outside, in
    // node order (only nodes whose eight cells are in the range). Marching cubes meshes each as a
    // bubble of its own; DMC asks whether the field joins it to a node across a face.
    std::vector<openvdb::Coord> loneInsideNodes;
    LatticeStats stats;
};

// The cells covering the field's domain on this frame. Throws Error naming "--voxel-size" when
// h is not a positive finite number or gives an absurd lattice.
openvdb::CoordBBox latticeCellRange(const Field& field, const LatticeFrame& frame);

enum class CellTest {
    Bounds,      // cells whose bounds straddle iso: every cell the surface may pass (thin parts too)
    CornerSigns  // only cells whose corner values change side: all that plain marching cubes meshes
};

// Bytes a mesh takes while it is made, per active cell (about one vertex each): DMC on smooth
// surfaces and gyroids peaks at 100-160 (the lattice, the deformation, crossings, the mesh).
constexpr double kMeshBytesPerActiveCell = 128;

// Active cells: those whose corner values change side (so that every edge with a sign change has
// its owning cell active, whatever the rounding of the bounds), plus, with CellTest::Bounds, those
// whose bounds straddle iso; those among them without data are counted (stats.cellsWithoutData).
// Blocks above the cells are always culled by their bounds. Throws Error naming the field where a node
// value is NaN, and Error naming "--voxel-size" as soon as the cells found would need more than
// memoryLimit bytes to mesh (kMeshBytesPerActiveCell each; 0: 80 % of the memory free when it
// starts) — past it the kernel would kill the process.
Lattice buildLattice(const Field& field, const LatticeFrame& frame, const openvdb::CoordBBox& cellRange, double iso,
                     CellTest test = CellTest::Bounds, const CancelToken* cancel = nullptr, double memoryLimit = 0);

} // namespace vdbsurf
