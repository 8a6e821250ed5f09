#include "vdbsurf/dmc/hidden_edges.h"

#include "vdbsurf/core/cancel.h"
#include "vdbsurf/dmc/edge_runs.h"
#include "vdbsurf/dmc/lattice_deformation.h"
#include "vdbsurf/dmc/leaf_nodes.h"
#include "vdbsurf/dmc/thin_search.h"
#include "vdbsurf/lattice/lattice.h"

#include <openvdb/tree/LeafManager.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <optional>
#include <stdexcept>
#include <tuple>

namespace vdbsurf {

using openvdb::Coord;

namespace {

constexpr int kMaxRounds = 32;
// Places beside an edge an end tries, nearest the part first (each costs a move's checks), on a
// grid of at most 8^3 over its Ω (the search's h/k step, capped: a last resort, not the search).
constexpr std::size_t kBesideTries = 8;
constexpr int kBesideStepsMax = 8;

// The segments examined: lattice edges (kinds 0-2, along x, y, z) and face diagonals (kinds
// 3-8), named by the end from which the step's first non-zero component is positive.
constexpr int kStep[9][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {1, 1, 0}, {1, -1, 0}, {1, 0, 1}, {1, 0, -1}, {0, 1, 1}, {0, 1, -1}};
constexpr int kSegmentKinds = 9;

struct Edge {
    Coord node;
    int kind;
    bool operator<(const Edge& o) const { return std::tie(node, kind) < std::tie(o.node, o.kind); }
    bool operator==(const Edge& o) const { return node == o.node && kind == o.kind; }
    Coord other() const { return node.offsetBy(kStep[kind][0], kStep[kind][1], kStep[kind][2]); }
    bool diagonal() const { return kind >= 3; }
    // A face diagonal's face has two more corners, one step along each of its axes.
    Coord corner(int which) const {
        int seen = 0, d[3] = {0, 0, 0};
        for (int i = 0; i < 3; ++i)
            if (kStep[kind][i] != 0 && seen++ == which) d[i] = kStep[kind][i];
        return node.offsetBy(d[0], d[1], d[2]);
    }
};

// The node one step from c along axis (0-2), towards sign (-1 or 1).
Coord neighbour(const Coord& c, int axis, int sign) { return c + axisStep(axis, sign); }

// The segment between two nodes one edge or one face diagonal apart.
Edge segment(const Coord& p, const Coord& q) {
    const Coord d = q - p;
    const bool flip = d.x() < 0 || (d.x() == 0 && (d.y() < 0 || (d.y() == 0 && d.z() < 0)));
    const Coord s = flip ? p - q : d;
    for (int k = 0; k < kSegmentKinds; ++k)
        if (s.x() == kStep[k][0] && s.y() == kStep[k][1] && s.z() == kStep[k][2]) return Edge{flip ? q : p, k};
    throw std::logic_error("hidden edges: nodes are not one edge or face diagonal apart");
}

struct Move {
    Coord node;
    Vec3f offset;
    Edge edge;
    bool operator<(const Move& o) const {
        return std::tie(node, offset.x, offset.y, offset.z, edge) < std::tie(o.node, o.offset.x, o.offset.y, o.offset.z, o.edge);
    }
};

class EdgeExaminer {
public:
    EdgeExaminer(const Field& field, const Lattice& lattice, double iso, int steps)
        : mRuns(field, lattice, iso, steps), mField(field), mFrame(lattice.frame), mIso(iso), mSide(field.inside()) {
        // From border to border of Ω: a part may cross only a corner of it.
        const int m = std::min(steps, kBesideStepsMax);
        const double step = mFrame.h / m;
        for (int z = 0; z <= m; ++z)
            for (int y = 0; y <= m; ++y)
                for (int x = 0; x <= m; ++x)
                    if (const auto off = offsetInOmega(Vec3d(-mFrame.h / 2 + x * step, -mFrame.h / 2 + y * step, -mFrame.h / 2 + z * step),
                                                       mFrame.h))
                        mBesideOffsets.push_back(*off);
    }

