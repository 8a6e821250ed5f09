#include "vdbsurf/dmc/thin_search.h"

#include "vdbsurf/core/cancel.h"
#include "vdbsurf/core/error.h"
#include "vdbsurf/core/progress.h"
#include "vdbsurf/dmc/edge_runs.h"
#include "vdbsurf/dmc/hidden_edges.h"
#include "vdbsurf/dmc/lattice_deformation.h"
#include "vdbsurf/dmc/leaf_nodes.h"
#include "vdbsurf/dmc/lone_nodes.h"
#include "vdbsurf/lattice/lattice.h"

#include <Eigen/Dense>
#include <openvdb/tree/LeafManager.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <functional>
#include <optional>
#include <tuple>

namespace vdbsurf {

using openvdb::Coord;

int thinSearchSamplesPerAxis(int steps) { return int(std::ceil(steps * std::sqrt(5.0) / 2.0 - 1e-9)); }

namespace {

using MaskLeaf = CellTree::LeafNodeType;

// Does marching cubes separate two nodes of one side that meet across a diagonal of this cell
// (inside nodes across a face, either side across the cell)? Then the field may join them.
bool separatesDiagonal(unsigned config) {
    for (int axis = 0; axis < 3; ++axis)
        for (int s = 0; s < 2; ++s) {
            const int u = 1 << ((axis + 1) % 3), v = 1 << ((axis + 2) % 3), base = s << axis;
            const bool c00 = config >> base & 1u, c11 = config >> (base | u | v) & 1u;
            const bool c10 = config >> (base | u) & 1u, c01 = config >> (base | v) & 1u;
            if ((c00 && c11 && !c10 && !c01) || (c10 && c01 && !c00 && !c11)) return true;
        }
    for (int c = 0; c < 4; ++c) {
        const unsigned pair = (1u << c) | (1u << (7 - c));
        if (config == pair || config == (255u & ~pair)) return true;
    }
    return false;
}

// Could at least 4 of the six neighbours of the node at leaf-local (x, y, z) lie across from it?
// Counted from the leaf's values; a neighbour beyond the leaf's nodes, or not sampled, may be
// (centreThinParts decides).
bool mayBeCrowded(const std::array<double, kLeafNodeCount>& vals, const std::array<std::uint8_t, kLeafNodeCount>& needed, int x, int y,
                  int z, double iso, Inside side) {
    const bool inside = isInside(vals[std::size_t(leafNodeIndex(x, y, z))], iso, side);
    int across = 0;
    for (int k = 0; k < 6; ++k) {
        const int s = k % 2 ? 1 : -1;
        const int nx = x + (k / 2 == 0 ? s : 0), ny = y + (k / 2 == 1 ? s : 0), nz = z + (k / 2 == 2 ? s : 0);
        const bool beyond = nx < 0 || ny < 0 || nz < 0 || nx >= kLeafNodesPerSide || ny >= kLeafNodesPerSide || nz >= kLeafNodesPerSide;
        const int i = beyond ? 0 : leafNodeIndex(nx, ny, nz);
        across += beyond || !needed[std::size_t(i)] || isInside(vals[std::size_t(i)], iso, side) != inside;
    }
    return across >= 4;
}

// The corners of hidden cells (`hidden`), of cells where marching cubes separates a diagonal pair
// (`ambiguous`), and nodes that may have at least 4 of their six neighbours across (`crowded`),
// each sorted and unique.
void classifyCells(const Field& field, const Lattice& lattice, double iso, const CancelToken* cancel, std::uint64_t& hiddenCells,
                   std::vector<Coord>& hidden, std::vector<Coord>& ambiguous, std::vector<Coord>& crowded) {
    openvdb::tree::LeafManager<const CellTree> leaves(*lattice.cells);
    std::vector<std::vector<Coord>> perLeaf(leaves.leafCount()), ambiguousPerLeaf(leaves.leafCount()),
        crowdedPerLeaf(leaves.leafCount());
    std::vector<std::uint64_t> hiddenPerLeaf(leaves.leafCount(), 0);
    const Inside side = field.inside();
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, leaves.leafCount(), 8), [&](const tbb::blocked_range<std::size_t>& r) {
        std::array<double, kLeafNodeCount> vals;
        std::array<std::uint8_t, kLeafNodeCount> needed;
        for (std::size_t li = r.begin(); li < r.end(); ++li) {
            if (cancel) cancel->check();
            const MaskLeaf& leaf = leaves.leaf(li);
            const Coord o = leaf.origin();
            sampleLeafNodes(field, lattice.frame, leaf, needed, vals);
            auto& out = perLeaf[li];
            for (auto it = leaf.cbeginValueOn(); it; ++it) {
                const int off = int(it.pos()), x = off >> 6, y = (off >> 3) & 7, z = off & 7;
                unsigned config = 0;
                for (int c = 0; c < 8; ++c)
                    if (isInside(vals[std::size_t(leafCornerIndex(it.pos(), c))], iso, side)) config |= 1u << c;
                if (config != 0 && config != 255)
                    for (int c = 0; c < 8; ++c) {
                        const bool at = config >> c & 1u;
                        const int across = int((config >> (c ^ 1) & 1u) != at) + int((config >> (c ^ 2) & 1u) != at) +
                                           int((config >> (c ^ 4) & 1u) != at);
                        const int cx = x + (c & 1), cy = y + ((c >> 1) & 1), cz = z + ((c >> 2) & 1);
                        if (across >= 2 && mayBeCrowded(vals, needed, cx, cy, cz, iso, side))
                            crowdedPerLeaf[li].push_back(o.offsetBy(cx, cy, cz));
                    }
                std::vector<Coord>* to = nullptr;
                if (config == 0 || config == 255) {
                    ++hiddenPerLeaf[li];
                    to = &out;
                } else if (separatesDiagonal(config)) {
                    to = &ambiguousPerLeaf[li];
                } else if (__builtin_popcount(config) == 1 || __builtin_popcount(config) == 7) {
                    // A corner alone on its side here may be alone among its six neighbours too.
                    const int c = __builtin_ctz(__builtin_popcount(config) == 1 ? config : (~config & 255u));
                    ambiguousPerLeaf[li].push_back(o.offsetBy(x + (c & 1), y + ((c >> 1) & 1), z + ((c >> 2) & 1)));
                }
                if (!to) continue;
                for (int c = 0; c < 8; ++c) to->push_back(o.offsetBy(x + (c & 1), y + ((c >> 1) & 1), z + ((c >> 2) & 1)));
            }
            for (auto* list : {&out, &ambiguousPerLeaf[li], &crowdedPerLeaf[li]}) {
                std::sort(list->begin(), list->end());
                list->erase(std::unique(list->begin(), list->end()), list->end());
            }
        }
    });
    auto gather = [](std::vector<std::vector<Coord>>& parts, std::vector<Coord>& all) {
        for (auto& p : parts) all.insert(all.end(), p.begin(), p.end());
        std::sort(all.begin(), all.end());
        all.erase(std::unique(all.begin(), all.end()), all.end());
    };
    gather(perLeaf, hidden);
    gather(ambiguousPerLeaf, ambiguous);
    gather(crowdedPerLeaf, crowded);
    for (std::uint64_t n : hiddenPerLeaf) hiddenCells += n;
}

// Searches one node's Ω. With `onlyUnrepresented`, only the parts of Ω in active cells that have
// no corner on the other side count (the first phase); without, all of Ω does (bridging).
class OmegaSearch {
public:
    OmegaSearch(const Field& field, const Lattice& lattice, double iso, int steps)
        : mField(field), mLattice(lattice), mIso(iso), mSide(field.inside()), mH(lattice.frame.h) {
        const int m = thinSearchSamplesPerAxis(steps);
        const double a = mH / m;
        for (int i = 0; i < m; ++i) {
            const double cubic = -mH / 2 + (i + 0.5) * a, centred = -mH / 2 + i * a;
            mAxis[0][cubic < 0 ? 0 : 1].push_back(cubic);
            mAxis[1][centred < 0 ? 0 : 1].push_back(centred);
        }
    }

