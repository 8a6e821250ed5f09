// Numbering, for an old halfedge h in face f with face point P (vertex nV + f):
//   A(h) = 2·slot(h)       the spoke to(h) → P            (the piece of h, in the new face of h's edge)
//   B(h) = 2·slot(h) + 1   the spoke P → to(h), i.e. the spoke out of P of next(h)'s piece
// so the pair {A(h), B(h)} is one new edge, as OpenMesh wants (opposite = index ^ 1). An old
// boundary halfedge b whose edge is kept gives the kept edge: A(b) inside the fan triangle,
// B(b) on the new boundary. Where the even step splits a boundary edge at the stored midpoint
// M instead, the piece of h is missing: A(h) = to(h) → M and B(prev h) = M → from(h) are the
// two new boundary halves, and b gets no edge (slots are then compacted by rank).
#include "vdbsurf/subdiv/uniform_step.h"

#include <algorithm>

namespace vdbsurf::subdiv {

namespace {

using VH = HalfedgeMesh::VertexHandle;
using HH = HalfedgeMesh::HalfedgeHandle;
using FH = HalfedgeMesh::FaceHandle;
using Point = HalfedgeMesh::Point;

// Rank of each entry among the entries not dropped (block-wise in parallel); returns the count kept.
std::size_t rankKept(std::size_t n, const std::vector<std::uint8_t>& dropped, std::vector<std::uint32_t>& rank) {
    constexpr std::size_t kBlock = 1 << 15;
    const std::size_t blocks = (n + kBlock - 1) / kBlock;
    std::vector<std::size_t> start(blocks + 1, 0);
    parallelFor(blocks, [&](std::size_t b) {
        const std::size_t end = std::min(n, (b + 1) * kBlock);
        std::size_t kept = 0;
        for (std::size_t i = b * kBlock; i < end; ++i) kept += !dropped[i];
        start[b + 1] = kept;
    });
    for (std::size_t b = 0; b < blocks; ++b) start[b + 1] += start[b];
    rank.resize(n);
    parallelFor(blocks, [&](std::size_t b) {
        const std::size_t end = std::min(n, (b + 1) * kBlock);
        std::uint32_t r = std::uint32_t(start[b]);
        for (std::size_t i = b * kBlock; i < end; ++i) {
            rank[i] = r;
            r += !dropped[i];
        }
    });
    return start[blocks];
}

} // namespace

void refineEveryFace(const HalfedgeMesh& from, const FaceProperties& props, bool odd, bool mergeByOr, HalfedgeMesh& to) {
    const std::size_t nV = from.n_vertices(), nE = from.n_edges(), nH = from.n_halfedges(), nF = from.n_faces();
    // The even step splits the boundary edge of a fan triangle made on it by the odd step.
    auto splitsBoundary = [&](HH h) {
        if (odd) return false;
        const FH f = from.face_handle(h);
        return f.is_valid() && from.property(props.kind, f) == kBoundaryEdge && from.is_boundary(from.opposite_halfedge_handle(h));
    };

    std::vector<std::uint8_t> dropEdge;
    std::vector<std::uint32_t> edgeSlot, faceSlot;
    std::size_t newEdges = nH, newFaces = nE;
    if (!odd) {
        dropEdge.assign(nE, 0);
        parallelFor(nE, [&](std::size_t e) { dropEdge[e] = splitsBoundary(HH(int(2 * e))) || splitsBoundary(HH(int(2 * e + 1))); });
        if (std::find(dropEdge.begin(), dropEdge.end(), 1) != dropEdge.end()) {
            newFaces = rankKept(nE, dropEdge, faceSlot);
            std::vector<std::uint8_t> dropHalfedge(nH);
            parallelFor(nH, [&](std::size_t h) { dropHalfedge[h] = dropEdge[h >> 1] && from.is_boundary(HH(int(h))); });
            newEdges = rankKept(nH, dropHalfedge, edgeSlot);
        } else {
            dropEdge.clear();
        }
    }
    auto slot = [&](HH h) { return edgeSlot.empty() ? std::uint32_t(h.idx()) : edgeSlot[std::size_t(h.idx())]; };
    auto A = [&](HH h) { return HH(int(2 * slot(h))); };
    auto B = [&](HH h) { return HH(int(2 * slot(h) + 1)); };
    auto newFace = [&](std::size_t e) { return FH(int(faceSlot.empty() ? e : faceSlot[e])); };
    auto facePointVertex = [&](FH f) { return VH(int(nV + std::size_t(f.idx()))); };
    // The first new boundary halfedge along the old boundary halfedge b.
    auto firstAlong = [&](HH b) {
        const HH inner = from.opposite_halfedge_handle(b);
        return splitsBoundary(inner) ? A(inner) : B(b);
    };

    to.clean();
    to.resize(nV + nF, newEdges, newFaces);

    // Face points first: the vertex rule and the edge points read them from `to`.
    parallelFor(nF, [&](std::size_t i) { to.set_point(VH(int(nV + i)), nextFacePoint(from, props, FH{int(i)}, odd)); });

    // Connectivity, from each old halfedge inside a face: its piece's spoke pair, and the kept or
    // split boundary edge beside it.
    parallelFor(nH, [&](std::size_t i) {
        const HH h{int(i)};
        const FH f = from.face_handle(h);
        if (!f.is_valid()) return;
        const HH prev = from.prev_halfedge_handle(h), opp = from.opposite_halfedge_handle(h);
        const VH u = from.to_vertex_handle(opp), w = from.to_vertex_handle(h);
        const HH in = A(h), out = B(prev);
        to.set_vertex_handle(in, facePointVertex(f));
        to.set_vertex_handle(out, u);
        if (splitsBoundary(h)) {
            to.set_boundary(in);
            to.set_boundary(out);
            to.set_next_halfedge_handle(in, out);
            to.set_next_halfedge_handle(out, firstAlong(from.next_halfedge_handle(opp)));
            return;
        }
        const FH F = newFace(i >> 1);
        to.set_face_handle(in, F);
        to.set_face_handle(out, F);
        to.set_next_halfedge_handle(in, out);
        to.set_next_halfedge_handle(out, A(opp));
        if (from.is_boundary(opp)) {
            const HH kept = A(opp), border = B(opp);
            to.set_vertex_handle(kept, w);
            to.set_face_handle(kept, F);
            to.set_next_halfedge_handle(kept, in);
            to.set_vertex_handle(border, u);
            to.set_boundary(border);
            to.set_next_halfedge_handle(border, firstAlong(from.next_halfedge_handle(opp)));
        }
    });

    // Old vertices: outgoing halfedge (the boundary one on a boundary, as OpenMesh requires) and
    // position (moved on the odd step).
    parallelFor(nV, [&](std::size_t i) {
        const VH v{int(i)};
        const Point& s = from.point(v);
        const HH first = from.halfedge_handle(v);
        if (!first.is_valid()) {
            to.set_point(v, s);
            return;
        }
        const bool boundary = from.is_boundary(first);
        to.set_halfedge_handle(v, boundary ? firstAlong(first) : A(from.opposite_halfedge_handle(first)));
        if (!odd) {
            to.set_point(v, s);
            return;
        }
        int valence = 0;
        Point faceSum(0, 0, 0), neighbourSum(0, 0, 0), boundarySum(0, 0, 0);
        HH h = first;
        do {
            const FH f = from.face_handle(h);
            const HH opp = from.opposite_halfedge_handle(h);
            const Point& w = from.point(from.to_vertex_handle(h));
            if (f.is_valid()) faceSum += to.point(facePointVertex(f));
            if (!f.is_valid() || from.is_boundary(opp)) boundarySum += w;
            neighbourSum += w;
            ++valence;
            h = from.next_halfedge_handle(opp);
        } while (h != first);
        if (boundary) {
            // Crease rule of a smooth boundary (OpenSubdiv's edge-only interpolation).
            to.set_point(v, s * 0.75 + boundarySum * 0.125);
        } else {
            // Eq. (1): Q/n + 2R/n + S(n − 3)/n, with R the average of edge midpoints.
            const double n = valence;
            const Point q = faceSum / n;
            const Point r = (s * n + neighbourSum) / (2.0 * n);
            to.set_point(v, q / n + r * (2.0 / n) + s * ((n - 3.0) / n));
        }
    });

    // Face points' outgoing halfedge: the spoke out of P of the face's first piece, or on the
    // even step the new boundary half M → from(h) where the face's boundary edge is split.
    parallelFor(nF, [&](std::size_t i) {
        const FH f{int(i)};
        HH pick = from.halfedge_handle(f);
        if (!odd && from.property(props.kind, f) == kBoundaryEdge) {
            HH h = pick;
            do {
                if (splitsBoundary(h)) pick = h;
                h = from.next_halfedge_handle(h);
            } while (h != from.halfedge_handle(f));
        }
        to.set_halfedge_handle(facePointVertex(f), B(from.prev_halfedge_handle(pick)));
    });

    // New faces, one per old edge: the merged quad (u, P_g, w, P_f) starting at the edge's first
    // halfedge's start, or the fan triangle (u, w, P) on a kept boundary edge.
    auto combine = [&](std::uint32_t a, std::uint32_t b) { return mergeByOr ? (a | b) : std::max(a, b); };
    parallelFor(nE, [&](std::size_t e) {
        if (!dropEdge.empty() && dropEdge[e]) return;
        const HH h0(int(2 * e)), h1(int(2 * e + 1));
        const FH f0 = from.face_handle(h0), f1 = from.face_handle(h1), F = newFace(e);
        const Point& a = from.point(from.to_vertex_handle(h0));
        const Point& b = from.point(from.to_vertex_handle(h1));
        if (f0.is_valid() && f1.is_valid()) {
            to.set_halfedge_handle(F, A(h1));
            to.property(props.kind, F) = odd ? kStoredPoint : kPlain;
            to.property(props.storedPoint, F) =
                odd ? (a + b + to.point(facePointVertex(f0)) + to.point(facePointVertex(f1))) * 0.25 : Point(0, 0, 0);
            to.property(props.tag, F) = combine(from.property(props.tag, f0), from.property(props.tag, f1));
        } else {
            const HH inner = f0.is_valid() ? h0 : h1;
            to.set_halfedge_handle(F, A(from.opposite_halfedge_handle(inner)));
            to.property(props.kind, F) = odd ? kBoundaryEdge : kPlain;
            to.property(props.storedPoint, F) = odd ? (a + b) * 0.5 : Point(0, 0, 0);
            to.property(props.tag, F) = from.property(props.tag, from.face_handle(inner));
        }
    });
}

} // namespace vdbsurf::subdiv
