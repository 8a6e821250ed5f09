#include "vdbsurf/density/rasterize.h"

#include "vdbsurf/core/cancel.h"
#include "vdbsurf/core/error.h"
#include "vdbsurf/core/free_memory.h"
#include "vdbsurf/core/progress.h"
#include "vdbsurf/density/scene_json.h"
#include "vdbsurf/vdb/voxel_transform.h"

#include <openvdb/openvdb.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <bitset>
#include <chrono>
#include <cmath>
#include <deque>
#include <map>
#include <sstream>
#include <stdexcept>
#include <unordered_map>

namespace vdbsurf {

using openvdb::Coord;
using openvdb::FloatGrid;
using LeafT = FloatGrid::TreeType::LeafNodeType;

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

// Blocks are decided whole before their leaves: a node, then halves of it down to 16³, so the
// leaves asked for bounds follow the surface instead of filling every node it passes through.
constexpr int kLeaf = 8, kNode = 128;
// Surface-only leaves are decided per 4³ block, then voxel by voxel in blocks the surface may
// pass within the halo of (what a voxel's value can matter to: kHalo steps).
constexpr int kBlock = DensityScene::kNearBlock, kBlocksPerLeaf = (kLeaf / kBlock) * (kLeaf / kBlock) * (kLeaf / kBlock);
constexpr int kHalo = 2;

enum class Fill { Empty, Full, Exact };

// What an edit needs to update an exact leaf without summing every primitive again: the
// fixed-point sum at each voxel that was evaluated and, in surface-only mode, each 4³ block's
// bound sums and, for the blocks those left exact, each voxel's bound sums over its
// neighbourhood (which together decide which voxels are evaluated). Those are kept only for
// exact blocks (1 KB each): with many primitives, correcting them by the changed ones is far
// cheaper than an anchor of every primitive again.
struct LeafSums {
    static constexpr int kBlockVoxels = kBlock * kBlock * kBlock;
    std::array<FixedDensity, LeafT::SIZE> voxel; // where `known` (4 KB a leaf not cleared)
    std::bitset<LeafT::SIZE> known;
    std::array<FixedInterval, kBlocksPerLeaf> blocks{};
    std::array<std::int16_t, kBlocksPerLeaf> boundsAt; // where a block's voxel bounds start in voxelBounds (-1: none)
    std::vector<FixedInterval> voxelBounds;
    LeafSums() { boundsAt.fill(-1); }
};

// The voxels of one leaf to evaluate, gathered so that their sums are computed in batches (the
// ellipsoids' roots four at a time, PreparedPrimitive::densities): those summed afresh from the
// front of the arrays, those an edit corrects from the back. One per task rather than per leaf:
// 17 KB that a leaf need not clear.
struct VoxelBatch {
    std::array<openvdb::Index, LeafT::SIZE> which;
    std::array<Vec3d, LeafT::SIZE> points;
    std::array<FixedDensity, LeafT::SIZE> sum;
};

struct LeafResult {
    Coord origin;
    Fill fill = Fill::Empty;
    std::unique_ptr<LeafT> leaf;
    std::unique_ptr<LeafSums> sums;
    std::uint64_t voxels = 0, updated = 0;
};

// The fields that make a primitive's density (not its name), ordered as doubles are: two keys
// are equivalent exactly when every field compares equal.
using PrimitiveKey = std::array<double, 13>;
PrimitiveKey keyOf(const Primitive& p) {
    return {double(p.core), double(p.op), p.center.x, p.center.y, p.center.z, p.size.x, p.size.y, p.size.z,
            p.rotationDegrees.x, p.rotationDegrees.y, p.rotationDegrees.z, p.falloff, p.weight};
}

// The primitives an edit changed: indices into the scene before (removed) and after (added).
struct Change {
    const DensityScene* before = nullptr;
    std::vector<std::uint32_t> removed, added;
};

struct CoordHash {
    std::size_t operator()(const Coord& c) const { return c.hash<20>(); }
};

// A block of n³ voxels that one decision fills whole.
struct BlockFill {
    Coord origin;
    int size = kLeaf;
    Fill fill = Fill::Empty;
};

// What the descent through one 128³ node decided: blocks filled whole, and the leaves whose
// own rule (computeLeaf) is still to run.
struct NodePlan {
    std::vector<BlockFill> fills;
    std::vector<Coord> leaves;
    std::uint64_t fullLeaves = 0, blocksDecided = 0, reachTests = 0;
};

template <typename F> void forEachChild(const Coord& origin, int n, F&& f) {
    const int m = n / 2;
    for (int i = 0; i < n; i += m)
        for (int j = 0; j < n; j += m)
            for (int k = 0; k < n; k += m) f(origin.offsetBy(i, j, k));
}

} // namespace

