// A rasterized scene on disk: the density grid carries the scene it was made from, the voxel size
// and the mode as metadata, so `vdbsurf edit` can change one primitive of a file and recompute
// only what that primitive touches.
#pragma once
#include "vdbsurf/density/rasterize.h"

#include <string>

namespace vdbsurf {

// Writes the raster's grid (with its scene as metadata) to path atomically.
void writeDensityVdb(const std::string& path, const DensityRaster& raster, bool surfaceOnly, const std::string& source);

struct DensityFile {
    GridBasePtr grid;
    std::string sceneJson;
    double voxelSize = 0;
    bool surfaceOnly = false;
};
// Throws Error naming path when the file holds no density grid written by `vdbsurf rasterize`.
DensityFile readDensityVdb(const std::string& path);

} // namespace vdbsurf
