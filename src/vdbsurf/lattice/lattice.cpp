#include "vdbsurf/lattice/lattice.h"

#include "vdbsurf/core/cancel.h"
#include "vdbsurf/core/error.h"
#include "vdbsurf/core/free_memory.h"
#include "vdbsurf/core/progress.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <sstream>

namespace vdbsurf {

using openvdb::Coord;
using openvdb::CoordBBox;

namespace {

using MaskLeaf = CellTree::LeafNodeType;

constexpr int kLeafDim = 8;
constexpr int kBlockNodes = kLeafDim + 1;
constexpr int kBlockNodeCount = kBlockNodes * kBlockNodes * kBlockNodes;
// Largest lattice extent along one axis: beyond this a user has almost surely mistyped the
// voxel size (a million cells along an axis is ~10^12 cells in the bounding box).
constexpr double kMaxCellsPerAxis = double(1 << 20);

// Guard against lattices that cannot fit in memory (each 8^3 block costs ~1 KiB when meshed).
constexpr std::size_t kMaxLeafBlocks = std::size_t(1) << 24;

Vec3i toVec(const Coord& c) { return {c.x(), c.y(), c.z()}; }

Box3 cellsBox(const LatticeFrame& frame, const CoordBBox& cells) {
    return frame.nodeBox(toVec(cells.min()), toVec(cells.max()) + Vec3i(1, 1, 1));
}

std::string pointText(const Vec3d& p) {
    std::ostringstream s;
    s.precision(9);
    s << "(" << p.x << ", " << p.y << ", " << p.z << ")";
    return s.str();
}

[[noreturn]] void tooFine(const Field& field, const LatticeFrame& frame, std::size_t blocks, int size) {
    std::ostringstream s;
    s << frame.h << " would make the lattice around " << field.describe() << " too fine (more than " << blocks
      << " blocks of " << size << "^3 cells may hold surface, at most " << kMaxLeafBlocks << "); use a larger voxel size";
    throw Error("--voxel-size", s.str());
}

// The children of size `child` of each block of size `size` (clipped to the range) whose
// bounds straddle iso; parents are processed in parallel, children stay in parent order.
std::vector<Coord> straddlingChildren(const Field& field, const LatticeFrame& frame, const std::vector<Coord>& parents,
                                      int size, int child, const CoordBBox& range, double iso, const CancelToken* cancel,
                                      std::uint64_t& tested) {
    std::vector<std::vector<Coord>> kept(parents.size());
    std::atomic<std::uint64_t> count{0}, survivors{0};
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, parents.size()), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i < r.end(); ++i) {
            if (cancel && cancel->cancelled()) return;
            if (survivors.load(std::memory_order_relaxed) > kMaxLeafBlocks) return;
            CoordBBox box(parents[i], parents[i].offsetBy(size - 1));
            box.intersect(range);
            const Coord lo = box.min() & ~(child - 1), hi = box.max() & ~(child - 1);
            std::vector<Coord> children;
            std::vector<Box3> boxes;
            for (int x = lo.x(); x <= hi.x(); x += child)
                for (int y = lo.y(); y <= hi.y(); y += child)
                    for (int z = lo.z(); z <= hi.z(); z += child) {
                        CoordBBox cb(Coord(x, y, z), Coord(x, y, z).offsetBy(child - 1));
                        cb.intersect(range);
                        children.emplace_back(x, y, z);
                        boxes.push_back(cellsBox(frame, cb));
                    }
            std::vector<std::uint8_t> straddle(children.size());
            field.mayStraddleWithin(cellsBox(frame, box), boxes.data(), boxes.size(), iso, straddle.data());
            for (std::size_t c = 0; c < children.size(); ++c)
                if (straddle[c]) kept[i].push_back(children[c]);
            const std::uint64_t n = children.size();
            count += n;
            survivors += kept[i].size();
        }
    });
    if (cancel) cancel->check();
    if (survivors > kMaxLeafBlocks) tooFine(field, frame, survivors, child);
    // A surface through a block of side n leaf blocks meets about n^2 of them: stop here rather
    // than test millions of blocks to learn that the lattice cannot fit.
    const double perBlock = double(child / kLeafDim) * double(child / kLeafDim);
    if (double(survivors) * perBlock > 8.0 * double(kMaxLeafBlocks)) {
        std::ostringstream s;
        s << frame.h << " would make the lattice around " << field.describe() << " too fine (about "
          << double(survivors) * perBlock << " blocks of 8^3 cells would hold surface, at most " << kMaxLeafBlocks
          << "); use a larger voxel size";
        throw Error("--voxel-size", s.str());
    }
    tested += count;
    std::vector<Coord> out;
    out.reserve(survivors);
    for (auto& k : kept) out.insert(out.end(), k.begin(), k.end());
    return out;
}

} // namespace