    // Strictly on the other side of a node whose side is `inside`: an iso value counts for neither.
    bool otherSide(bool inside, double v) const { return isOtherSide(inside, v, mIso, mSide); }

    // The node's new offset, if its Ω holds samples on the other side. `around` holds the values
    // of the 3x3x3 nodes centred on it (x fastest).
    std::optional<Vec3f> search(const Coord& n, const double* around, bool onlyUnrepresented,
                                openvdb::tree::ValueAccessor<const CellTree, false>& cells, std::uint64_t& evaluated,
                                std::vector<Vec3d>& found) const {
        const LatticeFrame& frame = mLattice.frame;
        const Vec3i ni(n.x(), n.y(), n.z());
        const bool nodeInside = isInside(around[13], mIso, mSide);
        const Vec3d centre = frame.nodeWorld(ni);
        found.clear();
        int octants[8], asked = 0;
        Box3 boxes[8];
        for (int d = 0; d < 8; ++d) {
            const int dx = d & 1, dy = (d >> 1) & 1, dz = (d >> 2) & 1;
            const Coord cell = n.offsetBy(dx - 1, dy - 1, dz - 1);
            if (!mLattice.cellRange.isInside(cell)) continue;
            if (onlyUnrepresented) {
                if (!cells.isValueOn(cell)) continue;
                bool represented = false; // the other side already has a corner in this cell
                for (int c = 0; c < 8 && !represented; ++c) {
                    const int x = dx + (c & 1), y = dy + ((c >> 1) & 1), z = dz + ((c >> 2) & 1);
                    represented = isInside(around[x + 3 * y + 9 * z], mIso, mSide) != nodeInside;
                }
                if (represented) continue;
            }
            octants[asked] = d;
            boxes[asked++] = octantBox(centre, d);
        }
        // The octants' bounds, asked together within Ω. (Bounds over the octants' eighths before
        // sampling them paid while a formula's points cost a few microseconds each; evaluated
        // together they cost less than the bounds: 20 spikes at 80^3 5.7 -> 3.1 s, the lens 2.9 ->
        // 1.4 s at one thread.)
        std::uint8_t straddle[8];
        const Box3 omega{centre - Vec3d(mH / 2, mH / 2, mH / 2), centre + Vec3d(mH / 2, mH / 2, mH / 2)};
        mField.mayStraddleWithin(omega, boxes, std::size_t(asked), mIso, straddle);
        for (int k = 0; k < asked; ++k)
            if (straddle[k]) collectOctant(centre, octants[k], nodeInside, evaluated, found);
        return placeAtCentroid(centre, found, nodeInside);
    }

    // The centroid of the samples of Ω strictly on the node's own side (`inside`), as an offset,
    // if it lies on that side too (else the sample nearest to it) — where those samples are
    // thin across two directions, as a wire's are: the second largest variance of their
    // positions below 0.85 of a full cube's, h²/12 (a wire a cell thick: 0.75; the half of Ω
    // on one side of a smooth surface through the node: 1, whatever its orientation).
    std::optional<Vec3f> thinOwnSideCentroid(const Coord& n, bool inside, std::uint64_t& evaluated) const {
        const Vec3d centre = mLattice.frame.nodeWorld(Vec3i(n.x(), n.y(), n.z()));
        thread_local std::vector<Vec3d> own;
        own.clear();
        for (int d = 0; d < 8; ++d)
            if (mField.mayHoldOtherSide(octantBox(centre, d), !inside, mIso))
                collectOctant(centre, d, !inside, evaluated, own);
        if (own.empty()) return std::nullopt;
        Vec3d mean;
        for (const Vec3d& p : own) mean += p;
        mean = mean / double(own.size());
        Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
        for (const Vec3d& p : own) {
            const Eigen::Vector3d d(p.x - mean.x, p.y - mean.y, p.z - mean.z);
            covariance += d * d.transpose();
        }
        covariance /= double(own.size());
        const Eigen::Vector3d variances = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(covariance, Eigen::EigenvaluesOnly).eigenvalues();
        if (variances[1] >= 0.85 * mH * mH / 12) return std::nullopt; // ascending: [1] is the second largest
        return placeAtCentroid(centre, own, !inside);
    }

    Inside side() const { return mSide; }
    double iso() const { return mIso; }

private:
    // Octant d (bit 0: x, 1: y, 2: z above the centre) of the Ω around `centre`.
    Box3 octantBox(const Vec3d& centre, int d) const {
        const Vec3d lo = centre + Vec3d(d & 1 ? 0 : -mH / 2, d & 2 ? 0 : -mH / 2, d & 4 ? 0 : -mH / 2);
        return Box3{lo, lo + Vec3d(mH / 2, mH / 2, mH / 2)};
    }

    // Appends to `out` the samples of octant d strictly on the other side from a node whose side
    // is `from`. Evaluated together (a grid reads the voxels under the octant once, a formula runs
    // over them at once), in the order they are listed.
    void collectOctant(const Vec3d& centre, int d, bool from, std::uint64_t& evaluated, std::vector<Vec3d>& out) const {
        const int dx = d & 1, dy = (d >> 1) & 1, dz = (d >> 2) & 1;
        thread_local std::vector<Vec3d> points;
        thread_local std::vector<double> values;
        points.clear();
        for (int pattern = 0; pattern < 2; ++pattern)
            for (double oz : mAxis[std::size_t(pattern)][std::size_t(dz)])
                for (double oy : mAxis[std::size_t(pattern)][std::size_t(dy)])
                    for (double ox : mAxis[std::size_t(pattern)][std::size_t(dx)]) points.push_back(centre + Vec3d(ox, oy, oz));
        values.resize(points.size());
        mField.values(octantBox(centre, d), points.data(), points.size(), values.data());
        evaluated += points.size();
        for (std::size_t i = 0; i < points.size(); ++i)
            if (otherSide(from, values[i])) out.push_back(points[i]);
    }

    // The offset from `centre` to the centroid of `samples` (strictly on the other side from a
    // node whose side is `from`), if the lattice, evaluating it as a float offset, finds it on
    // that side too; else to the sample nearest the centroid (the centroid of a curved or split
    // part can fall outside it), if that holds.
    std::optional<Vec3f> placeAtCentroid(const Vec3d& centre, const std::vector<Vec3d>& samples, bool from) const {
        if (samples.empty()) return std::nullopt;
        auto placed = [&](const Vec3d& p) -> std::optional<Vec3f> {
            const Vec3f off(p - centre);
            return otherSide(from, mField.value(centre + Vec3d(off))) ? std::optional<Vec3f>(off) : std::nullopt;
        };
        Vec3d mean;
        for (const Vec3d& p : samples) mean += p;
        mean = mean / double(samples.size());
        if (auto move = placed(mean)) return move;
        std::size_t best = 0;
        double bestDistance = INFINITY;
        for (std::size_t i = 0; i < samples.size(); ++i) {
            const Vec3d dv = samples[i] - mean;
            const double dist = dot(dv, dv);
            if (dist < bestDistance) bestDistance = dist, best = i;
        }
        return placed(samples[best]);
    }

    const Field& mField;
    const Lattice& mLattice;
    double mIso;
    Inside mSide;
    double mH;
    std::array<std::array<std::vector<double>, 2>, 2> mAxis; // [pattern: cubic, centred][half of Ω: below, above]
};

inline int local3(int x, int y, int z) { return (x + 1) + 3 * (y + 1) + 9 * (z + 1); }

