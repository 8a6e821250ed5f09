// The deformed lattice of Deformed Marching Cubes: which nodes moved, where to (an offset in
// world units, always inside the node's own cell Ω = node + [-h/2, h/2)^3, so deformed cells
// never fold), and which nodes were placed on a sharp feature of the surface. A node on a feature
// takes the iso value itself but keeps the side it had before it moved (insideOnSurface), so
// the cell cases, and with them the mesh's topology, do not change: only the crossings on its
// edges move onto it. Sparse VDB trees in lattice node index space (with small internal nodes:
// vdb/sparse_tree.h); --lattice-out writes the offsets as a standard Vec3f grid.
#pragma once
#include "vdbsurf/core/lattice_frame.h"
#include "vdbsurf/field/field.h"
#include "vdbsurf/vdb/sparse_tree.h"

#include <openvdb/openvdb.h>

#include <algorithm>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace vdbsurf {

struct Lattice;

// Trees for the few nodes a deformation touches: sparse_tree.h says why not the standard ones.
// Offsets take 12 bytes a node, so their leaves are 4^3 nodes (768 bytes) under internal nodes
// of 4^3 and 8^3 entries: feature nodes lie along curves, a few to a leaf, and 8^3 leaves (6 KB
// each, filled when made) took the armadillo's 2,181 moved nodes to 4.1 MB of fresh memory,
// 1.7 ms of page faults in the sharp pass's serial placement; this layout holds them in 1.3 MB.
using OffsetTree = openvdb::tree::Tree<openvdb::tree::RootNode<
    openvdb::tree::InternalNode<openvdb::tree::InternalNode<openvdb::tree::LeafNode<openvdb::Vec3f, 2>, 2>, 3>>>;
using NodeMaskTree = SparseNodeTree<openvdb::ValueMask>;

struct LatticeDeformation {
    OffsetTree::Ptr offsets = std::make_shared<OffsetTree>(openvdb::Vec3f(0.0f));
    NodeMaskTree::Ptr onSurface = std::make_shared<NodeMaskTree>(false);
    NodeMaskTree::Ptr insideOnSurface = std::make_shared<NodeMaskTree>(false); // subset of onSurface

    bool empty() const { return offsets->empty() && onSurface->empty(); }
    std::uint64_t movedNodes() const { return offsets->activeVoxelCount(); }
    // Frees the trees this deformation alone holds (vdb/sparse_tree.h: clearTree) and leaves it
    // empty: the mesher does so while the mesh is made.
    void release();
};

// The float offset that moves a node by `rel` (world units), if that stays in its Ω. A point on
// the border between two Ω (an edge's middle) is rounded to either side, so it is taken a hair
// inside; so is any float that would round out.
inline std::optional<Vec3f> offsetInOmega(Vec3d rel, double h) {
    const double half = h / 2, tol = 1e-6 * h, inner = half * (1 - 1e-5);
    for (int i = 0; i < 3; ++i) {
        double& r = rel[std::size_t(i)];
        if (r < -half - tol || r >= half + tol) return std::nullopt;
        r = std::clamp(r, -inner, inner);
    }
    return Vec3f(rel);
}

// Activates the cells around every moved node (clipped to the lattice's range): a node that
// moved can change the sides of the cells it is a corner of.
void activateCellsAroundMovedNodes(Lattice& lattice, const LatticeDeformation& deformation);

// Activates the cells around the given nodes only (clipped likewise): after the sharp pass,
// the nodes that changed side. A node placed on a feature keeps its side, so the cells around
// it keep their cases, and those with no surface need not become active.
void activateCellsAround(Lattice& lattice, const std::vector<Vec3i>& nodes);

// Writes the deformed lattice as a .vdb readable by any OpenVDB tool: a Vec3f grid "offsets"
// (world-unit node offsets; every node of an active cell is active, unmoved nodes hold zero), a
// mask grid "cells" (the lattice's active cells) and a mask grid "on_surface" (nodes placed on
// sharp features), with the lattice spacing and origin as their transform. `own` (not null where
// the lattice lies in a field's own frame) maps it to world: the grids' transform follows the
// frame (a rotated grid's lattice is rotated with it, a frustum grid's is a frustum), the
// offsets are world vectors (from the node's place to where it moved).
void writeLatticeVdb(const std::string& path, const Lattice& lattice, const LatticeDeformation& deformation,
                     const std::map<std::string, std::string>& metadata, const OwnFrame* own = nullptr);
// The same three grids, to write later (`mesh --lattice-out` writes them with the mesh, so that
// a run cancelled in between leaves neither). `what` names the output in errors.
std::vector<GridBasePtr> latticeGrids(const Lattice& lattice, const LatticeDeformation& deformation,
                                      const std::map<std::string, std::string>& metadata, const OwnFrame* own, const std::string& what);

} // namespace vdbsurf
