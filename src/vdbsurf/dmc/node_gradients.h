// Central-difference gradients at the nodes of one lattice leaf, for a grid meshed at its own
// voxel size (Field::edgesAreLinear). The leaf's node values plus a one-node apron give each
// node's gradient; a crossing's normal is then its edge's two node gradients interpolated, which
// is what the field's own gradient (central differences of the trilinear interpolant) gives
// across the edge, from 12 values instead of 48 trilinear lookups.
//
// They also tell which cells cannot hold a sharp edge: every crossing normal in a cell is a
// positive combination of two of its corner gradients, and the widest angle within a spherical
// convex hull (in a hemisphere) is between two of its generators; so when the corners' unit
// gradients all lie within the edge cosine of each other, no two crossing normals can fall below
// it, and the sharp-feature pass skips the cell without gathering its crossings.
#pragma once
#include "vdbsurf/dmc/leaf_nodes.h"

#include <array>
#include <cmath>
#include <cstdint>

namespace vdbsurf {

class NodeGradients {
public:
    // Values of the leaf's nodes at `origin` and of the nodes beside them (one sampleNodes call:
    // a grid copies its leaf buffers).
    void sample(const Field& field, const LatticeFrame& frame, const openvdb::Coord& origin) {
        mUnitState.fill(0);
        field.sampleNodes(frame, {origin.x() - 1, origin.y() - 1, origin.z() - 1}, {kSide, kSide, kSide}, nullptr, mValues.data());
    }

    // Gradient (index units) at a node of the leaf.
    Vec3d at(const Vec3i& n) const {
        return Vec3d(mValues[index(n.x + 1, n.y, n.z)] - mValues[index(n.x - 1, n.y, n.z)],
                     mValues[index(n.x, n.y + 1, n.z)] - mValues[index(n.x, n.y - 1, n.z)],
                     mValues[index(n.x, n.y, n.z + 1)] - mValues[index(n.x, n.y, n.z - 1)]) *
               0.5;
    }

    // May a sharp edge (two crossing normals with cosine below `edgeCosine`) pass through the
    // leaf's cell at (x, y, z)? Conservative: true also where a corner has no usable gradient.
    bool mayHoldSharpEdge(int x, int y, int z, double edgeCosine) {
        Vec3f u[8];
        for (int c = 0; c < 8; ++c)
            if (!unit(x + (c & 1), y + ((c >> 1) & 1), z + ((c >> 2) & 1), u[c])) return true;
        // Float unit vectors: a small margin keeps the test on the safe side of rounding.
        const double limit = edgeCosine + 1e-5;
        for (int a = 0; a < 8; ++a)
            for (int b = a + 1; b < 8; ++b)
                if (double(dot(u[a], u[b])) < limit) return true;
        return false;
    }

private:
    static constexpr int kSide = kLeafNodesPerSide + 2;
    static constexpr int kCount = kSide * kSide * kSide;

    // x, y, z from -1 to kLeafNodesPerSide.
    static std::size_t index(int x, int y, int z) { return std::size_t((x + 1) + kSide * ((y + 1) + kSide * (z + 1))); }

    bool unit(int x, int y, int z, Vec3f& out) {
        const std::size_t i = std::size_t(leafNodeIndex(x, y, z));
        if (mUnitState[i] == 0) {
            const Vec3d g = at({x, y, z});
            const double len = std::sqrt(dot(g, g));
            const bool ok = len > 0 && std::isfinite(len);
            mUnitState[i] = ok ? 1 : 2;
            if (ok) mUnit[i] = Vec3f(g / len);
        }
        out = mUnit[i];
        return mUnitState[i] == 1;
    }

    std::array<double, kCount> mValues;
    std::array<Vec3f, kLeafNodeCount> mUnit;
    std::array<std::uint8_t, kLeafNodeCount> mUnitState; // 0 not computed, 1 unit, 2 no gradient
};

} // namespace vdbsurf
