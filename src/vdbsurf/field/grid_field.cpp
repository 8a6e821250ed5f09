#include "vdbsurf/field/grid_field.h"
#include "vdbsurf/field/grid_field_impl.h"

#include "vdbsurf/field/tree_ranges.h"

#include "vdbsurf/core/error.h"
#include "vdbsurf/vdb/voxel_transform.h"

#include <openvdb/openvdb.h>
#include <openvdb/tools/Interpolation.h>
#include <openvdb/tree/LeafManager.h>

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <optional>
#include <stdexcept>

namespace vdbsurf {

namespace {

using openvdb::Coord;
using openvdb::CoordBBox;

// Visitors of TreeRanges::visit: the range of a box's values, and whether it straddles iso.
struct RangeOf {
    static constexpr bool kWholeMayServe = false;
    MinMax& mm;
    bool add(double v) { return mm.add(v), false; }
    bool add(const MinMax& r) { return mm.add(r), false; }
};
struct StraddleOf {
    static constexpr bool kWholeMayServe = true;
    double iso, clear; // clear: the widest tolerance straddles() gives a range of the grid's values
    MinMax mm;
    bool straddles() const { return vdbsurf::straddles({mm.lo, mm.hi}, iso); }
    bool add(double v) { return mm.add(v), straddles(); }
    bool add(const MinMax& r) { return mm.add(r), straddles(); }
    bool wholeServes(const MinMax& r) const { return r.lo - clear > iso || r.hi + clear < iso; }
};

} // namespace

namespace {

// BoxSampler's trilinear interpolation at fraction uvw from the voxel at (x, y, z) of a block
// read by sampleBlock (x fastest, dims its size): BoxSampler::sample's bits, from memory.
template <typename ValueT>
ValueT interpolateBlock(const ValueT* voxels, const Vec3i& dims, int x, int y, int z, const openvdb::Vec3d& uvw) {
    ValueT data[2][2][2];
    for (int a = 0; a < 2; ++a)
        for (int b = 0; b < 2; ++b)
            for (int c = 0; c < 2; ++c)
                data[a][b][c] = voxels[(std::size_t(z + c) * std::size_t(dims.y) + std::size_t(y + b)) * std::size_t(dims.x) + std::size_t(x + a)];
    return openvdb::tools::BoxSampler::trilinearInterpolation(data, uvw);
}

template <typename GridT>
class TypedGrid final : public GridField::Impl {
public:
    using TreeT = typename GridT::TreeType;
    using LeafT = typename TreeT::LeafNodeType;
    using RootT = typename TreeT::RootNodeType;
    using Node2T = typename RootT::ChildNodeType;
    using Acc = openvdb::tree::ValueAccessor<const TreeT, /*IsSafe=*/false>;

    TypedGrid(typename GridT::ConstPtr grid, const std::string& label)
        : mGrid(std::move(grid)), mTree(mGrid->constTree()), mMap(mGrid->transform().baseMap().get()) {
        const openvdb::Mat4d m = mMap->getAffineMap()->getConstMat4(); // linear: GridField checked
        mAxisAligned = true;
        for (int r = 0; r < 3; ++r)
            for (int c = 0; c < 3; ++c)
                if (r != c && m(r, c) != 0.0) mAxisAligned = false;
        const openvdb::Vec3d vs = mGrid->voxelSize();
        mAxisAligned = mAxisAligned && m(0, 0) > 0 && m(0, 0) == m(1, 1) && m(1, 1) == m(2, 2);
        mVoxel = std::min({vs.x(), vs.y(), vs.z()});
        if (!(mVoxel > 0) || !std::isfinite(mVoxel)) throw Error(label, "has a degenerate transform (voxel size 0)");
        mOrigin = toVec(mGrid->indexToWorld(openvdb::Vec3d(0.0)));
        mRanges.emplace(mTree, label);
        computeDomain(label);
    }

    GridBaseCPtr grid() const override { return mGrid; }
    double voxelSize() const override { return mVoxel; }
    bool axisAligned() const override { return mAxisAligned; }
    Interval valueRange() const override { return {mRanges->all().lo, mRanges->all().hi}; }
    Box3 domain() const override { return mDomain; }

    openvdb::Vec3d worldToIndex(const Vec3d& p) const {
        if (mAxisAligned) return openvdb::Vec3d((p.x - mOrigin.x) / mVoxel, (p.y - mOrigin.y) / mVoxel, (p.z - mOrigin.z) / mVoxel);
        return mGrid->worldToIndex(toVdb(p));
    }

    // BoxSampler::sample's bits: the same eight voxels, read in one probe where they lie in one
    // leaf (most do), and the same interpolation of them.
    double value(const Vec3d& p) const override {
        Acc acc(mTree);
        const openvdb::Vec3d ip = worldToIndex(p);
        const openvdb::Vec3i idx = openvdb::tools::local_util::floorVec3(ip);
        typename TreeT::ValueType block[8];
        smallBlock<2>(acc, Coord(idx), block);
        return double(interpolateBlock(block, Vec3i(2, 2, 2), 0, 0, 0, ip - idx));
    }

