// Central-difference gradients at the nodes of one lattice leaf, for a grid meshed at its own
// voxel size (Field::edgesAreLinear). The leaf's node values plus a one-node apron give each
// node's gradient; a crossing's normal is then its edge's two node gradients interpolated, which
// is what the field's own gradient (central differences of the trilinear interpolant) gives
// across the edge, from 12 values instead of 48 trilinear lookups.
//
// They also tell which cells cannot hold a sharp edge: every crossing normal in a cell is a
// positive combination of two of its corner gradients, and the widest angle within a spherical
// convex hull (in a hemisphere) is between two of its generators; so when the corners'
// gradients all lie within the edge angle of each other, no two crossing normals can, and the
// sharp-feature pass skips the cell without gathering its crossings. Most cells of a smooth
// surface are ruled out without the 28 pairs: two unit vectors at angle θ lie 2 - 2 cos θ apart
// (squared), and no two of the corners' unit gradients lie farther apart than the box around
// them is wide; so a box narrower than the edge angle's distance rules the cell out, from one
// minimum and maximum per component. Each node's unit gradient is found once (a node is a
// corner of up to eight cells). The box is only a shortcut: which cells are candidates is the
// pair test's answer either way (squared products of the gradients themselves).
#pragma once
#include "vdbsurf/dmc/leaf_nodes.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>

namespace vdbsurf {

// The edge cosine of the sharp-feature pass as the corner test uses it.
class SharpEdgeLimit {
public:
    explicit SharpEdgeLimit(double edgeCosine)
        // A small margin keeps the test on the safe side of the normals' float rounding.
        : mPair(edgeCosine + 1e-5),
          // Unit vectors closer than this (squared) have a cosine above the pair limit's: its
          // distance less a margin ten times what rounding them to float can add (negative, so
          // that nothing is that close, where the limit leaves no angle at all).
          mUnitDistance(2 - 2 * std::min(mPair, 1.0) - 1e-5) {}

    // Is the angle between a and b (squared lengths aa, bb) wider than the edge angle?
    bool pairWider(const Vec3d& a, double aa, const Vec3d& b, double bb) const {
        const double d = dot(a, b), bound = mPair * mPair * aa * bb;
        return mPair >= 0 ? d < 0 || d * d < bound : d < 0 && d * d > bound;
    }
    // Are unit vectors this far apart (squared) surely within the edge angle of each other?
    bool unitsWithin(double squaredDistance) const { return squaredDistance < mUnitDistance; }

private:
    double mPair, mUnitDistance;
};

class NodeGradients {
public:
    // Values of the leaf's nodes at `origin` and of the nodes beside them (one sampleNodes call:
    // a grid copies its leaf buffers), and the gradients of the nodes `needed` marks (the corners
    // of the leaf's cells), each once: a node is a corner of up to eight cells, and each of them
    // reads its gradient.
    void sample(const Field& field, const LatticeFrame& frame, const openvdb::Coord& origin,
                const std::array<std::uint8_t, kLeafNodeCount>& needed) {
        field.sampleNodes(frame, {origin.x() - 1, origin.y() - 1, origin.z() - 1}, {kSide, kSide, kSide}, nullptr, mValues.data());
        std::size_t n = 0;
        for (int z = 0; z < kLeafNodesPerSide; ++z)
            for (int y = 0; y < kLeafNodesPerSide; ++y)
                for (int x = 0; x < kLeafNodesPerSide; ++x, ++n) {
                    if (!needed[n]) continue;
                    const std::size_t i = index(x, y, z);
                    double* g = mGradient[n];
                    for (std::size_t a = 0; a < 3; ++a) g[a] = (mValues[i + kStride[a]] - mValues[i - kStride[a]]) * 0.5;
                    const double gg = g[0] * g[0] + g[1] * g[1] + g[2] * g[2];
                    mSquared[n] = gg;
                    // A gradient the pair test cannot use (its squared products could overflow or
                    // vanish) gets a point far off the unit sphere: every box with it is too wide.
                    if (usable(gg)) {
                        const double inverse = 1 / std::sqrt(gg);
                        mUnit[n] = Float4{float(g[0] * inverse), float(g[1] * inverse), float(g[2] * inverse), 0.0f};
                    } else {
                        mUnit[n] = Float4{8.0f, 8.0f, 8.0f, 0.0f};
                    }
                }
    }

