#include "vdbsurf/subdiv/halfedge_mesh.h"

#include "vdbsurf/core/error.h"
#include "vdbsurf/mesh/vertex_fans.h"

#include <vector>

namespace vdbsurf::subdiv {

HalfedgeMesh::Point nextFacePoint(const HalfedgeMesh& mesh, const FaceProperties& props, HalfedgeMesh::FaceHandle f, bool odd) {
    if (!odd && mesh.property(props.kind, f) != kPlain) return mesh.property(props.storedPoint, f);
    HalfedgeMesh::Point p(0, 0, 0);
    const auto first = mesh.halfedge_handle(f);
    auto h = first;
    int n = 0;
    do {
        p += mesh.point(mesh.to_vertex_handle(h));
        ++n;
        h = mesh.next_halfedge_handle(h);
    } while (h != first);
    return p / double(n);
}

void releaseSpare(HalfedgeMesh& mesh, const FaceProperties& props) {
    mesh.clean(); // frees vertices, edges and faces but not property storage
    std::vector<HalfedgeMesh::Point>().swap(mesh.property(mesh.points_pph()).data_vector());
    std::vector<HalfedgeMesh::Point>().swap(mesh.property(props.storedPoint).data_vector());
    std::vector<std::uint8_t>().swap(mesh.property(props.kind).data_vector());
    std::vector<std::uint32_t>().swap(mesh.property(props.tag).data_vector());
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
