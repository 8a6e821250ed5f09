#include "vdbsurf/mesh/mesh_check.h"

#include "vdbsurf/mesh/mesh_folds.h"
#include "vdbsurf/mesh/vertex_fans.h"

#include <algorithm>
#include <numeric>
#include <vector>

namespace vdbsurf {

MeshTopology checkTopology(const Mesh& mesh) {
    MeshTopology t;
    struct HalfEdge {
        std::uint32_t lo, hi;
        bool forward; // lo -> hi
        bool operator<(const HalfEdge& o) const { return lo != o.lo ? lo < o.lo : hi != o.hi ? hi < o.hi : forward < o.forward; }
    };
    std::vector<HalfEdge> hes;
    hes.reserve(mesh.indices.size());
    std::vector<char> used(mesh.points.size(), 0);
    for (std::size_t p = 0; p < mesh.polygonCount(); ++p) {
        const std::uint32_t* v = mesh.polygon(p);
        const std::uint32_t n = mesh.polygonSize(p);
        bool degenerate = false;
        for (std::uint32_t i = 0; i < n; ++i) {
            const std::uint32_t a = v[i], b = v[(i + 1) % n];
            used[a] = 1;
            for (std::uint32_t j = i + 1; j < n; ++j) degenerate |= v[j] == a;
            hes.push_back({std::min(a, b), std::max(a, b), a < b});
        }
        t.degeneratePolygons += degenerate;
    }
    std::sort(hes.begin(), hes.end());
    for (std::size_t i = 0; i < hes.size();) {
        std::size_t j = i, fwd = 0;
        while (j < hes.size() && hes[j].lo == hes[i].lo && hes[j].hi == hes[i].hi) fwd += hes[j++].forward;
        const std::size_t n = j - i;
        ++t.edges;
        if (n == 1) ++t.boundaryEdges;
        else if (n > 2) ++t.nonManifoldEdges;
        else if (fwd != 1) ++t.inconsistentEdges;
        i = j;
    }
    t.unusedVertices = std::size_t(std::count(used.begin(), used.end(), 0));
    if (t.nonManifoldEdges == 0) { // fans are only defined around manifold edges
        std::vector<std::uint32_t> all(mesh.points.size());
        std::iota(all.begin(), all.end(), 0u);
        t.nonManifoldVertices = countSplitFans(mesh, std::move(all));
        t.foldedVertices = foldedVertices(mesh).size();
    }
    return t;
}

std::size_t countComponents(const Mesh& mesh) {
    std::vector<std::uint32_t> parent(mesh.points.size());
    std::iota(parent.begin(), parent.end(), 0u);
    auto find = [&](std::uint32_t x) {
        while (parent[x] != x) x = parent[x] = parent[parent[x]];
        return x;
    };
    std::vector<char> used(mesh.points.size(), 0);
    for (std::size_t p = 0; p < mesh.polygonCount(); ++p) {
        const std::uint32_t* v = mesh.polygon(p);
        used[v[0]] = 1;
        for (std::uint32_t i = 1; i < mesh.polygonSize(p); ++i) {
            used[v[i]] = 1;
            parent[find(v[i])] = find(v[0]);
        }
    }
    std::size_t count = 0;
    for (std::uint32_t i = 0; i < parent.size(); ++i) count += used[i] && find(i) == i;
    return count;
}

} // namespace vdbsurf
