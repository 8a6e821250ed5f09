// PLY, binary little endian: float x y z per vertex, "uchar int" index lists per face, which
// Blender, Houdini and MeshLab read.
#include "vdbsurf/core/atomic_file.h"
#include "vdbsurf/core/buffered_file.h"
#include "vdbsurf/mesh/mesh_io.h"

namespace vdbsurf {

void writePly(const std::string& path, const Mesh& mesh, const std::vector<std::string>& comments) {
    AtomicFile target(path);
    {
        BufferedFile out(target);
        std::string header = "ply\nformat binary_little_endian 1.0\n";
        for (const std::string& c : comments) header += "comment " + c + "\n";
        header += "element vertex " + std::to_string(mesh.points.size()) + "\nproperty float x\nproperty float y\nproperty float z\n";
        header += "element face " + std::to_string(mesh.polygonCount()) + "\nproperty list uchar int vertex_indices\nend_header\n";
        out.put(header);
        auto putLE32 = [&](std::uint32_t w) {
            const char b[4] = {char(w & 0xff), char((w >> 8) & 0xff), char((w >> 16) & 0xff), char((w >> 24) & 0xff)};
            out.put(b, 4);
        };
        for (const Vec3f& p : mesh.points) {
            for (int a = 0; a < 3; ++a) {
                std::uint32_t w;
                const float f = p[std::size_t(a)];
                std::memcpy(&w, &f, 4);
                putLE32(w);
            }
        }
        for (std::size_t f = 0; f < mesh.polygonCount(); ++f) {
            const std::uint32_t n = mesh.polygonSize(f);
            if (n > 255) throw Error(path, "a polygon has more than 255 vertices, which PLY's uchar count cannot hold");
            const char count = char(n);
            out.put(&count, 1);
            for (std::uint32_t i = 0; i < n; ++i) putLE32(mesh.polygon(f)[i]);
        }
        out.close();
    }
    target.commit();
}

} // namespace vdbsurf