// Moves are proposed in parallel, each checked with the nodes as they were before the batch; they
// are applied in node order, and a move near one applied before it (`movedInBatch`) is checked
// again: two nodes of a crack, each moving into the half on its side, would join the
// halves by the edge between them.
bool stillKeeps(const EdgeRuns& edgeRuns, const Field& field, const LatticeFrame& frame, double iso, const LatticeDeformation& deformation,
                const Coord& n, const Vec3f& offset, const std::function<bool(const Coord&)>& movedInBatch, std::uint64_t& samples) {
    if (!movedNear(n, movedInBatch)) return true;
    NodeStates nodes(deformation);
    std::uint64_t examined = 0;
    double rest = 0;
    field.sampleNodes(frame, Vec3i(n.x(), n.y(), n.z()), {1, 1, 1}, nullptr, &rest);
    const Vec3d to = frame.nodeWorld(Vec3i(n.x(), n.y(), n.z())) + Vec3d(offset);
    return edgeRuns.moveEffect(n, isInside(rest, iso, field.inside()), to, nodes, examined, samples).keeps;
}

// The side of node c now: its value at rest, then where the deformation put it.
bool nodeInsideNow(const Field& field, const LatticeFrame& frame, double iso, NodeStates& nodes, const Coord& c) {
    double v = 0;
    field.sampleNodes(frame, {c.x(), c.y(), c.z()}, {1, 1, 1}, nullptr, &v);
    return nodes.inside(c, isInside(v, iso, field.inside()));
}

// Nodes of `moved` (the first phase's) that went into a part of the inside and stand alone on
// their side among their six neighbours, where the part reaches a node of the rest that is not
// alone (a path inside within a cell of both, EdgeRuns::joinedNearby): the part is the tip of
// a larger one which the lattice cannot join to it, since every node between would join it
// across a gap too (a wedge of a fractured piece where two gaps and the surface meet). Decided
// on one state.
std::vector<Coord> cutOffTips(const EdgeRuns& edgeRuns, const Field& field, const LatticeFrame& frame, double iso,
                              const std::vector<Coord>& moved, const LatticeDeformation& deformation, std::uint64_t& samples) {
    NodeStates nodes(deformation);
    auto insideNow = [&](const Coord& c) { return nodeInsideNow(field, frame, iso, nodes, c); };
    auto where = [&](const Coord& c) {
        openvdb::Vec3f o(0.0f);
        nodes.offsets.probeValue(c, o);
        return frame.nodeWorld(Vec3i(c.x(), c.y(), c.z())) + Vec3d(o.x(), o.y(), o.z());
    };
    auto alone = [&](const Coord& c) {
        for (int k = 0; k < 6; ++k)
            if (insideNow(c + axisStep(k / 2, k % 2 ? 1 : -1))) return false;
        return true;
    };
    std::vector<Coord> tips;
    for (const Coord& c : moved) {
        if (!nodes.offsets.isValueOn(c) || !insideNow(c) || !alone(c)) continue;
        bool joined = false;
        for (int z = -1; z <= 1 && !joined; ++z)
            for (int y = -1; y <= 1 && !joined; ++y)
                for (int x = -1; x <= 1 && !joined; ++x) {
                    const Coord n = c.offsetBy(x, y, z);
                    if (n == c || !insideNow(n) || alone(n)) continue;
                    joined = edgeRuns.joinedNearby(where(c), where(n), true, samples);
                }
        if (joined) tips.push_back(c);
    }
    return tips;
}

} // namespace

std::vector<Vec3i> restoreLoneJoins(const Field& field, const LatticeFrame& frame, double iso, const std::vector<Vec3i>& joinNodes,
                                    LatticeDeformation& deformation) {
    constexpr std::size_t kLargestPiece = 27; // a larger piece made of joins is taken to be a part
    NodeStates nodes(deformation);
    auto insideNow = [&](const Coord& c) { return nodeInsideNow(field, frame, iso, nodes, c); };
    std::vector<Coord> joins;
    for (const Vec3i& n : joinNodes) joins.emplace_back(n.x, n.y, n.z);
    std::sort(joins.begin(), joins.end());
    joins.erase(std::unique(joins.begin(), joins.end()), joins.end());
    auto isJoin = [&](const Coord& c) { return std::binary_search(joins.begin(), joins.end(), c) && nodes.offsets.isValueOn(c); };
    std::vector<Coord> restore;
    NodeMaskTree seen; // (a sorted list merged with every piece was quadratic in the joins: 20 k on the lens)
    openvdb::tree::ValueAccessor<NodeMaskTree> seenAcc(seen);
    for (const Coord& start : joins) {
        if (!isJoin(start) || !insideNow(start) || seenAcc.isValueOn(start)) continue;
        std::vector<Coord> piece{start};
        bool anchored = false;
        for (std::size_t i = 0; i < piece.size() && !anchored; ++i)
            for (int k = 0; k < 6 && !anchored; ++k) {
                const Coord nb = piece[i] + axisStep(k / 2, k % 2 ? 1 : -1);
                if (std::find(piece.begin(), piece.end(), nb) != piece.end() || !insideNow(nb)) continue;
                anchored = !isJoin(nb) || piece.size() >= kLargestPiece;
                piece.push_back(nb);
            }
        for (const Coord& c : piece) seenAcc.setValueOn(c);
        if (!anchored) restore.insert(restore.end(), piece.begin(), piece.end());
    }
    // A join off the surface whose one inside neighbour lies on it, and has another inside
    // neighbour off the surface: the crossings on such a node's edges sit on it, so the join meets
    // the rest at a point only, and gets a fan of its own there (a node bridged beside a node
    // flipped onto a crack's rim edge, across it from the half's nodes: a 6-vertex bubble). Joins
    // behind a cube's corner node lean on it and on an edge node at once, and stay.
    auto insideOffSurface = [&](const Coord& c) { return !nodes.onSurface.isValueOn(c) && insideNow(c); };
    for (const Coord& x : joins) {
        if (!isJoin(x) || !insideOffSurface(x)) continue;
        std::vector<Coord> insideNeighbours;
        for (int k = 0; k < 6; ++k) {
            const Coord nb = x + axisStep(k / 2, k % 2 ? 1 : -1);
            if (insideNow(nb)) insideNeighbours.push_back(nb);
        }
        if (insideNeighbours.size() != 1 || !nodes.onSurface.isValueOn(insideNeighbours[0])) continue;
        const Coord f = insideNeighbours[0];
        for (int k = 0; k < 6; ++k) {
            const Coord g = f + axisStep(k / 2, k % 2 ? 1 : -1);
            if (g != x && insideOffSurface(g)) {
                restore.push_back(x);
                break;
            }
        }
    }
    std::sort(restore.begin(), restore.end());
    restore.erase(std::unique(restore.begin(), restore.end()), restore.end());
    openvdb::tree::ValueAccessor<OffsetTree> acc(*deformation.offsets);
    openvdb::tree::ValueAccessor<NodeMaskTree> onSurface(*deformation.onSurface), insideOnSurface(*deformation.insideOnSurface);
    std::vector<Vec3i> restored;
    for (const Coord& c : restore) {
        acc.setValueOff(c, openvdb::Vec3f(0.0f));
        onSurface.setValueOff(c);
        insideOnSurface.setValueOff(c);
        restored.emplace_back(c.x(), c.y(), c.z());
    }
    return restored;
}