struct DensityRaster::Impl {
    DensityScene scene;
    RasterOptions options;
    FloatGrid::Ptr grid;
    RasterStats stats;
    std::unordered_map<Coord, std::unique_ptr<LeafSums>, CoordHash> sums; // options.keepSums
    double memoryBudget = 0; // bytes of leaf values a build or edit may add (0: no limit known)
    bool broken = false;     // an edit stopped half way: the grid is neither scene's
    // Nodes planned and applied at a time (see build).
    static constexpr std::size_t kNodesPerBatch = 64;

    Impl(const DensityScene& s, const RasterOptions& o) : scene(s), options(o) {}

    // A build past the memory the machine had free would be killed by the kernel, without a
    // message and after minutes; stop while an error can still be reported. Leaf values are
    // nearly all of a build's memory (tiles are values in their parents' tables).
    // `pending`: leaves computed and not yet in the tree.
    void checkMemory(std::uint64_t pending = 0, bool editing = false) const {
        if (memoryBudget <= 0) return;
        // A leaf node holds its values on the heap, apart from the node itself.
        // Kept sums: surface-only voxel bounds counted as if every block of the leaf were exact.
        const double keptBounds = options.surfaceOnly ? double(LeafT::SIZE * sizeof(FixedInterval)) : 0.0;
        const double perLeaf = double(sizeof(LeafT) + LeafT::SIZE * sizeof(float)) +
                               (options.keepSums ? double(sizeof(LeafSums)) + keptBounds : 0.0);
        const std::uint64_t leaves = stats.leavesEvaluated + pending;
        const double used = double(leaves) * perLeaf;
        if (used <= memoryBudget) return;
        const double gib = double(1 << 30);
        // What was asked and what may be used, the same for a build and an edit.
        std::ostringstream usage;
        usage.precision(3);
        usage << "(" << leaves << " leaves of values so far, " << used / gib << " GiB; limit " << memoryBudget / gib << " GiB"
              << (options.memoryLimit > 0 ? "" : ", 80 % of the memory free when it started") << ")";
        if (editing)
            throw Error(scene.describe(), "the edit makes the density grid larger than the memory it may use at voxel size " +
                                              messageNumber(h()) + " " + usage.str() +
                                              "; make the change smaller or rasterize the scene at a larger voxel size");
        std::ostringstream s;
        s << messageNumber(h()) << " makes the density grid of " << scene.describe() << " larger than the memory it may use "
          << usage.str() << "; use a larger voxel size" << (options.surfaceOnly ? "" : " or --surface-only");
        throw Error("--voxel-size", s.str());
    }

    void checkUsable() const {
        if (broken) throw std::logic_error("DensityRaster: used after an edit stopped half way (rebuild it)");
    }

    double h() const { return options.voxelSize; }

    // World box of the voxel centres of the block [origin, origin + n), grown by `grow` voxels.
    Box3 blockBox(const Coord& origin, int n, int grow) const {
        return {Vec3d(origin.x() - grow, origin.y() - grow, origin.z() - grow) * h(),
                Vec3d(origin.x() + n - 1 + grow, origin.y() + n - 1 + grow, origin.z() + n - 1 + grow) * h()};
    }

    // Everything a leaf's values depend on lies in its reach: the leaf itself in full mode; in
    // surface-only mode the leaf grown by the halo. Only primitives that reach it take part in the
    // leaf's rule (among, below); their bounds over the balls around its blocks, which reach past
    // it, are looser than over the reach but as valid, and a function of those primitives alone,
    // so an edit and a rebuild still agree on every leaf.
    int reachGrow() const { return options.surfaceOnly ? kHalo : 0; }
    Box3 reachBox(const Coord& origin) const { return blockBox(origin, kLeaf, reachGrow()); }

    Fill decide(const Interval& b) const {
        if (options.surfaceOnly) return b.hi < 0.5 ? Fill::Empty : (b.lo > 0.5 ? Fill::Full : Fill::Exact);
        return b.hi <= 0 ? Fill::Empty : (b.lo >= 1 ? Fill::Full : Fill::Exact);
    }
    Fill decide(const FixedInterval& b) const { // surface-only blocks; exact comparisons with 0.5
        return b.hi < kFixedHalf ? Fill::Empty : (b.lo > kFixedHalf ? Fill::Full : Fill::Exact);
    }

