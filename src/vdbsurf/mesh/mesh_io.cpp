#include "vdbsurf/mesh/mesh_io.h"

#include "vdbsurf/core/error.h"

#include <algorithm>
#include <cctype>
#include <filesystem>

namespace vdbsurf {

MeshFormat meshFormatOf(const std::string& path) {
    std::string ext = std::filesystem::path(path).extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    if (ext == ".obj") return MeshFormat::Obj;
    if (ext == ".ply") return MeshFormat::Ply;
    if (ext == ".vdb") return MeshFormat::Vdb;
    if (ext == ".pov") return MeshFormat::Pov;
    return MeshFormat::Unknown;
}

Mesh readMesh(const std::string& path) {
    switch (meshFormatOf(path)) {
    case MeshFormat::Obj: return readObj(path);
    case MeshFormat::Ply: return readPly(path);
    default: throw Error(path, "unsupported mesh format (read .obj or .ply)");
    }
}

void writeMesh(const std::string& path, const Mesh& mesh, const std::vector<std::string>& comments, const ViewCamera* camera) {
    switch (meshFormatOf(path)) {
    case MeshFormat::Obj: writeObj(path, mesh, comments); return;
    case MeshFormat::Ply: writePly(path, mesh, comments); return;
    case MeshFormat::Pov: writePov(path, mesh, camera ? *camera : framingCamera(mesh.bounds()), comments); return;
    default: throw Error(path, "unsupported mesh format (use .obj, .ply or .pov)");
    }
}

} // namespace vdbsurf
