// Marching cubes on a sparse, possibly deformed, lattice: the surface of a Field over the active
// cells of a Lattice whose nodes may have moved (LatticeDeformation). Parallel over the
// lattice's VDB leaves (one leaf = one TBB task). Each lattice edge with a crossing gets exactly
// one vertex, computed by the leaf of the cell that owns the edge, so vertices are shared between
// leaves without duplicates; vertices and polygons are numbered leaf by leaf in tree order, so
// the output does not depend on the number of threads.
//
// Crossings: where the field is linear along undeformed lattice edges (a grid at its own voxel
// size) by linear interpolation, which is then exact; otherwise Field::edgeCrossing on the true
// field along the (deformed) edge. Normals likewise: interpolated node gradients where the field
// is linear along undeformed edges, else the field's gradient. A node whose value is exactly the iso value (data, or a node
// placed on a sharp feature) carries the crossings of all its edges; those vertices are welded
// into one and the polygons that collapse are removed, so there are no slivers and no cracks;
// where separate fans of polygons meet at such a node, each further fan gets its own copy.
#pragma once
#include "vdbsurf/field/field.h"
#include "vdbsurf/lattice/lattice.h"
#include "vdbsurf/mesh/mesh.h"

#include <functional>
#include <memory>
#include <vector>

namespace vdbsurf {

class CancelToken;
struct LatticeDeformation;

struct SurfaceOptions {
    double iso = 0;
    bool triangulate = false; // split quads (shorter diagonal): triangles only
    // Emit loops of five or more vertices whole (not fanned from a corner), for a step after the
    // surface that fans them round a centre itself (the surface fit).
    bool keepLoops = false;
    bool normals = false;     // also compute the unit outward normal at every crossing
    // With normals: cells whose crossing normals provably all lie within this cosine of each
    // other are not sharp candidates (see node_gradients.h), nor are the cells of a leaf where
    // nearly all surface cells would be (unresolved: SurfaceStats::unresolvedLeaves); 1 makes
    // every cell a candidate.
    double sharpEdgeCosine = 1.0;
    // With normals on a grid at its own voxel size: a leaf where at least this share of 32 or
    // more surface cells are candidates is not resolved (noise) and none of its cells is one.
    double unresolvedShare = 0.95;
    const CancelToken* cancel = nullptr;
};

struct SurfaceStats {
    std::uint64_t cellsWithSurface = 0;
    std::uint64_t leaves = 0;
    std::uint64_t weldedVertices = 0;
    std::uint64_t collapsedPolygons = 0;
    std::uint64_t splitVertices = 0; // welded nodes given one copy per further fan of polygons
    std::uint64_t foldsClosed = 0;   // vertices whose fan two polygons closed alone, folded (mesh/mesh_folds.h)
    std::uint64_t separatedVertices = 0; // vertices left on one node's point, moved apart (mesh/separate_points.h)
    // Leaves where nearly every surface cell's normals may turn past the edge threshold: the
    // surface is not resolved there (noise) and they hold no sharp candidates.
    std::uint64_t unresolvedLeaves = 0;
    double seconds = 0;
};

// The crossings on the edges of one cell with surface: position and (if asked) outward unit
// normal per cube edge (cube_table.h numbering); only edges in cubeCase(config).edgeMask are set.
struct CellCrossings {
    openvdb::Coord cell;
    unsigned config = 0;
    const Vec3f* position = nullptr; // [12]
    const Vec3f* normal = nullptr;   // [12], null unless SurfaceOptions::normals
};

class LatticeSurface {
public:
    // The lattice and deformation must outlive this object.
    LatticeSurface(const Field& field, const Lattice& lattice, const LatticeDeformation* deformation,
                   const SurfaceOptions& options);
    ~LatticeSurface();
    LatticeSurface(const LatticeSurface&) = delete;
    LatticeSurface& operator=(const LatticeSurface&) = delete;

    // Calls fn for every cell with surface, in parallel (fn must be thread-safe); with
    // onlySharpCandidates, skips the cells that cannot hold a sharp edge (SurfaceOptions).
    void forEachSurfaceCell(const std::function<void(const CellCrossings&)>& fn, bool onlySharpCandidates = false) const;

    // After the sharp pass flipped nodes to the other side (and bridged them; `nodes` lists both)
    // and the lattice gained the cells around moved nodes: recomputes, with `deformation`, the
    // leaves holding cells at those nodes and the leaves that gained cells (new leaves among
    // them), as a new surface would. Follow it with moveCrossingsToFeatureNodes for the feature
    // nodes elsewhere.
    void rebuildAround(const std::vector<Vec3i>& nodes, const LatticeDeformation& deformation);

    // After nodes were placed on sharp features (deformation.onSurface; each keeps its side, so
    // no cell case changes): the crossing on every edge of such a node becomes the node itself.
    // Returns how many crossings moved.
    std::uint64_t moveCrossingsToFeatureNodes(const LatticeDeformation& deformation);

    // The mesh: polygons oriented with normals from inside to outside. `beforeWeld`, if given,
    // may refine the polygons before the crossings at nodes are welded; it is told which vertices
    // the weld will join (crossings at a node), and must keep every vertex in place and numbered
    // as it was, only appending new ones. Once only: the surface's own data is freed then, and
    // stats() alone stays.
    Mesh mesh(const std::function<void(Mesh&, const std::vector<std::uint32_t>&)>& beforeWeld = {});
    const SurfaceStats& stats() const;

    struct Impl;

private:
    std::unique_ptr<Impl> mImpl;
};

// Plain marching cubes on an undeformed lattice, as one call.
Mesh marchingCubes(const Field& field, const Lattice& lattice, const SurfaceOptions& options, SurfaceStats* stats = nullptr);

} // namespace vdbsurf
