#include "vdbsurf/mesh/vertex_fans.h"

#include "vdbsurf/core/error.h"
#include "vdbsurf/core/parallel_buckets.h"
#include "vdbsurf/core/prefault.h"
#include "vdbsurf/core/union_find.h"

#include <tbb/blocked_range.h>
#include <algorithm>
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

namespace {

// Calls extra(candidate, corner, fan) for every corner at a candidate vertex that is not in the
// fan of the vertex's first corner (fan: 1, 2, ... per further fan, in polygon order). Only the
// listed polygons (ascending) are looked at when `polygons` is given. `scratch`: see splitFansAt.
template <typename F>
void forEachExtraFanCorner(const Mesh& mesh, std::vector<std::uint32_t> candidates, const std::vector<std::uint32_t>* polygons,
                           std::vector<std::uint32_t>* scratch, F&& extra) {
    std::sort(candidates.begin(), candidates.end());
    candidates.erase(std::unique(candidates.begin(), candidates.end()), candidates.end());
    if (candidates.empty()) return;
    constexpr std::uint32_t kNone = ~0u;
    std::vector<std::uint32_t> own;
    std::vector<std::uint32_t>& slot = scratch ? *scratch : own;
    if (slot.size() < mesh.points.size()) resizePrefaulted(slot, mesh.points.size(), kNone);
    for (std::uint32_t i = 0; i < candidates.size(); ++i) slot[candidates[i]] = i;
    // The corners at each candidate with their polygon neighbours: candidate s owns
    // corners[first[s] .. first[s + 1]) (counted, then filled: no vector per candidate), both in
    // parallel (the corner grouping was most of the time where every polygon scanned is one
    // around a candidate); each candidate's corners are put in corner order (that of the
    // polygons, then of the corners in each) below.
    struct Corner {
        std::uint32_t corner, prev, next;
    };
    const std::size_t scanned = polygons ? polygons->size() : mesh.polygonCount();
    auto forEachCandidateCorner = [&](auto&& visit) {
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, scanned, 1024), [&](const tbb::blocked_range<std::size_t>& r) {
            for (std::size_t i = r.begin(); i < r.end(); ++i) {
                const std::size_t f = polygons ? (*polygons)[i] : i;
                const std::uint32_t first = mesh.offsets[f], n = mesh.polygonSize(f);
                for (std::uint32_t k = 0; k < n; ++k) {
                    const std::uint32_t s = slot[mesh.indices[first + k]];
                    if (s != kNone) visit(s, first, n, k);
                }
            }
        });
    };
    std::vector<std::uint32_t> first;
    std::vector<Corner> corners;
    fillBuckets(candidates.size(), [&](auto&& put) {
        forEachCandidateCorner([&](std::uint32_t s, std::uint32_t b, std::uint32_t n, std::uint32_t k) {
            put(s, [&] { return Corner{b + k, mesh.indices[b + (k + n - 1) % n], mesh.indices[b + (k + 1) % n]}; });
        });
    }, first, corners);
    for (const std::uint32_t v : candidates) slot[v] = kNone; // (a caller's scratch left as it came)
    // Each corner's fan at its vertex (0: the fan of the vertex's first corner), per candidate
    // in parallel (each writes only its own corners), then reported in order.
    std::vector<std::uint32_t> fanOf(corners.size(), 0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, candidates.size(), 256), [&](const tbb::blocked_range<std::size_t>& r) {
        std::vector<std::uint32_t> parent, fanOfRoot;
        std::vector<std::pair<std::uint32_t, std::uint32_t>> byNeighbour; // (neighbour vertex, corner slot)
        for (std::size_t s = r.begin(); s < r.end(); ++s) {
            Corner* at = corners.data() + first[s];
            const std::uint32_t count = first[s + 1] - first[s];
            std::sort(at, at + count, [](const Corner& x, const Corner& y) { return x.corner < y.corner; });
            if (count < 2) continue;
            // Corners sharing an edge at the vertex (a neighbour vertex) are in one fan.
            parent.resize(count);
            for (std::uint32_t i = 0; i < count; ++i) parent[i] = i;
            auto find = [&](std::uint32_t x) {
                while (parent[x] != x) x = parent[x] = parent[parent[x]];
                return x;
            };
            byNeighbour.clear();
            for (std::uint32_t i = 0; i < count; ++i) {
                byNeighbour.emplace_back(at[i].prev, i);
                byNeighbour.emplace_back(at[i].next, i);
            }
            std::sort(byNeighbour.begin(), byNeighbour.end());
            for (std::size_t i = 1; i < byNeighbour.size(); ++i)
                if (byNeighbour[i].first == byNeighbour[i - 1].first) {
                    const std::uint32_t a = find(byNeighbour[i].second), b = find(byNeighbour[i - 1].second);
                    if (a != b) parent[std::max(a, b)] = std::min(a, b); // a fan's root is its first corner
                }
            fanOfRoot.assign(count, 0);
            std::uint32_t fans = 0;
            for (std::uint32_t i = 0; i < count; ++i) {
                const std::uint32_t root = find(i);
                if (root == 0) continue;
                if (fanOfRoot[root] == 0) fanOfRoot[root] = ++fans;
                fanOf[first[s] + i] = fanOfRoot[root];
            }
        }
    });
    for (std::size_t s = 0; s < candidates.size(); ++s)
        for (std::uint32_t i = first[s]; i < first[s + 1]; ++i)
            if (fanOf[i] > 0) extra(candidates[s], corners[i].corner, fanOf[i]);
}

} // namespace

std::size_t splitFansAt(Mesh& mesh, std::vector<std::uint32_t> candidates, const std::vector<std::uint32_t>* polygons,
                        std::vector<std::uint32_t>* scratch) {
    std::size_t copies = 0;
    std::uint32_t lastVertex = ~0u, lastFan = 0, firstCopy = 0;
    std::vector<std::pair<std::uint32_t, std::uint32_t>> rewrite; // (corner, new vertex)
    forEachExtraFanCorner(mesh, std::move(candidates), polygons, scratch, [&](std::uint32_t v, std::uint32_t corner, std::uint32_t fan) {
        if (v != lastVertex) lastVertex = v, lastFan = 0, firstCopy = std::uint32_t(mesh.points.size());
        if (fan > lastFan) { // fans are numbered in order of first appearance
            mesh.points.push_back(mesh.points[v]);
            lastFan = fan;
            ++copies;
        }
        rewrite.emplace_back(corner, firstCopy + fan - 1);
    });
    for (const auto& [corner, vertex] : rewrite) mesh.indices[corner] = vertex;
    return copies;
}

std::size_t countSplitFans(const Mesh& mesh, std::vector<std::uint32_t> candidates) {
    std::size_t count = 0;
    std::uint32_t lastVertex = ~0u;
    forEachExtraFanCorner(mesh, std::move(candidates), nullptr, nullptr, [&](std::uint32_t v, std::uint32_t, std::uint32_t) {
        if (v != lastVertex) ++count, lastVertex = v;
    });
    return count;
}

} // namespace vdbsurf
