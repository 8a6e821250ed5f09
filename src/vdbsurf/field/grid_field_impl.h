// GridField's type-erased grid access, private to the field module: one implementation per
// value type for grids with linear transforms (grid_field.cpp), and one for frustum grids
// (frustum_grid.cpp), which answers in world space through the grid's own frame.
#pragma once
#include "vdbsurf/field/grid_field.h"

#include <openvdb/math/Coord.h>
#include <openvdb/math/Vec3.h>

#include <cstdint>
#include <memory>

namespace vdbsurf {

// Between vdbsurf's vectors and OpenVDB's.
inline Vec3d toVec(const openvdb::math::Vec3d& v) { return {v.x(), v.y(), v.z()}; }
inline openvdb::math::Vec3d toVdb(const Vec3d& v) { return {v.x, v.y, v.z}; }

struct GridField::Impl {
    virtual ~Impl() = default;
    virtual double value(const Vec3d& p) const = 0;
    virtual Vec3d gradient(const Vec3d& p) const = 0;
    virtual double valueAndGradient(const Vec3d& p, Vec3d& gradient) const = 0;
    // values() and sampleNodes() return false, writing nothing, where they have no faster way than
    // value() a point: GridField then takes Field's, which asks value().
    virtual bool values(const Box3& box, const Vec3d* points, std::size_t n, double* out) const = 0;
    virtual Interval bounds(const Box3& box) const = 0;
    virtual bool mayStraddle(const Box3& box, double iso) const = 0;
    virtual Box3 domain() const = 0;
    virtual Interval valueRange() const = 0;
    virtual double voxelSize() const = 0;
    virtual bool axisAligned() const = 0;
    virtual LatticeFrame naturalFrame(double h) const = 0;
    virtual bool sampleNodes(const LatticeFrame& frame, const Vec3i& first, const Vec3i& dims,
                             const std::uint8_t* needed, double* out) const = 0;
    virtual bool directStride(const LatticeFrame& frame, int& stride, openvdb::math::Coord& offset) const = 0;
    virtual bool cellsInsideVoxelCells(const LatticeFrame& frame) const = 0;
    virtual void dropCellsWithoutData(const LatticeFrame& frame, const Vec3i& first, std::uint64_t* cells) const = 0;
    virtual void pointsWithData(const Vec3f* points, std::size_t n, std::uint8_t* out) const = 0;
    virtual bool piecewiseLinearCrossing(const Vec3d& a, const Vec3d& b, double iso, Inside side, double& t) const = 0;
    virtual GridBaseCPtr grid() const = 0;
};

// A frustum grid (its transform a NonlinearFrustumMap): `frame` is the same tree in index space
// scaled by `frameVoxel` (GridField's own frame), `grid` the grid as read. Sets `curved` to the
// frame's map to world. Throws Error naming `label` when the grid's data reaches behind the
// frustum's apex, where the map has no inverse.
std::unique_ptr<GridField::Impl> makeFrustumGrid(GridBaseCPtr grid, std::shared_ptr<const GridField> frame, double frameVoxel,
                                                 const std::string& label, std::shared_ptr<const CurvedFrameMap>& curved);

// The smallest side of a frustum grid's voxels over its frustum (at a corner of its index box,
// where the frustum is narrowest).
double smallestFrustumVoxel(const openvdb::GridBase& grid);

} // namespace vdbsurf
