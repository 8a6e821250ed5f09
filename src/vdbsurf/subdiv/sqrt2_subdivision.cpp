// One √2 step reads the old level and writes the new one whole: face points, edge points and
// vertex moves from the old mesh; the new polygons face by face (counted, prefix-summed, then
// filled, all in parallel, each value depending only on the old mesh, so the thread count
// cannot change the result); then subdiv::assemble() links the halfedges of the new level.
// A step that refines every face goes through subdiv::refineEveryFace instead, which writes the
// next level into the second mesh by arithmetic numbering.
#include "vdbsurf/subdiv/sqrt2_subdivision.h"

#include "vdbsurf/core/error.h"
#include "vdbsurf/core/free_memory.h"
#include "vdbsurf/subdiv/halfedge_mesh.h"
#include "vdbsurf/subdiv/uniform_step.h"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace vdbsurf {

using subdiv::HalfedgeMesh;
using Point = HalfedgeMesh::Point;

using subdiv::kBoundaryEdge;
using subdiv::kPlain;
using subdiv::kStoredPoint;

struct Sqrt2Subdivider::Impl {
    // The current level and the spare a full step writes the next level into; they swap roles.
    HalfedgeMesh meshes[2];
    int current = 0;
    subdiv::FaceProperties props;
    TagMerge merge = TagMerge::Max;
    bool alwaysGeneral = false;

    HalfedgeMesh& mesh() { return meshes[current]; }
    const HalfedgeMesh& mesh() const { return meshes[current]; }
    int steps = 0;
    std::size_t splitVertices = 0;
    std::string inputName;
    double memoryLimit = 0; // bytes; 0: no limit known
    bool limitGiven = false; // by setMemoryLimit, not from the memory free

    std::size_t facesAfter(const std::vector<std::uint8_t>& refine, bool all) const;
    void checkMemory(double faces, int stepsMore) const;

    std::uint32_t combine(std::uint32_t a, std::uint32_t b) const { return merge == TagMerge::Max ? std::max(a, b) : (a | b); }

    void step(const std::vector<std::uint8_t>& refine);
};

Sqrt2Subdivider::Sqrt2Subdivider(const Mesh& mesh, const std::string& inputName) : mImpl(new Impl) {
    mImpl->inputName = inputName;
    // Before the halfedge mesh takes its share: the limit covers everything the refinement holds.
    mImpl->memoryLimit = memoryBudgetBytes();
    HalfedgeMesh& m = mImpl->mesh();
    mImpl->splitVertices = subdiv::buildHalfedgeMesh(mesh, inputName, m);
    subdiv::FaceProperties& props = mImpl->props;
    m.add_property(props.storedPoint);
    m.add_property(props.kind);
    m.add_property(props.tag);
    subdiv::FaceProperties spare;
    HalfedgeMesh& other = mImpl->meshes[1 - mImpl->current];
    other.add_property(spare.storedPoint);
    other.add_property(spare.kind);
    other.add_property(spare.tag);
    if (spare.storedPoint != props.storedPoint || spare.kind != props.kind || spare.tag != props.tag)
        throw std::logic_error("Sqrt2Subdivider: the two meshes registered their properties differently");
    for (const auto f : m.faces()) {
        m.property(props.kind, f) = kPlain;
        m.property(props.tag, f) = 0;
    }
}

Sqrt2Subdivider::~Sqrt2Subdivider() = default;

int Sqrt2Subdivider::stepsDone() const { return mImpl->steps; }
std::size_t Sqrt2Subdivider::splitVertices() const { return mImpl->splitVertices; }
std::size_t Sqrt2Subdivider::faceCount() const { return mImpl->mesh().n_faces(); }
std::size_t Sqrt2Subdivider::vertexCount() const { return mImpl->mesh().n_vertices(); }

