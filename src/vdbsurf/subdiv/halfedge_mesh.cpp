#include "vdbsurf/subdiv/halfedge_mesh.h"

#include "vdbsurf/core/error.h"

#include <OpenMesh/Core/System/omstream.hh>

#include <vector>

namespace vdbsurf::subdiv {

namespace {

// Corner c of `mesh` is indices[c]; its polygon's next and previous corners.
struct Corners {
    std::vector<std::uint32_t> next, prev;
    explicit Corners(const Mesh& mesh) : next(mesh.indices.size()), prev(mesh.indices.size()) {
        for (std::size_t f = 0; f < mesh.polygonCount(); ++f) {
            const std::uint32_t b = mesh.offsets[f], n = mesh.polygonSize(f);
            for (std::uint32_t k = 0; k < n; ++k) {
                next[b + k] = b + (k + 1) % n;
                prev[b + k] = b + (k + n - 1) % n;
            }
        }
    }
};

std::uint32_t findRoot(std::vector<std::uint32_t>& parent, std::uint32_t x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
}

} // namespace

std::vector<std::uint32_t> splitVertexFans(const Mesh& mesh, const std::string& inputName, std::vector<std::uint32_t>& cornerVertex) {
    const std::size_t nc = mesh.indices.size();
    const Corners corners(mesh);
    // Corners of each vertex, grouped (counting sort keeps corner order within a vertex).
    std::vector<std::uint32_t> start(mesh.points.size() + 1, 0), byVertex(nc);
    for (std::uint32_t v : mesh.indices) ++start[v + 1];
    for (std::size_t v = 0; v < mesh.points.size(); ++v) start[v + 1] += start[v];
    {
        std::vector<std::uint32_t> fill(start.begin(), start.end() - 1);
        for (std::uint32_t c = 0; c < nc; ++c) byVertex[fill[mesh.indices[c]]++] = c;
    }
    // Two corners of v belong to one fan when their polygons share an edge at v: corner c goes
    // v -> w, and the neighbour's corner at v comes from w.
    std::vector<std::uint32_t> parent(nc);
    for (std::uint32_t c = 0; c < nc; ++c) parent[c] = c;
    for (std::size_t v = 0; v < mesh.points.size(); ++v)
        for (std::uint32_t a = start[v]; a < start[v + 1]; ++a) {
            const std::uint32_t c = byVertex[a];
            const std::uint32_t w = mesh.indices[corners.next[c]];
            for (std::uint32_t b = start[v]; b < start[v + 1]; ++b) {
                const std::uint32_t d = byVertex[b];
                if (d == c) continue;
                if (mesh.indices[corners.prev[d]] == w) parent[findRoot(parent, c)] = findRoot(parent, d);
                if (mesh.indices[corners.next[d]] == w)
                    throw Error(inputName, "two polygons run along the edge " + std::to_string(v) + "-" + std::to_string(w) +
                                               " in the same direction: they are oriented inconsistently, or the edge has "
                                               "three or more polygons; subdivision needs a manifold, consistently oriented mesh");
            }
        }
    // The first fan of a vertex keeps its index; each further fan gets a copy of the vertex.
    cornerVertex.assign(mesh.indices.begin(), mesh.indices.end());
    std::vector<std::uint32_t> copiesOf; // source vertex of each added copy
    std::vector<std::uint32_t> fanVertex(nc, ~0u);
    for (std::size_t v = 0; v < mesh.points.size(); ++v) {
        std::uint32_t firstRoot = ~0u;
        for (std::uint32_t a = start[v]; a < start[v + 1]; ++a) {
            const std::uint32_t c = byVertex[a];
            const std::uint32_t r = findRoot(parent, c);
            if (firstRoot == ~0u) firstRoot = r;
            if (r == firstRoot) continue;
            if (fanVertex[r] == ~0u) {
                fanVertex[r] = std::uint32_t(mesh.points.size() + copiesOf.size());
                copiesOf.push_back(std::uint32_t(v));
            }
            cornerVertex[c] = fanVertex[r];
        }
    }
    return copiesOf;
}

std::size_t buildHalfedgeMesh(const Mesh& mesh, const std::string& inputName, HalfedgeMesh& out) {
    out.clear();
    for (std::size_t f = 0; f < mesh.polygonCount(); ++f) {
        const std::uint32_t* v = mesh.polygon(f);
        const std::uint32_t n = mesh.polygonSize(f);
        for (std::uint32_t a = 0; a < n; ++a)
            for (std::uint32_t b = a + 1; b < n; ++b)
                if (v[a] == v[b]) throw Error(inputName, "polygon " + std::to_string(f) + " repeats vertex " + std::to_string(v[a]));
    }
    std::vector<std::uint32_t> cornerVertex;
    const std::vector<std::uint32_t> copiesOf = splitVertexFans(mesh, inputName, cornerVertex);
    const std::size_t total = mesh.points.size() + copiesOf.size();
    auto pointOf = [&](std::size_t i) { return mesh.points[i < mesh.points.size() ? i : copiesOf[i - mesh.points.size()]]; };
    std::vector<int> used(total, -1);
    std::size_t usedCount = 0;
    for (std::uint32_t i : cornerVertex)
        if (used[i] < 0) used[i] = int(usedCount++);
    out.reserve(usedCount, mesh.indices.size(), mesh.polygonCount());
    std::vector<HalfedgeMesh::VertexHandle> handle(total);
    // Vertices keep the input's order among the used ones, so output order follows input order.
    for (std::size_t i = 0; i < total; ++i)
        if (used[i] >= 0) {
            const Vec3f& p = pointOf(i);
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
        for (std::uint32_t c = 0; c < mesh.polygonSize(f); ++c) corners.push_back(handle[cornerVertex[mesh.offsets[f] + c]]);
        if (!out.add_face(corners).is_valid())
            throw Error(inputName, "polygon " + std::to_string(f) +
                                       " cannot join the mesh: it would make an edge of three polygons, or it is oriented "
                                       "against its neighbour, or it repeats a polygon; subdivision needs a manifold, "
                                       "consistently oriented mesh");
    }
    return copiesOf.size();
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