    bool values(const Box3& box, const Vec3d* points, std::size_t n, double* out) const override {
        // The voxels under the box, read once leaf by leaf (up to 8 a side), then each point
        // interpolated as BoxSampler::sample does: value()'s bits, without a tree walk and eight
        // accessor reads a point.
        using ValueT = typename TreeT::ValueType;
        constexpr int kMaxSide = 8;
        const Interval3 ib = indexBox(box);
        bool small = ib.finite();
        for (int a = 0; a < 3 && small; ++a)
            small = std::fabs(ib.lo[a]) < 1e9 && std::floor(ib.hi[a]) + 2 - std::floor(ib.lo[a]) <= kMaxSide;
        if (!small) return false;
        const Coord base(int(std::floor(ib.lo.x())), int(std::floor(ib.lo.y())), int(std::floor(ib.lo.z())));
        const Vec3i dims(int(std::floor(ib.hi.x())) + 2 - base.x(), int(std::floor(ib.hi.y())) + 2 - base.y(),
                         int(std::floor(ib.hi.z())) + 2 - base.z());
        ValueT voxels[kMaxSide * kMaxSide * kMaxSide];
        Acc acc(mTree);
        sampleBlock(acc, base, dims, voxels);
        for (std::size_t i = 0; i < n; ++i) {
            const openvdb::Vec3d ip = worldToIndex(points[i]);
            const openvdb::Vec3i idx = openvdb::tools::local_util::floorVec3(ip);
            const int x = idx.x() - base.x(), y = idx.y() - base.y(), z = idx.z() - base.z();
            // Rounding of the transform can put a point of the box's edge a hair outside it.
            if (x < 0 || y < 0 || z < 0 || x + 1 >= dims.x || y + 1 >= dims.y || z + 1 >= dims.z) {
                out[i] = value(points[i]);
                continue;
            }
            out[i] = double(interpolateBlock(voxels, dims, x, y, z, ip - idx));
        }
        return true;
    }

    // Central differences of the trilinear interpolant half a voxel either side, mapped to world
    // space through the inverse Jacobian transpose: valueAndGradient's, which reads the 3x3x3
    // voxels once (six BoxSampler samples read 48 through a fresh accessor: twice the time,
    // 0.55-0.68 against 0.25-0.32 µs near the armadillo's surface).
    Vec3d gradient(const Vec3d& p) const override {
        Vec3d g;
        valueAndGradient(p, g);
        return g;
    }

    // The same by six BoxSampler samples, where rounding takes ip +- 0.5 out of that block.
    Vec3d sampledGradient(const Vec3d& p) const {
        Acc acc(mTree);
        const openvdb::Vec3d ip = worldToIndex(p);
        openvdb::Vec3d g;
        for (int a = 0; a < 3; ++a) {
            openvdb::Vec3d lo = ip, hi = ip;
            lo[a] -= 0.5;
            hi[a] += 0.5;
            g[a] = double(openvdb::tools::BoxSampler::sample(acc, hi)) - double(openvdb::tools::BoxSampler::sample(acc, lo));
        }
        return toVec(mMap->applyIJT(g));
    }

    double valueAndGradient(const Vec3d& p, Vec3d& gradient) const override {
        // The value and the six samples of sampledGradient() read the 3x3x3 voxels from
        // floor(ip - 0.5): fetched once, then interpolated as BoxSampler does (same arithmetic,
        // so the results are value()'s and sampledGradient()'s bit for bit).
        using ValueT = typename TreeT::ValueType;
        const openvdb::Vec3d ip = worldToIndex(p);
        openvdb::Vec3d samples[7] = {ip, ip, ip, ip, ip, ip, ip}; // ip, then lo/hi per axis
        for (int a = 0; a < 3; ++a) samples[1 + 2 * a][a] -= 0.5, samples[2 + 2 * a][a] += 0.5;
        // Each coordinate of a sample is ip's, or ip's -+ 0.5 along one axis: three floors an axis.
        int at[3], below[3], above[3];
        for (int a = 0; a < 3; ++a)
            at[a] = int(std::floor(ip[a])), below[a] = int(std::floor(samples[1 + 2 * a][a])), above[a] = int(std::floor(samples[2 + 2 * a][a]));
        const Coord base(below[0], below[1], below[2]);
        Coord corner[7];
        for (int s = 0; s < 7; ++s) {
            for (int a = 0; a < 3; ++a) corner[s][a] = s == 1 + 2 * a ? below[a] : s == 2 + 2 * a ? above[a] : at[a];
            const Coord d = corner[s] - base;
            // Rounding of ip +- 0.5 can step outside the block: the plain calls are exact there.
            if (d.x() < 0 || d.y() < 0 || d.z() < 0 || d.x() > 1 || d.y() > 1 || d.z() > 1) {
                gradient = sampledGradient(p);
                return value(p);
            }
        }
        Acc acc(mTree);
        ValueT block[27]; // x fastest, as sampleBlock writes it
        smallBlock<3>(acc, base, block);
        auto sample = [&](int s) {
            const Coord d = corner[s] - base;
            const openvdb::Vec3d uvw = samples[s] - openvdb::Vec3d(corner[s].x(), corner[s].y(), corner[s].z());
            return double(interpolateBlock(block, Vec3i(3, 3, 3), d.x(), d.y(), d.z(), uvw));
        };
        openvdb::Vec3d g;
        for (int a = 0; a < 3; ++a) g[a] = sample(2 + 2 * a) - sample(1 + 2 * a);
        gradient = toVec(mMap->applyIJT(g));
        return sample(0);
    }

    // The box in index space (the bounding box of its corners' images when the grid is rotated).
    struct Interval3 {
        openvdb::Vec3d lo, hi;
        bool finite() const { return std::isfinite(lo.x() + lo.y() + lo.z() + hi.x() + hi.y() + hi.z()); }
    };
    Interval3 indexBox(const Box3& box) const {
        if (mAxisAligned) return {worldToIndex(box.min), worldToIndex(box.max)};
        Interval3 out{openvdb::Vec3d(std::numeric_limits<double>::infinity()), openvdb::Vec3d(-std::numeric_limits<double>::infinity())};
        for (int c = 0; c < 8; ++c) {
            const openvdb::Vec3d ip = worldToIndex(box.corner(c));
            out.lo = openvdb::math::minComponent(out.lo, ip);
            out.hi = openvdb::math::maxComponent(out.hi, ip);
        }
        return out;
    }

    Interval bounds(const Box3& box) const override {
        Interval out;
        const Interval3 ib = indexBox(box);
        if (boundsOverFewCells(ib, nullptr, out) == FewCells::Bounds) return out;
        MinMax mm;
        query(supportBox(ib), mm);
        return {mm.lo, mm.hi};
    }