    bool validNode(const Coord& c) const { return mRuns.validNode(c); }

    double rest(const Coord& c) const {
        double v = 0;
        mField.sampleNodes(mFrame, {c.x(), c.y(), c.z()}, {1, 1, 1}, nullptr, &v);
        return v;
    }

    // The move a segment asks for, if it hides a part that marching cubes would miss: an edge
    // whose ends' sides do not explain its runs, or the outside diagonal of a face whose inside
    // corners lie on the other diagonal (marching cubes joins the outside corners there).
    // restAt(node) gives a node's value at its rest place.
    template <typename RestAt>
    std::optional<Move> examine(const Edge& e, const RestAt& restAt, NodeStates& nodes, std::uint64_t& examined,
                                std::uint64_t& evaluated) const {
        const Coord a = e.node, b = e.other();
        openvdb::Vec3f offA(0.0f), offB(0.0f);
        const bool movedA = nodes.offsets.probeValue(a, offA), movedB = nodes.offsets.probeValue(b, offB);
        if (movedA && movedB) return std::nullopt;
        auto sideOf = [&](const Coord& c) { return nodes.inside(c, isInside(restAt(c), mIso, mSide)); };
        const bool insideA = sideOf(a), insideB = sideOf(b);
        if (e.diagonal()) {
            if (insideA || insideB) return std::nullopt;
            for (int w = 0; w < 2; ++w)
                if (!sideOf(e.corner(w))) return std::nullopt;
        }
        const Vec3d pa = world(a) + Vec3d(offA.x(), offA.y(), offA.z()), pb = world(b) + Vec3d(offB.x(), offB.y(), offB.z());
        int n = 0;
        const std::vector<EdgeRuns::Run> runs = mRuns.runsAlong(pa, pb, insideA, insideB, n, examined, evaluated);
        if (runs.size() <= (insideA == insideB ? 1u : 2u)) return std::nullopt;
        // Ends that a bent path joins on their side lie in one piece of it: the run between is the
        // other side's surface bulging across the edge (a crack's slanted wall between two of its
        // nodes), and a node moved into it would stand alone for a sliver of a thick part. So do
        // ends that a search over samples joins nearby where bent paths miss: a wire 1.5 voxels
        // thick in a level set, one end barely inside at the wire's side, the other moved into its
        // middle — moving the first out across the wire's surface cut the wire in two.
        if (insideA == insideB && (mRuns.bentPathJoins(pa, pb, insideA, evaluated) || mRuns.joinedNearby(pa, pb, insideA, evaluated)))
            return std::nullopt;
        // An end that has not moved goes into the run next to its own, when that run is inside the
        // edge (a part the edge hides), at the sample nearest the run's middle that its Ω holds —
        // if that leaves fewer hidden runs on its six edges than before and none more on any one,
        // and it is not the only node of a part itself.
        // A diagonal's own runs count too (the axis edges are among the six).
        const std::size_t own = e.diagonal() ? runs.size() - 1 : 0;
        // `outsideReach`: how far the outside is searched for a path that makes harmless what a
        // move joins across a part of the inside (EdgeRuns::moveEffect).
        auto firstAccepted = [&](const EdgeRuns::JoinReach& outsideReach) -> std::optional<Move> {
            auto accepts = [&](const Coord& c, bool inside, const Vec3f& off, const Vec3d& far) {
                const Vec3d to = world(c) + Vec3d(off);
                const std::size_t ownAfter = e.diagonal() ? mRuns.hiddenRuns(to, far, !inside, false, examined, evaluated) : 0;
                return ownAfter <= own && improves(c, inside, to, own - ownAfter, nodes, examined, evaluated, outsideReach);
            };
            bool reaches[2] = {false, false}; // does the end's Ω hold the run along the edge?
            for (const bool fromA : {true, false}) {
                if (fromA ? movedA : movedB) continue;
                const EdgeRuns::Run& run = runs[fromA ? 1 : runs.size() - 2];
                if (run.first == 0 || run.last == n) continue;
                const Coord c = fromA ? a : b;
                const bool inside = fromA ? insideA : insideB;
                const double middle = 0.5 * (run.first + run.last);
                std::vector<int> order;
                for (int i = run.first; i <= run.last; ++i) order.push_back(i);
                std::stable_sort(order.begin(), order.end(),
                                 [&](int x, int y) { return std::fabs(x - middle) < std::fabs(y - middle); });
                for (int i : order) {
                    const std::optional<Vec3f> placed = offsetInOmega(pa + (pb - pa) * (double(i) / n) - world(c), mFrame.h);
                    if (!placed) continue;
                    reaches[fromA ? 0 : 1] = true;
                    ++evaluated;
                    if (!isOtherSide(inside, mField.value(world(c) + Vec3d(*placed)), mIso, mSide)) continue;
                    if (accepts(c, inside, *placed, fromA ? pb : pa)) return Move{c, *placed, e};
                }
            }
            // Only one end's Ω holds the part along the edge, and that end may not go there (where a
            // crack meets the outside: it would leave the node across the crack alone on its side, tied
            // to its half by face diagonals only, or make a face hide the rim). The other end may go
            // into the part beside the edge, within its Ω: to the samples of the other side there
            // nearest the part's middle on the edge, nearest first.
            for (const bool fromA : {true, false}) {
                if ((fromA ? movedA : movedB) || reaches[fromA ? 0 : 1]) continue;
                const EdgeRuns::Run& run = runs[fromA ? 1 : runs.size() - 2];
                if (run.first == 0 || run.last == n) continue;
                const Coord c = fromA ? a : b;
                const bool inside = fromA ? insideA : insideB;
                const Vec3d middle = pa + (pb - pa) * (0.5 * (run.first + run.last) / n);
                std::vector<std::pair<double, Vec3f>> nearest;
                for (const Vec3f& off : mBesideOffsets) nearest.emplace_back(length(world(c) + Vec3d(off) - middle), off);
                std::stable_sort(nearest.begin(), nearest.end(), [](const auto& x, const auto& y) { return x.first < y.first; });
                std::size_t tried = 0;
                for (const auto& [distance, off] : nearest) {
                    if (tried == kBesideTries) break;
                    ++evaluated;
                    if (!isOtherSide(inside, mField.value(world(c) + Vec3d(off)), mIso, mSide)) continue;
                    ++tried;
                    if (accepts(c, inside, off, fromA ? pb : pa)) return Move{c, off, e};
                }
            }
            return std::nullopt;
        };
        if (const std::optional<Move> m = firstAccepted(EdgeRuns::kRimReach)) return m;
        // Between two inside nodes the run is a gap that joins them unless a node moves into it.
        // Where every move would join what lies beyond the gap to another part of the outside
        // across the solid (an edge's far end that the move puts on its side, a face it turns
        // ambiguous) which the outside reaches only round a junction (cracks that cross or meet,
        // a fractured solid's gaps where three pieces meet), the outside is searched as far as
        // the inside is, as a last resort: the move then cuts a tunnel through the wedge of solid
        // between the two gaps at worst, where refusing welds two pieces of the solid together.
        // (As the first choice, the wider search took moves from the other end of the edge, which
        // needed no such join, and cut tunnels; everywhere in moveEffect, it slowed the thin
        // search on noisy fog and gave random blob scenes handles.) Balls fractured into 5 Voronoi
        // pieces, gaps 0.2-0.8 H wide: 22 of 120 not their pieces before, 7 after (8 pieces: 25
        // of 60, 12; as level sets of voxel H/5, 5 pieces: 10 of 60, 3; a turned cube, 5
        // pieces: 36 of 60, 18); pairs of crossing cracks 0.2-1 H wide: 11 of 60 wrong before, 4.
        if (!(insideA && insideB)) return std::nullopt;
        return firstAccepted(EdgeRuns::kJunctionReach);
    }

private:
    // Does moving node c (on side `inside`, not moved) to `to` keep what its edges show, leave
    // its six edges, with the diagonal that asks (`gained` runs fewer there), hiding fewer runs in
    // all, and is c not alone on its side among its neighbours (then it is a thin part itself)?
    bool improves(const Coord& c, bool inside, const Vec3d& to, std::size_t gained, NodeStates& nodes, std::uint64_t& examined,
                  std::uint64_t& evaluated, const EdgeRuns::JoinReach& outsideReach) const {
        const EdgeRuns::MoveEffect effect = mRuns.moveEffect(c, inside, to, nodes, examined, evaluated, outsideReach);
        return effect.keeps && !effect.alone && effect.after < effect.before + gained && !(inside && mRuns.partsJoined(c, true, nodes, evaluated));
    }

