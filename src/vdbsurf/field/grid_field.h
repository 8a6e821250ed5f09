// GridField: an OpenVDB float or double grid as a Field, sampled trilinearly in world space
// through the grid's transform (any linear map, or a camera frustum's: frustum_grid.cpp). Bounds over a box come from per-node min/max
// of every stored value (active, inactive, tiles, background), so they are exact for the
// trilinear interpolant's support and cost O(tree depth) per query.
#pragma once
#include "vdbsurf/field/field.h"
#include "vdbsurf/vdb/openvdb_fwd.h"

#include <memory>
#include <optional>

namespace vdbsurf {

class GridField final : public Field {
public:
    // Throws Error naming `label` when the grid is not float/double, holds NaN or infinity, is
    // empty, or has a transform vdbsurf cannot sample. inside: override of the class-based rule.
    GridField(GridBaseCPtr grid, std::string label, std::optional<Inside> inside = std::nullopt);
    ~GridField() override;

    double value(const Vec3d& p) const override;
    Vec3d gradient(const Vec3d& p) const override;
    double valueAndGradient(const Vec3d& p, Vec3d& gradient) const override;
    Interval bounds(const Box3& box) const override;
    bool mayStraddle(const Box3& box, double iso) const override;
    void values(const Box3& box, const Vec3d* points, std::size_t n, double* out) const override;
    Inside inside() const override { return mInside; }
    Box3 domain() const override;
    std::string describe() const override { return mLabel; }
    std::optional<double> naturalSpacing() const override;
    std::optional<double> sampleSpacing() const override { return naturalSpacing(); }
    LatticeFrame naturalFrame(double h) const override;
    // Where the grid's axes are not world's (rotated, mirrored, sheared or unequal voxels, or a
    // frustum): the grid in index space scaled by its smallest voxel size, so that a lattice at
    // that spacing is its voxels, and the map back to world.
    const OwnFrame* ownFrame() const override { return mOwnFrame.get(); }
    void sampleNodes(const LatticeFrame& frame, const Vec3i& first, const Vec3i& dims, const std::uint8_t* needed,
                     double* out) const override;
    bool cellBoundsAreCornerRange(const LatticeFrame& frame) const override;
    void dropCellsWithoutData(const LatticeFrame& frame, const Vec3i& first, std::uint64_t* cells) const override;
    void pointsWithData(const Vec3f* points, std::size_t n, std::uint8_t* out) const override;
    bool edgesAreLinear(const LatticeFrame& frame) const override;
    double edgeCrossing(const Vec3d& a, const Vec3d& b, double va, double vb, double iso) const override;

    // "level set", "fog" or "unknown", and why inside() is what it is.
    const std::string& gridClass() const { return mClass; }
    const std::string& insideReason() const { return mInsideReason; }
    // Smallest and largest value stored anywhere in the grid (background included).
    Interval valueRange() const;
    GridBaseCPtr grid() const;

    struct Impl;

private:
    std::unique_ptr<Impl> mImpl;
    std::unique_ptr<OwnFrame> mOwnFrame;
    std::string mLabel, mClass, mInsideReason;
    Inside mInside = Inside::Below;
};

} // namespace vdbsurf