    bool mayStraddle(const Box3& box, double iso) const override {
        Interval out;
        const Interval3 ib = indexBox(box);
        switch (boundsOverFewCells(ib, &iso, out)) {
        case FewCells::Apart: return false;
        case FewCells::Bounds: return straddles(out, iso);
        case FewCells::TooMany: break;
        }
        return queryStraddles(supportBox(ib), iso);
    }

    // Trilinear samples at index position q use voxels floor(q) and floor(q) + 1, the latter
    // with weight zero when q is a whole number (up to rounding, which straddles() absorbs).
    static CoordBBox supportBox(const Interval3& ib) { return CoordBBox(lowerSupport(ib.lo), upperSupport(ib.hi)); }

    enum class FewCells { Apart, Bounds, TooMany };
    // Over a box that spans few voxel cells: bounds(box) in `out` (Bounds), or, with an iso value,
    // Apart when the voxels the box reads (which hold the interpolant's range) lie clear of it
    // already (most cells a lattice asks about lie clear of the surface). TooMany otherwise.
    FewCells boundsOverFewCells(const Interval3& ib, const double* iso, Interval& out) const {
        const openvdb::Vec3d &lo = ib.lo, &hi = ib.hi;
        // Between voxel planes the trilinear interpolant is multilinear, so over a box that
        // spans only a few voxel cells its range is the range of its values at the box's corners
        // and where the box meets the voxel planes: exact, and much tighter than the stored
        // values when the mesh lattice is finer than the grid.
        std::array<std::array<double, 5>, 3> ticks;
        std::array<int, 3> nticks{};
        if (!ib.finite()) return FewCells::TooMany;
        for (int a = 0; a < 3; ++a) {
            ticks[a][0] = lo[a];
            int n = 1;
            for (double plane = std::floor(lo[a]) + 1; plane < hi[a]; plane += 1) {
                if (n >= 4) return FewCells::TooMany;
                ticks[a][std::size_t(n++)] = plane;
            }
            ticks[a][std::size_t(n++)] = hi[a];
            nticks[std::size_t(a)] = n;
        }
        // The voxels every tick's trilinear sample reads (at most 6 a side), read once leaf by
        // leaf; each sample is then BoxSampler's own interpolation of them (the same bits as
        // BoxSampler::sample, which read 8 voxels through the accessor for each of up to 125
        // ticks: on a lattice 3 voxels a cell that was most of the lattice's time).
        using ValueT = typename TreeT::ValueType;
        const Coord base(int(std::floor(lo.x())), int(std::floor(lo.y())), int(std::floor(lo.z())));
        const Vec3i dims(int(std::floor(hi.x())) + 2 - base.x(), int(std::floor(hi.y())) + 2 - base.y(),
                         int(std::floor(hi.z())) + 2 - base.z());
        ValueT voxels[6 * 6 * 6];
        if (dims.x > 6 || dims.y > 6 || dims.z > 6) throw std::logic_error("GridField::bounds: more voxels than ticks allow");
        Acc acc(mTree);
        sampleBlock(acc, base, dims, voxels);
        if (iso) {
            // Widened by the rounding of BoxSampler's three lerps in ValueT, which can land a
            // few ulps beyond the voxels' range.
            MinMax range;
            for (int i = 0; i < dims.x * dims.y * dims.z; ++i) range.add(double(voxels[i]));
            const double margin = 16 * double(std::numeric_limits<ValueT>::epsilon()) * std::max(std::fabs(range.lo), std::fabs(range.hi));
            if (!straddles({range.lo - margin, range.hi + margin}, *iso)) return FewCells::Apart;
        }
        MinMax mm;
        for (int i = 0; i < nticks[0]; ++i)
            for (int j = 0; j < nticks[1]; ++j)
                for (int k = 0; k < nticks[2]; ++k) {
                    const openvdb::Vec3d t(ticks[0][std::size_t(i)], ticks[1][std::size_t(j)], ticks[2][std::size_t(k)]);
                    const openvdb::Vec3i idx = openvdb::tools::local_util::floorVec3(t);
                    mm.add(double(interpolateBlock(voxels, dims, idx.x() - base.x(), idx.y() - base.y(), idx.z() - base.z(), t - idx)));
                }
        out = {mm.lo, mm.hi};
        return FewCells::Bounds;
    }

    LatticeFrame naturalFrame(double h) const override {
        if (mAxisAligned) return {mOrigin, h};
        return {mDomain.min, h};
    }

    bool directStride(const LatticeFrame& frame, int& stride, Coord& offset) const override {
        if (!mAxisAligned) return false;
        const double m = frame.h / mVoxel;
        const double mr = std::nearbyint(m);
        if (mr < 1 || std::fabs(m - mr) > 1e-9 * mr) return false;
        const Vec3d o = (frame.origin - mOrigin) / mVoxel;
        for (int a = 0; a < 3; ++a) {
            if (std::fabs(o[a] - std::nearbyint(o[a])) > 1e-6) return false;
            offset[a] = int(std::nearbyint(o[a]));
        }
        stride = int(mr);
        return true;
    }

    // Do lattice cells never cross a voxel plane (h = voxel / k, nodes on the voxel planes)? Then a
    // cell's bounds are its corners' range, the interpolant being multilinear inside.
    bool cellsInsideVoxelCells(const LatticeFrame& frame) const override {
        if (!mAxisAligned) return false;
        const double k = mVoxel / frame.h;
        const double kr = std::nearbyint(k);
        if (kr < 1 || std::fabs(k - kr) > 1e-6 * kr) return false;
        const Vec3d o = (frame.origin - mOrigin) / frame.h;
        for (int a = 0; a < 3; ++a)
            if (std::fabs(o[a] - std::nearbyint(o[a])) > 1e-6) return false;
        return true;
    }