    Vec3d world(const Coord& c) const { return mRuns.world(c); }
    EdgeRuns mRuns;
    const Field& mField;
    const LatticeFrame& mFrame;
    double mIso;
    Inside mSide;
    std::vector<Vec3f> mBesideOffsets; // a cubic grid over Ω where an end may go beside its edge
};

// Every edge of the active cells, examined leaf by leaf with the leaf's node values.
std::vector<Move> examineActiveCells(const EdgeExaminer& examiner, const Field& field, const Lattice& lattice,
                                     const LatticeDeformation& deformation, const CancelToken* cancel, HiddenEdgeStats& stats) {
    openvdb::tree::LeafManager<const CellTree> leaves(*lattice.cells);
    std::vector<std::vector<Move>> perLeaf(leaves.leafCount());
    std::vector<std::uint64_t> examined(leaves.leafCount(), 0), evaluated(leaves.leafCount(), 0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, leaves.leafCount(), 4), [&](const tbb::blocked_range<std::size_t>& r) {
        NodeStates nodes(deformation);
        std::array<double, kLeafNodeCount> vals;
        std::array<std::uint8_t, kLeafNodeCount> needed;
        std::vector<std::uint8_t> seen(std::size_t(kLeafNodeCount) * kSegmentKinds);
        for (std::size_t li = r.begin(); li < r.end(); ++li) {
            if (cancel) cancel->check();
            const auto& leaf = leaves.leaf(li);
            const Coord o = leaf.origin();
            sampleLeafNodes(field, lattice.frame, leaf, needed, vals);
            std::fill(seen.begin(), seen.end(), 0);
            auto restAt = [&](const Coord& c) {
                const Coord l = c - o;
                return vals[std::size_t(leafNodeIndex(l.x(), l.y(), l.z()))];
            };
            for (auto it = leaf.cbeginValueOn(); it; ++it) {
                const Coord cell = it.getCoord();
                // The cell's 12 edges and 12 face diagonals: corner pairs one or two steps apart.
                for (int c1 = 0; c1 < 8; ++c1)
                    for (int c2 = c1 + 1; c2 < 8; ++c2) {
                        if (__builtin_popcount(unsigned(c1 ^ c2)) > 2) continue;
                        auto corner = [&](int c) { return cell.offsetBy(c & 1, (c >> 1) & 1, (c >> 2) & 1); };
                        const Edge e = segment(corner(c1), corner(c2));
                        const Coord l = e.node - o;
                        std::uint8_t& mark = seen[std::size_t(leafNodeIndex(l.x(), l.y(), l.z())) * kSegmentKinds + std::size_t(e.kind)];
                        if (mark) continue;
                        mark = 1;
                        if (auto m = examiner.examine(e, restAt, nodes, examined[li], evaluated[li])) perLeaf[li].push_back(*m);
                    }
            }
        }
    });
    std::vector<Move> all;
    for (std::size_t li = 0; li < perLeaf.size(); ++li) {
        all.insert(all.end(), perLeaf[li].begin(), perLeaf[li].end());
        stats.edgesExamined += examined[li];
        stats.samples += evaluated[li];
    }
    return all;
}

// Examined again after nodes moved: `edges` (deferred ones), and around each of `nodes` every
// edge at it and both diagonals of every face it is a corner of.
std::vector<Move> examineAround(const EdgeExaminer& examiner, const std::vector<Coord>& nodes, std::vector<Edge> edges,
                                const LatticeDeformation& deformation, HiddenEdgeStats& stats) {
    for (const Coord& n : nodes)
        for (int u = 0; u < 3; ++u)
            for (int su = -1; su <= 1; su += 2) {
                const Coord nu = neighbour(n, u, su);
                edges.push_back(segment(n, nu));
                for (int v = u + 1; v < 3; ++v)
                    for (int sv = -1; sv <= 1; sv += 2) {
                        edges.push_back(segment(n, neighbour(nu, v, sv)));
                        edges.push_back(segment(nu, neighbour(n, v, sv)));
                    }
            }
    edges.erase(std::remove_if(edges.begin(), edges.end(),
                               [&](const Edge& e) {
                                   return !examiner.validNode(e.node) || !examiner.validNode(e.other()) ||
                                          (e.diagonal() && (!examiner.validNode(e.corner(0)) || !examiner.validNode(e.corner(1))));
                               }),
                edges.end());
    std::sort(edges.begin(), edges.end());
    edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
    std::vector<std::optional<Move>> moves(edges.size());
    std::vector<std::uint64_t> examined(edges.size(), 0), evaluated(edges.size(), 0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, edges.size(), 64), [&](const tbb::blocked_range<std::size_t>& r) {
        NodeStates nodes(deformation);
        for (std::size_t i = r.begin(); i < r.end(); ++i)
            moves[i] = examiner.examine(edges[i], [&](const Coord& c) { return examiner.rest(c); }, nodes, examined[i],
                                        evaluated[i]);
    });
    std::vector<Move> all;
    for (std::size_t i = 0; i < edges.size(); ++i) {
        if (moves[i]) all.push_back(*moves[i]);
        stats.edgesExamined += examined[i];
        stats.samples += evaluated[i];
    }
    return all;
}

} // namespace

