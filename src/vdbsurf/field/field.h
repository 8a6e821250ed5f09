// Field: the one abstraction the mesher sees. A scalar function of world position with its
// gradient, conservative bounds over a box, and the side that is inside. Implementations:
// GridField (an OpenVDB float/double grid), ExpressionField (a user formula), and later the
// density scene. Bounds are what make sparsity honest: a box whose bounds do not straddle the iso
// value cannot hold surface and is never visited.
#pragma once
#include "vdbsurf/core/affine_map.h"
#include "vdbsurf/core/lattice_frame.h"
#include "vdbsurf/core/vec3.h"
#include "vdbsurf/vdb/openvdb_fwd.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <string>

namespace vdbsurf {

struct Interval {
    double lo = -std::numeric_limits<double>::infinity();
    double hi = std::numeric_limits<double>::infinity();
    bool contains(double v) const { return v >= lo && v <= hi; }
};

// How far bounds are widened for the rounding of point evaluations.
inline double boundsTolerance(const Interval& b, double iso) {
    return 1e-9 * std::max({1.0, std::fabs(b.lo), std::fabs(b.hi), std::fabs(iso)});
}

// Does [lo, hi], widened by boundsTolerance, contain iso?
inline bool straddles(const Interval& b, double iso) {
    const double tol = boundsTolerance(b, iso);
    return b.lo - tol <= iso && iso <= b.hi + tol;
}

// Level sets and formulas are negative inside (Below); fog volumes and densities are dense
// inside (Above).
enum class Inside { Below, Above };

inline bool isInside(double v, double iso, Inside side) { return side == Inside::Below ? v < iso : v > iso; }

// Strictly on the other side from a point whose side is `inside`: an iso value counts for neither.
inline bool isOtherSide(bool inside, double v, double iso, Inside side) {
    return inside ? (side == Inside::Below ? v > iso : v < iso) : isInside(v, iso, side);
}

// Can a value within b (widened by boundsTolerance) lie strictly on the other side from a point
// whose side is `inside`?
inline bool mayBeOtherSide(bool inside, const Interval& b, double iso, Inside side) {
    const double tol = boundsTolerance(b, iso);
    const bool otherAbove = inside == (side == Inside::Below);
    return otherAbove ? b.hi + tol >= iso : b.lo - tol <= iso;
}

class Field;

// A field whose samples lie on a lattice that world axes do not follow (a grid whose transform
// rotates, mirrors, shears or scales its axes unequally) is meshed in that lattice's own frame,
// where its samples are the nodes of an axis-aligned lattice, and the mesh is then mapped to
// world (meshField): the nodes sit on the voxels, as volumeToMesh's do. Meshed on a world-axis
// lattice instead, a rotated grid's cube came out farther from its own surface than
// volumeToMesh's (F at H/4 0.993 against 1.000) and three times slower.
//
// A frame no affine map takes to world is curved: a frustum grid's index space, whose voxels
// widen with depth (a perspective map). Its mesh is mapped point by point, as volumeToMesh maps
// its points through the grid's transform.
class CurvedFrameMap {
public:
    virtual ~CurvedFrameMap() = default;
    virtual Vec3d apply(const Vec3d& p) const = 0;
    // True when the map turns outward-facing polygons inward (its Jacobian's determinant, which
    // keeps one sign over the frame, is negative).
    virtual bool mirrors() const = 0;
    // The OpenVDB transform whose voxel (i, j, k) is apply(frame.nodeWorld(i, j, k)). Throws Error
    // naming `what` when OpenVDB cannot store it.
    virtual std::shared_ptr<openvdb::math::Transform> latticeTransform(const LatticeFrame& frame, const std::string& what) const = 0;
};

struct OwnFrame {
    std::shared_ptr<const Field> field;            // the same values, in frame coordinates
    AffineMap toWorld;                             // frame coordinates -> world, where `curved` is null
    std::shared_ptr<const CurvedFrameMap> curved;  // the map, where it is not affine
    // How a lattice spacing in this frame is measured, where a user would not guess it (a
    // frustum's voxels widen; voxels below what OpenVDB stores count in that size), for messages.
    std::string spacingNote;

    Vec3d apply(const Vec3d& p) const { return curved ? curved->apply(p) : toWorld.apply(p); }
    bool mirrors() const { return curved ? curved->mirrors() : toWorld.mirrors(); }
    // The world vector from frame point p's image to (p + offset)'s.
    Vec3d offsetToWorld(const Vec3d& p, const Vec3d& offset) const {
        return curved ? curved->apply(p + offset) - curved->apply(p) : toWorld.linear(offset);
    }
};

class Field {
public:
    virtual ~Field() = default;