    // A cell's values are trilinear samples of the voxels in its support; when none of them is
    // active or in an active tile, they are all the fill's, and the cell holds no data.
    void dropCellsWithoutData(const LatticeFrame& frame, const Vec3i& first, std::uint64_t* cells) const override {
        if (std::all_of(cells, cells + 8, [](std::uint64_t w) { return w == 0; })) return;
        Acc acc(mTree);
        int stride = 0;
        Coord offset;
        if (directStride(frame, stride, offset) && stride == 1) {
            // Nodes on voxel centres: a cell reads its 8 corner voxels alone. Their active bits,
            // gathered as 9 x 9 columns along z from the leaves' masks, give all 512 cells at once.
            const Coord base(offset.x() + first.x, offset.y() + first.y, offset.z() + first.z);
            std::array<std::uint16_t, 81> column{};
            activeColumns(acc, base, column);
            for (int x = 0; x < 8; ++x)
                for (int y = 0; y < 8; ++y) {
                    const unsigned c = column[std::size_t(x * 9 + y)] | column[std::size_t(x * 9 + y + 1)] |
                                       column[std::size_t(x * 9 + 9 + y)] | column[std::size_t(x * 9 + 9 + y + 1)];
                    const std::uint64_t has = (c | (c >> 1)) & 0xFFu;
                    cells[x] &= ~((~has & 0xFFu) << (8 * y));
                }
            return;
        }
        for (int x = 0; x < 8; ++x) {
            std::uint64_t word = cells[x];
            for (std::uint64_t bits = word; bits; bits &= bits - 1) {
                const int b = __builtin_ctzll(bits);
                const Interval3 ib = indexBox(frame.cellBox(first + Vec3i(x, b >> 3, b & 7)));
                if (ib.finite() && !anyActive(acc, CoordBBox(lowerSupport(ib.lo), upperSupport(ib.hi))))
                    word &= ~(std::uint64_t(1) << b);
            }
            cells[x] = word;
        }
    }

    // A point on a lattice edge through voxel centres reads the edge's two voxels alone (the
    // others weigh zero), so a crossing between two inactive voxels has no data, as volumeToMesh
    // has no edge there. The points are floats: within a few of their ulps of a voxel plane, a
    // point is on it.
    void pointsWithData(const Vec3f* points, std::size_t n, std::uint8_t* out) const override {
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 4096), [&](const tbb::blocked_range<std::size_t>& r) {
            Acc acc(mTree);
            for (std::size_t i = r.begin(); i < r.end(); ++i) {
                openvdb::Vec3d ip = worldToIndex(Vec3d(points[i]));
                for (int a = 0; a < 3; ++a) {
                    const double plane = std::nearbyint(ip[a]);
                    const double ulps = 4 * double(std::numeric_limits<float>::epsilon()) * (std::fabs(double(points[i][std::size_t(a)])) / mVoxel + 1);
                    if (std::fabs(ip[a] - plane) < ulps) ip[a] = plane;
                }
                out[i] = std::uint8_t(anyActive(acc, CoordBBox(lowerSupport(ip), upperSupport(ip))));
            }
        });
    }

    bool sampleNodes(const LatticeFrame& frame, const Vec3i& first, const Vec3i& dims, const std::uint8_t* needed,
                     double* out) const override {
        int stride = 0;
        Coord offset;
        Acc acc(mTree);
        if (!directStride(frame, stride, offset)) {
            if (mAxisAligned && sampleNodesFromBlock(frame, first, dims, needed, out)) return true;
            std::size_t n = 0;
            for (int k = 0; k < dims.z; ++k)
                for (int j = 0; j < dims.y; ++j)
                    for (int i = 0; i < dims.x; ++i, ++n) {
                        if (needed && !needed[n]) continue;
                        const Vec3d p = frame.nodeWorld(first.x + i, first.y + j, first.z + k);
                        out[n] = double(openvdb::tools::BoxSampler::sample(acc, worldToIndex(p)));
                    }
            return true;
        }
        const Coord base(offset.x() + stride * first.x, offset.y() + stride * first.y, offset.z() + stride * first.z);
        if (stride == 1) {
            sampleBlock(acc, base, dims, out);
            return true;
        }
        std::size_t n = 0;
        for (int k = 0; k < dims.z; ++k)
            for (int j = 0; j < dims.y; ++j)
                for (int i = 0; i < dims.x; ++i, ++n) {
                    if (needed && !needed[n]) continue;
                    out[n] = double(acc.getValue(Coord(base.x() + stride * i, base.y() + stride * j, base.z() + stride * k)));
                }
        return true;
    }

