// A frustum grid as GridField sees it in world space. Its voxels are the cells of a camera's
// frustum: index space goes to world through a perspective map (OpenVDB's NonlinearFrustumMap),
// which no lattice in world follows. GridField meshes it in its own frame (the tree in index
// space, scaled by its smallest voxel or the smallest OpenVDB stores) and maps the mesh through
// the frustum; this file answers the world-space questions — values and gradients where
// `compare` measures a mesh, bounds over world boxes — through that frame, and holds the map
// itself (CurvedFrameMap).
//
// The map's inverse is projective (x and y divided by a linear function of depth), so over the
// half-space in front of the frustum's apex it takes segments to segments and a box to a convex
// polytope whose corners are the box's corners' images: their bounding box bounds the preimage.
// Behind the apex (where the camera is) no voxel maps; the field is the background there.
#include "vdbsurf/field/grid_field_impl.h"

#include "vdbsurf/core/error.h"
#include "vdbsurf/vdb/voxel_transform.h"

#include <openvdb/openvdb.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace vdbsurf {

namespace {

using openvdb::math::NonlinearFrustumMap;

// Points whose depth factor (the frustum's scale across its axis, relative to the near plane's)
// is below this are taken as behind the apex: their preimage is a voxel thousands of times wider
// than the near plane's, or none.
constexpr double kSmallestDepthFactor = 1e-6;

// The frustum and its frame: frame point q is index point q / frameVoxel.
class Frustum {
public:
    Frustum(const NonlinearFrustumMap& map, double frameVoxel)
        : mMap(map), mS(frameVoxel), mGamma((1.0 / map.getTaper() - 1.0) / map.getDepth()),
          mDepthOnLz(map.getDepth() / map.getBBox().extents().z()) {}

    const NonlinearFrustumMap& map() const { return mMap; }
    double frameVoxel() const { return mS; }

    // (γ z' + 1) for index depth z: positive in front of the apex, 1 at the index box's near face.
    double depthFactorAtIndexZ(double z) const { return mGamma * (z - mMap.getBBox().min().z()) * mDepthOnLz + 1.0; }
    double depthFactorAtWorld(const Vec3d& p) const {
        return mGamma * mMap.secondMap().applyInverseMap(toVdb(p)).z() + 1.0;
    }

    Vec3d toWorld(const Vec3d& q) const { return toVec(mMap.applyMap(toVdb(q / mS))); }
    // The frame point of world point p, or false where p lies behind the apex.
    bool toFrame(const Vec3d& p, Vec3d& q) const {
        if (!(depthFactorAtWorld(p) > kSmallestDepthFactor)) return false;
        q = toVec(mMap.applyInverseMap(toVdb(p))) * mS;
        return std::isfinite(q.x) && std::isfinite(q.y) && std::isfinite(q.z);
    }
    // d(value)/d(world) from the gradient in frame coordinates at frame point q.
    Vec3d gradientToWorld(const Vec3d& frameGradient, const Vec3d& q) const {
        return toVec(mMap.applyIJT(toVdb(frameGradient * mS), toVdb(q / mS)));
    }

private:
    NonlinearFrustumMap mMap;
    double mS, mGamma, mDepthOnLz;
};

class FrustumFrameMap final : public CurvedFrameMap {
public:
    explicit FrustumFrameMap(const Frustum& f) : mF(f) {}
    Vec3d apply(const Vec3d& p) const override { return mF.toWorld(p); }
    // The frustum's own part keeps orientation (its Jacobian's determinant is the square of the
    // depth factor times positive lengths); the second, affine map may mirror.
    bool mirrors() const override { return mF.map().secondMap().determinant() < 0; }

    // Lattice node i is at index point a + b i (a = origin / s, b = h / s); a frustum whose
    // index box is the grid's, moved and scaled the same way, puts it where this map does.
    std::shared_ptr<openvdb::math::Transform> latticeTransform(const LatticeFrame& frame, const std::string& what) const override {
        const double b = frame.h / mF.frameVoxel();
        const openvdb::Vec3d a = toVdb(frame.origin / mF.frameVoxel());
        const openvdb::BBoxd& box = mF.map().getBBox();
        const openvdb::BBoxd lattice((box.min() - a) / b, (box.max() - a) / b);
        if (!(lattice.extents().x() >= 1 && lattice.extents().y() >= 1 && lattice.extents().z() >= 1))
            throw Error(what, "a lattice spacing of " + messageNumber(frame.h) + " leaves the frustum less than two lattice nodes deep "
                                                                            "or wide; OpenVDB cannot store such a frustum transform");
        const auto second = std::make_shared<openvdb::math::AffineMap>(mF.map().secondMap());
        return std::make_shared<openvdb::math::Transform>(
            std::make_shared<NonlinearFrustumMap>(lattice, mF.map().getTaper(), mF.map().getDepth(), second));
    }

private:
    Frustum mF;
};

class FrustumGrid final : public GridField::Impl {
public:
    FrustumGrid(GridBaseCPtr grid, std::shared_ptr<const GridField> frame, const Frustum& frustum, const std::string& label)
        : mGrid(std::move(grid)), mFrame(std::move(frame)), mF(frustum) {
        // The data's depth range must lie in front of the apex, or part of it has no place in world.
        const Box3 fd = mFrame->domain();
        for (const double z : {fd.min.z, fd.max.z})
            if (!(mF.depthFactorAtIndexZ(z / mF.frameVoxel()) > kSmallestDepthFactor))
                throw Error(label, "has data at index depth " + messageNumber(z / mF.frameVoxel()) +
                                       ", at or behind its frustum's apex (the camera), where its transform maps no voxel");
        Vec3d corners[8];
        for (int c = 0; c < 8; ++c) corners[c] = mF.toWorld(fd.corner(c));
        mDomain = Box3::around(corners, 8);
        // The corners' images carry the map's rounding: the box is widened past it.
        const Vec3d pad = mDomain.extent() * 1e-9 + (abs(mDomain.min) + abs(mDomain.max)) * 1e-12;
        mDomain = {mDomain.min - pad, mDomain.max + pad};
        if (auto f = openvdb::GridBase::constGrid<openvdb::FloatGrid>(mGrid)) mOutside = double(f->background());
        if (auto g = openvdb::GridBase::constGrid<openvdb::DoubleGrid>(mGrid)) mOutside = g->background();
    }

