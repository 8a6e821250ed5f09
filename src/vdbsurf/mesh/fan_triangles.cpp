#include "vdbsurf/mesh/fan_triangles.h"

#include <algorithm>

namespace vdbsurf {

Mesh fanIntoTriangles(const Mesh& mesh, std::vector<std::uint32_t>* polygonOf) {
    const std::size_t polygons = mesh.polygonCount();
    // The apex of each polygon's fan, as an index into its corners.
    std::vector<std::uint32_t> apex(polygons, 0);
    bool anyLarger = false;
    for (std::size_t p = 0; p < polygons && !anyLarger; ++p) anyLarger = mesh.polygonSize(p) > 3;
    if (anyLarger) {
        // Polygons around each vertex (compressed rows), to ask whether two vertices share an
        // edge or an earlier fan's diagonal without a table of all edges.
        const std::size_t vertices = mesh.points.size();
        std::vector<std::uint32_t> first(vertices + 1, 0), around(mesh.indices.size());
        for (const std::uint32_t v : mesh.indices) ++first[v + 1];
        for (std::size_t v = 0; v < vertices; ++v) first[v + 1] += first[v];
        std::vector<std::uint32_t> fill(first.begin(), first.end() - 1);
        for (std::size_t p = 0; p < polygons; ++p)
            for (std::uint32_t k = 0; k < mesh.polygonSize(p); ++k) around[fill[mesh.polygon(p)[k]]++] = std::uint32_t(p);
        // Do a and b share an edge of polygon q, or a diagonal of q's fan (q before `before`)?
        auto joinedIn = [&](std::uint32_t q, std::uint32_t a, std::uint32_t b, std::size_t before) {
            const std::uint32_t* vs = mesh.polygon(q);
            const std::uint32_t n = mesh.polygonSize(q);
            for (std::uint32_t k = 0; k < n; ++k) {
                const std::uint32_t u = vs[k], w = vs[(k + 1) % n];
                if ((u == a && w == b) || (u == b && w == a)) return true;
            }
            if (n < 4 || q >= before) return false;
            const std::uint32_t top = vs[apex[q]];
            if (top != a && top != b) return false;
            const std::uint32_t other = top == a ? b : a;
            for (std::uint32_t k = 2; k + 1 < n; ++k)
                if (vs[(apex[q] + k) % n] == other) return true;
            return false;
        };
        auto joined = [&](std::uint32_t a, std::uint32_t b, std::size_t before) {
            for (std::uint32_t i = first[a]; i < first[a + 1]; ++i)
                if (joinedIn(around[i], a, b, before)) return true;
            return false;
        };
        for (std::size_t p = 0; p < polygons; ++p) {
            const std::uint32_t n = mesh.polygonSize(p);
            if (n < 4) continue;
            const std::uint32_t* vs = mesh.polygon(p);
            for (std::uint32_t s = 0; s < n; ++s) {
                bool fresh = true;
                for (std::uint32_t k = 2; k + 1 < n && fresh; ++k) fresh = !joined(vs[s], vs[(s + k) % n], p);
                if (fresh) {
                    apex[p] = s;
                    break;
                }
            }
        }
    }
    Mesh tris;
    tris.points = mesh.points;
    tris.offsets.reserve(mesh.fannedTriangleCount() + 1);
    tris.indices.reserve(3 * mesh.fannedTriangleCount());
    if (polygonOf) {
        polygonOf->clear();
        polygonOf->reserve(mesh.fannedTriangleCount());
    }
    for (std::size_t p = 0; p < polygons; ++p) {
        const std::uint32_t* vs = mesh.polygon(p);
        const std::uint32_t n = mesh.polygonSize(p), s = apex[p];
        for (std::uint32_t k = 1; k + 1 < n; ++k) {
            tris.addPolygon({vs[s], vs[(s + k) % n], vs[(s + k + 1) % n]});
            if (polygonOf) polygonOf->push_back(std::uint32_t(p));
        }
    }
    return tris;
}

} // namespace vdbsurf
