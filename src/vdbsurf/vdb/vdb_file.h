// Reading .vdb files the way a pipeline user expects: every failure (missing, not a VDB,
// truncated, no such grid, wrong value type) becomes one Error naming the file, and grids are
// read fully (no delayed loading), so a damaged file fails here rather than later.
#pragma once
#include "vdbsurf/core/vec3.h"
#include "vdbsurf/vdb/openvdb_fwd.h"

#include <cstdint>
#include <string>
#include <vector>

namespace vdbsurf {

struct GridSummary {
    std::string name;
    std::string valueType;  // OpenVDB's name: float, double, vec3s, ...
    std::string gridClass;  // "level set", "fog", "staggered", "unknown"
    Vec3d voxelSize;
    std::uint64_t activeVoxels = 0;
    bool empty = true;      // no active voxels
    Box3 worldBounds;       // of the active voxels; meaningless when empty
    bool scalar = false;    // float or double: meshable
    bool frustum = false;   // a camera frustum's transform: voxelSize is at its near plane's centre
    // A density grid written by `vdbsurf rasterize`: the scene it was made from (JSON, as
    // `edit` reads it; empty otherwise) and whether it holds the surface's band only.
    std::string scene;
    bool surfaceOnly = false;
};

void initializeOpenVdb();

// Grid summaries from the file's metadata (reading a grid only where its writer left no voxel
// count); verify: read every grid in full, so damaged data is reported.
std::vector<GridSummary> summarizeVdbFile(const std::string& path, bool verify = false);

struct LoadedGrid {
    GridBasePtr grid;
    std::string name;
    std::string note;   // which grid was picked and why
    std::string source; // how messages name it: "file.vdb:name", or the file alone for an unnamed grid
};

// How messages name a grid: 'name', or (unnamed) — OpenVDB's own tools write unnamed grids.
std::string gridLabel(const std::string& name);

// Reads the grid to mesh: by name, or the first float/double grid when name is empty. Throws
// Error naming the file.
LoadedGrid readScalarGrid(const std::string& path, const std::string& name);

// Writes grids to path atomically (temporary file + rename), with file-level metadata and an
// identifier from the contents (content_uuid.h): the same grids give a byte-identical file.
void writeVdbFile(const std::string& path, const std::vector<GridBasePtr>& grids);

} // namespace vdbsurf
