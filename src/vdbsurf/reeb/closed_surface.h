// The reeb module's view of its input: a closed, manifold, consistently oriented triangle
// surface in flat corner arrays. Corner c of triangle c / 3 starts the edge from vertex[c] to
// vertex[next(c)]; opposite[c] is the corner of the neighbouring triangle running that edge the
// other way. The sweep, the cut and the contour tracing only ever step between corners, so flat
// arrays (filled by the mesh module's vertex-fan analysis) are all they need.
#pragma once
#include "vdbsurf/core/vec3.h"
#include "vdbsurf/mesh/mesh.h"

#include <cstdint>
#include <string>
#include <vector>

namespace vdbsurf::reeb {

struct ClosedSurface {
    std::vector<Vec3d> points;           // used vertices only
    std::vector<std::uint32_t> vertex;   // 3 per triangle
    std::vector<std::uint32_t> opposite; // per corner
    std::vector<std::uint32_t> polygon;  // the input polygon each triangle comes from
    std::vector<std::uint32_t> inputVertex; // input index of each point
    std::vector<std::uint32_t> vertexCorner; // one corner at each vertex
    std::vector<std::uint32_t> edgeOf;   // per corner: index of its undirected edge
    std::size_t edgeCount = 0;
    std::size_t components = 0;
    std::vector<std::uint32_t> piece;   // per vertex: its piece's representative vertex
    // Input points merged into an earlier one at the same position, which closed the surface
    // (mergeCoincidentPoints; 0 when the input was closed as given).
    std::size_t mergedPoints = 0;

    std::size_t triangleCount() const { return vertex.size() / 3; }
    static std::uint32_t next(std::uint32_t c) { return c % 3 == 2 ? c - 2 : c + 1; }
    static std::uint32_t prev(std::uint32_t c) { return c % 3 == 0 ? c + 2 : c - 1; }
    // The next corner at the same vertex (turning across the edge that ends at the vertex).
    std::uint32_t around(std::uint32_t c) const { return opposite[prev(c)]; }
    long eulerCharacteristic() const { return long(points.size()) - long(edgeCount) + long(triangleCount()); }
    double meanEdgeLength() const;
};

// Polygons are fanned into triangles as mesh/fan_triangles.h does. Throws Error naming
// inputName for an open surface (naming a boundary edge), an edge of three or more polygons or inconsistent
// orientation, a non-manifold vertex (two fans meeting at a point), a polygon with fewer than
// three corners or a repeated vertex, a non-finite point, or an empty mesh. Input that fails
// as given but passes once points at equal positions are merged (a file written per corner, or
// split at texture seams: open along them) is taken merged, and says so (mergedPoints).
ClosedSurface buildClosedSurface(const Mesh& mesh, const std::string& inputName);

} // namespace vdbsurf::reeb
