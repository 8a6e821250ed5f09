// A density scene (seed 003): primitives summed with their signs (op add / subtract), the sum
// clamped to [0, 1]; surface at 0.5, inside above it (fog convention). It is a Field — exact
// value, analytic gradient, conservative bounds — so the mesher meshes it without a grid, and
// the rasterizer turns it into a sparse VDB fog volume.
#pragma once
#include "vdbsurf/density/primitive.h"
#include "vdbsurf/density/primitive_index.h"
#include "vdbsurf/field/field.h"

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace vdbsurf {

// Sums of primitives are kept in fixed point, in units of 2^-32 of density: each primitive's
// contribution is rounded once, so a sum is exact and does not depend on the order of its terms.
// That is what lets an edit take one primitive's old contribution out of a stored sum and put
// its new one in, and get bit for bit what summing afresh gives. 2^-32 is far below a float's
// step at 0.5 (2^-25), and weights of at most kMaxWeight keep any scene's sum inside 63 bits.
using FixedDensity = std::int64_t;
struct FixedInterval {
    FixedDensity lo = 0, hi = 0;
    FixedInterval& operator+=(const FixedInterval& t) {
        lo += t.lo;
        hi += t.hi;
        return *this;
    }
    FixedInterval& operator-=(const FixedInterval& t) { // takes a term out of a sum
        lo -= t.lo;
        hi -= t.hi;
        return *this;
    }
};
constexpr double kFixedPerUnit = 4294967296.0; // 2^32
constexpr FixedDensity kFixedHalf = FixedDensity(1) << 31;
constexpr double kMaxWeight = 1000;
inline double fromFixed(FixedDensity f) { return double(f) / kFixedPerUnit; }
// A primitive's density as a fixed-point term: rounded to the nearest unit, ties to even, as
// std::llrint does in the default rounding mode, for every |density · 2^32| < 2^51 (weights are at
// most kMaxWeight): a double in [2^52, 2^53) has no fraction bits, so adding 1.5 · 2^52 rounds
// and taking it away again is exact. Inline: llrint is a libm call, and an edit makes two per
// voxel it corrects.
inline FixedDensity toFixed(double density) {
    constexpr double kRounder = 6755399441055744.0; // 1.5 · 2^52
    return FixedDensity((density * kFixedPerUnit + kRounder) - kRounder);
}

class DensityScene final : public Field {
public:
    // Throws Error naming `source` when there is no primitive that adds density.
    DensityScene(std::vector<Primitive> primitives, std::string source, std::optional<double> voxelSize = std::nullopt);

    double value(const Vec3d& p) const override;
    // value() at many points, bit for bit (sums are exact and order-free), from the primitives
    // that touch the box once and their batched densities (PreparedPrimitive::densities); lattice
    // blocks come through it too (Field::sampleNodes).
    void values(const Box3& box, const Vec3d* points, std::size_t n, double* out) const override;
    Vec3d gradient(const Vec3d& p) const override;
    Interval bounds(const Box3& box) const override;
    Inside inside() const override { return Inside::Above; }
    double defaultIso() const override { return 0.5; }
    Box3 domain() const override { return mDomain; }
    std::string describe() const override { return mSource; }
    std::optional<double> naturalSpacing() const override { return mVoxelSize; }
    LatticeFrame naturalFrame(double h) const override;

    // The unclamped signed sum, and which primitives may touch a box (indices, ascending).
    double sum(const Vec3d& p) const;
    void primitivesTouching(const Box3& box, std::vector<std::uint32_t>& out) const;
    double sum(const Vec3d& p, const std::vector<std::uint32_t>& among) const;
    Interval bounds(const Box3& box, const std::vector<std::uint32_t>& among) const;
    // Bounds over a box from every primitive, listing those that reach it (PreparedPrimitive::reaches).
    Interval boundsReaching(const Box3& box, std::vector<std::uint32_t>& reaching) const;

    // Fixed-point terms: primitive i's signed contribution at p, and their sum over `among`.
    FixedDensity contribution(std::uint32_t i, const Vec3d& p) const;
    FixedDensity fixedSum(const Vec3d& p, const std::vector<std::uint32_t>& among) const;
    // The same for `count` points at once, bit for bit (PreparedPrimitive::densities): primitive
    // i's terms added to sums[] or taken out of them (an edit's old primitive), and whole sums.
    void addContributions(std::uint32_t i, const Vec3d* points, std::size_t count, bool takeOut, FixedDensity* sums) const;
    void fixedSums(const Vec3d* points, std::size_t count, const std::vector<std::uint32_t>& among, FixedDensity* sums) const;
    // Primitive i's anchor at a ball's centre (PreparedPrimitive::anchorAround), and from it the
    // primitive's signed bounds over the cube centre ± halfWidth inside that ball (rounded outwards,
    // so still conservative; tighter than over the ball, by the anchor's half-space).
    DensityAnchor anchorAround(std::uint32_t i, const Vec3d& centre, double radius) const {
        return mPrepared[i].anchorAround(centre, radius);
    }
    FixedInterval contributionBounds(std::uint32_t i, const DensityAnchor& anchor, const Vec3d& centre, double halfWidth) const;
    // Adds primitive i's signed bounds near each voxel of the 4³ block whose first voxel centre is
    // `first` (voxels `step` apart, z fastest), over the voxel's neighbourhood, to sums[] — or takes
    // them out (an edit's old primitive). The anchor is the block's (its ball holds the neighbourhoods).
    static constexpr int kNearBlock = 4;
    void accumulateBoundsNear(std::uint32_t i, const DensityAnchor& anchor, const Vec3d& first, double step,
                              const Neighbourhood& around, bool takeOut, FixedInterval* sums) const;

    // Scans every primitive instead of asking the index (same results, slower): for tests and
    // benchmarks that compare the two.
    void dropIndex() { buildIndex(false); }
    bool indexed() const { return mIndex.active(); }

    const std::vector<Primitive>& primitives() const { return mPrimitives; }
    const std::vector<PreparedPrimitive>& prepared() const { return mPrepared; }
    const std::string& source() const { return mSource; }
    std::optional<double> voxelSize() const { return mVoxelSize; }

private:
    std::vector<Primitive> mPrimitives;
    std::vector<PreparedPrimitive> mPrepared;
    std::string mSource;
    std::optional<double> mVoxelSize;
    Box3 mDomain;
    PrimitiveIndex mIndex; // which primitives can matter near a point or box

    void buildIndex(bool grid);
};

inline double clampDensity(double v) { return v < 0 ? 0.0 : (v > 1 ? 1.0 : v); }

} // namespace vdbsurf
