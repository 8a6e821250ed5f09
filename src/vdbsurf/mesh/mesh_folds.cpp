#include "vdbsurf/mesh/mesh_folds.h"

#include <algorithm>

namespace vdbsurf {

namespace {

constexpr int kMaxRounds = 8; // closing one fold can expose another (a pillow left behind)
constexpr std::uint32_t kNone = ~0u;

struct Fold {
    std::uint32_t p, atP, q, atQ; // polygon numbers, positions of v in them
};

// The folds among the listed polygons, in list order: each corner is compared with the first
// one listed at its vertex, which `firstAt` (per vertex: position in the list) remembers. (A
// vertex with more than two listed polygons and a fold between its second and third is not
// vertex-manifold; that is not looked for.) One serial pass: on the armadillo's 9,600 polygons
// from the weld 0.5 ms, where a parallel sort of the corners took 1.2 to 1.7.
std::vector<Fold> findFolds(const Mesh& mesh, const std::vector<std::uint32_t>& polygons, std::vector<std::uint32_t>& firstAt) {
    if (firstAt.size() < mesh.points.size()) firstAt.resize(mesh.points.size());
    for (std::uint32_t f : polygons)
        for (std::uint32_t c = mesh.offsets[f]; c < mesh.offsets[f + 1]; ++c) firstAt[mesh.indices[c]] = kNone;
    auto around = [&](std::uint32_t f, std::uint32_t at, std::uint32_t& prev, std::uint32_t& next) {
        const std::uint32_t n = mesh.polygonSize(f);
        const std::uint32_t* v = mesh.polygon(f);
        prev = v[at > 0 ? at - 1 : n - 1];
        next = v[at + 1 < n ? at + 1 : 0];
    };
    std::vector<Fold> folds;
    for (std::uint32_t k = 0; k < polygons.size(); ++k) {
        const std::uint32_t f = polygons[k], n = mesh.polygonSize(f);
        const std::uint32_t* v = mesh.polygon(f);
        for (std::uint32_t i = 0; i < n; ++i) {
            std::uint32_t& first = firstAt[v[i]];
            if (first == kNone) {
                first = k;
                continue;
            }
            const std::uint32_t g = polygons[first];
            const std::uint32_t* w = mesh.polygon(g);
            const std::uint32_t j = std::uint32_t(std::find(w, w + mesh.polygonSize(g), v[i]) - w);
            std::uint32_t pf, nf, pg, ng;
            around(f, i, pf, nf);
            around(g, j, pg, ng);
            if (pf == ng && nf == pg) folds.push_back({g, j, f, i});
        }
    }
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