    double value(const Vec3d& p) const override {
        Vec3d q;
        return mF.toFrame(p, q) ? mFrame->value(q) : mOutside;
    }
    Vec3d gradient(const Vec3d& p) const override {
        Vec3d g;
        valueAndGradient(p, g);
        return g;
    }
    double valueAndGradient(const Vec3d& p, Vec3d& gradient) const override {
        Vec3d q;
        if (!mF.toFrame(p, q)) {
            gradient = Vec3d(0, 0, 0);
            return mOutside;
        }
        Vec3d gq;
        const double v = mFrame->valueAndGradient(q, gq);
        gradient = mF.gradientToWorld(gq, q);
        return v;
    }
    // No faster way than value() a point through the frustum: Field's loops serve.
    bool values(const Box3&, const Vec3d*, std::size_t, double*) const override { return false; }
    Interval bounds(const Box3& box) const override {
        Vec3d q[8];
        for (int c = 0; c < 8; ++c)
            if (!mF.toFrame(box.corner(c), q[c])) return valueRange(); // reaches behind the apex: any value may be there
        const Box3 fb = Box3::around(q, 8);
        // The corners' images carry the map's rounding: a millionth of a voxel more holds it.
        const double v = 1e-6 * mF.frameVoxel();
        const Vec3d pad = Vec3d(v, v, v) + (abs(fb.min) + abs(fb.max)) * 1e-12;
        return mFrame->bounds({fb.min - pad, fb.max + pad});
    }
    bool mayStraddle(const Box3& box, double iso) const override { return straddles(bounds(box), iso); }
    Box3 domain() const override { return mDomain; }
    Interval valueRange() const override { return mFrame->valueRange(); }
    double voxelSize() const override { return mF.frameVoxel(); }
    bool axisAligned() const override { return false; }
    LatticeFrame naturalFrame(double h) const override { return {mDomain.min, h}; }
    bool sampleNodes(const LatticeFrame&, const Vec3i&, const Vec3i&, const std::uint8_t*, double*) const override { return false; }
    bool directStride(const LatticeFrame&, int&, openvdb::math::Coord&) const override { return false; }
    bool cellsInsideVoxelCells(const LatticeFrame&) const override { return false; }
    // World lattices are not where the data's cells are (the frame's are): every cell is kept.
    void dropCellsWithoutData(const LatticeFrame&, const Vec3i&, std::uint64_t*) const override {}
    void pointsWithData(const Vec3f* points, std::size_t n, std::uint8_t* out) const override {
        for (std::size_t i = 0; i < n; ++i) {
            Vec3d q;
            out[i] = 0;
            if (!mF.toFrame(Vec3d(points[i]), q)) continue;
            const Vec3f qf(q);
            mFrame->pointsWithData(&qf, 1, &out[i]);
        }
    }
    bool piecewiseLinearCrossing(const Vec3d&, const Vec3d&, double, Inside, double&) const override { return false; }
    GridBaseCPtr grid() const override { return mGrid; }

private:
    static Vec3d abs(const Vec3d& v) { return {std::fabs(v.x), std::fabs(v.y), std::fabs(v.z)}; }

    GridBaseCPtr mGrid;
    std::shared_ptr<const GridField> mFrame;
    Frustum mF;
    Box3 mDomain;
    double mOutside = 0; // the grid's background: the value behind the apex, where no voxel is
};

} // namespace

double smallestFrustumVoxel(const openvdb::GridBase& grid) {
    const NonlinearFrustumMap& map = *grid.transform().constMap<NonlinearFrustumMap>();
    const Box3 box{toVec(map.getBBox().min()), toVec(map.getBBox().max())};
    double smallest = std::numeric_limits<double>::infinity();
    for (int c = 0; c < 8; ++c) {
        const openvdb::Vec3d v = map.voxelSize(toVdb(box.corner(c)));
        smallest = std::min({smallest, v.x(), v.y(), v.z()});
    }
    return smallest;
}

std::unique_ptr<GridField::Impl> makeFrustumGrid(GridBaseCPtr grid, std::shared_ptr<const GridField> frame, double frameVoxel,
                                                 const std::string& label, std::shared_ptr<const CurvedFrameMap>& curved) {
    const Frustum f(*grid->transform().constMap<NonlinearFrustumMap>(), frameVoxel);
    auto impl = std::make_unique<FrustumGrid>(std::move(grid), std::move(frame), f, label);
    curved = std::make_shared<FrustumFrameMap>(f);
    return impl;
}

} // namespace vdbsurf
