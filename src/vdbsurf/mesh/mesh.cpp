#include "vdbsurf/mesh/mesh.h"

#include <limits>

namespace vdbsurf {

void Mesh::addPolygon(std::initializer_list<std::uint32_t> vs) { addPolygon(vs.begin(), vs.size()); }

void Mesh::addPolygon(const std::uint32_t* vs, std::size_t n) {
    indices.insert(indices.end(), vs, vs + n);
    offsets.push_back(std::uint32_t(indices.size()));
}

std::size_t Mesh::countPolygonsOfSize(std::uint32_t n) const {
    std::size_t count = 0;
    for (std::size_t p = 0; p < polygonCount(); ++p) count += polygonSize(p) == n;
    return count;
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
