// Trees for sparse sets of lattice cells and nodes. OpenVDB's standard configuration (internal
// nodes of 32^3 and 16^3 entries above 8^3 leaves) allocates and fills a 32^3-entry node per
// 4096^3 octant and a 16^3-entry node per 128^3 block that holds a single cell: 256 KB and 32 KB
// of fresh memory, which a new process pays for a page fault at a time. A lattice around the
// origin (most scanned and modelled data) touches all eight octants: 2 MB for the armadillo's
// mask of cells, a third of what its mesh's arrays take; the deformation's offsets of its 2,200
// feature nodes took 8.8 MB. Internal nodes of 8^3 entries at both levels cover the same index
// space with far less; the leaves are OpenVDB's usual 8^3.
#pragma once
#include <openvdb/openvdb.h>

#include <cstddef>
#include <vector>

namespace vdbsurf {

template <typename ValueT>
using SparseNodeTree = openvdb::tree::Tree<
    openvdb::tree::RootNode<openvdb::tree::InternalNode<openvdb::tree::InternalNode<openvdb::tree::LeafNode<ValueT, 3>, 3>, 3>>>;

// Empties a tree, freeing its nodes on the calling thread when they are few (else as OpenVDB
// does, in parallel). Tree::clear frees leaves on all threads: where one thread made them (the
// sharp pass places feature nodes serially), every free on another thread goes to that thread's
// heap under its lock, and the two threads took twice as long as one (the armadillo's
// deformation: 0.72 ms against 0.31).
template <typename TreeT>
void clearTree(TreeT& tree, std::size_t serialLeaves = 16384) {
    if (tree.leafCount() <= serialLeaves) {
        std::vector<typename TreeT::LeafNodeType*> leaves;
        tree.stealNodes(leaves);
        for (auto* leaf : leaves) delete leaf;
        std::vector<typename TreeT::RootNodeType::ChildNodeType*> upper;
        tree.stealNodes(upper);
        for (auto* node : upper) delete node;
    }
    tree.clear();
}

// The cells of a lattice (active voxel = cell), as Lattice holds them.
using CellTree = SparseNodeTree<openvdb::ValueMask>;

// The same set in OpenVDB's standard mask tree, for files other tools read (only trees of the
// standard configurations are registered for I/O).
inline openvdb::MaskTree::Ptr toStandardMaskTree(const CellTree& cells) {
    auto out = std::make_shared<openvdb::MaskTree>(false);
    for (auto leaf = cells.cbeginLeaf(); leaf; ++leaf) out->addLeaf(new openvdb::MaskTree::LeafNodeType(*leaf));
    auto tile = cells.cbeginValueOn();
    tile.setMaxDepth(CellTree::ValueOnCIter::LEAF_DEPTH - 1); // tiles only: leaves are copied whole above
    for (; tile; ++tile) out->fill(tile.getBoundingBox(), true, true);
    return out;
}

} // namespace vdbsurf
