// One √2 step = geometry first (face points, edge points, vertex moves, all from the old mesh,
// in parallel: each value depends only on the old mesh, so the thread count cannot change it),
// then topology in face and edge index order (serial, so the result is the same every run).
#include "vdbsurf/subdiv/sqrt2_subdivision.h"

#include "vdbsurf/core/error.h"
#include "vdbsurf/subdiv/halfedge_mesh.h"

#include <tbb/parallel_for.h>

#include <algorithm>

namespace vdbsurf {

using subdiv::HalfedgeMesh;
using Point = HalfedgeMesh::Point;

namespace {

// What a face carries into the next step.
enum FaceKind : std::uint8_t {
    kPlain = 0,       // next face point is the vertex average
    kStoredPoint = 1, // merged quad of an odd step: next face point is the stored edge point
    kBoundaryEdge = 2 // fan triangle on a boundary edge: the even step splits that edge at the stored midpoint
};

template <typename F>
void parallelIndices(std::size_t n, F&& f) {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 1024), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) f(i);
    });
}

} // namespace

struct Sqrt2Subdivider::Impl {
    HalfedgeMesh mesh;
    OpenMesh::FPropHandleT<Point> storedPoint;
    OpenMesh::FPropHandleT<std::uint8_t> kind;
    OpenMesh::FPropHandleT<std::uint32_t> tag;
    TagMerge merge = TagMerge::Max;
    int steps = 0;
    std::size_t splitVertices = 0;

    Point centroid(HalfedgeMesh::FaceHandle f) const {
        Point c(0, 0, 0);
        int n = 0;
        for (const auto v : mesh.fv_range(f)) {
            c += mesh.point(v);
            ++n;
        }
        return c / double(n);
    }

    std::uint32_t combine(std::uint32_t a, std::uint32_t b) const { return merge == TagMerge::Max ? std::max(a, b) : (a | b); }

    void step(const std::vector<std::uint8_t>& refine);
};

Sqrt2Subdivider::Sqrt2Subdivider(const Mesh& mesh, const std::string& inputName) : mImpl(new Impl) {
    mImpl->splitVertices = subdiv::buildHalfedgeMesh(mesh, inputName, mImpl->mesh);
    mImpl->mesh.add_property(mImpl->storedPoint);
    mImpl->mesh.add_property(mImpl->kind);
    mImpl->mesh.add_property(mImpl->tag);
    for (const auto f : mImpl->mesh.faces()) {
        mImpl->mesh.property(mImpl->kind, f) = kPlain;
        mImpl->mesh.property(mImpl->tag, f) = 0;
    }
}

Sqrt2Subdivider::~Sqrt2Subdivider() = default;

int Sqrt2Subdivider::stepsDone() const { return mImpl->steps; }
std::size_t Sqrt2Subdivider::splitVertices() const { return mImpl->splitVertices; }
std::size_t Sqrt2Subdivider::faceCount() const { return mImpl->mesh.n_faces(); }
std::size_t Sqrt2Subdivider::vertexCount() const { return mImpl->mesh.n_vertices(); }

void Sqrt2Subdivider::setTags(const std::vector<std::uint32_t>& tags, TagMerge merge) {
    if (tags.size() != faceCount()) throw std::invalid_argument("Sqrt2Subdivider::setTags: one tag per face");
    mImpl->merge = merge;
    for (const auto f : mImpl->mesh.faces()) mImpl->mesh.property(mImpl->tag, f) = tags[std::size_t(f.idx())];
}

std::vector<std::uint32_t> Sqrt2Subdivider::tags() const {
    std::vector<std::uint32_t> out(faceCount());
    for (const auto f : mImpl->mesh.faces()) out[std::size_t(f.idx())] = mImpl->mesh.property(mImpl->tag, f);
    return out;
}

void Sqrt2Subdivider::step() { step(std::vector<std::uint8_t>(faceCount(), 1)); }

void Sqrt2Subdivider::step(const std::vector<std::uint8_t>& refine) {
    if (refine.size() != faceCount()) throw std::invalid_argument("Sqrt2Subdivider::step: one flag per face");
    mImpl->step(refine);
}

