#include "vdbsurf/mesh/mesh.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <numeric>

namespace vdbsurf {

void Mesh::addPolygon(std::initializer_list<std::uint32_t> vs) { addPolygon(vs.begin(), vs.size()); }

void Mesh::addPolygon(const std::uint32_t* vs, std::size_t n) {
    indices.insert(indices.end(), vs, vs + n);
    offsets.push_back(std::uint32_t(indices.size()));
}

std::size_t Mesh::countPolygonsOfSize(std::uint32_t n) const {
    // (In parallel: the mesher counts triangles and quads of every mesh it makes.)
    return tbb::parallel_reduce(
        tbb::blocked_range<std::size_t>(0, polygonCount(), 16384), std::size_t(0),
        [&](const tbb::blocked_range<std::size_t>& r, std::size_t count) {
            for (std::size_t p = r.begin(); p != r.end(); ++p) count += polygonSize(p) == n;
            return count;
        },
        std::plus<std::size_t>());
}

Mesh keepPolygons(const Mesh& mesh, const std::vector<std::uint8_t>& keep) {
    constexpr std::uint32_t kUnused = ~std::uint32_t(0);
    std::vector<std::uint32_t> newId(mesh.points.size(), kUnused);
    for (std::size_t p = 0; p < mesh.polygonCount(); ++p)
        if (keep[p])
            for (std::uint32_t i = mesh.offsets[p]; i < mesh.offsets[p + 1]; ++i) newId[mesh.indices[i]] = 0;
    Mesh out;
    for (std::size_t v = 0; v < mesh.points.size(); ++v) {
        if (newId[v] == kUnused) continue;
        newId[v] = std::uint32_t(out.points.size());
        out.points.push_back(mesh.points[v]);
    }
    for (std::size_t p = 0; p < mesh.polygonCount(); ++p) {
        if (!keep[p]) continue;
        for (std::uint32_t i = mesh.offsets[p]; i < mesh.offsets[p + 1]; ++i) out.indices.push_back(newId[mesh.indices[i]]);
        out.offsets.push_back(std::uint32_t(out.indices.size()));
    }
    return out;
}

namespace {

// For each point, the first point at exactly its position (itself if none); non-finite points
// map to themselves.
std::vector<std::uint32_t> firstPointAtEachPosition(const Mesh& mesh) {
    std::vector<std::uint32_t> order;
    order.reserve(mesh.points.size());
    for (std::uint32_t v = 0; v < mesh.points.size(); ++v) {
        const Vec3f& p = mesh.points[v];
        if (std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z)) order.push_back(v);
    }
    // By position (as floats: -0 and 0 are one), then index, so each run starts at its first point.
    const auto before = [&](std::uint32_t a, std::uint32_t b) {
        const Vec3f &p = mesh.points[a], &q = mesh.points[b];
        if (p.x != q.x) return p.x < q.x;
        if (p.y != q.y) return p.y < q.y;
        if (p.z != q.z) return p.z < q.z;
        return a < b;
    };
    std::sort(order.begin(), order.end(), before);
    std::vector<std::uint32_t> to(mesh.points.size());
    std::iota(to.begin(), to.end(), 0u);
    for (std::size_t i = 1; i < order.size(); ++i) {
        const Vec3f &p = mesh.points[order[i]], &q = mesh.points[order[i - 1]];
        if (p.x == q.x && p.y == q.y && p.z == q.z) to[order[i]] = to[order[i - 1]];
    }
    return to;
}

// How many used points map elsewhere; `rewrite` (the mesh's own indices, or null) gets those
// others in their place.
std::size_t coincidentPoints(const Mesh& mesh, std::vector<std::uint32_t>* rewrite) {
    const std::vector<std::uint32_t> to = firstPointAtEachPosition(mesh);
    std::vector<std::uint8_t> counted(mesh.points.size(), 0);
    std::size_t count = 0;
    for (std::size_t k = 0; k < mesh.indices.size(); ++k) {
        const std::uint32_t i = mesh.indices[k];
        if (to[i] == i) continue;
        count += !counted[i];
        counted[i] = 1;
        if (rewrite) (*rewrite)[k] = to[i];
    }
    return count;
}

} // namespace

std::size_t mergeCoincidentPoints(Mesh& mesh) { return coincidentPoints(mesh, &mesh.indices); }

std::size_t countCoincidentPoints(const Mesh& mesh) { return coincidentPoints(mesh, nullptr); }

Box3 Mesh::bounds() const {
    const double inf = std::numeric_limits<double>::infinity();
    Box3 b{{inf, inf, inf}, {-inf, -inf, -inf}};
    for (const Vec3f& p : points) {
        b.min = vmin(b.min, Vec3d(p));
        b.max = vmax(b.max, Vec3d(p));
    }
    return b;
}

double surfaceArea(const Mesh& mesh) {
    double area = 0;
    for (std::size_t p = 0; p < mesh.polygonCount(); ++p) {
        const std::uint32_t* v = mesh.polygon(p);
        const Vec3d a(mesh.points[v[0]]);
        for (std::uint32_t i = 1; i + 1 < mesh.polygonSize(p); ++i)
            area += 0.5 * length(cross(Vec3d(mesh.points[v[i]]) - a, Vec3d(mesh.points[v[i + 1]]) - a));
    }
    return area;
}

double enclosedVolume(const Mesh& mesh) {
    double vol = 0;
    for (std::size_t p = 0; p < mesh.polygonCount(); ++p) {
        const std::uint32_t* v = mesh.polygon(p);
        const Vec3d a(mesh.points[v[0]]);
        for (std::uint32_t i = 1; i + 1 < mesh.polygonSize(p); ++i)
            vol += dot(a, cross(Vec3d(mesh.points[v[i]]), Vec3d(mesh.points[v[i + 1]])));
    }
    return vol / 6.0;
}

void splitToTrianglesAndQuads(const Mesh& mesh, std::vector<std::uint32_t>& triangles, std::vector<std::uint32_t>& quads) {
    triangles.clear();
    quads.clear();
    for (std::size_t p = 0; p < mesh.polygonCount(); ++p) {
        const std::uint32_t* v = mesh.polygon(p);
        const std::uint32_t n = mesh.polygonSize(p);
        if (n == 4) {
            quads.insert(quads.end(), v, v + 4);
            continue;
        }
        for (std::uint32_t i = 1; i + 1 < n; ++i) triangles.insert(triangles.end(), {v[0], v[i], v[i + 1]});
    }
}

} // namespace vdbsurf