    // sampleNodes on an axis-aligned grid whose voxels the nodes do not sit on: the voxels under
    // the nodes read once, leaf by leaf, then each node interpolated from them as BoxSampler
    // does (value()'s bits) — not eight accessor reads a node. False (nothing written) when the
    // voxels under the nodes are too many to gather (nodes much farther apart than voxels).
    bool sampleNodesFromBlock(const LatticeFrame& frame, const Vec3i& first, const Vec3i& dims, const std::uint8_t* needed,
                              double* out) const {
        using ValueT = typename TreeT::ValueType;
        constexpr std::size_t kMaxVoxels = 32 * 32 * 32;
        // Index position of each node along each axis: worldToIndex of nodeWorld, one axis at a time.
        std::array<std::vector<double>, 3> at;
        Coord base;
        Vec3i size;
        for (int a = 0; a < 3; ++a) {
            at[std::size_t(a)].resize(std::size_t(dims[std::size_t(a)]));
            for (int i = 0; i < dims[std::size_t(a)]; ++i) {
                Vec3i n = first;
                n[std::size_t(a)] += i;
                at[std::size_t(a)][std::size_t(i)] = (frame.nodeWorld(n)[std::size_t(a)] - mOrigin[std::size_t(a)]) / mVoxel;
            }
            const auto [lo, hi] = std::minmax_element(at[std::size_t(a)].begin(), at[std::size_t(a)].end());
            if (!std::isfinite(*lo) || !std::isfinite(*hi) || *hi - *lo > 64) return false;
            base[a] = int(std::floor(*lo));
            size[std::size_t(a)] = int(std::floor(*hi)) + 2 - base[a];
        }
        if (std::size_t(size.x) * std::size_t(size.y) * std::size_t(size.z) > kMaxVoxels) return false;
        std::vector<ValueT> voxels(std::size_t(size.x) * std::size_t(size.y) * std::size_t(size.z));
        Acc acc(mTree);
        sampleBlock(acc, base, size, voxels.data());
        std::size_t n = 0;
        for (int k = 0; k < dims.z; ++k)
            for (int j = 0; j < dims.y; ++j)
                for (int i = 0; i < dims.x; ++i, ++n) {
                    if (needed && !needed[n]) continue;
                    const openvdb::Vec3d ip(at[0][std::size_t(i)], at[1][std::size_t(j)], at[2][std::size_t(k)]);
                    const openvdb::Vec3i idx = openvdb::tools::local_util::floorVec3(ip);
                    out[n] = double(interpolateBlock(voxels.data(), size, idx.x() - base.x(), idx.y() - base.y(), idx.z() - base.z(), ip - idx));
                }
        return true;
    }

    bool piecewiseLinearCrossing(const Vec3d& a, const Vec3d& b, double iso, Inside side, double& t) const override {
        // Along a line through voxel centres parallel to an axis, the trilinear interpolant is the
        // piecewise-linear interpolant of the voxel values on that line: its crossing is exact.
        if (!mAxisAligned) return false;
        const openvdb::Vec3d ia = worldToIndex(a), ib = worldToIndex(b);
        int axis = -1;
        for (int k = 0; k < 3; ++k) {
            if (std::fabs(ia[k] - ib[k]) > 1e-9) {
                if (axis >= 0) return false;
                axis = k;
            }
        }
        if (axis < 0) return false;
        Coord c;
        for (int k = 0; k < 3; ++k) {
            if (k == axis) continue;
            if (std::fabs(ia[k] - std::nearbyint(ia[k])) > 1e-9) return false;
            c[k] = int(std::nearbyint(ia[k]));
        }
        const double s0 = ia[axis], s1 = ib[axis];
        // The walk visits every voxel plane between the ends: an edge of a lattice far coarser
        // than the grid (--voxel-size thousands of voxels) is left to the generic refinement.
        if (!(std::fabs(s1 - s0) <= kMaxWalkVoxels)) return false;
        const double dir = s1 > s0 ? 1.0 : -1.0;
        Acc acc(mTree);
        auto sampleAt = [&](double s) {
            openvdb::Vec3d q = ia;
            q[axis] = s;
            return double(openvdb::tools::BoxSampler::sample(acc, q));
        };
        // Breakpoints strictly between the ends, walked from a to b.
        double prevS = s0, prevV = sampleAt(s0);
        const bool startInside = isInside(prevV, iso, side);
        double s = dir > 0 ? std::floor(s0) + 1.0 : std::ceil(s0) - 1.0;
        for (;; s += dir) {
            const bool last = dir > 0 ? s >= s1 - 1e-9 : s <= s1 + 1e-9;
            const double cs = last ? s1 : s;
            const double cv = sampleAt(cs);
            if (isInside(cv, iso, side) != startInside) {
                const double local = (iso - prevV) / (cv - prevV);
                const double sc = prevS + (cs - prevS) * std::clamp(local, 0.0, 1.0);
                t = std::clamp((sc - s0) / (s1 - s0), 0.0, 1.0);
                return true;
            }
            if (last) break;
            prevS = cs;
            prevV = cv;
        }
        return false; // no sign change found on the samples: fall back to generic refinement
    }

private:
    static constexpr double kMaxWalkVoxels = 4096;
    static int clampIndex(double f) { return int(std::clamp(f, -double(1 << 30), double(1 << 30))); }
    static Coord lowerSupport(const openvdb::Vec3d& v) {
        auto c = [](double x) {
            const double r = std::nearbyint(x);
            return clampIndex(std::fabs(x - r) < 1e-9 ? r : std::floor(x));
        };
        return Coord(c(v.x()), c(v.y()), c(v.z()));
    }
    static Coord upperSupport(const openvdb::Vec3d& v) {
        auto c = [](double x) {
            const double r = std::nearbyint(x);
            return clampIndex(std::fabs(x - r) < 1e-9 ? r : std::floor(x) + 1);
        };
        return Coord(c(v.x()), c(v.y()), c(v.z()));
    }

    // Calls fn(leaf, lo, hi) for each leaf-sized cube (origin `leaf`) the box [base, end) meets,
    // with the box's part in it, [lo, hi).
    template <typename Fn>
    static void forEachLeafPart(const Coord& base, const Coord& end, Fn&& fn) {
        for (int cz = base.z() & ~7; cz < end.z(); cz += 8)
            for (int cy = base.y() & ~7; cy < end.y(); cy += 8)
                for (int cx = base.x() & ~7; cx < end.x(); cx += 8)
                    fn(Coord(cx, cy, cz), Coord(std::max(cx, base.x()), std::max(cy, base.y()), std::max(cz, base.z())),
                       Coord(std::min(cx + 8, end.x()), std::min(cy + 8, end.y()), std::min(cz + 8, end.z())));
    }