void thinSearch(const Field& field, const Lattice& lattice, const ThinSearchOptions& options, LatticeDeformation& deformation,
                ThinSearchStats* stats, std::vector<Vec3i>* crowded, std::vector<Vec3i>* loneJoins) {
    const auto start = std::chrono::steady_clock::now();
    if (options.steps < 1 || options.steps > 64)
        throw Error("--search-steps", "must be between 1 and 64, not " + std::to_string(options.steps));
    ThinSearchStats local;
    const LatticeFrame& frame = lattice.frame;
    const double iso = options.iso;
    const OmegaSearch searcher(field, lattice, iso, options.steps);
    const EdgeRuns edgeRuns(field, lattice, iso, options.steps);

    // A field whose bounds over a cell are its corners' range has nothing hidden inside a cell.
    std::vector<Coord> candidates, ambiguous, crowdedNodes;
    if (!field.cellBoundsAreCornerRange(frame))
        classifyCells(field, lattice, iso, options.cancel, local.hiddenCells, candidates, ambiguous, crowdedNodes);
    if (crowded) {
        crowded->clear();
        for (const Coord& c : crowdedNodes) crowded->emplace_back(c.x(), c.y(), c.z());
    }
    local.candidates = candidates.size();

    // Phase 1: corners of hidden cells search the parts of their Ω that no corner represents.
    std::vector<std::optional<Vec3f>> moves(candidates.size());
    std::vector<std::uint64_t> samples(candidates.size(), 0);
    {
        Progress progress("thin search", candidates.size(), options.cancel);
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, candidates.size(), 64), [&](const tbb::blocked_range<std::size_t>& r) {
            openvdb::tree::ValueAccessor<const CellTree, false> cells(*lattice.cells);
            NodeStates nodes(deformation);
            std::array<double, 27> around;
            std::vector<Vec3d> found;
            for (std::size_t ci = r.begin(); ci < r.end(); ++ci) {
                progress.advance();
                const Coord n = candidates[ci];
                field.sampleNodes(frame, Vec3i(n.x() - 1, n.y() - 1, n.z() - 1), {3, 3, 3}, nullptr, around.data());
                moves[ci] = searcher.search(n, around.data(), true, cells, samples[ci], found);
                // Not where an edge of the node would then hide what it showed (near a crack's
                // rim, a cell with no inside corner holds a wedge of one half, and a node moved into
                // it would join the halves across the crack).
                std::uint64_t examined = 0;
                const bool inside = isInside(around[13], iso, field.inside());
                if (moves[ci] && !edgeRuns.moveEffect(n, inside, frame.nodeWorld(Vec3i(n.x(), n.y(), n.z())) + Vec3d(*moves[ci]), nodes,
                                                      examined, samples[ci]).keeps)
                    moves[ci].reset();
            }
        });
    }
    if (options.cancel) options.cancel->check();

    openvdb::tree::ValueAccessor<OffsetTree> acc(*deformation.offsets);
    std::vector<Coord> frontier = std::move(ambiguous), phaseOne;
    for (std::size_t ci = 0; ci < candidates.size(); ++ci) {
        local.samples += samples[ci];
        if (!moves[ci]) continue;
        // Each move was checked with every node at rest (see stillKeeps).
        const Coord n = candidates[ci];
        if (!stillKeeps(edgeRuns, field, frame, iso, deformation, n, *moves[ci], [&](const Coord& c) { return acc.isValueOn(c); },
                        local.samples))
            continue;
        acc.setValue(candidates[ci], openvdb::Vec3f(moves[ci]->x, moves[ci]->y, moves[ci]->z));
        frontier.push_back(candidates[ci]);
        phaseOne.push_back(candidates[ci]);
        ++local.nodesMoved;
    }
    std::sort(frontier.begin(), frontier.end());
    frontier.erase(std::unique(frontier.begin(), frontier.end()), frontier.end());

    std::vector<Vec3i> from;
    for (const Coord& c : frontier) from.emplace_back(c.x(), c.y(), c.z());
    local.bridged = bridgeThinParts(field, lattice, options, deformation, from, &local.samples);
    local.nodesMoved += local.bridged;

    // Phase 3: edges whose ends agree although a part crosses them.
    HiddenEdgeStats hidden;
    splitHiddenEdges(field, lattice, options, deformation, &hidden);
    local.edgesSplit = hidden.edgesSplit;
    local.bridged += hidden.bridged;
    local.nodesMoved += hidden.edgesSplit + hidden.bridged;
    local.samples += hidden.samples;
    std::sort(phaseOne.begin(), phaseOne.end());
    std::vector<Vec3i> joins;
    for (auto it = deformation.offsets->cbeginValueOn(); it; ++it)
        if (!std::binary_search(phaseOne.begin(), phaseOne.end(), it.getCoord()))
            joins.emplace_back(it.getCoord().x(), it.getCoord().y(), it.getCoord().z());
    local.nodesMoved -= restoreLoneJoins(field, frame, iso, joins, deformation).size();
    // Such a tip alone is a bubble of 4 to 8 vertices, a piece the shape does not have: it goes
    // back to rest, and the tip (within the node's Ω) with it.
    for (const Coord& c : cutOffTips(edgeRuns, field, frame, iso, phaseOne, deformation, local.samples)) {
        acc.setValueOff(c, openvdb::Vec3f(0.0f));
        --local.nodesMoved;
    }
    // Where the cells hide nothing, a node alone inside may still be joined across a face.
    if (loneJoins) loneJoins->clear();
    if (field.cellBoundsAreCornerRange(frame)) {
        const std::vector<Vec3i> joined = joinLoneNodes(field, lattice, options, deformation, &local.samples);
        local.loneJoined = joined.size();
        local.nodesMoved += joined.size();
        local.bridged += joined.size();
        if (loneJoins) *loneJoins = joined;
    }
    local.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (stats) *stats = local;
}

