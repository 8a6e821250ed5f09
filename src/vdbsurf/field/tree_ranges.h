// The value ranges of a grid's tree, summarised once so that range queries over boxes
// (GridField's bounds and mayStraddle, the lattice's inner loop) read cached ranges instead of
// voxels: each leaf's and internal node's min and max, the whole grid's, and the boxes where
// values and active data are. Non-finite values are refused here, with the first one in tree
// order named. Internal to grid_field.cpp, the one place that includes OpenVDB's tree for it.
#pragma once

#include "vdbsurf/core/error.h"

#include <openvdb/openvdb.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

namespace vdbsurf {

struct MinMax {
    double lo = std::numeric_limits<double>::infinity();
    double hi = -std::numeric_limits<double>::infinity();
    void add(double v) { lo = std::min(lo, v); hi = std::max(hi, v); }
    void add(const MinMax& o) { lo = std::min(lo, o.lo); hi = std::max(hi, o.hi); }
};

// Calls fn with each table slot of the node that meets the box, until fn returns true.
template <typename NodeT, typename Fn>
bool anySlotIn(const NodeT& node, const openvdb::CoordBBox& box, Fn&& fn) {
    openvdb::CoordBBox in = node.getNodeBoundingBox();
    in.intersect(box);
    constexpr int CD = int(NodeT::ChildNodeType::DIM);
    const openvdb::Coord lo = in.min() & ~(CD - 1), hi = in.max() & ~(CD - 1);
    for (int x = lo.x(); x <= hi.x(); x += CD)
        for (int y = lo.y(); y <= hi.y(); y += CD)
            for (int z = lo.z(); z <= hi.z(); z += CD)
                if (fn(NodeT::coordToOffset(openvdb::Coord(x, y, z)))) return true;
    return false;
}

// The range of n values (a multiple of 8), in two sets of 16-byte lanes (a large grid's leaves
// are millions of values, all read before its first mesh); false if one is NaN or infinite.
template <typename ValueT>
bool finiteRange(const ValueT* data, std::size_t n, MinMax& out) {
    constexpr int kLanes = int(16 / sizeof(ValueT));
    static_assert(2 * kLanes <= 8, "two sets of lanes over eight values");
    typedef ValueT Lanes __attribute__((vector_size(16)));
    Lanes lo[2], hi[2], bad[2] = {};
    std::memcpy(&lo[0], data, sizeof(Lanes));
    lo[1] = hi[0] = hi[1] = lo[0];
    for (std::size_t i = 0; i < n; i += 2 * kLanes)
        for (int s = 0; s < 2; ++s) {
            Lanes x;
            std::memcpy(&x, data + i + s * kLanes, sizeof x);
            lo[s] = x < lo[s] ? x : lo[s];
            hi[s] = x > hi[s] ? x : hi[s];
            bad[s] += x - x; // 0 for a finite value, NaN for NaN or an infinity (and NaN stays)
        }
    for (int s = 0; s < 2; ++s)
        for (int k = 0; k < kLanes; ++k) {
            if (!(bad[s][k] == 0)) return false;
            out.add(double(lo[s][k]));
            out.add(double(hi[s][k]));
        }
    return true;
}

// Children of an internal node numbered in slot order: a child's number is the children before
// it, counted with popcounts over the child mask's words.
template <typename NodeT>
struct ChildRanks {
    static constexpr openvdb::Index kWords = NodeT::NUM_VALUES / 64;
    static_assert(NodeT::NUM_VALUES <= 65536, "counts within a node fit 16 bits");
    std::uint32_t first = 0; // the number of the node's first child
    std::array<std::uint16_t, kWords> before{}; // (128 bytes a lower node, 1 KB an upper one)

    // Numbers the node's children from `firstChild`; returns how many it has.
    std::uint32_t build(const NodeT& node, std::uint32_t firstChild) {
        first = firstChild;
        std::uint32_t n = 0;
        for (openvdb::Index w = 0; w < kWords; ++w) {
            before[w] = std::uint16_t(n);
            n += std::uint32_t(__builtin_popcountll(word(node, w)));
        }
        return n;
    }
    std::uint32_t of(const NodeT& node, openvdb::Index slot) const {
        const std::uint64_t below = word(node, slot >> 6) & ((std::uint64_t(1) << (slot & 63)) - 1);
        return first + before[slot >> 6] + std::uint32_t(__builtin_popcountll(below));
    }
    static std::uint64_t word(const NodeT& node, openvdb::Index w) { return node.getChildMask().template getWord<std::uint64_t>(w); }
};

template <typename TreeT>
class TreeRanges {
public:
    using ValueT = typename TreeT::ValueType;
    using LeafT = typename TreeT::LeafNodeType;
    using RootT = typename TreeT::RootNodeType;
    using Node2T = typename RootT::ChildNodeType;
    using Node1T = typename Node2T::ChildNodeType;
    using CoordBBox = openvdb::CoordBBox;
    using Coord = openvdb::Coord;

