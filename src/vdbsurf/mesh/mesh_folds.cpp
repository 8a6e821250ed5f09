#include "vdbsurf/mesh/mesh_folds.h"

#include "vdbsurf/core/fixed_chunks.h"

#include <algorithm>

namespace vdbsurf {

namespace {

constexpr int kMaxRounds = 8; // closing one fold can expose another (a pillow left behind)
constexpr std::uint32_t kNone = ~0u;
constexpr std::size_t kFoldChunk = 1024; // polygons of the list a task: the folds found do not depend on it

struct Fold {
    std::uint32_t p, atP, q, atQ; // polygon numbers, positions of v in them
};

// The folds among the listed polygons, in list order: each corner is compared with the first
// one listed at its vertex, which `firstAt` (per vertex: position in the list) remembers. (A
// vertex with more than two listed polygons and a fold between its second and third is not
// vertex-manifold; that is not looked for.) In parallel over fixed chunks of the list, joined in
// order: each vertex's first listing is found first (the least position, by atomic minimum on
// firstAt), then every other corner compared with it. (One serial pass took 0.5-0.8 ms of the
// armadillo's weld, on one thread whatever the count.)
std::vector<Fold> findFolds(const Mesh& mesh, const std::vector<std::uint32_t>& polygons, std::vector<std::uint32_t>& firstAt) {
    if (firstAt.size() < mesh.points.size()) firstAt.resize(mesh.points.size());
    std::uint32_t* first = firstAt.data();
    // (GCC's atomic builtins on the plain array: several chunks write one vertex's entry.)
    auto forEachChunk = [&](auto&& body) { forEachFixedChunk(polygons.size(), kFoldChunk, body); };
    forEachChunk([&](std::size_t, std::size_t b, std::size_t e) {
        for (std::size_t k = b; k < e; ++k)
            for (std::uint32_t c = mesh.offsets[polygons[k]]; c < mesh.offsets[polygons[k] + 1]; ++c)
                __atomic_store_n(&first[mesh.indices[c]], kNone, __ATOMIC_RELAXED);
    });
    forEachChunk([&](std::size_t, std::size_t b, std::size_t e) {
        for (std::size_t k = b; k < e; ++k)
            for (std::uint32_t c = mesh.offsets[polygons[k]]; c < mesh.offsets[polygons[k] + 1]; ++c) {
                std::uint32_t* at = &first[mesh.indices[c]];
                std::uint32_t seen = __atomic_load_n(at, __ATOMIC_RELAXED);
                while (std::uint32_t(k) < seen &&
                       !__atomic_compare_exchange_n(at, &seen, std::uint32_t(k), true, __ATOMIC_RELAXED, __ATOMIC_RELAXED)) {
                }
            }
    });
    auto around = [&](std::uint32_t f, std::uint32_t at, std::uint32_t& prev, std::uint32_t& next) {
        const std::uint32_t n = mesh.polygonSize(f);
        const std::uint32_t* v = mesh.polygon(f);
        prev = v[at > 0 ? at - 1 : n - 1];
        next = v[at + 1 < n ? at + 1 : 0];
    };
    std::vector<std::vector<Fold>> found(fixedChunkCount(polygons.size(), kFoldChunk));
    forEachChunk([&](std::size_t chunk, std::size_t b, std::size_t e) {
        for (std::size_t k = b; k < e; ++k) {
            const std::uint32_t f = polygons[k], n = mesh.polygonSize(f);
            const std::uint32_t* v = mesh.polygon(f);
            for (std::uint32_t i = 0; i < n; ++i) {
                const std::uint32_t listed = __atomic_load_n(&first[v[i]], __ATOMIC_RELAXED);
                const std::uint32_t g = polygons[listed];
                const std::uint32_t* w = mesh.polygon(g);
                const std::uint32_t j = std::uint32_t(std::find(w, w + mesh.polygonSize(g), v[i]) - w);
                if (listed == k && j == i) continue; // the vertex's first corner in the list
                std::uint32_t pf, nf, pg, ng;
                around(f, i, pf, nf);
                around(g, j, pg, ng);
                if (pf == ng && nf == pg) found[chunk].push_back({g, j, f, i});
            }
        }
    });
    std::vector<Fold> folds;
    for (const std::vector<Fold>& part : found) folds.insert(folds.end(), part.begin(), part.end());
    return folds;
}

// The edge a-b that closing the fold makes (v's neighbours in p).
std::uint64_t newEdge(const Mesh& mesh, const Fold& f) {
    const std::uint32_t n = mesh.polygonSize(f.p);
    const std::uint32_t* v = mesh.polygon(f.p);
    return undirectedEdgeKey(v[f.atP > 0 ? f.atP - 1 : n - 1], v[f.atP + 1 < n ? f.atP + 1 : 0]);
}

} // namespace

FoldStats closeFolds(Mesh& mesh, std::vector<std::uint32_t> polygons, std::vector<std::uint32_t>& scratch) {
    FoldStats stats;
    for (int round = 0; round < kMaxRounds; ++round) {
        const std::vector<Fold> folds = findFolds(mesh, polygons, scratch);
        if (folds.empty()) break;
        // Rare: resolved serially, one fold a polygon a round (the next round sees what is left).
        // Two polygons that both keep three vertices share the new edge a-b, which must not be
        // an edge already (a, b and v would then bound a triangle of edges: left as it is).
        std::vector<std::uint64_t> joined, existing;
        for (const Fold& f : folds)
            if (mesh.polygonSize(f.p) > 3 && mesh.polygonSize(f.q) > 3) joined.push_back(newEdge(mesh, f));
        if (!joined.empty()) {
            std::sort(joined.begin(), joined.end());
            for (std::size_t p = 0; p < mesh.polygonCount(); ++p) {
                const std::uint32_t* v = mesh.polygon(p);
                const std::uint32_t n = mesh.polygonSize(p);
                for (std::uint32_t i = 0; i < n; ++i) {
                    const std::uint64_t key = undirectedEdgeKey(v[i], v[i + 1 < n ? i + 1 : 0]);
                    if (std::binary_search(joined.begin(), joined.end(), key)) existing.push_back(key);
                }
            }
            std::sort(existing.begin(), existing.end());
        }
        std::vector<std::uint8_t> touched(mesh.polygonCount(), 0), dropCorner(mesh.indices.size(), 0);
        std::size_t closedNow = 0;
        for (const Fold& f : folds) {
            if (touched[f.p] || touched[f.q]) continue;
            if (mesh.polygonSize(f.p) > 3 && mesh.polygonSize(f.q) > 3 &&
                std::binary_search(existing.begin(), existing.end(), newEdge(mesh, f))) {
                ++stats.left;
                continue;
            }
            touched[f.p] = touched[f.q] = 1;
            dropCorner[mesh.offsets[f.p] + f.atP] = dropCorner[mesh.offsets[f.q] + f.atQ] = 1;
            ++closedNow;
        }
        if (closedNow == 0) break;
        stats.closed += closedNow;
        stats.left = 0; // counted again by the last round
        // The polygons without their dropped corners; those left under three vertices go, and
        // with them (keepPolygons) the points nothing uses any more: the folds' vertices.
        Mesh out;
        out.points = std::move(mesh.points);
        out.offsets.reserve(mesh.offsets.size());
        out.indices.reserve(mesh.indices.size());
        std::vector<std::uint32_t> newPolygon(mesh.polygonCount(), kNone);
        for (std::size_t p = 0; p < mesh.polygonCount(); ++p) {
            const std::size_t before = out.indices.size();
            for (std::uint32_t c = mesh.offsets[p]; c < mesh.offsets[p + 1]; ++c)
                if (!dropCorner[c]) out.indices.push_back(mesh.indices[c]);
            if (out.indices.size() - before < 3) {
                out.indices.resize(before);
                ++stats.removedPolygons;
                continue;
            }
            newPolygon[p] = std::uint32_t(out.offsets.size() - 1);
            out.offsets.push_back(std::uint32_t(out.indices.size()));
        }
        std::vector<std::uint32_t> renumbered;
        for (std::uint32_t p : polygons)
            if (newPolygon[p] != kNone) renumbered.push_back(newPolygon[p]);
        polygons = std::move(renumbered);
        mesh = keepPolygons(out, std::vector<std::uint8_t>(out.polygonCount(), 1));
    }
    return stats;
}

std::vector<std::uint32_t> foldedVertices(const Mesh& mesh) {
    std::vector<std::uint32_t> all(mesh.polygonCount()), scratch, out;
    for (std::size_t p = 0; p < all.size(); ++p) all[p] = std::uint32_t(p);
    // Only vertices with exactly two polygons: on a mesh that is not edge-manifold a reversed
    // pair can sit among more, which is another fault (named by the edge checks).
    std::vector<std::uint8_t> corners(mesh.points.size(), 0);
    for (std::uint32_t v : mesh.indices) corners[v] = std::uint8_t(std::min(3, corners[v] + 1));
    for (const Fold& f : findFolds(mesh, all, scratch)) {
        const std::uint32_t v = mesh.polygon(f.p)[f.atP];
        if (corners[v] == 2) out.push_back(v);
    }
    std::sort(out.begin(), out.end());
    out.erase(std::unique(out.begin(), out.end()), out.end());
    return out;
}

} // namespace vdbsurf