void splitHiddenEdges(const Field& field, const Lattice& lattice, const ThinSearchOptions& options,
                      LatticeDeformation& deformation, HiddenEdgeStats* statsOut) {
    HiddenEdgeStats stats;
    if (field.cellBoundsAreCornerRange(lattice.frame)) {
        if (statsOut) *statsOut = stats;
        return;
    }
    const EdgeExaminer examiner(field, lattice, options.iso, options.steps);
    std::vector<Move> proposals = examineActiveCells(examiner, field, lattice, deformation, options.cancel, stats);
    openvdb::tree::ValueAccessor<OffsetTree> acc(*deformation.offsets);
    for (int round = 0; round < kMaxRounds && !proposals.empty(); ++round) {
        if (options.cancel) options.cancel->check();
        // One move per node, and none next to a node moved this round.
        std::sort(proposals.begin(), proposals.end());
        std::vector<Coord> moved;
        std::vector<Edge> deferred;
        for (std::size_t i = 0; i < proposals.size(); ++i) {
            const Move& m = proposals[i];
            if (acc.isValueOn(m.node)) continue;
            // Its checks assumed the nodes around it stay.
            if (movedNear(m.node, [&](const Coord& c) { return std::binary_search(moved.begin(), moved.end(), c); })) {
                deferred.push_back(m.edge);
                continue;
            }
            acc.setValue(m.node, openvdb::Vec3f(m.offset.x, m.offset.y, m.offset.z));
            moved.push_back(m.node); // proposals go in node order, so `moved` stays sorted
        }
        stats.edgesSplit += moved.size();
        std::vector<Vec3i> from, bridgedNodes;
        for (const Coord& c : moved) from.emplace_back(c.x(), c.y(), c.z());
        stats.bridged += bridgeThinParts(field, lattice, options, deformation, from, &stats.samples, &bridgedNodes);
        for (const Vec3i& v : bridgedNodes) moved.emplace_back(v.x, v.y, v.z);
        proposals = examineAround(examiner, moved, std::move(deferred), deformation, stats);
    }
    if (statsOut) *statsOut = stats;
}

} // namespace vdbsurf