    // The one rule for a leaf, whatever path asks: a full build and an edit agree on it. In an
    // edit, with `prev` (the leaf's sums before it), voxels and blocks that were summed are
    // corrected by the changed primitives alone; the result is the same bit for bit.
    // `reuse`: where an edit keeps the leaf's sums, which the new ones then overwrite in place.
    LeafResult computeLeaf(const Coord& origin, const LeafSums* prev, std::unique_ptr<LeafSums>* reuse, const Change* change,
                           VoxelBatch& batch) const {
        LeafResult r;
        r.origin = origin;
        const Box3 reach = reachBox(origin);
        // The primitives that reach the leaf: one test (PreparedPrimitive::reaches) for a build, an
        // edit's dirty set and the sums an edit corrects, so all three agree on every leaf.
        std::vector<std::uint32_t> among;
        const Interval bounds = scene.boundsReaching(reach, among);
        r.fill = among.empty() ? Fill::Empty : decide(bounds);
        if (r.fill != Fill::Exact) return r;

        // The changed primitives that take part here, before and after.
        std::vector<std::uint32_t> removed, added;
        if (change) {
            for (std::uint32_t j : change->added)
                if (std::binary_search(among.begin(), among.end(), j)) added.push_back(j);
            if (added.size() == among.size()) {
                // No unchanged primitive reaches the leaf, so what it adds is exactly 0 at every
                // voxel and block: start from zero sums (typically where a moved primitive arrives).
                static const LeafSums zero = [] {
                    LeafSums z;
                    z.voxel.fill(0);
                    z.known.set();
                    return z;
                }();
                prev = &zero;
            } else if (prev) {
                for (std::uint32_t i : change->removed)
                    if (change->before->prepared()[i].reaches(reach)) removed.push_back(i);
            }
        }
        auto leaf = std::make_unique<LeafT>(origin, 0.0f, false);
        // Voxels go straight into the leaf's buffer and mask (setValueOn asks the buffer to load
        // itself at every voxel, and the voxels here are many).
        float* const leafValues = leaf->buffer().data();
        auto& leafActive = leaf->getValueMask();
        auto setVoxel = [&](openvdb::Index n, float v) {
            leafValues[n] = v;
            leafActive.setOn(n);
        };
        // The sums an edit would need, only when they are kept (5 KB a leaf otherwise wasted). An
        // edit writes them over the leaf's old ones (which are prev, unless prev is the zero sums):
        // every old value is read before the new one goes in its place, and the parts whose layout
        // changes (which voxels and blocks hold sums) are built aside and moved in at the end. New
        // ones would be fresh memory while the old are still held, which on this VM costs about
        // 2 µs a page: a fifth of a first edit.
        std::unique_ptr<LeafSums> out;
        if (options.keepSums) out = reuse && *reuse ? std::move(*reuse) : std::make_unique<LeafSums>();
        std::bitset<LeafT::SIZE> known;
        std::array<std::int16_t, kBlocksPerLeaf> boundsAt;
        boundsAt.fill(-1);
        std::vector<FixedInterval> voxelBounds;
        bool any = false;
        auto& which = batch.which;
        auto& points = batch.points;
        auto& sum = batch.sum;
        std::size_t fresh = 0, corrected = LeafT::SIZE;
        auto setExact = [&](openvdb::Index n, const Coord& ijk) {
            const std::size_t slot = prev && prev->known[n] ? --corrected : fresh++;
            which[slot] = n;
            points[slot] = Vec3d(ijk.x(), ijk.y(), ijk.z()) * h();
        };
        auto evaluate = [&] {
            scene.fixedSums(points.data(), fresh, among, sum.data());
            const std::size_t correctedCount = LeafT::SIZE - corrected;
            for (std::size_t k = corrected; k < LeafT::SIZE; ++k) sum[k] = prev->voxel[which[k]];
            for (std::uint32_t i : removed) change->before->addContributions(i, points.data() + corrected, correctedCount, true, sum.data() + corrected);
            for (std::uint32_t j : added) scene.addContributions(j, points.data() + corrected, correctedCount, false, sum.data() + corrected);
            r.voxels += fresh;
            r.updated += correctedCount;
            auto store = [&](std::size_t k) {
                const openvdb::Index n = which[k];
                if (out) {
                    out->voxel[n] = sum[k];
                    known.set(n);
                }
                const float v = float(clampDensity(fromFixed(sum[k])));
                if (v > 0) {
                    setVoxel(n, v);
                    any = true;
                }
            };
            for (std::size_t k = 0; k < fresh; ++k) store(k);
            for (std::size_t k = corrected; k < LeafT::SIZE; ++k) store(k);
        };
        if (!options.surfaceOnly) {
            for (openvdb::Index n = 0; n < LeafT::SIZE; ++n) setExact(n, leaf->offsetToGlobalCoord(n));
        } else {
            // The leaf is cut into 4³ blocks, each decided from the scene's bounds over the block
            // grown by the halo, from one distance per primitive at its centre (over the ball
            // around that cube — the distance is 1-Lipschitz — tightened to the cube by the
            // anchor's half-space). In a block the surface may pass within the halo of, each voxel
            // is decided again from the bounds over the points a mesher may read it for — its own
            // 3³ block (is it a corner of a lattice cell the surface crosses: marching cubes, DMC's
            // thin search) and its axis neighbours' (is it in the central difference at such a
            // corner: DMC's crossing normals and sharp-feature tests) — which the anchors give
            // without a root (densityBoundsNear). Only voxels whose neighbourhood may straddle 0.5
            // are evaluated; every other one is read for its side alone, 1 or background. The band
            // evaluated is a few voxels thick.
            const Neighbourhood meshReads{h(), h()}; // the voxel's 3³ block and its axis neighbours'
            const double halo = (0.5 * (kBlock - 1) + kHalo) * h(); // the block's voxels ± kHalo: a cube around its centre
            const double radius = std::sqrt(3.0) * halo;             // and the ball around that cube
            std::vector<DensityAnchor> anchors(among.size()), removedAnchors(removed.size()), addedAnchors(added.size());
            auto anchorAll = [&](const Vec3d& centre) {
                for (std::size_t q = 0; q < among.size(); ++q) anchors[q] = scene.anchorAround(among[q], centre, radius);
            };
            int index = 0;
            for (int i = 0; i < kLeaf; i += kBlock)
                for (int j = 0; j < kLeaf; j += kBlock)
                    for (int k = 0; k < kLeaf; k += kBlock, ++index) {
                        const Coord b = origin.offsetBy(i, j, k);
                        const Vec3d centre = (Vec3d(b.x(), b.y(), b.z()) + Vec3d(0.5, 0.5, 0.5) * (kBlock - 1)) * h();
                        // Summed afresh, every primitive here needs its anchor; corrected, only the changed ones.
                        FixedInterval bounds;
                        if (prev) {
                            bounds = prev->blocks[index];
                            for (std::size_t q = 0; q < removed.size(); ++q) {
                                removedAnchors[q] = change->before->anchorAround(removed[q], centre, radius);
                                bounds -= change->before->contributionBounds(removed[q], removedAnchors[q], centre, halo);
                            }
                            for (std::size_t q = 0; q < added.size(); ++q) {
                                addedAnchors[q] = scene.anchorAround(added[q], centre, radius);
                                bounds += scene.contributionBounds(added[q], addedAnchors[q], centre, halo);
                            }
                        } else {
                            anchorAll(centre);
                            for (std::size_t q = 0; q < among.size(); ++q) bounds += scene.contributionBounds(among[q], anchors[q], centre, halo);
                        }
                        if (out) out->blocks[index] = bounds;
                        const Fill f = decide(bounds);
                        if (f == Fill::Empty) continue;
                        if (f == Fill::Full) {
                            for (int a = 0; a < kBlock; ++a)
                                for (int c = 0; c < kBlock; ++c)
                                    for (int d = 0; d < kBlock; ++d) setVoxel(LeafT::coordToOffset(b.offsetBy(a, c, d)), 1.0f);
                            any = true;
                            continue;
                        }
                        // Each voxel's bounds over its neighbourhood: corrected where they were kept.
                        std::array<FixedInterval, LeafSums::kBlockVoxels> near{};
                        const Vec3d first = Vec3d(b.x(), b.y(), b.z()) * h();
                        if (prev && prev->boundsAt[index] >= 0) {
                            std::copy_n(prev->voxelBounds.begin() + prev->boundsAt[index] * LeafSums::kBlockVoxels, near.size(), near.begin());
                            for (std::size_t q = 0; q < removed.size(); ++q)
                                change->before->accumulateBoundsNear(removed[q], removedAnchors[q], first, h(), meshReads, true, near.data());
                            for (std::size_t q = 0; q < added.size(); ++q)
                                scene.accumulateBoundsNear(added[q], addedAnchors[q], first, h(), meshReads, false, near.data());
                        } else {
                            if (prev) anchorAll(centre);
                            for (std::size_t q = 0; q < among.size(); ++q)
                                scene.accumulateBoundsNear(among[q], anchors[q], first, h(), meshReads, false, near.data());
                        }
                        if (out) {
                            boundsAt[index] = std::int16_t(voxelBounds.size() / LeafSums::kBlockVoxels);
                            voxelBounds.insert(voxelBounds.end(), near.begin(), near.end());
                        }
                        int v = 0;
                        for (int a = 0; a < kBlock; ++a)
                            for (int c = 0; c < kBlock; ++c)
                                for (int d = 0; d < kBlock; ++d, ++v) {
                                    const Coord ijk = b.offsetBy(a, c, d);
                                    const Fill g = decide(near[v]);
                                    if (g == Fill::Exact) setExact(LeafT::coordToOffset(ijk), ijk);
                                    else if (g == Fill::Full) {
                                        setVoxel(LeafT::coordToOffset(ijk), 1.0f);
                                        any = true;
                                    }
                                }
                    }
        }
        evaluate();
        if (out) {
            out->known = known;
            out->boundsAt = boundsAt;
            out->voxelBounds = std::move(voxelBounds);
        }
        r.sums = std::move(out);
        if (any) r.leaf = std::move(leaf);
        else r.fill = Fill::Empty;
        return r;
    }

