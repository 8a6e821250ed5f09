// Sparse rasterization of a density scene into an OpenVDB fog FloatGrid named "density" (seed
// 003's octree becomes the VDB tree), and editing it one primitive at a time.
//
// Voxel (i, j, k) sits at world h·(i, j, k). Blocks are decided from the scene's bounds over
// them, from a 128³ node down through halves to the 8³ leaf, going on only into undecided ones
// (so the work follows the surface, not the volume): no density → background (no work);
// density 1 throughout → constant tiles (no per-voxel work; a 128³ node becomes one tile);
// otherwise a leaf's voxels are evaluated, only for the primitives that reach the leaf. With
// surfaceOnly, a leaf is decided per 4³ block, and in blocks the 0.5 surface can pass within
// two voxels of, per voxel: only voxels a mesher may read (corners of lattice cells the surface
// crosses, and their axis neighbours, for DMC's central differences) are evaluated; the rest
// are filled by side (1 inside, background outside). Each block's decision depends only on the
// primitives that reach it, and sums are exact fixed-point integers, so an edit redecides only the blocks and leaves
// the changed primitives reach before or after — with keepSums, correcting each stored sum by
// those primitives alone — and equals a full rebuild voxel for voxel.
#pragma once
#include "vdbsurf/density/scene.h"
#include "vdbsurf/vdb/openvdb_fwd.h"

#include <cstdint>
#include <memory>

namespace vdbsurf {

class CancelToken;

struct RasterOptions {
    double voxelSize = 0;
    bool surfaceOnly = false;
    // Keep each evaluated voxel's fixed-point sum (8 bytes a voxel, as long as the raster lives)
    // so that update() corrects it by the changed primitives alone instead of summing them all.
    bool keepSums = false;
    // Bytes of leaf values a build may hold before it stops with an Error naming --voxel-size (an
    // edit: new leaves, naming the scene); 0: 80 % of the memory free when the build or edit
    // starts (past it the kernel would kill the process).
    double memoryLimit = 0;
    const CancelToken* cancel = nullptr;
};

struct RasterStats {
    std::uint64_t nodeTiles = 0;       // 128³ constant tiles
    std::uint64_t leafTiles = 0;       // 8³ constant tiles
    std::uint64_t blocksDecided = 0;   // 128³ … 16³ blocks whose bounds were asked
    std::uint64_t leavesDecided = 0;   // leaves whose bounds were asked (inside undecided blocks)
    std::uint64_t leavesEvaluated = 0; // leaves whose voxels were computed
    std::uint64_t voxelsEvaluated = 0; // voxels whose sum was computed from every primitive
    std::uint64_t voxelsUpdated = 0;   // edits with keepSums: voxels corrected by the changed ones
    std::uint64_t leavesRecomputed = 0; // edits: leaves decided again or refilled by a block
    std::uint64_t reachTests = 0;       // edits: blocks and leaves tested for a changed primitive's reach
    double seconds = 0;
};

class DensityRaster {
public:
    // Rasterizes the scene; throws Error naming "--voxel-size" when the spacing is unusable.
    DensityRaster(const DensityScene& scene, const RasterOptions& options);
    // Adopts a grid that an earlier DensityRaster made from `scene` with the same options (read
    // back from a file) instead of rasterizing again.
    DensityRaster(const DensityScene& scene, const RasterOptions& options, GridBasePtr adopted);
    ~DensityRaster();

    GridBasePtr grid() const; // FloatGrid "density", fog volume, background 0
    bool empty() const;       // no active voxel or tile (surface only: no surface)
    const DensityScene& scene() const;
    const RasterStats& stats() const; // of the last build or edit

    // Makes the grid that of `edited`: recomputes only the leaves reached by the old or new
    // influence of the primitives that differ (reordering or renaming the others changes nothing).
    // Throws Error naming the scene when the new leaves would pass the memory limit (as a build
    // does), or Cancelled; the grid is then between the two scenes, and grid() and update() throw
    // std::logic_error: the raster must be built again.
    const RasterStats& update(const DensityScene& edited);

    struct Impl;

private:
    std::unique_ptr<Impl> mImpl;
};

// The density at every voxel of a dense block (x fastest), for comparisons: the work the paper's
// "all space" column does.
void evaluateDense(const DensityScene& scene, double voxelSize, const Vec3i& first, const Vec3i& dims, float* out);

// The index range of voxels (inclusive) that a scene's density can reach at spacing h.
void sceneVoxelRange(const DensityScene& scene, double voxelSize, Vec3i& first, Vec3i& last);

} // namespace vdbsurf