void Sqrt2Subdivider::setTags(const std::vector<std::uint32_t>& tags, TagMerge merge) {
    if (tags.size() != faceCount()) throw std::invalid_argument("Sqrt2Subdivider::setTags: one tag per face");
    mImpl->merge = merge;
    for (const auto f : mImpl->mesh().faces()) mImpl->mesh().property(mImpl->props.tag, f) = tags[std::size_t(f.idx())];
}

std::vector<std::uint32_t> Sqrt2Subdivider::tags() const {
    std::vector<std::uint32_t> out(faceCount());
    for (const auto f : mImpl->mesh().faces()) out[std::size_t(f.idx())] = mImpl->mesh().property(mImpl->props.tag, f);
    return out;
}

void Sqrt2Subdivider::setAlwaysGeneral(bool general) { mImpl->alwaysGeneral = general; }

void Sqrt2Subdivider::step() { step(std::vector<std::uint8_t>(faceCount(), 1)); }

void Sqrt2Subdivider::step(const std::vector<std::uint8_t>& refine) {
    if (refine.size() != faceCount()) throw std::invalid_argument("Sqrt2Subdivider::step: one flag per face");
    mImpl->step(refine);
}

void Sqrt2Subdivider::setMemoryLimit(double bytes) {
    mImpl->limitGiven = bytes > 0;
    mImpl->memoryLimit = memoryBudgetBytes(bytes);
}

std::size_t Sqrt2Subdivider::Impl::facesAfter(const std::vector<std::uint8_t>& refine, bool all) const {
    const HalfedgeMesh& m = mesh();
    if (all) return m.n_edges();
    std::size_t faces = 0;
    for (std::size_t f = 0; f < refine.size(); ++f) faces += refine[f] == 0;
    for (const auto e : m.edges()) {
        const auto f0 = m.face_handle(m.halfedge_handle(e, 0)), f1 = m.face_handle(m.halfedge_handle(e, 1));
        faces += (f0.is_valid() && refine[std::size_t(f0.idx())]) || (f1.is_valid() && refine[std::size_t(f1.idx())]);
    }
    return faces;
}

std::size_t Sqrt2Subdivider::facesAfterStep(const std::vector<std::uint8_t>& refine) const {
    if (refine.size() != faceCount()) throw std::invalid_argument("Sqrt2Subdivider::facesAfterStep: one flag per face");
    return mImpl->facesAfter(refine, std::find(refine.begin(), refine.end(), 0) == refine.end());
}

void Sqrt2Subdivider::Impl::checkMemory(double faces, int stepsMore) const {
    const double bytes = faces * kBytesPerFace;
    if (memoryLimit <= 0 || bytes <= memoryLimit) return;
    const double gib = double(1 << 30);
    std::ostringstream s;
    s.precision(3);
    s << "refining it to " << steps + stepsMore << " sqrt2 steps would make about " << faces << " polygons, which need about "
      << bytes / gib << " GiB, and " << memoryLimit / gib << " GiB may be used"
      << (limitGiven ? "" : " (80 % of the memory free when it started)") << "; refine it less";
    throw Error(inputName, s.str());
}

void Sqrt2Subdivider::checkUniformSteps(int steps) const {
    if (steps <= 0) return;
    // One polygon per edge after the first step; each further step doubles both.
    mImpl->checkMemory(double(mImpl->mesh().n_edges()) * std::ldexp(1.0, steps - 1), steps);
}