    // Puts a leaf's result in the tree; `replacing` when the tree may hold something there.
    void apply(LeafResult& r, bool replacing) {
        auto& tree = grid->tree();
        switch (r.fill) {
        case Fill::Empty:
            if (replacing && (tree.probeConstLeaf(r.origin) || tree.isValueOn(r.origin) || tree.getValue(r.origin) != 0.0f))
                tree.addTile(1, r.origin, 0.0f, false);
            break;
        case Fill::Full:
            tree.addTile(1, r.origin, 1.0f, true);
            ++stats.leafTiles;
            break;
        case Fill::Exact:
            tree.addLeaf(r.leaf.release());
            ++stats.leavesEvaluated;
            break;
        }
        if (r.sums) sums[r.origin] = std::move(r.sums);
        else if (replacing) sums.erase(r.origin);
        stats.voxelsEvaluated += r.voxels;
        stats.voxelsUpdated += r.updated;
    }

    void computeLeaves(const std::vector<Coord>& origins, std::vector<LeafResult>& out, const Change* change) {
        out.resize(origins.size());
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, origins.size(), 16), [&](const auto& range) {
            if (options.cancel) options.cancel->check();
            VoxelBatch batch;
            for (std::size_t i = range.begin(); i != range.end(); ++i) {
                // Each leaf's entry of `sums` is its own task's alone (apply() changes the map after).
                const LeafSums* prev = nullptr;
                std::unique_ptr<LeafSums>* reuse = nullptr;
                if (change) {
                    const auto it = sums.find(origins[i]);
                    if (it != sums.end()) {
                        prev = it->second.get();
                        reuse = &it->second;
                    }
                }
                out[i] = computeLeaf(origins[i], prev, reuse, change, batch);
            }
        });
    }

    // Origins of the n³ blocks (leaves, nodes) holding a leaf whose reach the world box touches.
    void blocksIn(const Box3& world, int n, std::vector<Coord>& out) const {
        const int grow = reachGrow();
        auto lo = [&](double v) { return (int(std::floor(v / h())) - grow) & ~(n - 1); };
        auto hi = [&](double v) { return int(std::ceil(v / h())) + grow; };
        const Coord a(lo(world.min.x), lo(world.min.y), lo(world.min.z));
        const Coord b(hi(world.max.x), hi(world.max.y), hi(world.max.z));
        for (int x = a.x(); x <= b.x(); x += n)
            for (int y = a.y(); y <= b.y(); y += n)
                for (int z = a.z(); z <= b.z(); z += n) out.emplace_back(x, y, z);
    }

    // One decision for a whole block of n³ voxels from the scene's bounds over its reach, by the
    // rule a leaf applies to itself: Empty or Full means every voxel within the reach is on one
    // side (exactly 0 or 1 in full mode), which is all either mode promises away from exact values.
    Fill decideBlock(const DensityScene& s, const Coord& origin, int n) const {
        std::vector<std::uint32_t> among;
        const Interval b = s.boundsReaching(blockBox(origin, n, reachGrow()), among);
        return among.empty() ? Fill::Empty : decide(b);
    }

    // A leaf's value is the fill of the first block above it (128³ down to 16³) decided Empty or
    // Full, else its own rule. The descent asks each block once and goes on only into undecided
    // ones, so the leaves asked follow the surface (and, in full mode, the falloff shell).
    void planBuild(const Coord& origin, int n, NodePlan& plan) const {
        ++plan.blocksDecided;
        const Fill f = decideBlock(scene, origin, n);
        if (f == Fill::Full) {
            plan.fills.push_back({origin, n, f});
            plan.fullLeaves += std::uint64_t(n / kLeaf) * (n / kLeaf) * (n / kLeaf);
        }
        if (f != Fill::Exact) return;
        forEachChild(origin, n, [&](const Coord& c) {
            if (n / 2 == kLeaf) plan.leaves.push_back(c);
            else planBuild(c, n / 2, plan);
        });
    }

    // Whether a primitive the edit changed takes part in a box, before (removed) or after (added):
    // the test a leaf's rule applies to its reach (PreparedPrimitive::reaches), so it agrees
    // with the leaves on where a changed primitive adds something.
    bool changeReaches(const Change& change, const Box3& box) const {
        for (std::uint32_t i : change.removed)
            if (change.before->prepared()[i].reaches(box)) return true;
        for (std::uint32_t j : change.added)
            if (scene.prepared()[j].reaches(box)) return true;
        return false;
    }
    // Whether a block may hold a block, at any level below it, that a changed primitive reaches:
    // its reach grown by a voxel holds every descendant's reach, and a voxel's margin is far
    // beyond the rounding of the distances the test compares.
    bool changeMayReachInside(const Change& change, const Coord& origin, int n) const {
        return changeReaches(change, blockBox(origin, n, reachGrow() + 1));
    }

    // An edit's descent, under a block whose voxels the edit left decided by `oldChain` (Exact:
    // by the blocks and leaves below). A block's decision depends only on the primitives reaching
    // it, so it can differ only where a changed primitive reaches; the walk goes where such a
    // block may lie below or the old fill must give way, and compares old and new fills. The
    // tests run here, per block visited and in parallel, rather than over every block of the
    // changed primitives' influence boxes: those hold volume, and the blocks visited follow the
    // surface.
    void planEdit(const Coord& origin, int n, Fill oldChain, const Change& change, NodePlan& plan) const {
        if (n == kLeaf) {
            // Filled from above, or a changed primitive takes part in the leaf's rule.
            if (oldChain == Fill::Exact) {
                ++plan.reachTests;
                if (!changeReaches(change, reachBox(origin))) return;
            }
            plan.leaves.push_back(origin);
            return;
        }
        if (oldChain == Fill::Exact) {
            ++plan.reachTests;
            if (!changeMayReachInside(change, origin, n)) return; // nothing below it can change
        }
        ++plan.blocksDecided;
        const Fill newFill = decideBlock(scene, origin, n);
        Fill oldFill = oldChain;
        if (oldChain == Fill::Exact) {
            oldFill = newFill;
            ++plan.reachTests;
            if (changeReaches(change, blockBox(origin, n, reachGrow()))) {
                ++plan.blocksDecided;
                oldFill = decideBlock(*change.before, origin, n);
            }
        }
        if (newFill != Fill::Exact) {
            if (oldFill != newFill) plan.fills.push_back({origin, n, newFill});
            return;
        }
        forEachChild(origin, n, [&](const Coord& c) { planEdit(c, n / 2, oldFill, change, plan); });
    }

    // Writes a block's fill; `replacing` when the tree may hold something there.
    void applyFill(const BlockFill& f, bool replacing) {
        auto& tree = grid->tree();
        if (f.size == kNode) {
            if (f.fill == Fill::Full) {
                tree.addTile(2, f.origin, 1.0f, true);
                ++stats.nodeTiles;
            } else if (replacing && (tree.getValueDepth(f.origin) > 0 || tree.isValueOn(f.origin) || tree.getValue(f.origin) != 0.0f)) {
                tree.addTile(2, f.origin, 0.0f, false);
            }
            if (replacing && !sums.empty())
                for (int x = 0; x < kNode; x += kLeaf)
                    for (int y = 0; y < kNode; y += kLeaf)
                        for (int z = 0; z < kNode; z += kLeaf) sums.erase(f.origin.offsetBy(x, y, z));
            return;
        }
        for (int x = 0; x < f.size; x += kLeaf)
            for (int y = 0; y < f.size; y += kLeaf)
                for (int z = 0; z < f.size; z += kLeaf) {
                    LeafResult r;
                    r.origin = f.origin.offsetBy(x, y, z);
                    r.fill = f.fill;
                    apply(r, replacing);
                }
    }

    // Descends every node in parallel, computes the leaves the descents leave open in one
    // parallel loop, and returns each node's plan with its leaves' results (in plan order).
    void runPlans(const std::vector<Coord>& nodes, std::vector<NodePlan>& plans, std::vector<LeafResult>& results,
                  const Change* change) {
        plans.assign(nodes.size(), NodePlan());
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nodes.size(), 1), [&](const auto& range) {
            if (options.cancel) options.cancel->check();
            for (std::size_t i = range.begin(); i != range.end(); ++i) {
                if (change) planEdit(nodes[i], kNode, Fill::Exact, *change, plans[i]);
                else planBuild(nodes[i], kNode, plans[i]);
            }
        });
        std::vector<Coord> origins;
        for (const NodePlan& p : plans) {
            origins.insert(origins.end(), p.leaves.begin(), p.leaves.end());
            stats.blocksDecided += p.blocksDecided;
            stats.reachTests += p.reachTests;
        }
        computeLeaves(origins, results, change);
        stats.leavesDecided += origins.size();
    }

    void build() {
        const auto t0 = Clock::now();
        stats = {};
        sums.clear();
        grid = FloatGrid::create(0.0f);
        grid->setName("density");
        grid->setGridClass(openvdb::GRID_FOG_VOLUME);
        grid->setTransform(voxelTransform(h(), "--voxel-size"));
        memoryBudget = memoryBudgetBytes(options.memoryLimit);

        // The 128³ nodes that added density reaches (subtraction alone makes none).
        std::vector<Coord> nodes;
        for (const PreparedPrimitive& p : scene.prepared())
            if (p.primitive().op == DensityOp::Add) blocksIn(p.influenceBox(), kNode, nodes);
        std::sort(nodes.begin(), nodes.end());
        nodes.erase(std::unique(nodes.begin(), nodes.end()), nodes.end());

        // Batches of nodes: a node's work varies from one decision to thousands of leaves, so a
        // loop per node would leave threads idle at each node's end; one loop over all of them
        // would hold a result for every exact leaf at once (12 GB at 3,000 voxels across) before
        // placing any.
        constexpr std::size_t kLeavesPerNode = (kNode / kLeaf) * (kNode / kLeaf) * (kNode / kLeaf);
        std::vector<Coord> batchNodes;
        std::vector<NodePlan> plans;
        std::vector<LeafResult> results;
        Progress progress("rasterize", nodes.size(), options.cancel);
        for (std::size_t batch = 0; batch < nodes.size(); batch += kNodesPerBatch) {
            batchNodes.assign(nodes.begin() + std::ptrdiff_t(batch), nodes.begin() + std::ptrdiff_t(std::min(nodes.size(), batch + kNodesPerBatch)));
            runPlans(batchNodes, plans, results, nullptr);
            auto next = results.begin();
            for (std::size_t n = 0; n < plans.size(); ++n) {
                const auto first = next;
                next += std::ptrdiff_t(plans[n].leaves.size());
                const auto computedFull = std::count_if(first, next, [](const LeafResult& r) { return r.fill == Fill::Full; });
                if (plans[n].fullLeaves + std::uint64_t(computedFull) == kLeavesPerNode) {
                    applyFill({batchNodes[n], kNode, Fill::Full}, false);
                    continue;
                }
                for (const BlockFill& f : plans[n].fills) applyFill(f, false);
                for (auto r = first; r != next; ++r) apply(*r, false);
            }
            checkMemory();
            progress.advance(batchNodes.size());
        }
        stats.seconds = since(t0);
    }

    void edit(const DensityScene& edited) {
        const auto t0 = Clock::now();
        stats = {};
        // Primitives in one list and not the other. Sums are order-free (fixed point), so the
        // rest may be reordered or renamed freely: they change nothing.
        const auto& before = scene.primitives();
        const auto& after = edited.primitives();
        // Each primitive before is matched to the first unmatched equal one after (a map from the
        // fields to the positions holding them: scenes of 10^5 blobs are matched in O(n log n)).
        std::vector<bool> keptBefore(before.size(), false), keptAfter(after.size(), false);
        std::map<PrimitiveKey, std::deque<std::size_t>> positions;
        for (std::size_t j = 0; j < after.size(); ++j) positions[keyOf(after[j])].push_back(j);
        for (std::size_t i = 0; i < before.size(); ++i) {
            const auto it = positions.find(keyOf(before[i]));
            if (it == positions.end() || it->second.empty()) continue;
            keptBefore[i] = keptAfter[it->second.front()] = true;
            it->second.pop_front();
        }
        Change change;
        for (std::uint32_t i = 0; i < before.size(); ++i)
            if (!keptBefore[i]) change.removed.push_back(i);
        for (std::uint32_t j = 0; j < after.size(); ++j)
            if (!keptAfter[j]) change.added.push_back(j);

        const DensityScene old = std::move(scene);
        scene = edited;
        change.before = &old;
        // The 128³ nodes a changed primitive's influence box meets, before or after (the descent
        // asks each whether the primitive reaches it). Elsewhere it adds exactly 0, so their
        // decisions and voxels are what they were.
        std::vector<Coord> nodes;
        auto nodesOf = [&](const PreparedPrimitive& p) { blocksIn(p.influenceBox(), kNode, nodes); };
        for (std::uint32_t i : change.removed) nodesOf(old.prepared()[i]);
        for (std::uint32_t j : change.added) nodesOf(scene.prepared()[j]);
        std::sort(nodes.begin(), nodes.end());
        nodes.erase(std::unique(nodes.begin(), nodes.end()), nodes.end());
        // In batches of nodes, as a build (a node's plan reads and writes that node alone), so that
        // an edit that grows a primitive far stops with an error instead of holding every new
        // leaf at once.
        memoryBudget = memoryBudgetBytes(options.memoryLimit);
        broken = true; // until the last batch is in: an error leaves the grid between two scenes
        std::vector<Coord> batchNodes;
        std::vector<NodePlan> plans;
        std::vector<LeafResult> results;
        std::uint64_t refilled = 0;
        Progress progress("edit", nodes.size(), options.cancel);
        for (std::size_t batch = 0; batch < nodes.size(); batch += kNodesPerBatch) {
            batchNodes.assign(nodes.begin() + std::ptrdiff_t(batch), nodes.begin() + std::ptrdiff_t(std::min(nodes.size(), batch + kNodesPerBatch)));
            runPlans(batchNodes, plans, results, &change);
            checkMemory(std::uint64_t(std::count_if(results.begin(), results.end(), [](const LeafResult& r) { return r.fill == Fill::Exact; })),
                        true);
            for (const NodePlan& p : plans)
                for (const BlockFill& f : p.fills) {
                    applyFill(f, true);
                    refilled += std::uint64_t(f.size / kLeaf) * (f.size / kLeaf) * (f.size / kLeaf);
                }
            for (LeafResult& r : results) apply(r, true);
            progress.advance(batchNodes.size());
        }
        broken = false;
        stats.leavesRecomputed = stats.leavesDecided + refilled;
        stats.seconds = since(t0);
    }
};

