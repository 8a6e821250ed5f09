// Mesh: positions plus polygons (triangles, quads, n-gons) in one compact index list. The
// common currency between the mesher, the writers, subdivision and surface fitting.
#pragma once
#include "vdbsurf/core/vec3.h"

#include <cstddef>
#include <cstdint>
#include <vector>

namespace vdbsurf {

struct Mesh {
    std::vector<Vec3f> points;
    // Polygon p uses indices[offsets[p] .. offsets[p + 1]); offsets always starts with 0.
    std::vector<std::uint32_t> offsets{0};
    std::vector<std::uint32_t> indices;

    std::size_t polygonCount() const { return offsets.size() - 1; }
    std::uint32_t polygonSize(std::size_t p) const { return offsets[p + 1] - offsets[p]; }
    const std::uint32_t* polygon(std::size_t p) const { return indices.data() + offsets[p]; }
    void addPolygon(std::initializer_list<std::uint32_t> vs);
    void addPolygon(const std::uint32_t* vs, std::size_t n);
    std::size_t countPolygonsOfSize(std::uint32_t n) const;
    // Triangles once every polygon is fanned (n - 2 for an n-gon).
    std::size_t fannedTriangleCount() const { return indices.size() - 2 * polygonCount(); }
    bool empty() const { return polygonCount() == 0; }
    Box3 bounds() const;
};

// One 64-bit key per undirected edge a-b (the lower index in the high half): edges sorted by it
// group the polygons that share them.
inline std::uint64_t undirectedEdgeKey(std::uint32_t a, std::uint32_t b) {
    return a < b ? (std::uint64_t(a) << 32) | b : (std::uint64_t(b) << 32) | a;
}

// Surface area and enclosed volume (divergence theorem; positive when oriented outwards).
// Polygons are fanned from their first vertex.
double surfaceArea(const Mesh& mesh);
double enclosedVolume(const Mesh& mesh);

// The polygons whose keep[] entry is non-zero, and the vertices they use, both in their order.
Mesh keepPolygons(const Mesh& mesh, const std::vector<std::uint8_t>& keep);

// Polygons that use a point at exactly the position of an earlier point (files written per
// corner, or split at texture seams and hard normals, store one point per side) use the first
// one instead; returns how many used points were merged away. Points are kept (unused), so indices
// still mean the input's. Non-finite points are left alone.
std::size_t mergeCoincidentPoints(Mesh& mesh);
// What mergeCoincidentPoints would return, the mesh left as it is.
std::size_t countCoincidentPoints(const Mesh& mesh);

// Triangles and quads only: n-gons (n > 4) fanned into triangles, as OpenVDB's tools expect.
void splitToTrianglesAndQuads(const Mesh& mesh, std::vector<std::uint32_t>& triangles, std::vector<std::uint32_t>& quads);

} // namespace vdbsurf