    // row[i] = column[64 i] for i < n, 1 <= n <= 8: one row along x of a leaf's buffer.
    template <typename InT, typename OutT>
    static void copyStrided(const InT* column, OutT* row, int n) {
        switch (n) {
        case 8: row[7] = OutT(column[7 << 6]); [[fallthrough]];
        case 7: row[6] = OutT(column[6 << 6]); [[fallthrough]];
        case 6: row[5] = OutT(column[5 << 6]); [[fallthrough]];
        case 5: row[4] = OutT(column[4 << 6]); [[fallthrough]];
        case 4: row[3] = OutT(column[3 << 6]); [[fallthrough]];
        case 3: row[2] = OutT(column[2 << 6]); [[fallthrough]];
        case 2: row[1] = OutT(column[1 << 6]); [[fallthrough]];
        case 1: row[0] = OutT(column[0]); break;
        default: break;
        }
    }

    // Every voxel of the box [base, base + dims), x fastest, leaf by leaf: one probe per leaf the
    // box touches and direct reads of its buffer, instead of an accessor lookup per voxel.
    template <typename OutT>
    void sampleBlock(Acc& acc, const Coord& base, const Vec3i& dims, OutT* out) const {
        auto at = [&](int x, int y, int z) -> OutT& {
            return out[(std::size_t(z - base.z()) * std::size_t(dims.y) + std::size_t(y - base.y())) * std::size_t(dims.x) +
                       std::size_t(x - base.x())];
        };
        forEachLeafPart(base, base.offsetBy(dims.x, dims.y, dims.z), [&](const Coord& leafOrigin, const Coord& lo, const Coord& hi) {
            if (const LeafT* leaf = acc.probeConstLeaf(leafOrigin)) {
                const auto* data = leaf->buffer().data();
                // A row along x at a time: x strides the leaf's buffer by 64, the output by 1. Rows
                // hold 1 to 8 values: copied straight, without the vector loop (and its set-up for
                // gathering strided values) the compiler makes of a loop of unknown length, which
                // cost twice the instructions.
                const int n = hi.x() - lo.x();
                const std::size_t rowStep = std::size_t(dims.x), planeStep = std::size_t(dims.x) * std::size_t(dims.y);
                OutT* plane = &at(lo.x(), lo.y(), lo.z());
                const auto* first = data + (((lo.x() & 7) << 6) | ((lo.y() & 7) << 3) | (lo.z() & 7));
                for (int z = lo.z(); z < hi.z(); ++z, plane += planeStep, ++first) {
                    OutT* row = plane;
                    const auto* column = first;
                    for (int y = lo.y(); y < hi.y(); ++y, row += rowStep, column += 8) copyStrided(column, row, n);
                }
            } else {
                const OutT v = OutT(acc.getValue(leafOrigin));
                for (int z = lo.z(); z < hi.z(); ++z)
                    for (int y = lo.y(); y < hi.y(); ++y)
                        for (int x = lo.x(); x < hi.x(); ++x) at(x, y, z) = v;
            }
        });
    }

    // sampleBlock of the N^3 voxels from base (N = 2 or 3): where they lie in one leaf, read from
    // its buffer after one probe, without sampleBlock's walk over leaf parts.
    template <int N, typename OutT>
    void smallBlock(Acc& acc, const Coord& base, OutT* out) const {
        const int x = base.x() & 7, y = base.y() & 7, z = base.z() & 7;
        if (x <= 8 - N && y <= 8 - N && z <= 8 - N) {
            if (const LeafT* leaf = acc.probeConstLeaf(base)) {
                const auto* first = leaf->buffer().data() + ((x << 6) | (y << 3) | z);
                for (int k = 0; k < N; ++k)
                    for (int j = 0; j < N; ++j)
                        for (int i = 0; i < N; ++i) out[(k * N + j) * N + i] = OutT(first[(i << 6) | (j << 3) | k]);
                return;
            }
        }
        sampleBlock(acc, base, {N, N, N}, out);
    }

    // Bit z of column[x * 9 + y]: is voxel base + (x, y, z) active (or in an active tile), for
    // x, y, z in 0 .. 8. A leaf's mask holds, in word x, byte y, its eight voxels along z.
    void activeColumns(Acc& acc, const Coord& base, std::array<std::uint16_t, 81>& column) const {
        forEachLeafPart(base, base.offsetBy(9), [&](const Coord& leafOrigin, const Coord& lo, const Coord& hi) {
            // Bits lo.z .. hi.z - 1 of the leaf, moved to column positions z - base.z.
            const int lz = leafOrigin.z();
            const unsigned zBits = (0xFFu << (lo.z() - lz)) & (0xFFu >> (8 - (hi.z() - lz)));
            const int shift = lz - base.z();
            auto put = [&](int x, int y, unsigned bits) {
                column[std::size_t((x - base.x()) * 9 + (y - base.y()))] |= std::uint16_t(shift >= 0 ? bits << shift : bits >> -shift);
            };
            if (const LeafT* leaf = acc.probeConstLeaf(leafOrigin)) {
                const auto& mask = leaf->getValueMask();
                for (int x = lo.x(); x < hi.x(); ++x) {
                    const std::uint64_t word = mask.template getWord<std::uint64_t>(openvdb::Index(x & 7));
                    for (int y = lo.y(); y < hi.y(); ++y) put(x, y, unsigned(word >> (8 * (y & 7))) & zBits);
                }
            } else if (acc.isValueOn(leafOrigin)) {
                for (int x = lo.x(); x < hi.x(); ++x)
                    for (int y = lo.y(); y < hi.y(); ++y) put(x, y, zBits);
            }
        });
    }

    // Is any voxel of the box active, or in an active tile? A box of a few leaves (a cell's support
    // on a lattice near the voxel size) goes through the caller's accessor, which keeps the last
    // leaf; a larger one walks the tree from the root, skipping tiles whole.
    bool anyActive(Acc& acc, const CoordBBox& box) const {
        const Coord lo = box.min() & ~7, hi = box.max() & ~7;
        if (hi.x() - lo.x() > 24 || hi.y() - lo.y() > 24 || hi.z() - lo.z() > 24) return anyActiveFromRoot(box);
        for (int x = lo.x(); x <= hi.x(); x += 8)
            for (int y = lo.y(); y <= hi.y(); y += 8)
                for (int z = lo.z(); z <= hi.z(); z += 8) {
                    const Coord c(x, y, z);
                    if (const LeafT* leaf = acc.probeConstLeaf(c)) {
                        if (anyActiveInLeaf(*leaf, box)) return true;
                    } else if (acc.isValueOn(c)) {
                        return true;
                    }
                }
        return false;
    }