DensityRaster::DensityRaster(const DensityScene& scene, const RasterOptions& options)
    : mImpl(std::make_unique<Impl>(scene, options)) {
    const double h = options.voxelSize;
    if (!(h > 0) || !std::isfinite(h)) throw Error("--voxel-size", "must be a positive number of world units");
    // As the mesher's lattice: a voxel wider than the whole scene holds nothing of its shape.
    const Box3 d = scene.domain();
    const double extent = d.longestSide();
    if (h > extent)
        throw Error("--voxel-size", messageNumber(h) + " is wider than all of " + scene.describe() + " (" + messageNumber(extent) +
                                        " along its longest side); choose a voxel size that puts voxels across it");
    Vec3i first, last;
    sceneVoxelRange(scene, h, first, last);
    for (int a = 0; a < 3; ++a)
        if (double(last[a]) - double(first[a]) > 1 << 20)
            throw Error("--voxel-size", "is too fine for " + scene.describe() + ": over a million voxels across");
    mImpl->build();
}

DensityRaster::DensityRaster(const DensityScene& scene, const RasterOptions& options, GridBasePtr adopted)
    : mImpl(std::make_unique<Impl>(scene, options)) {
    auto grid = openvdb::GridBase::grid<FloatGrid>(adopted);
    if (!grid) throw Error(adopted ? adopted->getName() : "grid", "is not a float grid");
    mImpl->grid = grid;
}

