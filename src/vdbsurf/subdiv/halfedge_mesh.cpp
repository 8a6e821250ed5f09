#include "vdbsurf/subdiv/halfedge_mesh.h"

#include "vdbsurf/core/error.h"

#include <OpenMesh/Core/System/omstream.hh>

#include <vector>

namespace vdbsurf::subdiv {

void buildHalfedgeMesh(const Mesh& mesh, const std::string& inputName, HalfedgeMesh& out) {
    out.clear();
    std::vector<int> used(mesh.points.size(), -1);
    std::size_t usedCount = 0;
    for (std::uint32_t i : mesh.indices)
        if (used[i] < 0) used[i] = int(usedCount++);
    out.reserve(usedCount, mesh.indices.size(), mesh.polygonCount());
    std::vector<HalfedgeMesh::VertexHandle> handle(mesh.points.size());
    // Vertices keep the input's order among the used ones, so output order follows input order.
    for (std::size_t i = 0; i < mesh.points.size(); ++i)
        if (used[i] >= 0) {
            const Vec3f& p = mesh.points[i];
            handle[i] = out.add_vertex(HalfedgeMesh::Point(p.x, p.y, p.z));
        }
    // OpenMesh logs a refused face on its own error stream; we throw one clear Error instead.
    struct QuietOpenMesh {
        QuietOpenMesh() { omerr().disable(); }
        ~QuietOpenMesh() { omerr().enable(); }
    } quiet;
    std::vector<HalfedgeMesh::VertexHandle> corners;
    for (std::size_t f = 0; f < mesh.polygonCount(); ++f) {
        corners.clear();
        const std::uint32_t* v = mesh.polygon(f);
        for (std::uint32_t c = 0; c < mesh.polygonSize(f); ++c) corners.push_back(handle[v[c]]);
        for (std::size_t a = 0; a < corners.size(); ++a)
            for (std::size_t b = a + 1; b < corners.size(); ++b)
                if (corners[a] == corners[b])
                    throw Error(inputName, "polygon " + std::to_string(f) + " repeats vertex " + std::to_string(v[a]));
        if (!out.add_face(corners).is_valid())
            throw Error(inputName, "polygon " + std::to_string(f) +
                                       " cannot join the mesh: it would make an edge of three polygons or a vertex joining "
                                       "separate fans (non-manifold), or it is oriented against its neighbour, or it repeats a "
                                       "polygon; subdivision needs a manifold, consistently oriented mesh");
    }
    for (const auto vh : out.vertices())
        if (!out.is_manifold(vh)) {
            const Vec3d p(out.point(vh)[0], out.point(vh)[1], out.point(vh)[2]);
            throw Error(inputName, "vertex at (" + std::to_string(p.x) + ", " + std::to_string(p.y) + ", " + std::to_string(p.z) +
                                       ") joins separate fans of polygons (non-manifold); subdivision needs a manifold mesh");
        }
}

Mesh toMesh(const HalfedgeMesh& mesh) {
    Mesh out;
    out.points.reserve(mesh.n_vertices());
    for (const auto vh : mesh.vertices()) {
        const auto& p = mesh.point(vh);
        out.points.emplace_back(float(p[0]), float(p[1]), float(p[2]));
    }
    out.offsets.reserve(mesh.n_faces() + 1);
    out.indices.reserve(mesh.n_halfedges());
    std::vector<std::uint32_t> poly;
    for (const auto fh : mesh.faces()) {
        poly.clear();
        for (const auto vh : mesh.fv_range(fh)) poly.push_back(std::uint32_t(vh.idx()));
        out.addPolygon(poly.data(), poly.size());
    }
    return out;
}

} // namespace vdbsurf::subdiv