    // The values alone (no gradients), for value(): a leaf's nodes and the nodes beside them.
    void sampleValues(const Field& field, const LatticeFrame& frame, const openvdb::Coord& origin) {
        field.sampleNodes(frame, {origin.x() - 1, origin.y() - 1, origin.z() - 1}, {kSide, kSide, kSide}, nullptr, mValues.data());
    }

    // The values of the leaf's own nodes, as sampleLeafNodes gives them (the sample holds them).
    void leafValues(std::array<double, kLeafNodeCount>& out) const {
        for (int z = 0; z < kLeafNodesPerSide; ++z)
            for (int y = 0; y < kLeafNodesPerSide; ++y)
                std::copy_n(&mValues[index(0, y, z)], kLeafNodesPerSide, &out[std::size_t(leafNodeIndex(0, y, z))]);
    }

    // The value at a node of the leaf or beside it (x, y, z from -1 to kLeafNodesPerSide).
    double value(int x, int y, int z) const { return mValues[index(x, y, z)]; }

    // Gradient (index units) at a node of the leaf.
    Vec3d at(const Vec3i& n) const {
        const double* g = mGradient[leafNodeIndex(n.x, n.y, n.z)];
        return Vec3d(g[0], g[1], g[2]);
    }

    // May a sharp edge (two crossing normals with cosine below the limit's) pass through the
    // leaf's cell at (x, y, z)? Conservative: true also where a corner has no usable gradient.
    bool mayHoldSharpEdge(int x, int y, int z, const SharpEdgeLimit& limit) const {
        constexpr int kY = kLeafNodesPerSide, kZ = kLeafNodesPerSide * kLeafNodesPerSide;
        const int first = leafNodeIndex(x, y, z);
        const int corner[8] = {first, first + 1, first + kY, first + kY + 1, first + kZ, first + kZ + 1, first + kZ + kY, first + kZ + kY + 1};
        // (Four floats a node: a minimum and a maximum per corner cover all three components.)
        Float4 lo = mUnit[first], hi = lo;
        for (int c = 1; c < 8; ++c) {
            const Float4 v = mUnit[corner[c]];
            lo = v < lo ? v : lo;
            hi = v > hi ? v : hi;
        }
        const Float4 d = hi - lo;
        if (limit.unitsWithin(double(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]))) return false;
        // Plain arrays (a Vec3d zeroes itself).
        const double* g[8];
        double gg[8];
        for (int c = 0; c < 8; ++c) {
            g[c] = mGradient[corner[c]], gg[c] = mSquared[corner[c]];
            if (!usable(gg[c])) return true;
        }
        auto vec = [&](int c) { return Vec3d(g[c][0], g[c][1], g[c][2]); };
        for (int a = 0; a < 8; ++a)
            for (int b = a + 1; b < 8; ++b)
                if (limit.pairWider(vec(a), gg[a], vec(b), gg[b])) return true;
        return false;
    }

private:
    // Can the pair test use a gradient of this squared length? (Outside this range its squared
    // products could overflow or vanish: such a corner makes its cells candidates.)
    static bool usable(double gg) { return gg > 1e-100 && gg < 1e100; }

    static constexpr int kSide = kLeafNodesPerSide + 2;
    static constexpr int kCount = kSide * kSide * kSide;
    static constexpr std::size_t kStride[3] = {1, kSide, kSide * kSide}; // index steps along x, y, z

    // x, y, z from -1 to kLeafNodesPerSide.
    static std::size_t index(int x, int y, int z) { return std::size_t((x + 1) + kSide * ((y + 1) + kSide * (z + 1))); }

    std::array<double, kCount> mValues;
    // Per needed node of the leaf (leafNodeIndex): gradient (index units) and its squared length.
    double mGradient[kLeafNodeCount][3];
    double mSquared[kLeafNodeCount];
    // Per needed node: its unit gradient (x, y, z, 0), rounded to float.
    using Float4 = float __attribute__((vector_size(16)));
    Float4 mUnit[kLeafNodeCount];
};

} // namespace vdbsurf
