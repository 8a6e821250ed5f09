// A mesh back to a narrow-band level set (OpenVDB's meshToLevelSet), written as a .vdb with
// metadata saying how it was made, so vdb_tool, Houdini and Blender read it as any other SDF.
#pragma once
#include "vdbsurf/mesh/mesh.h"

#include <map>
#include <string>

namespace vdbsurf {

struct LevelSetWriteOptions {
    double voxelSize = 0;          // world units
    float halfWidth = 3.0f;        // narrow band, in voxels
    std::string gridName = "surface";
    std::map<std::string, std::string> metadata; // written as string metadata on the grid
};

void writeMeshAsLevelSet(const std::string& path, const Mesh& mesh, const LevelSetWriteOptions& options);

} // namespace vdbsurf