CoordBBox latticeCellRange(const Field& field, const LatticeFrame& frame) {
    if (!(frame.h > 0) || !std::isfinite(frame.h))
        throw Error("--voxel-size", "must be a positive number of world units, not " + std::to_string(frame.h));
    const Box3 d = field.domain();
    // A spacing wider than the whole input puts it inside one or two cells: nothing of its shape
    // is left, and the lattice's nodes lie so far out that a grid's index coordinates of them
    // pass what an int holds (--voxel-size 1e300 crashed).
    const double extent = d.longestSide();
    if (frame.h > extent) {
        std::ostringstream s;
        s << frame.h << " is wider than all of " << field.describe() << " (" << extent
          << " along its longest side); choose a spacing that puts cells across it";
        throw Error("--voxel-size", s.str());
    }
    Coord lo, hi;
    for (int a = 0; a < 3; ++a) {
        const double n0 = std::floor((d.min[a] - frame.origin[a]) / frame.h);
        const double n1 = std::ceil((d.max[a] - frame.origin[a]) / frame.h);
        const double cells = std::max(1.0, n1 - n0);
        if (!std::isfinite(cells) || cells > kMaxCellsPerAxis) {
            std::ostringstream s;
            s << frame.h << " gives " << cells << " cells along " << "xyz"[a] << " over " << field.describe()
              << " (extent " << d.max[a] - d.min[a] << "); at most " << kMaxCellsPerAxis << " are allowed";
            throw Error("--voxel-size", s.str());
        }
        if (std::fabs(n0) > 1e9 || std::fabs(n1) > 1e9) throw Error("--voxel-size", "the lattice lies too far from the origin");
        lo[a] = int(n0);
        hi[a] = int(std::max(n0 + 1, n1)) - 1;
    }
    return CoordBBox(lo, hi);
}

