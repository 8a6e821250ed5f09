#include "vdbsurf/density/primitive_index.h"

#include <algorithm>
#include <cmath>

namespace vdbsurf {

namespace {
constexpr std::size_t kMinPrimitives = 16; // below this a scan costs less than a lookup
constexpr int kMaxDims = 256;
} // namespace

int PrimitiveIndex::cellIndex(double v, int axis) const {
    // Monotone in v (IEEE subtraction, division and floor are), clamped to the grid.
    const double c = std::floor((v - mOrigin[std::size_t(axis)]) / mCell);
    if (!(c >= 0)) return 0; // also NaN
    return c >= mDims[axis] ? mDims[axis] - 1 : int(c);
}

PrimitiveIndex::PrimitiveIndex(const std::vector<Box3>& boxes, bool grid) : mAll(boxes.size()) {
    for (std::uint32_t i = 0; i < mAll.size(); ++i) mAll[i] = i;
    if (!grid || boxes.size() < kMinPrimitives) return;
    Box3 all = boxes.front();
    std::vector<double> sizes;
    sizes.reserve(boxes.size());
    for (const Box3& b : boxes) {
        all = {vmin(all.min, b.min), vmax(all.max, b.max)};
        const Vec3d e = b.extent();
        sizes.push_back(std::max({e.x, e.y, e.z}));
    }
    // Cells about the size of a typical primitive (each then sits in a few), but no more than
    // about 8 a primitive and 256 along an axis.
    std::nth_element(sizes.begin(), sizes.begin() + std::ptrdiff_t(sizes.size() / 2), sizes.end());
    const Vec3d extent = all.extent();
    const double volume = std::max(extent.x, 1e-300) * std::max(extent.y, 1e-300) * std::max(extent.z, 1e-300);
    double cell = std::max({sizes[sizes.size() / 2], std::cbrt(volume / (8.0 * double(boxes.size()))),
                            std::max({extent.x, extent.y, extent.z}) / kMaxDims});
    if (!(cell > 0) || !std::isfinite(cell)) return;
    mOrigin = all.min;
    mCell = cell;
    for (int a = 0; a < 3; ++a) mDims[a] = std::max(1, std::min(kMaxDims, int(std::ceil(extent[std::size_t(a)] / cell)) + 1));
    const std::size_t cells = std::size_t(mDims[0]) * std::size_t(mDims[1]) * std::size_t(mDims[2]);

    // Counting pass, then filling: lists come out ascending because primitives are added in order.
    std::vector<std::uint32_t> counts(cells + 1, 0);
    std::size_t entries = 0;
    auto forCells = [&](const Box3& b, auto&& f) {
        const int x0 = cellIndex(b.min.x, 0), x1 = cellIndex(b.max.x, 0), y0 = cellIndex(b.min.y, 1), y1 = cellIndex(b.max.y, 1);
        const int z0 = cellIndex(b.min.z, 2), z1 = cellIndex(b.max.z, 2);
        for (int z = z0; z <= z1; ++z)
            for (int y = y0; y <= y1; ++y)
                for (int x = x0; x <= x1; ++x) f((std::size_t(z) * std::size_t(mDims[1]) + std::size_t(y)) * std::size_t(mDims[0]) + std::size_t(x));
    };
    for (const Box3& b : boxes) forCells(b, [&](std::size_t c) {
            ++counts[c];
            ++entries;
        });
    // Lists that would hold most of the scene each (boxes spanning the grid) save nothing.
    if (entries > 64 * boxes.size() || entries > (std::size_t(1) << 31)) {
        mDims[0] = mDims[1] = mDims[2] = 0;
        return;
    }
    mOffsets.assign(cells + 1, 0);
    for (std::size_t c = 0; c < cells; ++c) mOffsets[c + 1] = mOffsets[c] + counts[c];
    mEntries.resize(entries);
    std::vector<std::uint32_t> fill(mOffsets.begin(), mOffsets.end() - 1);
    for (std::uint32_t i = 0; i < boxes.size(); ++i) forCells(boxes[i], [&](std::size_t c) { mEntries[fill[c]++] = i; });
}

const std::uint32_t* PrimitiveIndex::at(const Vec3d& p, std::size_t& count) const {
    if (!active()) {
        count = mAll.size();
        return mAll.data();
    }
    count = 0;
    for (std::size_t a = 0; a < 3; ++a) // outside the grid no influence box holds p
        if (!(p[a] >= mOrigin[a] && p[a] <= mOrigin[a] + mCell * mDims[a])) return nullptr;
    const std::size_t c =
        (std::size_t(cellIndex(p.z, 2)) * std::size_t(mDims[1]) + std::size_t(cellIndex(p.y, 1))) * std::size_t(mDims[0]) +
        std::size_t(cellIndex(p.x, 0));
    count = mOffsets[c + 1] - mOffsets[c];
    return mEntries.data() + mOffsets[c];
}

void PrimitiveIndex::over(const Box3& box, std::vector<std::uint32_t>& out) const {
    out.clear();
    if (!active()) {
        out = mAll;
        return;
    }
    const int x0 = cellIndex(box.min.x, 0), x1 = cellIndex(box.max.x, 0), y0 = cellIndex(box.min.y, 1), y1 = cellIndex(box.max.y, 1);
    const int z0 = cellIndex(box.min.z, 2), z1 = cellIndex(box.max.z, 2);
    std::size_t listed = 0;
    for (int z = z0; z <= z1; ++z)
        for (int y = y0; y <= y1; ++y) {
            const std::size_t row = (std::size_t(z) * std::size_t(mDims[1]) + std::size_t(y)) * std::size_t(mDims[0]);
            listed += mOffsets[row + std::size_t(x1) + 1] - mOffsets[row + std::size_t(x0)];
        }
    if (listed > mAll.size() / 2) { // gathering and sorting would cost more than a scan
        out = mAll;
        return;
    }
    out.reserve(listed);
    for (int z = z0; z <= z1; ++z)
        for (int y = y0; y <= y1; ++y) {
            const std::size_t row = (std::size_t(z) * std::size_t(mDims[1]) + std::size_t(y)) * std::size_t(mDims[0]);
            out.insert(out.end(), mEntries.begin() + mOffsets[row + std::size_t(x0)], mEntries.begin() + mOffsets[row + std::size_t(x1) + 1]);
        }
    if (z1 > z0 || y1 > y0 || x1 > x0) {
        std::sort(out.begin(), out.end());
        out.erase(std::unique(out.begin(), out.end()), out.end());
    }
}

} // namespace vdbsurf
