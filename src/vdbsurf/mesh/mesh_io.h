// Reading and writing meshes by file extension (.obj, .ply). Writes are atomic: a temporary file
// in the target folder is renamed over the target only once it is complete.
#pragma once
#include "vdbsurf/core/camera.h"
#include "vdbsurf/mesh/mesh.h"

#include <string>
#include <vector>

namespace vdbsurf {

enum class MeshFormat { Obj, Ply, Vdb, Pov, Unknown };

// Lower-cased extension to format; Unknown for anything else.
MeshFormat meshFormatOf(const std::string& path);

// Comment lines (provenance) go into the file header. Throws Error naming the path. A .pov
// file is a whole POV-Ray scene seen from `camera`, or from framingCamera(bounds) when null.
void writeMesh(const std::string& path, const Mesh& mesh, const std::vector<std::string>& comments = {},
               const ViewCamera* camera = nullptr);

// Reads positions and polygons; texture coordinates, normals, groups and other elements are
// skipped. Throws Error naming the path (and the line or element) for anything malformed,
// for an index out of range, and for a file holding no polygons.
Mesh readMesh(const std::string& path);
Mesh readObj(const std::string& path);
Mesh readPly(const std::string& path);

void writeObj(const std::string& path, const Mesh& mesh, const std::vector<std::string>& comments);
void writePly(const std::string& path, const Mesh& mesh, const std::vector<std::string>& comments);
void writePov(const std::string& path, const Mesh& mesh, const ViewCamera& camera, const std::vector<std::string>& comments);

} // namespace vdbsurf
