#include "vdbsurf/reeb/closed_surface.h"

#include "vdbsurf/core/error.h"
#include "vdbsurf/core/union_find.h"
#include "vdbsurf/mesh/fan_triangles.h"
#include "vdbsurf/mesh/mesh_folds.h"
#include "vdbsurf/mesh/vertex_fans.h"

#include <cmath>

namespace vdbsurf::reeb {

double ClosedSurface::meanEdgeLength() const {
    double sum = 0;
    std::size_t n = 0;
    for (std::uint32_t c = 0; c < vertex.size(); ++c)
        if (c < opposite[c]) {
            sum += length(points[vertex[next(c)]] - points[vertex[c]]);
            ++n;
        }
    return n ? sum / double(n) : 0.0;
}

namespace {

ClosedSurface buildFrom(const Mesh& mesh, const std::string& inputName) {
    if (mesh.empty()) throw Error(inputName, "the mesh has no polygons");
    for (std::size_t p = 0; p < mesh.polygonCount(); ++p) {
        const std::uint32_t n = mesh.polygonSize(p);
        const std::uint32_t* vs = mesh.polygon(p);
        if (n < 3) throw Error(inputName, "polygon " + std::to_string(p) + " has fewer than three corners");
        for (std::uint32_t i = 0; i < n; ++i)
            for (std::uint32_t j = i + 1; j < n; ++j)
                if (vs[i] == vs[j])
                    throw Error(inputName, "polygon " + std::to_string(p) + " uses vertex " + std::to_string(vs[i]) + " twice");
    }
    // A vertex in two polygons only, which run opposite ways round it: a fold (a fin of no area,
    // as a weld can leave) or, in a modelled mesh, a vertex left on an edge by dissolving edges
    // (valence 2). Fanned from their first corners the two put an edge in four triangles; named
    // as what it is rather than as that edge. (fanIntoTriangles would triangulate it manifold;
    // taking it is left open: a fin and a flat valence-2 vertex differ only in their geometry.)
    if (const std::vector<std::uint32_t> folds = foldedVertices(mesh); !folds.empty())
        throw Error(inputName, "vertex " + std::to_string(folds.front()) +
                                   " is a fold: its only two polygons run opposite ways round it (a fin of no area, or a vertex of valence 2"
                                   " left on an edge by dissolving edges)" +
                                   (folds.size() > 1 ? " (and " + std::to_string(folds.size() - 1) + " more)" : std::string()) +
                                   "; the Reeb graph needs a closed manifold surface with three or more polygons round every vertex");
    // Fan every polygon into triangles first, so the fan analysis sees the triangles' edges.
    std::vector<std::uint32_t> polygonOf;
    const Mesh tris = fanIntoTriangles(mesh, &polygonOf);
    std::vector<std::uint32_t> cornerVertex, partner;
    const std::vector<std::uint32_t> copies = splitVertexFans(tris, inputName, cornerVertex, partner);
    if (!copies.empty())
        throw Error(inputName, "vertex " + std::to_string(copies.front()) + " joins separate fans of polygons (a non-manifold vertex" +
                                   (copies.size() > 1 ? ", and " + std::to_string(copies.size() - 1) + " more" : std::string()) +
                                   "); the Reeb graph needs a closed manifold surface");
    for (std::uint32_t c = 0; c < partner.size(); ++c)
        if (partner[c] == ~0u)
            throw Error(inputName, "the surface is open: the edge " + std::to_string(tris.indices[c]) + "-" +
                                       std::to_string(tris.indices[ClosedSurface::next(c)]) +
                                       " has one polygon; the Reeb graph needs a closed surface");

    ClosedSurface s;
    std::vector<std::uint32_t> local(mesh.points.size(), ~0u);
    s.vertex.resize(tris.indices.size());
    for (std::size_t c = 0; c < tris.indices.size(); ++c) {
        std::uint32_t& l = local[tris.indices[c]];
        if (l == ~0u) {
            l = std::uint32_t(s.points.size());
            const Vec3f& p = mesh.points[tris.indices[c]];
            if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
                throw Error(inputName, "vertex " + std::to_string(tris.indices[c]) + " is not a finite point");
            s.points.push_back(Vec3d(p));
            s.inputVertex.push_back(tris.indices[c]);
            s.vertexCorner.push_back(std::uint32_t(c));
        }
        s.vertex[c] = l;
    }
    s.opposite = std::move(partner);
    s.polygon = std::move(polygonOf);
    s.edgeOf.assign(s.vertex.size(), 0);
    for (std::uint32_t c = 0; c < s.vertex.size(); ++c)
        if (c < s.opposite[c]) s.edgeOf[c] = s.edgeOf[s.opposite[c]] = std::uint32_t(s.edgeCount++);
    UnionFind uf(s.points.size());
    for (std::uint32_t c = 0; c < s.vertex.size(); ++c) uf.unite(s.vertex[c], s.vertex[ClosedSurface::next(c)]);
    s.piece.resize(s.points.size());
    for (std::uint32_t v = 0; v < s.points.size(); ++v) {
        s.piece[v] = uf.find(v);
        s.components += s.piece[v] == v;
    }
    return s;
}

} // namespace

ClosedSurface buildClosedSurface(const Mesh& mesh, const std::string& inputName) {
    try {
        return buildFrom(mesh, inputName);
    } catch (const Error& asGiven) {
        // Points stored once per side of a seam leave the surface open along it (or, where
        // seams meet, a point shared by wedges that do not touch): merged, it may be whole.
        Mesh merged = mesh;
        const std::size_t n = mergeCoincidentPoints(merged);
        if (n == 0) throw;
        try {
            ClosedSurface s = buildFrom(merged, inputName);
            s.mergedPoints = n;
            return s;
        } catch (const Error&) {
            throw Error(asGiven.input(), asGiven.message() + " (merging the " + std::to_string(n) +
                                             " points at the position of another does not mend it)");
        }
    }
}

} // namespace vdbsurf::reeb