DensityRaster::~DensityRaster() = default;

GridBasePtr DensityRaster::grid() const {
    mImpl->checkUsable();
    return mImpl->grid;
}
bool DensityRaster::empty() const {
    mImpl->checkUsable();
    return mImpl->grid->activeVoxelCount() == 0; // (an edit may leave leaves whose voxels are all off)
}
const DensityScene& DensityRaster::scene() const { return mImpl->scene; }
const RasterStats& DensityRaster::stats() const { return mImpl->stats; }

const RasterStats& DensityRaster::update(const DensityScene& edited) {
    mImpl->checkUsable();
    Vec3i first, last;
    sceneVoxelRange(edited, mImpl->h(), first, last);
    for (int a = 0; a < 3; ++a)
        if (double(last[a]) - double(first[a]) > 1 << 20)
            throw Error(edited.describe(), "reaches over a million voxels across at this voxel size");
    mImpl->edit(edited);
    return mImpl->stats;
}

void sceneVoxelRange(const DensityScene& scene, double h, Vec3i& first, Vec3i& last) {
    const Box3 d = scene.domain();
    auto clampIndex = [](double v) { return int(std::max(-2e9, std::min(2e9, v))); };
    first = {clampIndex(std::floor(d.min.x / h)), clampIndex(std::floor(d.min.y / h)), clampIndex(std::floor(d.min.z / h))};
    last = {clampIndex(std::ceil(d.max.x / h)), clampIndex(std::ceil(d.max.y / h)), clampIndex(std::ceil(d.max.z / h))};
}

