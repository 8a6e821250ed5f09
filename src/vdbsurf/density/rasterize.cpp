#include "vdbsurf/density/rasterize.h"

#include "vdbsurf/core/cancel.h"
#include "vdbsurf/core/error.h"
#include "vdbsurf/density/scene_json.h"

#include <openvdb/openvdb.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>

namespace vdbsurf {

using openvdb::Coord;
using openvdb::FloatGrid;
using LeafT = FloatGrid::TreeType::LeafNodeType;

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

constexpr int kLeaf = 8, kNode = 128;

enum class Fill { Empty, Full, Exact };

struct LeafResult {
    Coord origin;
    Fill fill = Fill::Empty;
    std::unique_ptr<LeafT> leaf;
    std::uint64_t voxels = 0;
};

bool samePrimitive(const Primitive& a, const Primitive& b) {
    return a.core == b.core && a.center == b.center && a.size == b.size && a.rotationDegrees == b.rotationDegrees &&
           a.falloff == b.falloff && a.weight == b.weight && a.op == b.op;
}

} // namespace

struct DensityRaster::Impl {
    DensityScene scene;
    RasterOptions options;
    FloatGrid::Ptr grid;
    RasterStats stats;

    Impl(const DensityScene& s, const RasterOptions& o) : scene(s), options(o) {}

    double h() const { return options.voxelSize; }

    // World box of the voxel centres of the block [origin, origin + n), grown by `grow` voxels.
    Box3 blockBox(const Coord& origin, int n, int grow) const {
        return {Vec3d(origin.x() - grow, origin.y() - grow, origin.z() - grow) * h(),
                Vec3d(origin.x() + n - 1 + grow, origin.y() + n - 1 + grow, origin.z() + n - 1 + grow) * h()};
    }

    Fill decide(const Interval& b) const {
        if (options.surfaceOnly) return b.hi < 0.5 ? Fill::Empty : (b.lo > 0.5 ? Fill::Full : Fill::Exact);
        return b.hi <= 0 ? Fill::Empty : (b.lo >= 1 ? Fill::Full : Fill::Exact);
    }

    // The one rule for a leaf, whatever path asks: a full build and an edit agree on it.
    LeafResult computeLeaf(const Coord& origin) const {
        LeafResult r;
        r.origin = origin;
        std::vector<std::uint32_t> among;
        const Box3 box = blockBox(origin, kLeaf, options.surfaceOnly ? 1 : 0);
        scene.primitivesTouching(box, among);
        r.fill = among.empty() ? Fill::Empty : decide(scene.bounds(box, among));
        if (r.fill != Fill::Exact) return r;
        auto leaf = std::make_unique<LeafT>(origin, 0.0f, false);
        const bool any = options.surfaceOnly ? fillNearSurface(*leaf, among, r.voxels) : fillExact(*leaf, among, r.voxels);
        if (any) r.leaf = std::move(leaf);
        else r.fill = Fill::Empty;
        return r;
    }

    void setExact(LeafT& leaf, const Coord& ijk, const std::vector<std::uint32_t>& among, bool& any) const {
        const float v = float(clampDensity(scene.sum(Vec3d(ijk.x(), ijk.y(), ijk.z()) * h(), among)));
        if (v > 0) {
            leaf.setValueOn(ijk, v);
            any = true;
        }
    }

    bool fillExact(LeafT& leaf, const std::vector<std::uint32_t>& among, std::uint64_t& voxels) const {
        bool any = false;
        for (auto it = leaf.beginValueAll(); it; ++it) setExact(leaf, it.getCoord(), among, any);
        voxels += LeafT::SIZE;
        return any;
    }

    // Surface-only: the leaf is cut into 2³ blocks, each decided from the scene's bounds over the
    // block grown by one voxel — a ball around its centre, from one distance per primitive (the
    // distance is 1-Lipschitz). A block evaluated exactly is one that the surface may pass
    // within a voxel of; every other voxel then has all its 26 neighbours on its own side, so
    // no lattice edge that crosses 0.5 touches it and its side (1, or background) is all a
    // mesher reads. The band evaluated is a few voxels thick instead of a leaf's width.
    bool fillNearSurface(LeafT& leaf, const std::vector<std::uint32_t>& among, std::uint64_t& voxels) const {
        constexpr int kBlock = 2;
        // Block voxel centres span kBlock - 1 voxels; grown by one on each side, kBlock + 1.
        const double radius = 0.5 * std::sqrt(3.0) * (kBlock + 1) * h();
        const Coord origin = leaf.origin();
        bool any = false;
        for (int i = 0; i < kLeaf; i += kBlock)
            for (int j = 0; j < kLeaf; j += kBlock)
                for (int k = 0; k < kLeaf; k += kBlock) {
                    const Coord b = origin.offsetBy(i, j, k);
                    const Vec3d centre = (Vec3d(b.x(), b.y(), b.z()) + Vec3d(0.5, 0.5, 0.5) * (kBlock - 1)) * h();
                    const Fill f = decide(scene.boundsAround(centre, radius, among));
                    for (int a = 0; a < kBlock; ++a)
                        for (int c = 0; c < kBlock; ++c)
                            for (int d = 0; d < kBlock; ++d) {
                                const Coord ijk = b.offsetBy(a, c, d);
                                if (f == Fill::Exact) setExact(leaf, ijk, among, any);
                                else if (f == Fill::Full) {
                                    leaf.setValueOn(ijk, 1.0f);
                                    any = true;
                                }
                            }
                    if (f == Fill::Exact) voxels += kBlock * kBlock * kBlock;
                }
        return any;
    }

