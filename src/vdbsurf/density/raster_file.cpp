#include "vdbsurf/density/raster_file.h"

#include "vdbsurf/core/error.h"
#include "vdbsurf/density/scene_json.h"
#include "vdbsurf/vdb/vdb_file.h"

#include <openvdb/openvdb.h>

namespace vdbsurf {

void writeDensityVdb(const std::string& path, const DensityRaster& raster, bool surfaceOnly, const std::string& source) {
    // A shallow copy: the tree is shared, the metadata is the file's own.
    auto grid = openvdb::GridBase::grid<openvdb::FloatGrid>(raster.grid())->copy();
    const DensityScene& scene = raster.scene();
    grid->insertMeta("vdbsurf_version", openvdb::StringMetadata(VDBSURF_VERSION));
    grid->insertMeta("vdbsurf_source", openvdb::StringMetadata(source));
    grid->insertMeta("vdbsurf_scene", openvdb::StringMetadata(sceneToJsonText(scene.primitives(), scene.voxelSize())));
    grid->insertMeta("vdbsurf_voxel_size", openvdb::DoubleMetadata(grid->voxelSize()[0]));
    grid->insertMeta("vdbsurf_surface_only", openvdb::BoolMetadata(surfaceOnly));
    writeVdbFile(path, {grid});
}

DensityFile readDensityVdb(const std::string& path) {
    const LoadedGrid loaded = readScalarGrid(path, "density");
    DensityFile f;
    f.grid = loaded.grid;
    const auto scene = f.grid->getMetadata<openvdb::StringMetadata>("vdbsurf_scene");
    const auto voxel = f.grid->getMetadata<openvdb::DoubleMetadata>("vdbsurf_voxel_size");
    const auto surface = f.grid->getMetadata<openvdb::BoolMetadata>("vdbsurf_surface_only");
    if (!scene || !voxel || !surface)
        throw Error(path, "grid 'density' carries no scene; only grids written by `vdbsurf rasterize` can be edited");
    f.sceneJson = scene->value();
    f.voxelSize = voxel->value();
    f.surfaceOnly = surface->value();
    for (const char* key : {"vdbsurf_version", "vdbsurf_source", "vdbsurf_scene", "vdbsurf_voxel_size", "vdbsurf_surface_only"})
        f.grid->removeMeta(key);
    return f;
}

} // namespace vdbsurf