void evaluateDense(const DensityScene& scene, double h, const Vec3i& first, const Vec3i& dims, float* out) {
    // Row by row, with the kernel the rasterizer uses (PreparedPrimitive::densities): the
    // primitives whose influence box meets the row, each at every voxel of it (0 where it does not
    // reach: the same sums as value() point by point, which asks the index at each).
    tbb::parallel_for(tbb::blocked_range<int>(0, dims.z), [&](const tbb::blocked_range<int>& r) {
        std::vector<Vec3d> points(std::size_t(dims.x));
        std::vector<FixedDensity> sums(std::size_t(dims.x));
        std::vector<std::uint32_t> among;
        for (int k = r.begin(); k != r.end(); ++k)
            for (int j = 0; j < dims.y; ++j) {
                for (int i = 0; i < dims.x; ++i) points[std::size_t(i)] = Vec3d(first.x + i, first.y + j, first.z + k) * h;
                scene.primitivesTouching({points.front(), points.back()}, among);
                scene.fixedSums(points.data(), points.size(), among, sums.data());
                float* row = out + (std::size_t(k) * dims.y + j) * dims.x;
                for (int i = 0; i < dims.x; ++i) row[i] = float(clampDensity(fromFixed(sums[std::size_t(i)])));
            }
    });
}

} // namespace vdbsurf
