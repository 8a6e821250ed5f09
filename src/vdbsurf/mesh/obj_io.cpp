// Wavefront OBJ: "v x y z" lines then "f a b c ..." (1-based). Numbers are written in their
// shortest round-trip form (std::to_chars), so files are exact and identical run to run.
#include "vdbsurf/core/atomic_file.h"
#include "vdbsurf/core/buffered_file.h"
#include "vdbsurf/mesh/mesh_io.h"

#include <charconv>

namespace vdbsurf {

void writeObj(const std::string& path, const Mesh& mesh, const std::vector<std::string>& comments) {
    AtomicFile target(path);
    {
        BufferedFile out(target);
        for (const std::string& c : comments) out.put("# " + c + "\n");
        for (const Vec3f& p : mesh.points) {
            out.ensure(96);
            char* s = out.cursor();
            char* const begin = s;
            *s++ = 'v';
            for (int a = 0; a < 3; ++a) {
                *s++ = ' ';
                s = std::to_chars(s, s + 32, p[std::size_t(a)]).ptr;
            }
            *s++ = '\n';
            out.advance(std::size_t(s - begin));
        }
        for (std::size_t f = 0; f < mesh.polygonCount(); ++f) {
            const std::uint32_t n = mesh.polygonSize(f);
            const std::uint32_t* v = mesh.polygon(f);
            out.ensure(4 + 12 * std::size_t(n));
            char* s = out.cursor();
            char* const begin = s;
            *s++ = 'f';
            for (std::uint32_t i = 0; i < n; ++i) {
                *s++ = ' ';
                s = std::to_chars(s, s + 11, std::uint64_t(v[i]) + 1).ptr;
            }
            *s++ = '\n';
            out.advance(std::size_t(s - begin));
        }
        out.close();
    }
    target.commit();
}

} // namespace vdbsurf