    bool anyActiveFromRoot(const CoordBBox& box) const {
        const RootT& root = mTree.root();
        for (auto it = root.cbeginValueOn(); it; ++it)
            if (CoordBBox::createCube(it.getCoord(), int(Node2T::DIM)).hasOverlap(box)) return true;
        for (auto it = root.cbeginChildOn(); it; ++it)
            if (it->getNodeBoundingBox().hasOverlap(box) && anyActiveInNode(*it, box)) return true;
        return false;
    }

    template <typename NodeT>
    bool anyActiveInNode(const NodeT& node, const CoordBBox& box) const {
        return anySlotIn(node, box, [&](openvdb::Index n) {
            if (!node.isChildMaskOn(n)) return node.isValueMaskOn(n);
            const auto& child = *node.getTable()[n].getChild();
            if constexpr (std::is_same<typename NodeT::ChildNodeType, LeafT>::value) return anyActiveInLeaf(child, box);
            else return anyActiveInNode(child, box);
        });
    }

    // A leaf's value mask holds, in word x, byte y, the eight voxels along z.
    static bool anyActiveInLeaf(const LeafT& leaf, const CoordBBox& box) {
        CoordBBox in = leaf.getNodeBoundingBox();
        in.intersect(box);
        if (in.empty()) return false;
        const std::uint64_t zBits = (0xFFu << (in.min().z() & 7)) & (0xFFu >> (7 - (in.max().z() & 7)));
        const auto& mask = leaf.getValueMask();
        for (int x = in.min().x(); x <= in.max().x(); ++x) {
            const std::uint64_t word = mask.template getWord<std::uint64_t>(openvdb::Index(x & 7));
            for (int y = in.min().y(); y <= in.max().y(); ++y)
                if ((word >> (8 * (y & 7))) & zBits) return true;
        }
        return false;
    }

    // Where values other than the background are stored (for bounds()), and where the grid's
    // data is (the domain): its active voxels and active tiles. Inactive values are the fill
    // between them: a level set's signed flood fill writes them, and where its band is open (a
    // terrain or an ocean surface, a band clipped by a box) the fill's inside voxels and tiles
    // run on beyond it, for thousands of voxels in tiles. Their faces against the background
    // are no surface the grid holds (volumeToMesh meshes none of them either), and a domain
    // stretched over them made the lattice too large to mesh at all. The trilinear support
    // reaches one voxel beyond the data, where a fog's density may still be above the iso value
    // at its last voxel (so every grid but a level set keeps that voxel); a level set's narrow
    // band holds its surface, and in that voxel a band that ends open has the fill's values,
    // which put a skirt along its edge (up to 22 voxels off a terrain's sheet).
    void computeDomain(const std::string& label) {
        CoordBBox data = mRanges->activeTiles();
        data.expand(mRanges->leafActive());
        const MinMax& all = mRanges->all();
        if (data.empty() || (all.lo == all.hi && mGrid->activeVoxelCount() == 0))
            throw Error(label, "is empty (no active voxels or tiles)");
        if (mGrid->getGridClass() != openvdb::GRID_LEVEL_SET) data.expand(1);
        const openvdb::BBoxd wb = mGrid->transform().indexToWorld(CoordBBox(data.min(), data.max()));
        mDomain = {toVec(wb.min()), toVec(wb.max())};
    }

    // Min/max of every value in the index box, from cached node summaries where a node lies
    // wholly inside the box.
    void query(const CoordBBox& box, MinMax& mm) const {
        RangeOf collect{mm};
        mRanges->visit(box, collect);
    }

    // straddles(range of query(box), iso), the same answer sooner: it stops at the first proof (a
    // range only widens as voxels are added, and straddles() widens with it), and a node the box
    // covers in part counts with its whole range where that range lies on one side of iso by more
    // than any range of this grid's values widens the test (its part then lies on that side too,
    // and adds nothing the whole does not). A lattice's leaf blocks are mostly clear of the surface,
    // and a block at the grid's voxel size reads a one-voxel slab of seven neighbouring leaves:
    // those reads were a tenth of marching cubes' time on the armadillo.
    bool queryStraddles(const CoordBBox& box, double iso) const {
        StraddleOf q{iso, boundsTolerance(valueRange(), iso), {}};
        return mRanges->visit(box, q) || q.straddles();
    }

    typename GridT::ConstPtr mGrid;
    const TreeT& mTree;
    // The grid's map, held by its transform for mGrid's life. Read through this pointer:
    // transform().baseMap() returns a shared_ptr copy, whose reference count two threads asking
    // for gradients at once bounce between their cores.
    const openvdb::math::MapBase* mMap;
    bool mAxisAligned = false;
    double mVoxel = 1.0;
    Vec3d mOrigin;
    std::optional<TreeRanges<TreeT>> mRanges;
    Box3 mDomain;
};

} // namespace