void Sqrt2Subdivider::Impl::step(const std::vector<std::uint8_t>& refine) {
    const bool odd = steps % 2 == 0; // the step about to run is step steps + 1
    const bool all = std::find(refine.begin(), refine.end(), 0) == refine.end();
    checkMemory(double(facesAfter(refine, all)), 1);
    if (!alwaysGeneral && all) {
        HalfedgeMesh& next = meshes[1 - current];
        subdiv::refineEveryFace(mesh(), props, odd, merge == TagMerge::BitOr, next);
        releaseSpare(mesh(), props);
        current = 1 - current;
        ++steps;
        return;
    }
    HalfedgeMesh& m = mesh();
    const std::size_t nF = m.n_faces(), nE = m.n_edges(), nV = m.n_vertices();
    auto refined = [&](HalfedgeMesh::FaceHandle f) { return f.is_valid() && refine[std::size_t(f.idx())] != 0; };

    // New vertex of each refined face: nV + its rank among refined faces.
    std::vector<std::uint32_t> newVertex(nF, 0);
    std::uint32_t next = std::uint32_t(nV);
    for (std::size_t f = 0; f < nF; ++f)
        if (refine[f]) newVertex[f] = next++;
    if (next == nV) {
        ++steps;
        return;
    }

    // Face points: stored ones on the even step, vertex averages otherwise. On the even step a
    // boundary triangle's stored point is its boundary edge's midpoint, where the edge splits.
    std::vector<Point> facePoint(nF);
    subdiv::parallelFor(nF, [&](std::size_t i) {
        if (!refine[i]) return;
        const auto f = m.face_handle(int(i));
        facePoint[i] = subdiv::nextFacePoint(m, props, f, odd);
    });

    // Edges whose two faces are both refined disappear; on the odd step their Catmull-Clark edge
    // points go to the merged quads, and boundary edges beside a refined face keep a midpoint.
    std::vector<std::uint8_t> removed(nE);
    std::vector<Point> edgePoint(odd ? nE : 0);
    subdiv::parallelFor(nE, [&](std::size_t e) {
        const auto eh = m.edge_handle(int(e));
        const auto h0 = m.halfedge_handle(eh, 0), h1 = m.halfedge_handle(eh, 1);
        const auto f0 = m.face_handle(h0), f1 = m.face_handle(h1);
        removed[e] = refined(f0) && refined(f1);
        if (!odd) return;
        const Point& a = m.point(m.to_vertex_handle(h0));
        const Point& b = m.point(m.to_vertex_handle(h1));
        if (removed[e]) edgePoint[e] = (a + b + facePoint[std::size_t(f0.idx())] + facePoint[std::size_t(f1.idx())]) * 0.25;
        else if ((!f0.is_valid() && refined(f1)) || (!f1.is_valid() && refined(f0))) edgePoint[e] = (a + b) * 0.5;
    });

    // New positions: old vertices (moved on the odd step when every face around them is
    // refined), then the face points.
    std::vector<Point> position(next);
    subdiv::parallelFor(nV, [&](std::size_t i) {
        const auto v = m.vertex_handle(int(i));
        const Point& s = m.point(v);
        position[i] = s;
        if (!odd || m.is_isolated(v)) return;
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
        if (m.is_boundary(v)) {
            // Crease rule of a smooth boundary (OpenSubdiv's edge-only interpolation).
            position[i] = s * 0.75 + boundarySum * 0.125;
        } else {
            // Eq. (1): Q/n + 2R/n + S(n − 3)/n, with R the average of edge midpoints.
            const double n = valence;
            const Point q = faceSum / n;
            const Point r = (s * n + neighbourSum) / (2.0 * n);
            position[i] = q / n + r * (2.0 / n) + s * ((n - 3.0) / n);
        }
    });
    subdiv::parallelFor(nF, [&](std::size_t f) {
        if (refine[f]) position[newVertex[f]] = facePoint[f];
    });

    // The new polygons, face by face: an unrefined face as it is; a refined face's piece per
    // halfedge u -> w is the triangle (u, w, P); two pieces across a removed edge are one quad
    // (u, P_g, w, P_f), made by the face holding the edge's first halfedge. On the even step a
    // boundary triangle has no piece on its boundary halfedge: that edge is split at P instead.
    auto skipsHalfedge = [&](HalfedgeMesh::FaceHandle f, HalfedgeMesh::HalfedgeHandle h) {
        return !odd && m.property(props.kind, f) == kBoundaryEdge && m.is_boundary(m.opposite_halfedge_handle(h));
    };
    std::vector<std::uint32_t> polyCount(nF + 1, 0), cornerCount(nF + 1, 0);
    subdiv::parallelFor(nF, [&](std::size_t i) {
        const auto f = m.face_handle(int(i));
        std::uint32_t polys = 0, corners = 0;
        if (!refine[i]) {
            polys = 1;
            corners = std::uint32_t(m.valence(f));
        } else {
            for (const auto h : m.fh_range(f)) {
                if (skipsHalfedge(f, h)) continue;
                if (!removed[std::size_t(m.edge_handle(h).idx())]) {
                    ++polys;
                    corners += 3;
                } else if ((h.idx() & 1) == 0) {
                    ++polys;
                    corners += 4;
                }
            }
        }
        polyCount[i + 1] = polys;
        cornerCount[i + 1] = corners;
    });
    for (std::size_t i = 0; i < nF; ++i) {
        polyCount[i + 1] += polyCount[i];
        cornerCount[i + 1] += cornerCount[i];
    }
    const std::size_t newF = polyCount[nF];
    std::vector<std::uint32_t> offsets(newF + 1), indices(cornerCount[nF]);
    std::vector<std::uint8_t> newKind(newF);
    std::vector<Point> newStored(newF);
    std::vector<std::uint32_t> newTag(newF);
    offsets[newF] = cornerCount[nF];
    // Where each old halfedge's piece put its corners: the old edge u -> w (kept edges and
    // unrefined faces), the spoke w -> P and the spoke P -> u. Each is written by one face only.
    constexpr std::uint32_t kNone = ~0u;
    const std::size_t nH = m.n_halfedges();
    std::vector<std::uint32_t> edgeCorner(nH, kNone), spokeIn(nH, kNone), spokeOut(nH, kNone);
    subdiv::parallelFor(nF, [&](std::size_t i) {
        const auto f = m.face_handle(int(i));
        std::uint32_t p = polyCount[i], c = cornerCount[i];
        const std::uint32_t fTag = m.property(props.tag, f);
        if (!refine[i]) {
            offsets[p] = c;
            // From the face's first halfedge's start, so a face left alone keeps its corner order.
            for (const auto h : m.fh_range(f)) {
                edgeCorner[std::size_t(h.idx())] = c;
                indices[c++] = std::uint32_t(m.from_vertex_handle(h).idx());
            }
            newKind[p] = m.property(props.kind, f);
            newStored[p] = m.property(props.storedPoint, f);
            newTag[p] = fTag;
            return;
        }
        const std::uint32_t pf = newVertex[i];
        for (const auto h : m.fh_range(f)) {
            if (skipsHalfedge(f, h)) continue;
            const std::size_t e = std::size_t(m.edge_handle(h).idx());
            const std::uint32_t u = std::uint32_t(m.from_vertex_handle(h).idx()), w = std::uint32_t(m.to_vertex_handle(h).idx());
            const std::size_t hi = std::size_t(h.idx());
            if (!removed[e]) {
                offsets[p] = c;
                edgeCorner[hi] = c;
                spokeIn[hi] = c + 1;
                spokeOut[hi] = c + 2;
                indices[c++] = u;
                indices[c++] = w;
                indices[c++] = pf;
                const bool onBoundary = odd && m.is_boundary(m.opposite_halfedge_handle(h));
                newKind[p] = onBoundary ? kBoundaryEdge : kPlain;
                if (onBoundary) newStored[p] = edgePoint[e];
                newTag[p] = fTag;
                ++p;
            } else if ((h.idx() & 1) == 0) {
                const auto g = m.face_handle(m.opposite_halfedge_handle(h));
                const std::size_t oi = std::size_t(m.opposite_halfedge_handle(h).idx());
                offsets[p] = c;
                spokeIn[oi] = c;
                spokeOut[oi] = c + 1;
                spokeIn[hi] = c + 2;
                spokeOut[hi] = c + 3;
                indices[c++] = u;
                indices[c++] = newVertex[std::size_t(g.idx())];
                indices[c++] = w;
                indices[c++] = pf;
                newKind[p] = odd ? kStoredPoint : kPlain;
                if (odd) newStored[p] = edgePoint[e];
                newTag[p] = combine(fTag, m.property(props.tag, g));
                ++p;
            }
        }
    });

    // Partners from the old structure: an old edge's corner pairs with its opposite's; a piece's
    // spoke into P pairs with the next halfedge's spoke out of P (none where the even step split
    // a boundary edge instead of making a piece).
    std::vector<std::uint32_t> partner(indices.size(), kNone);
    subdiv::parallelFor(nH, [&](std::size_t hi) {
        const HalfedgeMesh::HalfedgeHandle h{int(hi)};
        if (edgeCorner[hi] != kNone) partner[edgeCorner[hi]] = edgeCorner[std::size_t(m.opposite_halfedge_handle(h).idx())];
        if (spokeIn[hi] != kNone) partner[spokeIn[hi]] = spokeOut[std::size_t(m.next_halfedge_handle(h).idx())];
        if (spokeOut[hi] != kNone) partner[spokeOut[hi]] = spokeIn[std::size_t(m.prev_halfedge_handle(h).idx())];
    });
    subdiv::assemble(m, next, offsets, indices, partner);
    subdiv::parallelFor(next, [&](std::size_t i) { m.set_point(HalfedgeMesh::VertexHandle(int(i)), position[i]); });
    m.property(props.kind).data_vector() = std::move(newKind);
    m.property(props.storedPoint).data_vector() = std::move(newStored);
    m.property(props.tag).data_vector() = std::move(newTag);
    ++steps;
}