    void apply(LeafResult& r) {
        auto& tree = grid->tree();
        switch (r.fill) {
        case Fill::Empty:
            if (tree.probeConstLeaf(r.origin) || tree.isValueOn(r.origin) || tree.getValue(r.origin) != 0.0f)
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
        stats.voxelsEvaluated += r.voxels;
    }

    void computeLeaves(const std::vector<Coord>& origins, std::vector<LeafResult>& out) const {
        out.resize(origins.size());
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, origins.size(), 16), [&](const auto& range) {
            if (options.cancel) options.cancel->check();
            for (std::size_t i = range.begin(); i != range.end(); ++i) out[i] = computeLeaf(origins[i]);
        });
    }

    // Leaf origins whose (grown) boxes the world box reaches.
    void leavesIn(const Box3& world, int grow, std::vector<Coord>& out) const {
        auto lo = [&](double v) { return int(std::floor(v / h())) - grow; };
        auto hi = [&](double v) { return int(std::ceil(v / h())) + grow; };
        const Coord a(lo(world.min.x) & ~(kLeaf - 1), lo(world.min.y) & ~(kLeaf - 1), lo(world.min.z) & ~(kLeaf - 1));
        const Coord b(hi(world.max.x), hi(world.max.y), hi(world.max.z));
        for (int x = a.x(); x <= b.x(); x += kLeaf)
            for (int y = a.y(); y <= b.y(); y += kLeaf)
                for (int z = a.z(); z <= b.z(); z += kLeaf) out.emplace_back(x, y, z);
    }

    void build() {
        const auto t0 = Clock::now();
        stats = {};
        grid = FloatGrid::create(0.0f);
        grid->setName("density");
        grid->setGridClass(openvdb::GRID_FOG_VOLUME);
        grid->setTransform(openvdb::math::Transform::createLinearTransform(h()));

        // The 128³ nodes that added density reaches (subtraction alone makes none).
        std::vector<Coord> nodes;
        const int grow = options.surfaceOnly ? 1 : 0;
        for (const PreparedPrimitive& p : scene.prepared()) {
            if (p.primitive().op != DensityOp::Add) continue;
            std::vector<Coord> leaves;
            leavesIn(p.influenceBox(), grow, leaves);
            for (const Coord& c : leaves) nodes.emplace_back(c.x() & ~(kNode - 1), c.y() & ~(kNode - 1), c.z() & ~(kNode - 1));
        }
        std::sort(nodes.begin(), nodes.end());
        nodes.erase(std::unique(nodes.begin(), nodes.end()), nodes.end());

        // Full mode: exact values are 0 or 1 throughout a node whose bounds say so, so deciding it
        // whole gives the same voxels as deciding its leaves (what an edit does) — only faster.
        std::vector<Fill> nodeFill(nodes.size(), Fill::Exact);
        if (!options.surfaceOnly)
            tbb::parallel_for(std::size_t(0), nodes.size(), [&](std::size_t i) {
                std::vector<std::uint32_t> among;
                const Box3 box = blockBox(nodes[i], kNode, 0);
                scene.primitivesTouching(box, among);
                nodeFill[i] = among.empty() ? Fill::Empty : decide(scene.bounds(box, among));
            });
        // The leaves of every undecided node in one parallel loop: a node's 4096 leaves are
        // mostly cheap decisions, so a loop per node would leave threads idle at each node's end.
        std::vector<Coord> origins, openNodes;
        for (std::size_t i = 0; i < nodes.size(); ++i) {
            if (nodeFill[i] == Fill::Full) {
                grid->tree().addTile(2, nodes[i], 1.0f, true);
                ++stats.nodeTiles;
            }
            if (nodeFill[i] != Fill::Exact) continue;
            openNodes.push_back(nodes[i]);
            for (int x = 0; x < kNode; x += kLeaf)
                for (int y = 0; y < kNode; y += kLeaf)
                    for (int z = 0; z < kNode; z += kLeaf) origins.push_back(nodes[i].offsetBy(x, y, z));
        }
        std::vector<LeafResult> results;
        computeLeaves(origins, results);
        stats.leavesDecided = origins.size();
        constexpr std::size_t kLeavesPerNode = (kNode / kLeaf) * (kNode / kLeaf) * (kNode / kLeaf);
        for (std::size_t n = 0; n < openNodes.size(); ++n) {
            const auto first = results.begin() + std::ptrdiff_t(n * kLeavesPerNode), last = first + std::ptrdiff_t(kLeavesPerNode);
            if (std::all_of(first, last, [](const LeafResult& r) { return r.fill == Fill::Full; })) {
                grid->tree().addTile(2, openNodes[n], 1.0f, true);
                ++stats.nodeTiles;
                continue;
            }
            for (auto r = first; r != last; ++r) apply(*r);
        }
        stats.seconds = since(t0);
    }

    void edit(const DensityScene& edited) {
        const auto t0 = Clock::now();
        stats = {};
        const auto& before = scene.primitives();
        const auto& after = edited.primitives();
        // Primitives in one list and not the other; the rest must keep their order, or sums
        // would be added in another order everywhere (then everything is recomputed).
        std::vector<bool> keptBefore(before.size(), false), keptAfter(after.size(), false);
        for (std::size_t i = 0; i < before.size(); ++i)
            for (std::size_t j = 0; j < after.size(); ++j)
                if (!keptAfter[j] && samePrimitive(before[i], after[j])) {
                    keptBefore[i] = keptAfter[j] = true;
                    break;
                }
        std::vector<const Primitive*> orderBefore, orderAfter;
        for (std::size_t i = 0; i < before.size(); ++i)
            if (keptBefore[i]) orderBefore.push_back(&before[i]);
        for (std::size_t j = 0; j < after.size(); ++j)
            if (keptAfter[j]) orderAfter.push_back(&after[j]);
        bool sameOrder = orderBefore.size() == orderAfter.size();
        for (std::size_t i = 0; sameOrder && i < orderBefore.size(); ++i) sameOrder = samePrimitive(*orderBefore[i], *orderAfter[i]);
        if (!sameOrder) {
            scene = edited;
            build();
            return;
        }

        // Leaves the changed primitives reach: within their influence boxes, and where their
        // own bounds say they add something (a ball fills half its box). Elsewhere they add
        // exactly 0, so the leaf's voxels and decision are what they were.
        std::vector<Coord> origins;
        const int grow = options.surfaceOnly ? 1 : 0;
        auto reached = [&](const PreparedPrimitive& p) {
            std::vector<Coord> leaves;
            leavesIn(p.influenceBox(), grow, leaves);
            for (const Coord& c : leaves) {
                double lo, hi;
                p.densityBounds(blockBox(c, kLeaf, grow), lo, hi);
                if (hi > 0) origins.push_back(c);
            }
        };
        for (std::size_t i = 0; i < before.size(); ++i)
            if (!keptBefore[i]) reached(scene.prepared()[i]);
        for (std::size_t j = 0; j < after.size(); ++j)
            if (!keptAfter[j]) reached(edited.prepared()[j]);
        std::sort(origins.begin(), origins.end());
        origins.erase(std::unique(origins.begin(), origins.end()), origins.end());

        scene = edited;
        std::vector<LeafResult> results;
        computeLeaves(origins, results);
        for (LeafResult& r : results) apply(r);
        stats.leavesDecided = stats.leavesRecomputed = origins.size();
        stats.seconds = since(t0);
    }
};

DensityRaster::DensityRaster(const DensityScene& scene, const RasterOptions& options)
    : mImpl(std::make_unique<Impl>(scene, options)) {
    const double h = options.voxelSize;
    if (!(h > 0) || !std::isfinite(h)) throw Error("--voxel-size", "must be a positive number of world units");
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

GridBasePtr DensityRaster::grid() const { return mImpl->grid; }
const DensityScene& DensityRaster::scene() const { return mImpl->scene; }
const RasterStats& DensityRaster::stats() const { return mImpl->stats; }

const RasterStats& DensityRaster::update(const DensityScene& edited) {
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
    tbb::parallel_for(tbb::blocked_range<int>(0, dims.z), [&](const tbb::blocked_range<int>& r) {
        for (int k = r.begin(); k != r.end(); ++k)
            for (int j = 0; j < dims.y; ++j)
                for (int i = 0; i < dims.x; ++i)
                    out[(std::size_t(k) * dims.y + j) * dims.x + i] =
                        float(scene.value(Vec3d(first.x + i, first.y + j, first.z + k) * h));
    });
}

} // namespace vdbsurf