GridField::GridField(GridBaseCPtr grid, std::string label, std::optional<Inside> inside) : mLabel(std::move(label)) {
    if (!grid) throw Error(mLabel, "no grid");
    const openvdb::math::MapBase& map = *grid->transform().baseMap();
    const bool frustum = map.isType<openvdb::math::NonlinearFrustumMap>();
    if (!frustum && !map.isLinear())
        throw Error(mLabel, "has a non-linear transform of type " + map.type() + "; vdbsurf samples linear and frustum transforms");
    double background = 0;
    if (auto f = openvdb::GridBase::constGrid<openvdb::FloatGrid>(grid)) {
        if (!frustum) mImpl = std::make_unique<TypedGrid<openvdb::FloatGrid>>(f, mLabel);
        background = double(f->background());
    } else if (auto d = openvdb::GridBase::constGrid<openvdb::DoubleGrid>(grid)) {
        if (!frustum) mImpl = std::make_unique<TypedGrid<openvdb::DoubleGrid>>(d, mLabel);
        background = d->background();
    } else {
        throw Error(mLabel, "holds " + grid->valueType() + " values; vdbsurf meshes float or double grids");
    }
    switch (grid->getGridClass()) {
    case openvdb::GRID_LEVEL_SET:
        mClass = "level set";
        mInside = Inside::Below;
        mInsideReason = "level set: inside is below the iso value";
        break;
    case openvdb::GRID_FOG_VOLUME:
        mClass = "fog";
        mInside = Inside::Above;
        mInsideReason = "fog volume: inside is above the iso value";
        break;
    default:
        mClass = "unknown";
        mInside = background > 0 ? Inside::Below : Inside::Above;
        mInsideReason = background > 0 ? "class unknown, background > 0: treated as a signed distance (inside below iso)"
                                        : "class unknown, background <= 0: treated as a density (inside above iso)";
    }
    if (inside) {
        mInside = *inside;
        mInsideReason = *inside == Inside::Below ? "inside below the iso value (--inside below)" : "inside above the iso value (--inside above)";
    }
    if (frustum || !mImpl->axisAligned()) {
        // Meshed in its own frame: its index space under a uniform scale s (frame point p is index
        // point p / s), s its smallest voxel size, so that a lattice at that spacing is its voxels
        // (as volumeToMesh meshes in index space); the mesh then goes to world, through a frustum
        // point by point. The frame's transform must be one OpenVDB stores: voxels smaller than
        // that count in the smallest it stores.
        const double smallest = frustum ? smallestFrustumVoxel(*grid) : mImpl->voxelSize();
        const double s = std::max(smallest, smallestStorableVoxelSize());
        auto own = std::make_unique<OwnFrame>();
        auto framed = std::make_shared<GridField>(grid->copyGridReplacingTransform(voxelTransform(s, mLabel)), mLabel, mInside);
        own->field = framed;
        if (frustum) {
            mImpl = makeFrustumGrid(grid, std::move(framed), s, mLabel, own->curved);
            own->spacingNote = "a frustum grid: measured where its voxels are smallest, the lattice widens with them";
        } else {
            const openvdb::Mat4d m = grid->transform().baseMap()->getAffineMap()->getConstMat4();
            // OpenVDB's matrices act on row vectors: world = index * m.
            for (int r = 0; r < 3; ++r)
                for (int c = 0; c < 3; ++c) own->toWorld.a[r][c] = m(c, r) / s;
            own->toWorld.t = Vec3d(m(3, 0), m(3, 1), m(3, 2));
        }
        if (s > smallest)
            own->spacingNote = std::string(frustum ? "a frustum grid whose" : "the grid's") + " smallest voxels (" + messageNumber(smallest) +
                               ") are below what OpenVDB stores: a spacing H is H / " + messageNumber(s) + " of its voxels" +
                               (frustum ? ", the lattice widens with them" : "");
        mOwnFrame = std::move(own);
    }
}

GridField::~GridField() = default;

double GridField::value(const Vec3d& p) const { return mImpl->value(p); }
Vec3d GridField::gradient(const Vec3d& p) const { return mImpl->gradient(p); }
double GridField::valueAndGradient(const Vec3d& p, Vec3d& gradient) const { return mImpl->valueAndGradient(p, gradient); }
Interval GridField::bounds(const Box3& box) const { return mImpl->bounds(box); }
bool GridField::mayStraddle(const Box3& box, double iso) const { return mImpl->mayStraddle(box, iso); }
void GridField::values(const Box3& box, const Vec3d* points, std::size_t n, double* out) const {
    if (!mImpl->values(box, points, n, out)) Field::values(box, points, n, out);
}
Box3 GridField::domain() const { return mImpl->domain(); }
std::optional<double> GridField::naturalSpacing() const {
    // Where the grid has its own frame, a spacing counts in the frame's units.
    return mOwnFrame ? mOwnFrame->field->naturalSpacing() : std::optional<double>(mImpl->voxelSize());
}
LatticeFrame GridField::naturalFrame(double h) const { return mImpl->naturalFrame(h); }
Interval GridField::valueRange() const { return mImpl->valueRange(); }
GridBaseCPtr GridField::grid() const { return mImpl->grid(); }

void GridField::sampleNodes(const LatticeFrame& frame, const Vec3i& first, const Vec3i& dims, const std::uint8_t* needed,
                            double* out) const {
    if (!mImpl->sampleNodes(frame, first, dims, needed, out)) Field::sampleNodes(frame, first, dims, needed, out);
}

bool GridField::cellBoundsAreCornerRange(const LatticeFrame& frame) const { return mImpl->cellsInsideVoxelCells(frame); }

void GridField::dropCellsWithoutData(const LatticeFrame& frame, const Vec3i& first, std::uint64_t* cells) const {
    mImpl->dropCellsWithoutData(frame, first, cells);
}

void GridField::pointsWithData(const Vec3f* points, std::size_t n, std::uint8_t* out) const {
    mImpl->pointsWithData(points, n, out);
}

bool GridField::edgesAreLinear(const LatticeFrame& frame) const {
    int stride = 0;
    Coord offset;
    return mImpl->directStride(frame, stride, offset) && stride == 1;
}

double GridField::edgeCrossing(const Vec3d& a, const Vec3d& b, double va, double vb, double iso) const {
    double t = 0;
    if (mImpl->piecewiseLinearCrossing(a, b, iso, mInside, t)) return t;
    return refineCrossing(*this, a, b, va, vb, iso);
}

} // namespace vdbsurf
