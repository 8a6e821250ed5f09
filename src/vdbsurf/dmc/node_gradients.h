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
// surface are ruled out by 8 products instead of 28: when every corner gradient lies within half
// the edge angle of one direction (their sum), no two lie farther apart than the angle. Both
// tests compare squared products, so they need no square root and no unit vectors.
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
          // Within β of one direction, two vectors are within 2β of each other: β = half the
          // angle whose cosine is the pair limit (none when the limit leaves no angle at all).
          mCone(mPair >= 1 ? 2.0 : std::cos(0.5 * std::acos(std::max(-1.0, mPair))) + 1e-5) {}

    // Is the angle between a and b (squared lengths aa, bb) wider than the edge angle?
    bool pairWider(const Vec3d& a, double aa, const Vec3d& b, double bb) const {
        const double d = dot(a, b), bound = mPair * mPair * aa * bb;
        return mPair >= 0 ? d < 0 || d * d < bound : d < 0 && d * d > bound;
    }
    // Is v (squared length vv) within half the edge angle of m (squared length mm)?
    bool inCone(const Vec3d& v, double vv, const Vec3d& m, double mm) const {
        const double d = dot(v, m);
        return mCone <= 1 && d > 0 && d * d >= mCone * mCone * vv * mm;
    }

private:
    double mPair, mCone;
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
                    mSquared[n] = g[0] * g[0] + g[1] * g[1] + g[2] * g[2];
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
        // Plain arrays (a Vec3d zeroes itself: that was a sixth of the test's time).
        const double* g[8];
        double gg[8];
        double sum[3] = {0, 0, 0};
        const int first = leafNodeIndex(x, y, z);
        for (int c = 0; c < 8; ++c) {
            const int i = first + (c & 1) + kLeafNodesPerSide * ((c >> 1) & 1) + kLeafNodesPerSide * kLeafNodesPerSide * (c >> 2);
            g[c] = mGradient[i];
            gg[c] = mSquared[i];
            // (Outside this range the squared products below could overflow or vanish.)
            if (!(gg[c] > 1e-100 && gg[c] < 1e100)) return true;
            for (int a = 0; a < 3; ++a) sum[a] += g[c][a];
        }
        const Vec3d m(sum[0], sum[1], sum[2]);
        const double mm = dot(m, m);
        auto vec = [&](int c) { return Vec3d(g[c][0], g[c][1], g[c][2]); };
        bool inCone = true;
        for (int c = 0; c < 8 && inCone; ++c) inCone = limit.inCone(vec(c), gg[c], m, mm);
        if (inCone) return false;
        for (int a = 0; a < 8; ++a)
            for (int b = a + 1; b < 8; ++b)
                if (limit.pairWider(vec(a), gg[a], vec(b), gg[b])) return true;
        return false;
    }

private:
    static constexpr int kSide = kLeafNodesPerSide + 2;
    static constexpr int kCount = kSide * kSide * kSide;
    static constexpr std::size_t kStride[3] = {1, kSide, kSide * kSide}; // index steps along x, y, z

    // x, y, z from -1 to kLeafNodesPerSide.
    static std::size_t index(int x, int y, int z) { return std::size_t((x + 1) + kSide * ((y + 1) + kSide * (z + 1))); }

    std::array<double, kCount> mValues;
    // Per needed node of the leaf (leafNodeIndex): gradient (index units) and its squared length.
    double mGradient[kLeafNodeCount][3];
    double mSquared[kLeafNodeCount];
};

} // namespace vdbsurf