    // Reads every value once, in parallel (a lower internal node a task, and an upper one's tiles
    // in chunks); throws an Error naming `label` at the first NaN or infinity in tree order, as a
    // serial walk would.
    TreeRanges(const TreeT& tree, const std::string& label) : mTree(tree) {
        const RootT& root = tree.root();
        const ValueT bg = root.background();
        std::vector<const Node2T*> upper;
        std::vector<const Node1T*> lower;
        for (auto it2 = root.cbeginChildOn(); it2; ++it2) {
            mNode2Of.emplace_back(&*it2, std::uint32_t(upper.size()));
            upper.push_back(&*it2);
            mNode2.emplace_back();
            mNode2.back().children.build(*it2, std::uint32_t(lower.size()));
            for (auto it1 = it2->cbeginChildOn(); it1; ++it1) lower.push_back(&*it1);
        }
        std::sort(mNode2Of.begin(), mNode2Of.end());
        mNode1.resize(lower.size());
        std::uint32_t leaves = 0;
        for (std::size_t k = 0; k < lower.size(); ++k) leaves += mNode1[k].children.build(*lower[k], leaves);
        mLeaf.resize(leaves);

        // The lower nodes: their leaves' ranges (numbered as ChildRanks numbers them) and tiles.
        struct Lower {
            TileScan tiles;
            CoordBBox leafNodes, leafActive;
            bool badLeaf = false;
            Coord badLeafAt;
            double badLeafValue = 0;
        };
        std::vector<Lower> found(lower.size());
        // The upper nodes' tiles, in chunks of slots (an upper node has 32,768, and a grid often
        // a few upper nodes: a serial scan of them was most of the summaries' time).
        constexpr openvdb::Index kChunk = 4096, kChunks = Node2T::NUM_VALUES / kChunk;
        std::vector<TileScan> upperTiles(upper.size() * kChunks);
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, lower.size() + upperTiles.size(), 1), [&](const tbb::blocked_range<std::size_t>& r) {
            for (std::size_t t = r.begin(); t < r.end(); ++t) {
                if (t >= lower.size()) {
                    const std::size_t u = t - lower.size();
                    const openvdb::Index begin = openvdb::Index(u % kChunks) * kChunk;
                    scanTiles(*upper[u / kChunks], begin, begin + kChunk, bg, upperTiles[u]);
                    continue;
                }
                const Node1T& n1 = *lower[t];
                Lower& f = found[t];
                std::uint32_t leafNumber = mNode1[t].children.first;
                for (auto it = n1.cbeginChildOn(); it; ++it) {
                    const LeafT& leaf = *it;
                    const ValueT* data = leaf.buffer().data();
                    MinMax mm;
                    if (!finiteRange(data, LeafT::SIZE, mm) && !f.badLeaf) {
                        for (openvdb::Index n = 0; n < LeafT::SIZE && !f.badLeaf; ++n)
                            if (!std::isfinite(double(data[n])))
                                f.badLeaf = true, f.badLeafAt = leaf.offsetToGlobalCoord(n), f.badLeafValue = double(data[n]);
                    }
                    mLeaf[leafNumber++] = mm;
                    mNode1[t].range.add(mm);
                    f.leafNodes.expand(leaf.getNodeBoundingBox());
                    addActiveBox(leaf, f.leafActive);
                }
                scanTiles(n1, 0, Node1T::NUM_VALUES, bg, f.tiles);
                mNode1[t].range.add(f.tiles.range);
            }
        });
        auto refuse = [&](double v, const Coord& at, const char* where) {
            std::ostringstream s;
            s << "holds " << (std::isnan(v) ? "NaN" : "an infinite value") << where << "(" << at.x() << ", " << at.y() << ", " << at.z() << ")";
            throw Error(label, s.str());
        };
        auto refuseTile = [&](const TileScan& t) { refuse(t.badValue, t.badAt, " in the tile at "); };
        for (const Lower& f : found)
            if (f.badLeaf) refuse(f.badLeafValue, f.badLeafAt, " at voxel ");
        if (!std::isfinite(double(bg))) throw Error(label, "has a NaN or infinite background value");
        mAll.add(double(bg));
        // In slot order, so that the first bad tile in tree order is the one named.
        std::size_t k = 0;
        for (std::size_t u = 0; u < upper.size(); ++u) {
            const Node2T& n2 = *upper[u];
            MinMax& mm2 = mNode2[u].range;
            for (openvdb::Index c = 0; c < kChunks; ++c) {
                const TileScan& chunk = upperTiles[u * kChunks + c];
                for (openvdb::Index i2 = n2.getChildMask().findNextOn(c * kChunk); i2 < (c + 1) * kChunk; i2 = n2.getChildMask().findNextOn(i2 + 1)) {
                    if (chunk.bad && chunk.badSlot < i2) refuseTile(chunk);
                    const Lower& f = found[k];
                    if (f.tiles.bad) refuseTile(f.tiles);
                    mm2.add(mNode1[k].range);
                    addTileBoxes(f.tiles);
                    mLeafNodes.expand(f.leafNodes);
                    mLeafActive.expand(f.leafActive);
                    ++k;
                }
                if (chunk.bad) refuseTile(chunk);
                mm2.add(chunk.range);
                addTileBoxes(chunk);
            }
            mAll.add(mm2);
        }
        for (auto it = root.cbeginValueAll(); it; ++it) {
            const double v = double(*it);
            if (!std::isfinite(v)) refuse(v, it.getCoord(), " in the tile at ");
            mAll.add(v);
            if (*it == bg) continue;
            const CoordBBox cube = CoordBBox::createCube(it.getCoord(), int(Node2T::DIM));
            mTiles.expand(cube);
            if (it.isValueOn()) mActiveTiles.expand(cube);
        }
        mValues = mTiles;
        mValues.expand(mLeafNodes);
        mValues.expand(1);
    }

    const MinMax& all() const { return mAll; }
    // Index boxes of the active tiles that differ from the background and of the leaves' active
    // voxels (empty boxes where there are none): the grid's data.
    const CoordBBox& activeTiles() const { return mActiveTiles; }
    const CoordBBox& leafActive() const { return mLeafActive; }

    // The values in the index box, as ranges handed to v.add (a range or one value; true stops the
    // walk, and visit returns true): a node the box holds whole gives its cached range, and so
    // does one it holds in part where the visitor may take that (Visitor::kWholeMayServe) and
    // v.wholeServes says so; a box over more than 512 root children gives the whole grid's range.
    template <typename Visitor>
    bool visit(const CoordBBox& box, Visitor& v) const {
        if (!box.hasOverlap(mValues)) return v.add(double(mTree.background()));
        const RootT& root = mTree.root();
        constexpr int D = int(Node2T::DIM);
        const Coord lo = box.min() & ~(D - 1), hi = box.max() & ~(D - 1);
        const std::int64_t count = std::int64_t((hi.x() - lo.x()) / D + 1) * ((hi.y() - lo.y()) / D + 1) * ((hi.z() - lo.z()) / D + 1);
        if (count > 512) return v.add(mAll);
        for (int x = lo.x(); x <= hi.x(); x += D)
            for (int y = lo.y(); y <= hi.y(); y += D)
                for (int z = lo.z(); z <= hi.z(); z += D) {
                    const Coord c(x, y, z);
                    const Node2T* n2 = root.template probeConstNode<Node2T>(c);
                    if (n2 ? visitNode(*n2, node2Cache(n2), box, v) : v.add(double(root.getValue(c)))) return true;
                }
        return false;
    }