Lattice buildLattice(const Field& field, const LatticeFrame& frame, const CoordBBox& cellRange, double iso, CellTest test,
                     const CancelToken* cancel, double memoryLimit) {
    const auto start = std::chrono::steady_clock::now();
    Lattice lat;
    lat.frame = frame;
    lat.cellRange = cellRange;
    lat.cells = std::make_shared<CellTree>(false);
    LatticeStats& st = lat.stats;

    // Top-down over VDB node sizes: 4096^3, 128^3, then 8^3 leaf blocks. The root has no bounds
    // of its own: its 4096^3 children are tested as children of one virtual parent per block.
    constexpr int kL2 = 4096, kL1 = 128;
    std::vector<Coord> roots;
    {
        const Coord lo = cellRange.min() & ~(kL2 - 1), hi = cellRange.max() & ~(kL2 - 1);
        for (int x = lo.x(); x <= hi.x(); x += kL2)
            for (int y = lo.y(); y <= hi.y(); y += kL2)
                for (int z = lo.z(); z <= hi.z(); z += kL2) roots.emplace_back(x, y, z);
    }
    std::vector<Coord> blocks = straddlingChildren(field, frame, roots, kL2, kL2, cellRange, iso, cancel, st.upperNodesTested);
    blocks = straddlingChildren(field, frame, blocks, kL2, kL1, cellRange, iso, cancel, st.upperNodesTested);
    blocks = straddlingChildren(field, frame, blocks, kL1, kLeafDim, cellRange, iso, cancel, st.leafBlocksTested);
    st.leafBlocksVisited = blocks.size();

    // Where a cell's bounds are its corners' range (or bounds are not wanted) the corner values decide.
    const bool cornersExact = test == CellTest::CornerSigns || field.cellBoundsAreCornerRange(frame);
    const Inside side = field.inside();
    std::vector<std::unique_ptr<MaskLeaf>> leaves(blocks.size());
    std::vector<std::uint32_t> withoutData(blocks.size(), 0); // active cells without data, per block
    std::vector<std::int64_t> nanAt(blocks.size(), -1);
    std::vector<std::uint32_t> cellsExamined(blocks.size(), 0);
    // Per block, the nodes alone inside among their six neighbours (each the low corner of one of
    // the block's cells, so listed once), and whether a neighbour below the block was not seen.
    struct Lone {
        Coord node;
        bool unseenNeighbour;
    };
    std::vector<std::vector<Lone>> lone(cornersExact ? blocks.size() : 0);
    Progress progress("lattice", blocks.size(), cancel);
    // Active cells counted as they are found, so that a lattice too fine for the machine stops
    // during this pass rather than minutes later, when the kernel kills the process.
    const double budget = memoryBudgetBytes(memoryLimit);
    const std::uint64_t maxActive = budget > 0 ? std::uint64_t(budget / kMeshBytesPerActiveCell) : ~std::uint64_t(0);
    std::atomic<std::uint64_t> activeSoFar{0};

    // Every stride-th block is examined first: a sample that tells within seconds whether the
    // rest can fit (cells per block vary, so block counts alone cannot say).
    const std::size_t stride = std::max<std::size_t>(1, blocks.size() / 4096);
    auto examine = [&](const tbb::blocked_range<std::size_t>& r, bool sample) {
        std::array<double, kBlockNodeCount> vals;
        std::vector<Box3> scratchBoxes;
        std::vector<int> scratchBits;
        std::vector<std::uint8_t> scratchOut;
        // Per node column (x, y), at x + kBlockNodes * y as in the sample: bit z set when node
        // (x, y, z) is inside / exactly at iso / NaN.
        std::array<std::uint16_t, kBlockNodes * kBlockNodes> inside, atIso, isNan;
        for (std::size_t i = r.begin(); i < r.end(); ++i) {
            if (activeSoFar.load(std::memory_order_relaxed) > maxActive) return;
            if (!sample && i % stride == 0) continue;
            const std::size_t bi = sample ? i * stride : i;
            const Coord o = blocks[bi];
            CoordBBox box(o, o.offsetBy(kLeafDim - 1));
            box.intersect(cellRange);
            const Coord lo = box.min() - o, hi = box.max() - o;
            field.sampleNodes(frame, toVec(o), {kBlockNodes, kBlockNodes, kBlockNodes}, nullptr, vals.data());
            // Without a branch a node, one z plane at a time over the sample's contiguous columns
            // (a NaN is neither inside nor at iso; the rare block that holds one is searched for
            // it below).
            inside.fill(0);
            atIso.fill(0);
            isNan.fill(0);
            constexpr int kColumns = kBlockNodes * kBlockNodes;
            const bool below = side == Inside::Below;
            for (int z = 0; z < kBlockNodes; ++z) {
                const double* plane = &vals[std::size_t(kColumns * z)];
                const std::uint16_t bit = std::uint16_t(1u << z);
                // (The side fixed in each loop, so that each compiles to one vector compare.)
                if (below)
                    for (int c = 0; c < kColumns; ++c) inside[std::size_t(c)] |= isInside(plane[c], iso, Inside::Below) ? bit : std::uint16_t(0);
                else
                    for (int c = 0; c < kColumns; ++c) inside[std::size_t(c)] |= isInside(plane[c], iso, Inside::Above) ? bit : std::uint16_t(0);
                for (int c = 0; c < kColumns; ++c) atIso[std::size_t(c)] |= plane[c] == iso ? bit : std::uint16_t(0);
                for (int c = 0; c < kColumns; ++c) isNan[std::size_t(c)] |= plane[c] != plane[c] ? bit : std::uint16_t(0);
            }
            unsigned nans = 0; // (a column array: a reduction straight from the compares does not vectorise)
            for (int c = 0; c < kColumns; ++c) nans |= isNan[std::size_t(c)];
            const bool anyNan = nans != 0;
            if (anyNan)
                for (int x = 0; x < kBlockNodes && nanAt[bi] < 0; ++x)
                    for (int y = 0; y < kBlockNodes && nanAt[bi] < 0; ++y)
                        for (int z = 0; z < kBlockNodes && nanAt[bi] < 0; ++z) {
                            const int n = x + kBlockNodes * y + kBlockNodes * kBlockNodes * z;
                            // Only nodes of cells inside the range count.
                            if (std::isnan(vals[std::size_t(n)]) && x <= hi.x() + 1 && y <= hi.y() + 1 && z <= hi.z() + 1 &&
                                x >= lo.x() && y >= lo.y() && z >= lo.z())
                                nanAt[bi] = n;
                        }
            // Eight cells along z at once: a cell changes side when some but not all of its
            // corners are inside; it also touches the surface when it has no inside corner and
            // a corner exactly at iso.
            const unsigned zMask = (0xFFu >> (7 - hi.z())) & (0xFFu << lo.z());
            if (cornersExact) {
                // Bit z of column (x, y): node inside, its neighbours along z and, where the
                // block holds them, along x and y outside. A neighbour at x, y or z = -1 is not in
                // the block: such nodes are checked below. Only nodes whose eight cells are in
                // the range.
                const Coord first = cellRange.min().offsetBy(1) - o;
                const unsigned zNodes = zMask & (0xFFu << std::max(0, first.z()));
                for (int x = std::max(lo.x(), first.x()); x <= hi.x(); ++x)
                    for (int y = std::max(lo.y(), first.y()); y <= hi.y(); ++y) {
                        const std::size_t c = std::size_t(x + kBlockNodes * y);
                        unsigned alone = inside[c] & ~(inside[c] << 1) & ~(inside[c] >> 1) & ~inside[c + 1] & ~inside[c + kBlockNodes];
                        if (x > 0) alone &= ~unsigned(inside[c - 1]);
                        if (y > 0) alone &= ~unsigned(inside[c - kBlockNodes]);
                        for (alone &= zNodes; alone; alone &= alone - 1) {
                            const int z = __builtin_ctz(alone);
                            lone[bi].push_back({o.offsetBy(x, y, z), x == 0 || y == 0 || z == 0});
                        }
                    }
            }
            // Where cells are asked for their bounds, the block's 2^3 groups of cells are asked
            // first (bit gx + 4 gy + 16 gz): a cell outside every straddling group cannot hold
            // surface. Each cell's own question is what costs (a long formula's bounds take
            // thousands of operations), and most cells of a block lie a few cells off the surface.
            // Asked together within the block (and a group's cells within the group): a field
            // may reuse its bounds over the box around them (Field::mayStraddleWithin).
            auto groupCells = [&](int gx, int gy, int gz) {
                CoordBBox cb(o.offsetBy(2 * gx, 2 * gy, 2 * gz), o.offsetBy(2 * gx + 1, 2 * gy + 1, 2 * gz + 1));
                cb.intersect(box);
                return cb;
            };
            std::uint64_t groups = 0;
            if (!cornersExact) {
                std::vector<Box3>& boxes = scratchBoxes;
                std::vector<int>& bits = scratchBits;
                boxes.clear();
                bits.clear();
                for (int gx = lo.x() / 2; gx <= hi.x() / 2; ++gx)
                    for (int gy = lo.y() / 2; gy <= hi.y() / 2; ++gy)
                        for (int gz = lo.z() / 2; gz <= hi.z() / 2; ++gz) {
                            boxes.push_back(cellsBox(frame, groupCells(gx, gy, gz)));
                            bits.push_back(gx + 4 * gy + 16 * gz);
                        }
                scratchOut.resize(boxes.size());
                field.mayStraddleWithin(cellsBox(frame, box), boxes.data(), boxes.size(), iso, scratchOut.data());
                for (std::size_t g = 0; g < boxes.size(); ++g)
                    if (scratchOut[g]) groups |= std::uint64_t(1) << bits[std::size_t(g)];
            }
            // Rows of cells along z (bit z of rows[x][y]) whose corners show a crossing.
            std::array<std::array<unsigned, kLeafDim>, kLeafDim> rows{};
            std::uint32_t examined = 0;
            for (int x = lo.x(); x <= hi.x(); ++x)
                for (int y = lo.y(); y <= hi.y(); ++y) {
                    // The columns (x, y), (x + 1, y), (x, y + 1), (x + 1, y + 1).
                    const std::size_t a = std::size_t(x + kBlockNodes * y), b = a + kBlockNodes;
                    const unsigned orIn = inside[a] | inside[a + 1] | inside[b] | inside[b + 1];
                    const unsigned andIn = inside[a] & inside[a + 1] & inside[b] & inside[b + 1];
                    const unsigned orEq = atIso[a] | atIso[a + 1] | atIso[b] | atIso[b + 1];
                    const unsigned anyIn = (orIn | (orIn >> 1)) & 0xFFu;
                    const unsigned allIn = (andIn & (andIn >> 1)) & 0xFFu;
                    const unsigned anyEq = (orEq | (orEq >> 1)) & 0xFFu;
                    rows[std::size_t(x)][std::size_t(y)] = ((anyIn & ~allIn) | (anyEq & ~anyIn)) & zMask;
                    examined += std::uint32_t(__builtin_popcount(zMask));
                }
            // The field may cross iso inside a cell whose corners agree: its bounds are asked,
            // where its group's straddle.
            for (std::uint64_t left = groups; left; left &= left - 1) {
                const int g = __builtin_ctzll(left), gx = g % 4, gy = (g / 4) % 4, gz = g / 16;
                std::vector<Box3>& boxes = scratchBoxes;
                std::vector<int>& bits = scratchBits;
                boxes.clear();
                bits.clear();
                for (int x = std::max(2 * gx, lo.x()); x <= std::min(2 * gx + 1, hi.x()); ++x)
                    for (int y = std::max(2 * gy, lo.y()); y <= std::min(2 * gy + 1, hi.y()); ++y)
                        for (int z = std::max(2 * gz, lo.z()); z <= std::min(2 * gz + 1, hi.z()); ++z) {
                            if (rows[std::size_t(x)][std::size_t(y)] & (1u << z)) continue;
                            boxes.push_back(frame.cellBox({o.x() + x, o.y() + y, o.z() + z}));
                            bits.push_back(x + 8 * y + 64 * z);
                        }
                if (boxes.empty()) continue;
                scratchOut.resize(boxes.size());
                field.mayStraddleWithin(cellsBox(frame, groupCells(gx, gy, gz)), boxes.data(), boxes.size(), iso, scratchOut.data());
                for (std::size_t c = 0; c < boxes.size(); ++c)
                    if (scratchOut[c]) {
                        const int bit = bits[c];
                        rows[std::size_t(bit % 8)][std::size_t((bit / 8) % 8)] |= 1u << (bit / 64);
                    }
            }
            std::array<std::uint64_t, kLeafDim> words{};
            for (int x = lo.x(); x <= hi.x(); ++x) {
                std::uint64_t word = 0;
                for (int y = lo.y(); y <= hi.y(); ++y) word |= std::uint64_t(rows[std::size_t(x)][std::size_t(y)]) << (8 * y);
                words[std::size_t(x)] = word;
            }
            std::array<std::uint64_t, kLeafDim> withData = words;
            field.dropCellsWithoutData(frame, toVec(o), withData.data());
            MaskLeaf::NodeMaskType mask;
            for (int x = 0; x < kLeafDim; ++x) {
                mask.template getWord<std::uint64_t>(openvdb::Index(x)) = words[std::size_t(x)];
                withoutData[bi] += std::uint32_t(__builtin_popcountll(words[std::size_t(x)] & ~withData[std::size_t(x)]));
            }
            cellsExamined[bi] = examined;
            if (!mask.isOff()) {
                activeSoFar += mask.countOn();
                auto leaf = std::make_unique<MaskLeaf>(o, false);
                leaf->setValueMask(mask);
                leaves[bi] = std::move(leaf);
            }
            progress.advance();
        }
    };
    auto tooMuch = [&](double cells, const std::string& atLeast, const std::string& how) {
        const double gib = double(1 << 30);
        std::ostringstream s;
        s.precision(3);
        s << frame.h << " would make the lattice around " << field.describe() << " too fine for this machine's memory (" << atLeast
          << cells << " cells may hold surface" << how << "; meshing them needs about " << cells * kMeshBytesPerActiveCell / gib
          << " GiB, and " << budget / gib << " GiB may be used" << (memoryLimit > 0 ? "" : ", 80 % of the memory free when it started")
          << "); use a larger voxel size";
        throw Error("--voxel-size", s.str());
    };
    const std::size_t sampled = (blocks.size() + stride - 1) / stride;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, sampled, 16), [&](const auto& r) { examine(r, true); });
    if (cancel) cancel->check();
    // A sample of thousands of blocks, each holding 0 to 512 cells, estimates the total within a
    // few per cent; the margin keeps a lattice that may just fit from being refused on it.
    const double estimate = double(activeSoFar.load()) * double(blocks.size()) / double(sampled);
    if (activeSoFar <= maxActive && estimate > 1.25 * double(maxActive))
        tooMuch(estimate, "", ", estimated from " + std::to_string(sampled) + " of its " + std::to_string(blocks.size()) + " blocks of 8^3 cells");
    if (stride > 1) tbb::parallel_for(tbb::blocked_range<std::size_t>(0, blocks.size(), 16), [&](const auto& r) { examine(r, false); });
    if (cancel) cancel->check();
    if (activeSoFar > maxActive) tooMuch(double(activeSoFar.load()), "at least ", "");
    for (std::size_t bi = 0; bi < blocks.size(); ++bi) {
        if (nanAt[bi] < 0) continue;
        const int n = int(nanAt[bi]);
        const Vec3i node = toVec(blocks[bi]) + Vec3i(n % kBlockNodes, (n / kBlockNodes) % kBlockNodes, n / (kBlockNodes * kBlockNodes));
        throw Error(field.describe(), "is undefined (NaN) at " + pointText(frame.nodeWorld(node)));
    }
    // Nodes whose neighbour below lay in another block: that neighbour decides.
    for (const std::vector<Lone>& found : lone)
        for (const Lone& l : found) {
            if (l.unseenNeighbour) {
                std::array<double, 27> around;
                field.sampleNodes(frame, toVec(l.node) - Vec3i(1, 1, 1), {3, 3, 3}, nullptr, around.data());
                if (isInside(around[4], iso, side) || isInside(around[10], iso, side) || isInside(around[12], iso, side)) continue;
            }
            lat.loneInsideNodes.push_back(l.node);
        }
    std::sort(lat.loneInsideNodes.begin(), lat.loneInsideNodes.end());
    for (std::size_t bi = 0; bi < blocks.size(); ++bi) {
        st.cellsExamined += cellsExamined[bi];
        st.cellsWithoutData += withoutData[bi];
        if (!leaves[bi]) continue;
        st.cellsActive += leaves[bi]->onVoxelCount();
        lat.cells->addLeaf(leaves[bi].release());
    }
    st.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return lat;
}

} // namespace vdbsurf
