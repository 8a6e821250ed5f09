#include "vdbsurf/mesh/vertex_fans.h"

#include "vdbsurf/core/error.h"
#include "vdbsurf/core/union_find.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace vdbsurf {

std::vector<std::uint32_t> nextCorners(const std::vector<std::uint32_t>& offsets, std::size_t nc) {
    std::vector<std::uint32_t> nextCorner(nc);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, offsets.size() - 1, 2048), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t f = r.begin(); f != r.end(); ++f) {
            const std::uint32_t b = offsets[f], n = offsets[f + 1] - b;
            for (std::uint32_t k = 0; k < n; ++k) nextCorner[b + k] = b + (k + 1 == n ? 0 : k + 1);
        }
    });
    return nextCorner;
}

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
    UnionFind fans(nc);
    for (std::size_t v = 0; v < mesh.points.size(); ++v)
        for (std::uint32_t a = start[v]; a < start[v + 1]; ++a) {
            const std::uint32_t c = byVertex[a];
            const std::uint32_t w = mesh.indices[next[c]];
            for (std::uint32_t b = start[v]; b < start[v + 1]; ++b) {
                const std::uint32_t d = byVertex[b];
                if (d == c) continue;
                if (mesh.indices[prev[d]] == w) {
                    fans.unite(c, d);
                    partner[c] = prev[d];
                }
                if (mesh.indices[next[d]] == w)
                    throw Error(inputName, "two polygons run along the edge " + std::to_string(v) + "-" + std::to_string(w) +
                                               " in the same direction: they are oriented inconsistently, or the edge has "
                                               "three or more polygons; surface algorithms need a manifold, consistently oriented mesh");
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
            const std::uint32_t r = fans.find(c);
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

} // namespace vdbsurf
