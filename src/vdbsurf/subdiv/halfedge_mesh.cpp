#include "vdbsurf/subdiv/halfedge_mesh.h"

#include "vdbsurf/core/error.h"

#include <vector>

namespace vdbsurf::subdiv {

namespace {

std::vector<std::uint32_t> nextCorners(const std::vector<std::uint32_t>& offsets, std::size_t nc) {
    std::vector<std::uint32_t> nextCorner(nc);
    parallelFor(offsets.size() - 1, [&](std::size_t f) {
        const std::uint32_t b = offsets[f], n = offsets[f + 1] - b;
        for (std::uint32_t k = 0; k < n; ++k) nextCorner[b + k] = b + (k + 1 == n ? 0 : k + 1);
    });
    return nextCorner;
}

std::uint32_t findRoot(std::vector<std::uint32_t>& parent, std::uint32_t x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
}

} // namespace

std::vector<std::uint32_t> splitVertexFans(const Mesh& mesh, const std::string& inputName, std::vector<std::uint32_t>& cornerVertex,
                                           std::vector<std::uint32_t>& partner) {
    const std::size_t nc = mesh.indices.size();
    const std::vector<std::uint32_t> next = nextCorners(mesh.offsets, nc);
    std::vector<std::uint32_t> prev(nc);
    for (std::uint32_t c = 0; c < nc; ++c) prev[next[c]] = c;
    // Corners of each vertex, grouped (counting sort keeps corner order within a vertex).
    std::vector<std::uint32_t> start(mesh.points.size() + 1, 0), byVertex(nc);
    for (std::uint32_t v : mesh.indices) ++start[v + 1];
    for (std::size_t v = 0; v < mesh.points.size(); ++v) start[v + 1] += start[v];
    {
        std::vector<std::uint32_t> fill(start.begin(), start.end() - 1);
        for (std::uint32_t c = 0; c < nc; ++c) byVertex[fill[mesh.indices[c]]++] = c;
    }
    // Two corners of v belong to one fan when their polygons share an edge at v: corner c goes
    // v -> w, and the neighbour's corner d at v comes from w, so corner prev(d) runs w -> v and
    // is c's partner.
    partner.assign(nc, ~0u);
    std::vector<std::uint32_t> parent(nc);
    for (std::uint32_t c = 0; c < nc; ++c) parent[c] = c;
    for (std::size_t v = 0; v < mesh.points.size(); ++v)
        for (std::uint32_t a = start[v]; a < start[v + 1]; ++a) {
            const std::uint32_t c = byVertex[a];
            const std::uint32_t w = mesh.indices[next[c]];
            for (std::uint32_t b = start[v]; b < start[v + 1]; ++b) {
                const std::uint32_t d = byVertex[b];
                if (d == c) continue;
                if (mesh.indices[prev[d]] == w) {
                    parent[findRoot(parent, c)] = findRoot(parent, d);
                    partner[c] = prev[d];
                }
                if (mesh.indices[next[d]] == w)
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

void assemble(HalfedgeMesh& m, std::size_t nV, const std::vector<std::uint32_t>& offsets, const std::vector<std::uint32_t>& indices,
              const std::vector<std::uint32_t>& partner) {
    const std::vector<std::uint32_t> nextCorner = nextCorners(offsets, indices.size());
    using VH = HalfedgeMesh::VertexHandle;
    using HH = HalfedgeMesh::HalfedgeHandle;
    using FH = HalfedgeMesh::FaceHandle;
    constexpr std::uint32_t kNone = ~0u;
    const std::size_t nF = offsets.size() - 1, nc = indices.size();
    // The lower corner of a pair (or a corner alone on the boundary) makes the edge.
    std::vector<std::uint32_t> halfedgeOf(nc);
    std::size_t nE = 0;
    for (std::uint32_t c = 0; c < nc; ++c)
        if (partner[c] == kNone || c < partner[c]) halfedgeOf[c] = std::uint32_t(2 * nE++);
    parallelFor(nc, [&](std::size_t c) {
        if (partner[c] != kNone && partner[c] < c) halfedgeOf[c] = halfedgeOf[partner[c]] + 1;
    });

    m.clean();
    m.resize(nV, nE, nF);
    std::vector<HH> boundaryOut(nV);
    for (std::uint32_t c = 0; c < nc; ++c)
        if (partner[c] == kNone) boundaryOut[indices[nextCorner[c]]] = HH(int(halfedgeOf[c] ^ 1u));
    parallelFor(nF, [&](std::size_t f) {
        const FH fh{int(f)};
        m.set_halfedge_handle(fh, HH(int(halfedgeOf[offsets[f]])));
        for (std::uint32_t c = offsets[f]; c < offsets[f + 1]; ++c) {
            const HH h{int(halfedgeOf[c])};
            m.set_vertex_handle(h, VH(int(indices[nextCorner[c]])));
            m.set_face_handle(h, fh);
            m.set_next_halfedge_handle(h, HH(int(halfedgeOf[nextCorner[c]])));
            if (partner[c] == kNone) {
                const HH b{int(halfedgeOf[c] ^ 1u)};
                m.set_vertex_handle(b, VH(int(indices[c])));
                m.set_boundary(b);
                m.set_next_halfedge_handle(b, boundaryOut[indices[c]]);
            }
        }
    });
    // A boundary vertex's halfedge must be its outgoing boundary halfedge (OpenMesh's rule);
    // otherwise the halfedge of the vertex's first corner.
    std::vector<std::uint32_t> firstCorner(nV, kNone);
    for (std::uint32_t c = 0; c < nc; ++c)
        if (firstCorner[indices[c]] == kNone) firstCorner[indices[c]] = c;
    parallelFor(nV, [&](std::size_t v) {
        if (boundaryOut[v].is_valid()) m.set_halfedge_handle(VH(int(v)), boundaryOut[v]);
        else if (firstCorner[v] != kNone) m.set_halfedge_handle(VH(int(v)), HH(int(halfedgeOf[firstCorner[v]])));
    });
}

std::size_t buildHalfedgeMesh(const Mesh& mesh, const std::string& inputName, HalfedgeMesh& out) {
    for (std::size_t f = 0; f < mesh.polygonCount(); ++f) {
        const std::uint32_t* v = mesh.polygon(f);
        const std::uint32_t n = mesh.polygonSize(f);
        if (n < 3) throw Error(inputName, "polygon " + std::to_string(f) + " has fewer than three vertices");
        for (std::uint32_t a = 0; a < n; ++a)
            for (std::uint32_t b = a + 1; b < n; ++b)
                if (v[a] == v[b]) throw Error(inputName, "polygon " + std::to_string(f) + " repeats vertex " + std::to_string(v[a]));
    }
    std::vector<std::uint32_t> cornerVertex, partner;
    const std::vector<std::uint32_t> copiesOf = splitVertexFans(mesh, inputName, cornerVertex, partner);
    const std::size_t total = mesh.points.size() + copiesOf.size();
    // Vertices keep the input's order among the used ones, then the copies.
    std::vector<char> isUsed(total, 0);
    for (std::uint32_t i : cornerVertex) isUsed[i] = 1;
    std::vector<std::uint32_t> compact(total, ~0u);
    std::uint32_t used = 0;
    for (std::size_t i = 0; i < total; ++i)
        if (isUsed[i]) compact[i] = used++;
    for (std::uint32_t& i : cornerVertex) i = compact[i];
    assemble(out, used, mesh.offsets, cornerVertex, partner);
    for (std::size_t i = 0; i < total; ++i)
        if (compact[i] != ~0u) {
            const Vec3f& p = mesh.points[i < mesh.points.size() ? i : copiesOf[i - mesh.points.size()]];
            out.set_point(HalfedgeMesh::VertexHandle(int(compact[i])), HalfedgeMesh::Point(p.x, p.y, p.z));
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
        // assemble() makes a face's halfedge its first corner's, so this is the input's order.
        for (const auto h : mesh.fh_range(fh)) poly.push_back(std::uint32_t(mesh.from_vertex_handle(h).idx()));
        out.addPolygon(poly.data(), poly.size());
    }
    return out;
}

} // namespace vdbsurf::subdiv