Mesh Sqrt2Subdivider::mesh() const { return subdiv::toMesh(mImpl->mesh()); }

std::vector<Vec3d> Sqrt2Subdivider::positions() const {
    std::vector<Vec3d> out;
    out.reserve(vertexCount());
    for (const auto v : mImpl->mesh().vertices()) {
        const Point& p = mImpl->mesh().point(v);
        out.emplace_back(p[0], p[1], p[2]);
    }
    return out;
}

void Sqrt2Subdivider::faceCorners(std::size_t f, std::vector<Vec3d>& out) const {
    out.clear();
    for (const auto v : mImpl->mesh().fv_range(mImpl->mesh().face_handle(int(f)))) {
        const Point& p = mImpl->mesh().point(v);
        out.emplace_back(p[0], p[1], p[2]);
    }
}

void Sqrt2Subdivider::faceVertices(std::size_t f, std::vector<std::uint32_t>& out) const {
    out.clear();
    for (const auto v : mImpl->mesh().fv_range(mImpl->mesh().face_handle(int(f)))) out.push_back(std::uint32_t(v.idx()));
}

void Sqrt2Subdivider::edgeFaces(std::vector<std::pair<std::int64_t, std::int64_t>>& faces,
                                std::vector<std::pair<std::uint32_t, std::uint32_t>>& vertices) const {
    const HalfedgeMesh& m = mImpl->mesh();
    faces.resize(m.n_edges());
    vertices.resize(m.n_edges());
    for (const auto e : m.edges()) {
        const auto h0 = m.halfedge_handle(e, 0), h1 = m.halfedge_handle(e, 1);
        faces[std::size_t(e.idx())] = {m.face_handle(h0).idx(), m.face_handle(h1).idx()};
        vertices[std::size_t(e.idx())] = {std::uint32_t(m.to_vertex_handle(h0).idx()), std::uint32_t(m.to_vertex_handle(h1).idx())};
    }
}

Mesh subdivideUniform(const Mesh& mesh, int steps, const std::string& inputName) {
    Sqrt2Subdivider s(mesh, inputName);
    s.checkUniformSteps(steps);
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
        // A face whose target is below i stopped earlier; its tag never rises again (merged faces
        // take the larger tag of two faces refined together), so it stays stopped.
        for (std::size_t f = 0; f < t.size(); ++f) refine[f] = t[f] >= std::uint32_t(i);
        s.step(refine);
    }
    return s.mesh();
}

} // namespace vdbsurf