void Sqrt2Subdivider::Impl::step(const std::vector<std::uint8_t>& refine) {
    HalfedgeMesh& m = mesh;
    const bool odd = steps % 2 == 0; // the step about to run is step steps + 1
    const std::size_t nF = m.n_faces(), nE = m.n_edges(), nV = m.n_vertices();
    auto refined = [&](HalfedgeMesh::FaceHandle f) { return f.is_valid() && refine[std::size_t(f.idx())] != 0; };

    // Face points: stored ones on the even step, vertex averages otherwise.
    std::vector<Point> facePoint(nF);
    std::size_t refinedCount = 0;
    for (std::size_t f = 0; f < nF; ++f) refinedCount += refine[f] != 0;
    if (refinedCount == 0) {
        ++steps;
        return;
    }
    parallelIndices(nF, [&](std::size_t i) {
        if (!refine[i]) return;
        const auto f = m.face_handle(int(i));
        facePoint[i] = (!odd && m.property(kind, f) != kPlain) ? m.property(storedPoint, f) : centroid(f);
    });

    // Edges whose two faces are both refined disappear; on the odd step their Catmull-Clark edge
    // points move to the merged quads, and boundary edges beside a refined face keep a midpoint.
    std::vector<int> removed;
    removed.reserve(nE);
    std::vector<Point> edgePoint(odd ? nE : 0);
    for (std::size_t e = 0; e < nE; ++e) {
        const auto eh = m.edge_handle(int(e));
        const auto f0 = m.face_handle(m.halfedge_handle(eh, 0)), f1 = m.face_handle(m.halfedge_handle(eh, 1));
        if (refined(f0) && refined(f1)) removed.push_back(int(e));
    }
    if (odd) {
        parallelIndices(nE, [&](std::size_t e) {
            const auto eh = m.edge_handle(int(e));
            const auto h0 = m.halfedge_handle(eh, 0), h1 = m.halfedge_handle(eh, 1);
            const auto f0 = m.face_handle(h0), f1 = m.face_handle(h1);
            const Point& a = m.point(m.to_vertex_handle(h0));
            const Point& b = m.point(m.to_vertex_handle(h1));
            if (refined(f0) && refined(f1))
                edgePoint[e] = (a + b + facePoint[std::size_t(f0.idx())] + facePoint[std::size_t(f1.idx())]) * 0.25;
            else if ((!f0.is_valid() && refined(f1)) || (!f1.is_valid() && refined(f0)))
                edgePoint[e] = (a + b) * 0.5;
        });
    }

    // Vertex moves (odd step only), for vertices whose every face is refined now.
    std::vector<Point> moved(odd ? nV : 0);
    std::vector<std::uint8_t> moves(odd ? nV : 0, 0);
    if (odd) {
        parallelIndices(nV, [&](std::size_t i) {
            const auto v = m.vertex_handle(int(i));
            if (m.is_isolated(v)) return;
            int valence = 0;
            Point faceSum(0, 0, 0), neighbourSum(0, 0, 0), boundarySum(0, 0, 0);
            for (const auto h : m.voh_range(v)) {
                const auto f = m.face_handle(h);
                if (f.is_valid()) {
                    if (!refined(f)) return;
                    faceSum += facePoint[std::size_t(f.idx())];
                }
                const Point& w = m.point(m.to_vertex_handle(h));
                neighbourSum += w;
                if (m.is_boundary(m.edge_handle(h))) boundarySum += w;
                ++valence;
            }
            const Point& s = m.point(v);
            if (m.is_boundary(v)) {
                // Crease rule of a smooth boundary (OpenSubdiv's edge-only interpolation).
                moved[i] = s * 0.75 + boundarySum * 0.125;
            } else {
                // Eq. (1): Q/n + 2R/n + S(n − 3)/n, with R the average of edge midpoints.
                const double n = valence;
                const Point q = faceSum / n;
                const Point r = (s * n + neighbourSum) / (2.0 * n);
                moved[i] = q / n + r * (2.0 / n) + s * ((n - 3.0) / n);
            }
            moves[i] = 1;
        });
    }

    // Topology, in index order.
    m.reserve(nV + refinedCount, nE + 3 * refinedCount + m.n_halfedges() / 2, nF + m.n_halfedges());
    std::vector<HalfedgeMesh::FaceHandle> fan;
    for (std::size_t i = 0; i < nF; ++i) {
        if (!refine[i]) continue;
        const auto f = m.face_handle(int(i));
        const auto vh = m.add_vertex(facePoint[i]);
        if (!odd && m.property(kind, f) == kBoundaryEdge) {
            // Split the boundary edge at its midpoint and join the midpoint to the apex.
            HalfedgeMesh::HalfedgeHandle onBoundary;
            for (const auto h : m.fh_range(f))
                if (m.is_boundary(m.opposite_halfedge_handle(h))) onBoundary = h;
            const auto apex = m.to_vertex_handle(m.next_halfedge_handle(onBoundary));
            m.split_edge(m.edge_handle(onBoundary), vh);
            HalfedgeMesh::HalfedgeHandle intoMid, outOfApex;
            for (const auto h : m.fh_range(f)) {
                if (m.to_vertex_handle(h) == vh) intoMid = h;
                if (m.from_vertex_handle(h) == apex) outOfApex = h;
            }
            const auto joined = m.insert_edge(intoMid, outOfApex);
            const auto other = m.face_handle(joined);
            const auto keep = m.face_handle(m.opposite_halfedge_handle(joined));
            for (const auto g : {other, keep}) {
                m.property(kind, g) = kPlain;
                m.property(tag, g) = m.property(tag, f);
            }
            continue;
        }
        m.split_copy(f, vh);
        for (const auto g : m.vf_range(vh)) m.property(kind, g) = kPlain;
        if (odd)
            for (const auto h : m.voh_range(vh)) {
                // The fan triangle's old edge is opposite vh; if it lies on the boundary, the
                // triangle remembers the edge's midpoint for the even step.
                const auto old = m.next_halfedge_handle(h);
                if (m.is_boundary(m.opposite_halfedge_handle(old))) {
                    const auto g = m.face_handle(h);
                    m.property(kind, g) = kBoundaryEdge;
                    m.property(storedPoint, g) = edgePoint[std::size_t(m.edge_handle(old).idx())];
                }
            }
    }
    if (odd)
        for (std::size_t i = 0; i < nV; ++i)
            if (moves[i]) m.set_point(m.vertex_handle(int(i)), moved[i]);

    for (const int e : removed) {
        const auto eh = m.edge_handle(e);
        const auto f0 = m.face_handle(m.halfedge_handle(eh, 0)), f1 = m.face_handle(m.halfedge_handle(eh, 1));
        const std::uint32_t t = combine(m.property(tag, f0), m.property(tag, f1));
        const auto merged = m.remove_edge(eh);
        m.property(tag, merged) = t;
        if (odd) {
            m.property(kind, merged) = kStoredPoint;
            m.property(storedPoint, merged) = edgePoint[std::size_t(e)];
        } else {
            m.property(kind, merged) = kPlain;
        }
    }
    m.garbage_collection();
    ++steps;
}

