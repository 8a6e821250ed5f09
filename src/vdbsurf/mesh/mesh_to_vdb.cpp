#include "vdbsurf/mesh/mesh_to_vdb.h"

#include "vdbsurf/core/error.h"
#include "vdbsurf/vdb/vdb_file.h"
#include "vdbsurf/vdb/voxel_transform.h"

#include <openvdb/openvdb.h>
#include <openvdb/tools/MeshToVolume.h>

#include <cmath>

namespace vdbsurf {

void writeMeshAsLevelSet(const std::string& path, const Mesh& mesh, const LevelSetWriteOptions& options) {
    if (!(options.voxelSize > 0) || !std::isfinite(options.voxelSize))
        throw Error(path, "level-set voxel size must be positive");
    initializeOpenVdb();
    std::vector<openvdb::Vec3s> points(mesh.points.size());
    for (std::size_t i = 0; i < points.size(); ++i) points[i] = {mesh.points[i].x, mesh.points[i].y, mesh.points[i].z};
    std::vector<std::uint32_t> tris, quads;
    splitToTrianglesAndQuads(mesh, tris, quads);
    std::vector<openvdb::Vec3I> t(tris.size() / 3);
    for (std::size_t i = 0; i < t.size(); ++i) t[i] = {tris[3 * i], tris[3 * i + 1], tris[3 * i + 2]};
    std::vector<openvdb::Vec4I> q(quads.size() / 4);
    for (std::size_t i = 0; i < q.size(); ++i) q[i] = {quads[4 * i], quads[4 * i + 1], quads[4 * i + 2], quads[4 * i + 3]};

    const auto xform = voxelTransform(options.voxelSize, path);
    openvdb::FloatGrid::Ptr grid = openvdb::tools::meshToLevelSet<openvdb::FloatGrid>(*xform, points, t, q, options.halfWidth);
    grid->setName(options.gridName);
    grid->setGridClass(openvdb::GRID_LEVEL_SET);
    for (const auto& [key, value] : options.metadata) grid->insertMeta(key, openvdb::StringMetadata(value));
    writeVdbFile(path, {grid});
}

} // namespace vdbsurf