    virtual double value(const Vec3d& p) const = 0;
    virtual Vec3d gradient(const Vec3d& p) const = 0;
    // value(p), with gradient(p) in `gradient`: exactly those two results. Fields override it
    // when both share their samples (a grid's voxels).
    virtual double valueAndGradient(const Vec3d& p, Vec3d& gradient) const {
        gradient = this->gradient(p);
        return value(p);
    }
    // Conservative: every value() at a point of the closed box lies in the result.
    virtual Interval bounds(const Box3& box) const = 0;
    // straddles(bounds(box), iso), the same answer, which a field may give sooner (a grid: from
    // the range of the voxels the box reads, before the interpolant's exact range).
    virtual bool mayStraddle(const Box3& box, double iso) const { return straddles(bounds(box), iso); }
    // mayStraddle of each of n boxes that all lie inside `around` (a block's children, a node's
    // octants), in out[i]: the same answers, which a field may give for less when it has bounded
    // the box around them first (a formula: its min and max arguments that cannot matter there
    // are skipped in them; see ExpressionField).
    virtual void mayStraddleWithin(const Box3& around, const Box3* boxes, std::size_t n, double iso, std::uint8_t* out) const {
        (void)around;
        for (std::size_t i = 0; i < n; ++i) out[i] = mayStraddle(boxes[i], iso);
    }
    // mayBeOtherSide(inside, bounds(box), iso, this->inside()), the same answer, which a field
    // may give sooner (a formula: from its cheaper natural bounds where those suffice).
    virtual bool mayHoldOtherSide(const Box3& box, bool inside, double iso) const {
        return mayBeOtherSide(inside, bounds(box), iso, this->inside());
    }
    virtual Inside inside() const = 0;
    // Outside this box the field is constant, so no surface can be there.
    virtual Box3 domain() const = 0;
    // What the user gave, for messages and metadata ("file.vdb:grid", "--expr ...").
    virtual std::string describe() const = 0;
    // The iso value a user means when they give none (0 for level sets, 0.5 for fog).
    virtual double defaultIso() const { return inside() == Inside::Below ? 0.0 : 0.5; }

    // Lattice spacing when the user gives none (a grid's own voxel size), if the field has one.
    virtual std::optional<double> naturalSpacing() const { return std::nullopt; }
    // The spacing of the samples the field interpolates (a grid's voxel size), if it is not an
    // exact function: its gradient blends the faces at a kink over a few samples.
    virtual std::optional<double> sampleSpacing() const { return std::nullopt; }
    // Where lattice nodes should sit for spacing h (a grid's voxel centres when h is a multiple).
    virtual LatticeFrame naturalFrame(double h) const { return {domain().min, h}; }
    // The frame to mesh in where it is not world space (see OwnFrame); null: world space.
    virtual const OwnFrame* ownFrame() const { return nullptr; }

    // Values at the nodes first + (i, j, k), 0 <= i < dims.x ..., x fastest. Only nodes whose
    // needed[] entry is non-zero must be filled (needed may be null: all). By default the needed
    // nodes go through values() together; a grid overrides this to read its voxels directly.
    virtual void sampleNodes(const LatticeFrame& frame, const Vec3i& first, const Vec3i& dims,
                             const std::uint8_t* needed, double* out) const;

    // value() at each of the n points, all of which lie in `box`, bit for bit. Fields override it
    // to read the data under a small box once (a grid's voxels) instead of once a point.
    virtual void values(const Box3& box, const Vec3d* points, std::size_t n, double* out) const;

    // True when, on this frame, a cell's bounds are exactly the range of its 8 corner values
    // (a grid meshed at its own voxel size), so the lattice need not ask bounds() per cell.
    virtual bool cellBoundsAreCornerRange(const LatticeFrame& frame) const { return false; }

    // Clears, in the 8^3 block of cells from `first` (8 words of 64 bits, bit z + 8 y of word x: an
    // OpenVDB leaf mask's layout), the cells whose every value comes from what the field's source
    // marks as no data. A grid's inactive voxels are the fill between its data: where a level
    // set's band ends open (a terrain, a band clipped by a box), the flood fill's inside and outside
    // meet with no surface of the grid there. The default keeps every cell.
    virtual void dropCellsWithoutData(const LatticeFrame& frame, const Vec3i& first, std::uint64_t* cells) const {
        (void)frame, (void)first, (void)cells;
    }
    // out[i] = 1 when value(points[i]) reads data, 0 when it reads only what the source marks as
    // none (as above). The default: every point has data.
    virtual void pointsWithData(const Vec3f* points, std::size_t n, std::uint8_t* out) const {
        (void)points;
        std::fill(out, out + n, std::uint8_t(1));
    }

    // True when, on this frame, the field is linear along every lattice edge, so the crossing
    // on an undeformed edge is plain linear interpolation of the two node values.
    virtual bool edgesAreLinear(const LatticeFrame& frame) const { return false; }

    // Where along the segment a -> b (values va, vb on opposite sides of iso) the field crosses
    // iso, as t in [0, 1]. The default refines linear interpolation on the true field
    // (Illinois regula falsi), because a formula or a resampled grid is not linear along an edge.
    virtual double edgeCrossing(const Vec3d& a, const Vec3d& b, double va, double vb, double iso) const;
};

// "values lie within LO .. HI" over the field's domain, for messages about a missing surface.
std::string valueRangeText(const Field& field);

// Illinois regula falsi on f(a + t (b - a)) - iso, bracketed, at most maxSteps evaluations.
double refineCrossing(const Field& field, const Vec3d& a, const Vec3d& b, double va, double vb, double iso,
                      int maxSteps = 8);

} // namespace vdbsurf
