// Writing meshes by file extension (.obj, .ply), atomically: a temporary file in the target
// folder is renamed over the target only once it is complete.
#pragma once
#include "vdbsurf/mesh/mesh.h"

#include <string>
#include <vector>

namespace vdbsurf {

enum class MeshFormat { Obj, Ply, Vdb, Pov, Unknown };

// Lower-cased extension to format; Unknown for anything else.
MeshFormat meshFormatOf(const std::string& path);

// Comment lines (provenance) go into the file header. Throws Error naming the path.
void writeMesh(const std::string& path, const Mesh& mesh, const std::vector<std::string>& comments = {});

void writeObj(const std::string& path, const Mesh& mesh, const std::vector<std::string>& comments);
void writePly(const std::string& path, const Mesh& mesh, const std::vector<std::string>& comments);

} // namespace vdbsurf