private:
    // The tiles among some of a node's slots: their range, the boxes of those that differ from
    // the background (all, active ones), and the first that is not finite.
    struct TileScan {
        MinMax range;
        CoordBBox tiles, activeTiles;
        bool bad = false;
        openvdb::Index badSlot = 0;
        Coord badAt;
        double badValue = 0;
    };

    template <typename NodeT>
    static void scanTiles(const NodeT& node, openvdb::Index begin, openvdb::Index end, ValueT bg, TileScan& t) {
        constexpr int dim = int(NodeT::ChildNodeType::DIM);
        bool sawBackground = false;
        for (openvdb::Index i = begin; i < end; ++i) {
            if (node.isChildMaskOn(i)) continue;
            const ValueT value = node.getTable()[i].getValue();
            if (value == bg) { // nearly every tile: nothing more to learn from it
                sawBackground = true;
                continue;
            }
            const double v = double(value);
            if (!std::isfinite(v) && !t.bad) t.bad = true, t.badSlot = i, t.badAt = node.offsetToGlobalCoord(i), t.badValue = v;
            t.range.add(v);
            const CoordBBox cube = CoordBBox::createCube(node.offsetToGlobalCoord(i), dim);
            t.tiles.expand(cube);
            if (node.isValueMaskOn(i)) t.activeTiles.expand(cube);
        }
        if (sawBackground) t.range.add(double(bg));
    }

    void addTileBoxes(const TileScan& t) {
        mTiles.expand(t.tiles);
        mActiveTiles.expand(t.activeTiles);
    }

    template <typename NodeT>
    struct NodeCache {
        MinMax range;
        ChildRanks<NodeT> children;
    };

    const NodeCache<Node2T>& node2Cache(const Node2T* n2) const {
        const auto it = std::lower_bound(mNode2Of.begin(), mNode2Of.end(), std::make_pair(n2, std::uint32_t(0)));
        if (it == mNode2Of.end() || it->first != n2) throw std::logic_error("TreeRanges: the tree changed after its ranges were read");
        return mNode2[it->second];
    }

    // The box of a leaf's active voxels, from its mask: word x holds, in byte y, the eight voxels along z.
    static void addActiveBox(const LeafT& leaf, CoordBBox& box) {
        const auto& mask = leaf.getValueMask();
        int xLo = -1, xHi = -1;
        std::uint64_t any = 0;
        for (int x = 0; x < 8; ++x) {
            const std::uint64_t w = mask.template getWord<std::uint64_t>(openvdb::Index(x));
            if (!w) continue;
            if (xLo < 0) xLo = x;
            xHi = x;
            any |= w;
        }
        if (!any) return;
        std::uint64_t z = any | any >> 32;
        z |= z >> 16;
        z |= z >> 8;
        z &= 0xFF;
        const Coord o = leaf.origin();
        box.expand(CoordBBox(o.offsetBy(xLo, __builtin_ctzll(any) / 8, __builtin_ctzll(z)),
                             o.offsetBy(xHi, (63 - __builtin_clzll(any)) / 8, 63 - __builtin_clzll(z))));
    }

    template <typename NodeT, typename Visitor>
    static bool takesWhole(const NodeT& node, const MinMax& whole, const CoordBBox& box, const Visitor& v) {
        if (box.isInside(node.getNodeBoundingBox())) return true;
        if constexpr (Visitor::kWholeMayServe) return v.wholeServes(whole);
        return false;
    }

    template <typename NodeT, typename Visitor>
    bool visitNode(const NodeT& node, const NodeCache<NodeT>& cache, const CoordBBox& box, Visitor& v) const {
        if (takesWhole(node, cache.range, box, v)) return v.add(cache.range);
        return anySlotIn(node, box, [&](openvdb::Index n) {
            if (!node.isChildMaskOn(n)) return v.add(double(node.getTable()[n].getValue()));
            const auto& child = *node.getTable()[n].getChild();
            const std::uint32_t k = cache.children.of(node, n);
            if constexpr (std::is_same<typename NodeT::ChildNodeType, LeafT>::value) return visitLeaf(child, mLeaf[k], box, v);
            else return visitNode(child, mNode1[k], box, v);
        });
    }

    template <typename Visitor>
    static bool visitLeaf(const LeafT& leaf, const MinMax& whole, const CoordBBox& box, Visitor& v) {
        if (takesWhole(leaf, whole, box, v)) return v.add(whole);
        CoordBBox in = leaf.getNodeBoundingBox();
        in.intersect(box);
        const auto* data = leaf.buffer().data();
        MinMax part;
        for (int x = in.min().x(); x <= in.max().x(); ++x)
            for (int y = in.min().y(); y <= in.max().y(); ++y)
                for (int z = in.min().z(); z <= in.max().z(); ++z) part.add(double(data[LeafT::coordToOffset(Coord(x, y, z))]));
        return v.add(part);
    }

    const TreeT& mTree;
    MinMax mAll;
    std::vector<NodeCache<Node2T>> mNode2; // in the root's order
    std::vector<std::pair<const Node2T*, std::uint32_t>> mNode2Of; // sorted by address
    std::vector<NodeCache<Node1T>> mNode1;                         // numbered by ChildRanks
    std::vector<MinMax> mLeaf;                                     // numbered by ChildRanks
    CoordBBox mTiles, mActiveTiles, mLeafNodes, mLeafActive;
    CoordBBox mValues; // where values other than the background are stored, one voxel out (the trilinear support)
};

} // namespace vdbsurf
