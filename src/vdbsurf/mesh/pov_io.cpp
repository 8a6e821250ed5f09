// POV-Ray scene with the mesh as `mesh2` (vertex_vectors, normal_vectors, face_indices), the
// user's camera and two lights, so `povray scene.pov` renders it as it is. POV-Ray is
// left-handed; the camera's negative `right` vector makes it render our right-handed data
// without mirroring. Polygons are fanned into triangles (mesh2 holds triangles only); normals
// are area-weighted vertex normals, so the subdivided surface renders smooth.
#include "vdbsurf/core/atomic_file.h"
#include "vdbsurf/core/buffered_file.h"
#include "vdbsurf/mesh/mesh_io.h"

#include <charconv>
#include <cmath>

namespace vdbsurf {

namespace {

void putNumber(BufferedFile& out, double v) {
    out.ensure(32);
    char* s = out.cursor();
    out.advance(std::size_t(std::to_chars(s, s + 32, float(v)).ptr - s));
}

void putVector(BufferedFile& out, const Vec3d& v) {
    out.put("<", 1);
    putNumber(out, v.x);
    out.put(",", 1);
    putNumber(out, v.y);
    out.put(",", 1);
    putNumber(out, v.z);
    out.put(">", 1);
}

std::vector<Vec3d> vertexNormals(const Mesh& mesh) {
    std::vector<Vec3d> normals(mesh.points.size(), Vec3d(0, 0, 0));
    for (std::size_t f = 0; f < mesh.polygonCount(); ++f) {
        const std::uint32_t* v = mesh.polygon(f);
        const std::uint32_t n = mesh.polygonSize(f);
        Vec3d area(0, 0, 0); // Newell: twice the vector area, exact for non-planar polygons too
        for (std::uint32_t k = 0; k < n; ++k) area += cross(Vec3d(mesh.points[v[k]]), Vec3d(mesh.points[v[(k + 1) % n]]));
        for (std::uint32_t k = 0; k < n; ++k) normals[v[k]] += area;
    }
    for (Vec3d& n : normals) {
        const double l = length(n);
        n = l > 0 ? n / l : Vec3d(0, 0, 1);
    }
    return normals;
}

} // namespace

void writePov(const std::string& path, const Mesh& mesh, const ViewCamera& camera, const std::vector<std::string>& comments) {
    validateCamera(camera, path);
    AtomicFile target(path);
    {
        BufferedFile out(target);
        for (const std::string& c : comments) out.put("// " + c + "\n");
        out.put("#version 3.7;\nglobal_settings { assumed_gamma 1.0 }\nbackground { color rgb <1, 1, 1> }\n");
        const Vec3d forward = normalized(camera.target - camera.position);
        const Vec3d right = normalized(cross(forward, camera.up));
        const Vec3d up = cross(right, forward);
        const double distance = length(camera.target - camera.position);
        out.put("camera {\n  perspective\n  location ");
        putVector(out, camera.position);
        out.put("\n  sky ");
        putVector(out, up);
        out.put("\n  up y\n  right ");
        putVector(out, Vec3d(-double(camera.width) / double(camera.height), 0, 0));
        out.put("\n  angle ");
        putNumber(out, camera.fovDegrees);
        out.put("\n  look_at ");
        putVector(out, camera.target);
        out.put("\n}\nlight_source { ");
        putVector(out, camera.position + (up * 0.6 - right * 0.4) * distance);
        out.put(" color rgb <1, 1, 1> }\nlight_source { ");
        putVector(out, camera.position + (right * 0.8 - up * 0.2) * distance);
        out.put(" color rgb <0.35, 0.35, 0.4> shadowless }\n");

        out.put("#declare VdbsurfMesh = mesh2 {\n  vertex_vectors {\n    " + std::to_string(mesh.points.size()));
        for (const Vec3f& p : mesh.points) {
            out.put(",\n    ", 6);
            putVector(out, Vec3d(p));
        }
        out.put("\n  }\n  normal_vectors {\n    " + std::to_string(mesh.points.size()));
        for (const Vec3d& n : vertexNormals(mesh)) {
            out.put(",\n    ", 6);
            putVector(out, n);
        }
        out.put("\n  }\n  face_indices {\n    " + std::to_string(mesh.fannedTriangleCount()));
        for (std::size_t f = 0; f < mesh.polygonCount(); ++f) {
            const std::uint32_t* v = mesh.polygon(f);
            for (std::uint32_t k = 1; k + 1 < mesh.polygonSize(f); ++k) {
                out.ensure(48);
                char* s = out.cursor();
                char* const begin = s;
                *s++ = ',';
                *s++ = '\n';
                char separator = '<';
                for (const std::uint32_t idx : {v[0], v[k], v[k + 1]}) {
                    *s++ = separator;
                    separator = ',';
                    s = std::to_chars(s, s + 11, idx).ptr;
                }
                *s++ = '>';
                out.advance(std::size_t(s - begin));
            }
        }
        out.put("\n  }\n}\nobject {\n  VdbsurfMesh\n  texture {\n    pigment { color rgb <0.80, 0.62, 0.42> }\n"
                "    finish { ambient 0.12 diffuse 0.75 specular 0.35 roughness 0.02 }\n  }\n}\n");
        out.close();
    }
    target.commit();
}

} // namespace vdbsurf
