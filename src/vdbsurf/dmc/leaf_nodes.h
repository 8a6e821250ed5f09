// The nodes of one lattice leaf's cells: an 8^3 block of cells has 9^3 corner nodes. The first
// pass of the surface and the thin search's cell classification both sample them the same way.
#pragma once
#include "vdbsurf/field/field.h"
#include "vdbsurf/vdb/sparse_tree.h"

#include <openvdb/openvdb.h>

#include <array>
#include <cstdint>

namespace vdbsurf {

constexpr int kLeafNodesPerSide = 9;
constexpr int kLeafNodeCount = kLeafNodesPerSide * kLeafNodesPerSide * kLeafNodesPerSide;

inline int leafNodeIndex(int x, int y, int z) { return x + kLeafNodesPerSide * (y + kLeafNodesPerSide * z); }

// The node at corner c (cube_table.h numbering) of the leaf's cell at local offset `offset`.
inline int leafCornerIndex(openvdb::Index offset, int c) {
    const int x = int(offset >> 6), y = int((offset >> 3) & 7), z = int(offset & 7);
    return leafNodeIndex(x + (c & 1), y + ((c >> 1) & 1), z + ((c >> 2) & 1));
}

// Marks the corners of the leaf's active cells.
inline void markLeafNodes(const CellTree::LeafNodeType& leaf, std::array<std::uint8_t, kLeafNodeCount>& needed) {
    needed.fill(0);
    for (auto it = leaf.cbeginValueOn(); it; ++it)
        for (int c = 0; c < 8; ++c) needed[std::size_t(leafCornerIndex(it.pos(), c))] = 1;
}

// Values at the corners of the leaf's active cells (`needed` marks them; other entries unset).
inline void sampleLeafNodes(const Field& field, const LatticeFrame& frame, const CellTree::LeafNodeType& leaf,
                            std::array<std::uint8_t, kLeafNodeCount>& needed, std::array<double, kLeafNodeCount>& values) {
    markLeafNodes(leaf, needed);
    const openvdb::Coord o = leaf.origin();
    field.sampleNodes(frame, {o.x(), o.y(), o.z()}, {kLeafNodesPerSide, kLeafNodesPerSide, kLeafNodesPerSide}, needed.data(),
                      values.data());
}

} // namespace vdbsurf