Mesh Sqrt2Subdivider::mesh() const { return subdiv::toMesh(mImpl->mesh); }

std::vector<Vec3d> Sqrt2Subdivider::positions() const {
    std::vector<Vec3d> out;
    out.reserve(vertexCount());
    for (const auto v : mImpl->mesh.vertices()) {
        const Point& p = mImpl->mesh.point(v);
        out.emplace_back(p[0], p[1], p[2]);
    }
    return out;
}

void Sqrt2Subdivider::faceCorners(std::size_t f, std::vector<Vec3d>& out) const {
    out.clear();
    for (const auto v : mImpl->mesh.fv_range(mImpl->mesh.face_handle(int(f)))) {
        const Point& p = mImpl->mesh.point(v);
        out.emplace_back(p[0], p[1], p[2]);
    }
}

void Sqrt2Subdivider::faceVertices(std::size_t f, std::vector<std::uint32_t>& out) const {
    out.clear();
    for (const auto v : mImpl->mesh.fv_range(mImpl->mesh.face_handle(int(f)))) out.push_back(std::uint32_t(v.idx()));
}

void Sqrt2Subdivider::edgeFaces(std::vector<std::pair<std::int64_t, std::int64_t>>& out,
                                std::vector<std::pair<std::uint32_t, std::uint32_t>>* edgeVertices) const {
    const HalfedgeMesh& m = mImpl->mesh;
    out.resize(m.n_edges());
    if (edgeVertices) edgeVertices->resize(m.n_edges());
    for (const auto e : m.edges()) {
        const auto h0 = m.halfedge_handle(e, 0), h1 = m.halfedge_handle(e, 1);
        out[std::size_t(e.idx())] = {m.face_handle(h0).idx(), m.face_handle(h1).idx()};
        if (edgeVertices)
            (*edgeVertices)[std::size_t(e.idx())] = {std::uint32_t(m.to_vertex_handle(h0).idx()), std::uint32_t(m.to_vertex_handle(h1).idx())};
    }
}

Mesh subdivideUniform(const Mesh& mesh, int steps, const std::string& inputName) {
    Sqrt2Subdivider s(mesh, inputName);
    for (int i = 0; i < steps; ++i) s.step();
    return s.mesh();
}

Mesh subdivideAdaptive(const Mesh& mesh, const std::vector<int>& targetSteps, const std::string& inputName) {
    if (targetSteps.size() != mesh.polygonCount()) throw Error(inputName, "adaptive subdivision needs one target depth per polygon");
    Sqrt2Subdivider s(mesh, inputName);
    // Faces dropped by buildHalfedgeMesh do not exist: face order equals polygon order.
    std::vector<std::uint32_t> tags(targetSteps.size());
    int deepest = 0;
    for (std::size_t i = 0; i < tags.size(); ++i) {
        if (targetSteps[i] < 0) throw Error(inputName, "a target depth is negative");
        tags[i] = std::uint32_t(targetSteps[i]);
        deepest = std::max(deepest, targetSteps[i]);
    }
    s.setTags(tags, Sqrt2Subdivider::TagMerge::Max);
    for (int i = 1; i <= deepest; ++i) {
        const std::vector<std::uint32_t> t = s.tags();
        std::vector<std::uint8_t> refine(t.size());
        // Faces that stopped earlier must stay stopped (only the previous step's faces may refine),
        // so a stopped face's tag is cleared when it stops.
        for (std::size_t f = 0; f < t.size(); ++f) refine[f] = t[f] >= std::uint32_t(i);
        s.step(refine);
    }
    return s.mesh();
}

} // namespace vdbsurf
