// Which primitives of a scene can matter at a point or over a box, without asking all of them:
// a uniform grid of cells over the primitives' influence boxes, each cell listing (ascending)
// the primitives whose influence box overlaps it. A scene of thousands of blobs (a particle
// system turned metaballs) is evaluated millions of times by the mesher and the rasterizer;
// each evaluation then visits the few primitives near it instead of all of them.
//
// Exact by construction: a primitive's density is exactly 0 outside its influence box, and a
// cell's index is a monotone function of the coordinate, so every primitive whose box holds a
// point (or meets a box) is listed in the point's cell (or one of the box's cells); visiting
// the candidates in ascending order gives bit for bit what visiting every primitive gives.
#pragma once
#include "vdbsurf/core/vec3.h"

#include <cstdint>
#include <vector>

namespace vdbsurf {

class PrimitiveIndex {
public:
    PrimitiveIndex() = default;
    // With `grid` false, or few primitives, or boxes that overlap so much that lists would not
    // be shorter than the scene, no grid is built and every query answers "all".
    explicit PrimitiveIndex(const std::vector<Box3>& influenceBoxes, bool grid = true);

    bool active() const { return !mOffsets.empty(); } // a grid was built

    // Candidates at p: a pointer to `count` ascending indices (none outside every box).
    const std::uint32_t* at(const Vec3d& p, std::size_t& count) const;
    // Candidates over a box, ascending and without repeats, into out: every primitive when the
    // box spans so many cells that gathering them would cost more than a scan.
    void over(const Box3& box, std::vector<std::uint32_t>& out) const;

private:
    int cellIndex(double v, int axis) const;
    Vec3d mOrigin;
    double mCell = 0;
    int mDims[3] = {0, 0, 0};
    std::vector<std::uint32_t> mOffsets; // per cell (x fastest), into mEntries; one more at the end
    std::vector<std::uint32_t> mEntries;
    std::vector<std::uint32_t> mAll; // 0 … n − 1: the answer without a grid
};

} // namespace vdbsurf