std::uint64_t bridgeThinParts(const Field& field, const Lattice& lattice, const ThinSearchOptions& options,
                              LatticeDeformation& deformation, const std::vector<Vec3i>& from, std::uint64_t* samplesOut,
                              std::vector<Vec3i>* movedOut) {
    const LatticeFrame& frame = lattice.frame;
    // A point for node n on the segment a-b (which lies in a thin part): the middle of the
    // stretch inside n's Ω, or, where the segment only grazes Ω (a part running along the edge
    // where four Ω meet), the point of Ω nearest to it, if that is within half a search step.
    // Returned as an offset from n (offsetInOmega).
    const double reach = frame.h / (2.0 * options.steps);
    // The point of the Ω around `centre` nearest to the points pointAt(0 … count-1), as an offset,
    // if it is within half a search step of one.
    auto nearestInOmega = [&](const Vec3d& centre, int count, const auto& pointAt) -> std::optional<Vec3f> {
        const double half = frame.h / 2;
        double best = INFINITY;
        Vec3d nearest;
        for (int i = 0; i < count; ++i) {
            const Vec3d rel = pointAt(i) - centre;
            Vec3d clamped;
            for (int k = 0; k < 3; ++k) clamped[k] = std::clamp(rel[k], -half, half);
            const double dist = length(clamped - rel);
            if (dist < best) best = dist, nearest = clamped;
        }
        return best <= reach ? offsetInOmega(nearest, frame.h) : std::nullopt;
    };
    auto segmentInOmega = [&](const Coord& n, const Vec3d& a, const Vec3d& b) -> std::optional<Vec3f> {
        const Vec3d centre = frame.nodeWorld(Vec3i(n.x(), n.y(), n.z())), d = b - a;
        const double half = frame.h / 2;
        double t0 = 0, t1 = 1;
        for (int k = 0; k < 3 && t0 <= t1; ++k) {
            if (d[k] == 0) {
                if (std::fabs(a[k] - centre[k]) > half) t0 = 1, t1 = 0;
                continue;
            }
            double ta = (centre[k] - half - a[k]) / d[k], tb = (centre[k] + half - a[k]) / d[k];
            if (ta > tb) std::swap(ta, tb);
            t0 = std::max(t0, ta);
            t1 = std::min(t1, tb);
        }
        if (t0 <= t1) return offsetInOmega(a + d * (0.5 * (t0 + t1)) - centre, frame.h);
        return nearestInOmega(centre, 33, [&](int i) { return a + d * (i / 32.0); });
    };
    // The same for a path of samples: the middle one of those in Ω, or the point of Ω nearest
    // to the path, if within half a search step.
    auto pathInOmega = [&](const Coord& n, const std::vector<Vec3d>& path) -> std::optional<Vec3f> {
        const Vec3d centre = frame.nodeWorld(Vec3i(n.x(), n.y(), n.z()));
        const double half = frame.h / 2;
        std::vector<std::size_t> within;
        for (std::size_t i = 0; i < path.size(); ++i) {
            const Vec3d rel = path[i] - centre;
            if (std::fabs(rel.x) <= half && std::fabs(rel.y) <= half && std::fabs(rel.z) <= half) within.push_back(i);
        }
        if (!within.empty()) return offsetInOmega(path[within[within.size() / 2]] - centre, frame.h);
        return nearestInOmega(centre, int(path.size()), [&](int i) { return path[std::size_t(i)]; });
    };
    const double iso = options.iso;
    const Inside side = field.inside();
    const OmegaSearch searcher(field, lattice, iso, options.steps);
    const EdgeRuns edgeRuns(field, lattice, iso, options.steps);
    openvdb::tree::ValueAccessor<OffsetTree> acc(*deformation.offsets);
    std::vector<Coord> frontier;
    for (const Vec3i& v : from) frontier.emplace_back(v.x, v.y, v.z);
    std::uint64_t bridged = 0;
    // Does node c (at rest, on side `inside`) stand where faces of its side meet, by the normals
    // where its edges cross to neighbours at rest on the other side (a moved neighbour's crossing
    // may lie on an edge, where the gradient is neither face's)? Then it is what the lattice has
    // of that edge or corner: the only outside node of a notch about a cell deep lies between its
    // walls, and bridged into the solid beside it (to join a node flipped onto the notch's rim)
    // it took the notch with it.
    auto standsAtFeature = [&](const Coord& c, bool inside, NodeStates& nodes, std::uint64_t& evaluated) {
        if (!(options.keepFeatureNodes > -1)) return false;
        const Vec3d a = frame.nodeWorld(Vec3i(c.x(), c.y(), c.z()));
        const double va = field.value(a);
        evaluated += 1;
        if (isInside(va, iso, side) != inside) return false;
        Vec3d normals[6];
        int count = 0;
        for (int k = 0; k < 6; ++k) {
            const Coord m = c + axisStep(k / 2, k % 2 ? 1 : -1);
            if (nodes.offsets.isValueOn(m)) continue;
            const Vec3d b = frame.nodeWorld(Vec3i(m.x(), m.y(), m.z()));
            const double vb = field.value(b);
            evaluated += 1;
            if (isInside(vb, iso, side) == inside) continue;
            const Vec3d g = field.gradient(a + (b - a) * field.edgeCrossing(a, b, va, vb, iso));
            const double len = length(g);
            if (!(len > 0) || !std::isfinite(len)) continue;
            normals[count++] = g / len;
        }
        for (int i = 0; i < count; ++i)
            for (int j = i + 1; j < count; ++j)
                if (dot(normals[i], normals[j]) < options.keepFeatureNodes) return true;
        return false;
    };
    // Phase 2, bridging: marching cubes never joins two inside nodes across the diagonal of a
    // face, nor two nodes of one side across a cell's diagonal. Where nodes of a thin part (moved
    // or not) meet like that and the part does join them (the segment between them stays on
    // their side), one of the nodes between searches its whole Ω and moves into the part.
    // Starts from the moved nodes and the corners of such cells, then repeats from the nodes
    // that moved, until nothing moves.
    // How far from a node the lattice is asked whether it joins two nodes already; and how far
    // a bent path is sought (EdgeRuns::joinedNearby): a cell, with fewer samples a step than a
    // move's check takes (kJunctionReach), as every node moved into a thin part asks for each
    // diagonal partner (noisy fog resampled to 2 voxels a cell: with 100, the thin search took
    // 1.5 times as long). The paths round a crossing of random wires mostly took fewer (with 12
    // or 16, one in 120 more was missed; with 100, 4 of 120 crossings in pieces instead of 8).
    constexpr int kLatticeJoinSteps = 4, kLatticeJoinWidth = 2 * kLatticeJoinSteps + 1, kLatticeJoinPath = 8;
    constexpr EdgeRuns::JoinReach kBentReach{1.0, 24};
    tbb::enumerable_thread_specific<std::uint64_t> bridgeSamples(0);
    std::uint64_t samplesAfter = 0;
    for (int round = 0; round < 16 && !frontier.empty(); ++round) {
        struct Bridge {
            Coord node;
            Vec3f offset;
        };
        std::vector<std::vector<Bridge>> proposals(frontier.size());
        // One node at a time if need be: a node's searches take tens of microseconds, and the
        // sharp pass bridges from a dozen flipped nodes (one task for all of them took 1.8 ms of
        // the armadillo's 15 in that pass).
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, frontier.size(), 1), [&](const tbb::blocked_range<std::size_t>& r) {
            openvdb::tree::ValueAccessor<const CellTree, false> cells(*lattice.cells);
            NodeStates nodes(deformation);
            std::vector<Vec3d> found;
            double block[125], around[27];
            std::uint64_t evaluated = 0, examined = 0;
            for (std::size_t fi = r.begin(); fi < r.end(); ++fi) {
                // (A round over a fine lattice's frontier can take minutes: a cancelled run stops
                // here, and the check after the loop throws.)
                if (options.cancel && options.cancel->cancelled()) return;
                const Coord p = frontier[fi];
                // Values at the 5x5x5 nodes around p (3x3x3 around each node between).
                field.sampleNodes(frame, Vec3i(p.x() - 2, p.y() - 2, p.z() - 2), {5, 5, 5}, nullptr, block);
                auto rest = [&](int x, int y, int z) { return block[(x + 2) + 5 * (y + 2) + 25 * (z + 2)]; };
                auto position = [&](int x, int y, int z, bool& moved) {
                    const Coord c = p.offsetBy(x, y, z);
                    openvdb::Vec3f off;
                    moved = nodes.offsets.probeValue(c, off);
                    return frame.nodeWorld(Vec3i(c.x(), c.y(), c.z())) + Vec3d(off.x(), off.y(), off.z());
                };
                // Side of the node at offset (x, y, z) from p, where it is now.
                auto insideAt = [&](int x, int y, int z) { return nodes.inside(p.offsetBy(x, y, z), isInside(rest(x, y, z), iso, side)); };
                const bool pInside = insideAt(0, 0, 0);
                // Does p end a part of its side thinner than a cell, or stand alone (at most one of
                // its six neighbours on its side)?
                auto endsThinPart = [&] {
                    int ownSide = 0;
                    for (int k = 0; k < 6; ++k) {
                        const Coord e = axisStep(k / 2, k % 2 ? 1 : -1);
                        ownSide += insideAt(e.x(), e.y(), e.z()) == pInside;
                    }
                    return ownSide <= 1;
                };
                bool pMoved = false;
                const Vec3d pPos = position(0, 0, 0, pMoved);
                // Does the segment from a to b stay on p's side at `steps` steps?
                auto onPSide = [&](const Vec3d& a, const Vec3d& b, int steps) {
                    for (int k = 1; k < steps; ++k) {
                        ++evaluated;
                        const double v = field.value(a + (b - a) * (double(k) / steps));
                        if (pInside ? !isInside(v, iso, side) : !searcher.otherSide(true, v)) return false;
                    }
                    return true;
                };
                // Does marching cubes join p to q (an offset from p) through nodes of p's side
                // (inside ones along edges, outside ones across face diagonals too), by a path of at
                // most kLatticeJoinPath steps within kLatticeJoinSteps of p? (The window's values are
                // sampled when first asked.) A longer path goes round something the bridge would
                // not close a handle around: in a cubic truss of wires thinner than a cell, 4 cells
                // apart, a wire's node next to a junction was joined to it only the long way, round
                // a square of the truss, and was not bridged; the square's loop broke there (7 of
                // 10 random trusses lost one to four of their 28 loops when any path in the window
                // counted). With paths of 4 steps, notches about a cell deep lost their concave
                // corners (bridged across: the path round the notch's floor is longer). With 6, a
                // torus in a grid of sheared, unequal voxels, meshed at 2.8 of its smallest, got a
                // second handle: its tube, two cells across one axis of the lattice, had nodes the
                // lattice joined by 7 steps round a notch of the outside, and a bent path bridged
                // them (with 8, random thin formulas' topology was unchanged, 60 of 60).
                std::vector<double> window;
                auto latticeJoins = [&](const Vec3i& q) {
                    if (window.empty()) {
                        window.resize(std::size_t(kLatticeJoinWidth) * kLatticeJoinWidth * kLatticeJoinWidth);
                        field.sampleNodes(frame, Vec3i(p.x() - kLatticeJoinSteps, p.y() - kLatticeJoinSteps, p.z() - kLatticeJoinSteps),
                                          {kLatticeJoinWidth, kLatticeJoinWidth, kLatticeJoinWidth}, nullptr, window.data());
                        evaluated += window.size();
                    }
                    return latticePathNear(Coord(0, 0, 0), Coord(q.x, q.y, q.z), kLatticeJoinSteps, kLatticeJoinPath, !pInside, [&](const Coord& n) {
                        const std::size_t at = std::size_t((n.x() + kLatticeJoinSteps) +
                                                           kLatticeJoinWidth * ((n.y() + kLatticeJoinSteps) + kLatticeJoinWidth * (n.z() + kLatticeJoinSteps)));
                        return nodes.inside(p + n, isInside(window[at], iso, side)) == pInside;
                    });
                };
                // Do all these nodes (offsets from p) lie on the other side from p?
                auto separate = [&](const std::vector<Vec3i>& nodes) {
                    return std::all_of(nodes.begin(), nodes.end(), [&](const Vec3i& b) { return insideAt(b.x, b.y, b.z) != pInside; });
                };
                // Try the nodes between (offsets from p); the one that lands nearest the middle moves.
                // With `to` (the other node of a diagonal the part joins), a node whose Ω the
                // samples miss (the part only clips a corner or runs along an edge of it) may move
                // onto the joining segment (or `path`) where it meets its Ω, if that point is in the part.
                // The inside node a straight bridge joins p to, if the bridge may be one the lattice
                // does not need (see bridgeTo).
                const Vec3i* joinedAlready = nullptr;
                // Node n moving by `off` becomes `best` if it lands nearer `middle` than `best` does
                // — unless the move would make one of its edges hide what it showed (a crack's
                // node pulled into the solid beside it), n stands at a feature, or n alone joins
                // outside nodes the field joins where the bridge is one the lattice does not need.
                auto consider = [&](const Coord& n, const Vec3f& off, const Vec3d& middle, std::optional<Bridge>& best,
                                    double& bestDistance) {
                    const Vec3d to = frame.nodeWorld(Vec3i(n.x(), n.y(), n.z())) + Vec3d(off);
                    const double dist = length(to - middle);
                    if (dist >= bestDistance) return;
                    const Coord d = n - p;
                    const bool restInside = isInside(rest(d.x(), d.y(), d.z()), iso, side);
                    if (!edgeRuns.moveEffect(n, restInside, to, nodes, examined, evaluated).keeps) return;
                    if (standsAtFeature(n, restInside, nodes, evaluated)) return;
                    if (joinedAlready && !restInside && edgeRuns.partsJoined(n, false, nodes, evaluated) && latticeJoins(*joinedAlready)) return;
                    bestDistance = dist, best = Bridge{n, off};
                };
                // The samples of Ω around node b (an offset from p, at rest) on its other side, in `found`.
                auto searchOmega = [&](const Vec3i& b) {
                    for (int z = -1; z <= 1; ++z)
                        for (int y = -1; y <= 1; ++y)
                            for (int x = -1; x <= 1; ++x) around[local3(x, y, z)] = rest(b.x + x, b.y + y, b.z + z);
                    return searcher.search(p.offsetBy(b.x, b.y, b.z), around, false, cells, evaluated, found);
                };
                auto bridge = [&](const std::vector<Vec3i>& between, const Vec3d& middle, const Vec3d* to,
                                  const std::vector<Vec3d>* path = nullptr) {
                    std::optional<Bridge> best;
                    double bestDistance = INFINITY;
                    std::vector<Vec3i> unmoved;
                    for (const Vec3i& b : between) {
                        bool moved = false;
                        position(b.x, b.y, b.z, moved);
                        if (!moved) unmoved.push_back(b);
                    }
                    for (const Vec3i& b : unmoved)
                        if (const std::optional<Vec3f> off = searchOmega(b)) consider(p.offsetBy(b.x, b.y, b.z), *off, middle, best, bestDistance);
                    for (std::size_t i = 0; i < unmoved.size() && !best && to; ++i) {
                        const Vec3i& b = unmoved[i];
                        const Coord n = p.offsetBy(b.x, b.y, b.z);
                        if (const std::optional<Vec3f> off = path ? pathInOmega(n, *path) : segmentInOmega(n, pPos, *to)) {
                            ++evaluated;
                            const bool restInside = isInside(rest(b.x, b.y, b.z), iso, side);
                            const Vec3d at = frame.nodeWorld(Vec3i(n.x(), n.y(), n.z())) + Vec3d(*off);
                            if (searcher.otherSide(restInside, field.value(at))) consider(n, *off, middle, best, bestDistance);
                        }
                    }
                    if (best) proposals[fi].push_back(*best);
                };
                // Where the segment from inside node p to q across a face leaves the inside, a path
                // bent at one point can still join them within the cell: a rod about half a cell
                // thick standing on a ball, whose node next to the ball lies just outside both, so
                // that no cell there is hidden and the rod's first node meets the ball's across a
                // face diagonal (2 of 100 random rods 0.2-0.6 H thick came off, marching cubes
                // leaving them apart too; 1 of them is joined so). One of the face's two outside
                // corners moves to the point of its Ω, on a grid at the search's steps, from which
                // both segments stay inside — the one nearest the diagonal's middle — if the move
                // keeps its edges (as any bridge). Its cost: smoke_fog at 2 voxels a cell, 3.7 M
                // thin-search samples without it, 5.1 M with it (5.8 M with OmegaSearch's samples
                // in place of the grid), about 10 % more time.
                auto bridgeViaPoint = [&](const Vec3d& qPos, const std::vector<Vec3i>& between) {
                    std::optional<Bridge> best;
                    double bestDistance = INFINITY;
                    const Vec3d middle = (pPos + qPos) * 0.5;
                    auto stepsTo = [&](const Vec3d& a, const Vec3d& b) { return int(std::ceil(length(b - a) / frame.h * (options.steps + 1))) + 1; };
                    const int m = options.steps;
                    for (const Vec3i& b : between) {
                        bool moved = false;
                        position(b.x, b.y, b.z, moved);
                        if (moved) continue;
                        const Coord n = p.offsetBy(b.x, b.y, b.z);
                        const Vec3d centre = frame.nodeWorld(Vec3i(n.x(), n.y(), n.z()));
                        const bool restInside = isInside(rest(b.x, b.y, b.z), iso, side);
                        for (int z = 0; z < m; ++z)
                            for (int y = 0; y < m; ++y)
                                for (int x = 0; x < m; ++x) {
                                    const Vec3d rel = Vec3d((x + 0.5) / m - 0.5, (y + 0.5) / m - 0.5, (z + 0.5) / m - 0.5) * frame.h;
                                    const Vec3d at = centre + rel;
                                    if (length(at - middle) >= bestDistance) continue;
                                    ++evaluated;
                                    if (!searcher.otherSide(restInside, field.value(at)) || !onPSide(pPos, at, stepsTo(pPos, at)) ||
                                        !onPSide(at, qPos, stepsTo(at, qPos)))
                                        continue;
                                    if (const std::optional<Vec3f> off = offsetInOmega(rel, frame.h)) consider(n, *off, middle, best, bestDistance);
                                }
                    }
                    if (best) proposals[fi].push_back(*best);
                };
                // Where p and q (an offset from p) lie in one part, one of `between` moves into it.
                // Joined is checked at steps finer than the thinnest part the search keeps: coarser
                // steps could step over a sheet of the other side between p and q, and a node
                // moved across that sheet would join its two sides (a thin shell's surfaces).
                // (`unlessJoined`: where the lattice does not join p and q already, along the straight
                // segment, or a bent path from the end of a thin part; `bentFromRest`: a bent path is
                // sought from p at rest too.)
                auto bridgeTo = [&](const Vec3i& q, const std::vector<Vec3i>& between, bool viaPoint = false, bool unlessJoined = false,
                                    bool bentFromRest = false) {
                    bool moved = false;
                    const Vec3d qPos = position(q.x, q.y, q.z, moved);
                    const int steps = int(std::ceil(length(qPos - pPos) / frame.h * (options.steps + 1)));
                    if (unlessJoined) {
                        if (onPSide(pPos, qPos, steps)) {
                            if (!latticeJoins(q)) bridge(between, (pPos + qPos) * 0.5, &qPos);
                        } else if (endsThinPart()) {
                            // A hole thinner than a cell through a solid pierces the face slantwise:
                            // the segment from the node in the hole, where the lattice's hole ends,
                            // to the node beyond leaves it, and the path bends (44 of 240 random
                            // boxes with a hole 0.3-1 H wide were wrong, 12 after this, 8 with every
                            // pair asked in partsJoined). Only from such an end: the outside either
                            // side of a sheet a cell thick is another pierced face, and the search
                            // spends its budget there (smoke_fog with every cell searched: 35 % more
                            // thin-search samples from every outside node, 2.6 % from these).
                            std::vector<Vec3d> path;
                            if (edgeRuns.joinedNearby(pPos, qPos, pInside, evaluated, EdgeRuns::kRimReach, &path) && !latticeJoins(q))
                                bridge(between, (pPos + qPos) * 0.5, &qPos, &path);
                        }
                        return;
                    }
                    // Or, from an inside node the search moved into a thin part, along a path that
                    // bends (a wire crossing another: the segment leaves the one before it enters
                    // the other), within a cell around both (kBentReach), where the lattice does
                    // not join them already (a bridge would close a loop around what lies between:
                    // a handle the part does not have). Not from outside nodes: the outside around
                    // a crack is mostly wide, and the search spent its whole budget there (noisy
                    // fog resampled to 2 voxels a cell: 690 searches, 5 paths). The search heads
                    // for its goal greedily, so it is made from both ends: where a rod stands on a
                    // thin plate, from the plate's node it spreads over the plate until the budget
                    // is spent; from the rod's it runs down the rod and across the plate (random
                    // rods 0.2-1 H on plates 0.2-1 H, at least 45 degrees from them: 14 of 300 came
                    // off or got a handle from one end, 8 from both; noisy fog resampled to 1 and 2
                    // voxels a cell: 7-8 % more thin-search samples).
                    // A node between whose Ω the samples miss moves onto the path found where it
                    // crosses its Ω: where a rod thinner than a cell leaves a junction along the
                    // edge where four Ω meet, the straight segment passes outside. Only across a
                    // face or a cell: to a node two steps away, the path can run round through a
                    // junction that the lattice joins further on (a bridge there made a handle).
                    std::vector<Vec3d> path;
                    auto bentJoins = [&] {
                        return edgeRuns.joinedNearby(pPos, qPos, true, evaluated, kBentReach, &path) ||
                               edgeRuns.joinedNearby(qPos, pPos, true, evaluated, kBentReach, &path);
                    };
                    if (onPSide(pPos, qPos, steps)) {
                        // Not by an outside node that alone joins outside nodes around it which
                        // the field joins, where the lattice joins p and q already: the one node in
                        // a hole about a cell wide through a plate two cells thick was so moved
                        // into the plate, to join two of its nodes across a face beside the hole,
                        // and the hole closed (2 of 60 random such plates, which marching cubes
                        // kept open). Where only the bridge joins p and q, it still may.
                        joinedAlready = pInside ? &q : nullptr;
                        bridge(between, (pPos + qPos) * 0.5, &qPos);
                        joinedAlready = nullptr;
                    } else if ((pMoved || bentFromRest) && pInside && bentJoins() && !latticeJoins(q))
                        bridge(between, (pPos + qPos) * 0.5, &qPos, std::max({std::abs(q.x), std::abs(q.y), std::abs(q.z)}) > 1 ? nullptr : &path);
                    else if (viaPoint && pInside && !latticeJoins(q))
                        bridgeViaPoint(qPos, between);
                };
                // The offset with a along `axis` and b, c along the next two axes.
                auto alongAxes = [](int axis, int a, int b, int c) {
                    Vec3i o;
                    o[std::size_t(axis)] = a;
                    o[std::size_t((axis + 1) % 3)] = b;
                    o[std::size_t((axis + 2) % 3)] = c;
                    return o;
                };
                // A node alone on its side among its six neighbours: the part it lies in is thin
                // here, and neighbours that find the part in their Ω join it (the paper's flood).
                {
                    std::vector<Vec3i> six;
                    for (int k = 0; k < 6; ++k) six.push_back(alongAxes(k / 2, k % 2 ? 1 : -1, 0, 0));
                    if (separate(six))
                        for (const Vec3i& e : six) bridge({e}, pPos, nullptr);
                }
                // Face diagonals: inside nodes only (outside ones are joined by marching cubes). A
                // bent path is sought from p at rest too, as across cell diagonals: a spike about a
                // cell thick standing out of a ball has its first node inside it at rest and the
                // ball's across a face diagonal, the segment between them leaving the inside where
                // the two meet (1 of 150 random stars lost a spike so; 1 % more thin-search samples
                // on smoke_fog at 2 voxels a cell).
                if (pInside)
                    for (int a = 0; a < 3; ++a)
                        for (int sa = -1; sa <= 1; sa += 2)
                            for (int b = a + 1; b < 3; ++b)
                                for (int sb = -1; sb <= 1; sb += 2) {
                                    Vec3i ea, eb;
                                    ea[std::size_t(a)] = sa;
                                    eb[std::size_t(b)] = sb;
                                    const Vec3i q = ea + eb;
                                    if (insideAt(q.x, q.y, q.z) && separate({ea, eb})) bridgeTo(q, {ea, eb}, true, false, true);
                                }
                // Cell diagonals, either side.
                for (int d = 0; d < 8; ++d) {
                    const Vec3i q((d & 1) ? 1 : -1, (d & 2) ? 1 : -1, (d & 4) ? 1 : -1);
                    if (insideAt(q.x, q.y, q.z) != pInside) continue;
                    std::vector<Vec3i> between;
                    for (int c = 1; c < 7; ++c) between.emplace_back((c & 1) ? q.x : 0, (c & 2) ? q.y : 0, (c & 4) ? q.z : 0);
                    // Nodes next to p first: after one moves, a face diagonal remains and is bridged next round.
                    // A bent path is sought from p at rest too: a rod about half a cell thick
                    // standing on a plate can have its first node inside it at rest and the
                    // plate's across a cell diagonal, the segment between leaving both (a rod on
                    // a plate came off so; cost: 0.5 % more thin-search samples on noisy fog).
                    if (separate(between)) bridgeTo(q, {Vec3i(q.x, 0, 0), Vec3i(0, q.y, 0), Vec3i(0, 0, q.z)}, false, false, true);
                }
                // Pierced faces, either side: p and a node q of the cell beyond a face whose
                // corners all lie on the other side (q is two steps from p along the face's axis,
                // at most one across). A part through that face alone joins two cells that
                // marching cubes keeps apart: one of the face's corners moves into it. Outside,
                // only where the lattice does not join p and q nearby already: where three rods
                // thinner than a cell cross, the outside between them reaches through a face whose
                // corners lie in the rods, the corner that moved out held a rod to the junction,
                // and the rod came off (5 of 100 random junctions 0.3-0.5 H; 14 of 500, 0.2-1 H,
                // 6 now).
                for (int axis = 0; axis < 3; ++axis)
                    for (int s = -1; s <= 1; s += 2)
                        for (int du = -1; du <= 1; ++du)
                            for (int dv = -1; dv <= 1; ++dv) {
                                const Vec3i q = alongAxes(axis, 2 * s, du, dv);
                                if (insideAt(q.x, q.y, q.z) != pInside) continue;
                                // The face's corners: one step along the axis; across it, the
                                // coordinates between p's and q's (where those agree, the faces on
                                // both sides of the line they share).
                                std::vector<Vec3i> corners;
                                for (int cu = du ? std::min(0, du) : -1; cu <= (du ? std::max(0, du) : 1); ++cu)
                                    for (int cv = dv ? std::min(0, dv) : -1; cv <= (dv ? std::max(0, dv) : 1); ++cv)
                                        corners.push_back(alongAxes(axis, s, cu, cv));
                                if (separate(corners)) bridgeTo(q, corners, false, !pInside);
                            }
            }
            bridgeSamples.local() += evaluated;
        });
        if (options.cancel) options.cancel->check();
        std::vector<Bridge> all;
        for (auto& v : proposals) all.insert(all.end(), v.begin(), v.end());
        // A node's Ω search gives one offset whoever asks; segment points depend on the asker:
        // the smallest offset wins (any order-free rule would do).
        std::sort(all.begin(), all.end(), [](const Bridge& x, const Bridge& y) {
            return std::tie(x.node, x.offset.x, x.offset.y, x.offset.z) < std::tie(y.node, y.offset.x, y.offset.y, y.offset.z);
        });
        frontier.clear();
        for (std::size_t i = 0; i < all.size(); ++i) {
            if (i > 0 && all[i].node == all[i - 1].node) continue;
            if (acc.isValueOn(all[i].node)) continue;
            if (!stillKeeps(edgeRuns, field, frame, iso, deformation, all[i].node, all[i].offset,
                            [&](const Coord& c) { return std::binary_search(frontier.begin(), frontier.end(), c); }, samplesAfter))
                continue;
            acc.setValue(all[i].node, openvdb::Vec3f(all[i].offset.x, all[i].offset.y, all[i].offset.z));
            frontier.push_back(all[i].node);
            if (movedOut) movedOut->emplace_back(all[i].node.x(), all[i].node.y(), all[i].node.z());
            ++bridged;
        }
    }

    if (samplesOut) {
        *samplesOut += samplesAfter;
        for (std::uint64_t n : bridgeSamples) *samplesOut += n;
    }
    return bridged;
}

