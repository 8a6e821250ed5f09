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

void writeMesh(const std::string& path, const Mesh& mesh, const std::vector<std::string>& comments) {
    switch (meshFormatOf(path)) {
    case MeshFormat::Obj: writeObj(path, mesh, comments); return;
    case MeshFormat::Ply: writePly(path, mesh, comments); return;
    default: throw Error(path, "unsupported mesh format (use .obj or .ply)");
    }
}

} // namespace vdbsurf