std::vector<Vec3i> centreThinParts(const Field& field, const Lattice& lattice, const ThinSearchOptions& options,
                                   LatticeDeformation& deformation, const std::vector<Vec3i>& crowded, std::uint64_t* samplesOut) {
    const LatticeFrame& frame = lattice.frame;
    const double iso = options.iso;
    const Inside side = field.inside();
    const OmegaSearch searcher(field, lattice, iso, options.steps);
    const EdgeRuns edgeRuns(field, lattice, iso, options.steps);
    struct Centring {
        Coord node;
        bool inside = false;
        std::optional<Vec3f> offset;
    };
    std::vector<Centring> proposals(crowded.size());
    tbb::enumerable_thread_specific<std::uint64_t> evaluations(0);
    std::vector<Coord> centred; // in node order, as applied
    auto isCentred = [&](const Coord& c) { return std::binary_search(centred.begin(), centred.end(), c); };
    // Where the node at offset d from c stands now, and on which side (`around`: rest values of
    // the 3x3x3 nodes centred on c); a centred node kept its side.
    auto neighbourAt = [&](NodeStates& nodes, const Coord& c, const double* around, const Coord& d, bool& nbInside) {
        const Coord nb = c + d;
        openvdb::Vec3f off(0.0f);
        nodes.offsets.probeValue(nb, off);
        const bool restInside = isInside(around[local3(d.x(), d.y(), d.z())], iso, side);
        nbInside = isCentred(nb) ? restInside : nodes.inside(nb, restInside);
        return frame.nodeWorld(Vec3i(nb.x(), nb.y(), nb.z())) + Vec3d(off.x(), off.y(), off.z());
    };
    // Do c's six edges hide no more runs with c moved by `off` than at rest?
    auto edgesKeep = [&](NodeStates& nodes, const Coord& c, const double* around, bool inside, const Vec3f& off,
                         std::uint64_t& evaluated) {
        const Vec3d rest = frame.nodeWorld(Vec3i(c.x(), c.y(), c.z()));
        std::size_t before = 0, after = 0;
        std::uint64_t examined = 0;
        for (int k = 0; k < 6; ++k) {
            bool nbInside = false;
            const Vec3d p = neighbourAt(nodes, c, around, axisStep(k / 2, k % 2 ? 1 : -1), nbInside);
            after += edgeRuns.hiddenRuns(rest + Vec3d(off), p, inside, nbInside, examined, evaluated);
            before += edgeRuns.hiddenRuns(rest, p, inside, nbInside, examined, evaluated);
        }
        return after <= before;
    };
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, crowded.size(), 16), [&](const tbb::blocked_range<std::size_t>& r) {
        NodeStates nodes(deformation);
        double around[27];
        std::uint64_t& evaluated = evaluations.local();
        for (std::size_t i = r.begin(); i < r.end(); ++i) {
            const Coord c(crowded[i].x, crowded[i].y, crowded[i].z);
            proposals[i].node = c;
            // Nodes that moved (into thin parts, onto features) already stand where they should;
            // nodes on the lattice's outer faces keep their place, as they keep their side.
            if (nodes.offsets.isValueOn(c) || nodes.onSurface.isValueOn(c)) continue;
            bool outer = false;
            for (int k = 0; k < 6 && !outer; ++k) outer = !edgeRuns.validNode(c + axisStep(k / 2, k % 2 ? 1 : -1));
            if (outer) continue;
            field.sampleNodes(frame, Vec3i(c.x() - 1, c.y() - 1, c.z() - 1), {3, 3, 3}, nullptr, around);
            const bool inside = isInside(around[13], iso, side);
            int across = 0;
            bool nextToFeature = false;
            for (int k = 0; k < 6; ++k) {
                const Coord d = axisStep(k / 2, k % 2 ? 1 : -1);
                bool nbInside = false;
                neighbourAt(nodes, c, around, d, nbInside);
                across += nbInside != inside;
                nextToFeature = nextToFeature || nodes.onSurface.isValueOn(c + d);
            }
            // Crossings on the edges to a node on a feature sit on that node: centring would not
            // spread them.
            if (across < 4 || nextToFeature) continue;
            const std::optional<Vec3f> off = searcher.thinOwnSideCentroid(c, inside, evaluated);
            if (!off) continue;
            if (!edgesKeep(nodes, c, around, inside, *off, evaluated)) continue;
            proposals[i].inside = inside;
            proposals[i].offset = off;
        }
    });
    // Applied in node order; a node next to one centred before it is checked again with that
    // one where it now stands (the edge between them moved at both ends).
    openvdb::tree::ValueAccessor<OffsetTree> acc(*deformation.offsets);
    std::uint64_t evaluated = 0;
    for (const Centring& p : proposals) {
        if (!p.offset) continue;
        bool besideCentred = false;
        for (int k = 0; k < 6; ++k) besideCentred = besideCentred || isCentred(p.node + axisStep(k / 2, k % 2 ? 1 : -1));
        if (besideCentred) {
            NodeStates nodes(deformation);
            double around[27];
            field.sampleNodes(frame, Vec3i(p.node.x() - 1, p.node.y() - 1, p.node.z() - 1), {3, 3, 3}, nullptr, around);
            if (!edgesKeep(nodes, p.node, around, p.inside, *p.offset, evaluated)) continue;
        }
        acc.setValue(p.node, openvdb::Vec3f(p.offset->x, p.offset->y, p.offset->z));
        centred.push_back(p.node);
    }
    if (samplesOut) {
        *samplesOut += evaluated;
        for (std::uint64_t n : evaluations) *samplesOut += n;
    }
    std::vector<Vec3i> out;
    for (const Coord& c : centred) out.emplace_back(c.x(), c.y(), c.z());
    return out;
}

} // namespace vdbsurf
