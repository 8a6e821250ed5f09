// Topological checks a mesh must pass before it leaves vdbsurf, and that tests assert:
// boundary edges, non-manifold edges, orientation consistency, degenerate polygons, folds.
#pragma once
#include "vdbsurf/mesh/mesh.h"

#include <cstddef>

namespace vdbsurf {

struct MeshTopology {
    std::size_t edges = 0;
    std::size_t boundaryEdges = 0;      // used by one polygon
    std::size_t nonManifoldEdges = 0;   // used by three or more polygons
    std::size_t inconsistentEdges = 0;  // two polygons traverse it in the same direction
    std::size_t degeneratePolygons = 0; // repeated vertex index
    std::size_t unusedVertices = 0;
    std::size_t nonManifoldVertices = 0; // where several fans of polygons meet at one vertex
    // Vertices whose fan is two polygons folded onto each other (a -> v -> b and b -> v -> a): a
    // fin of no area, which fanning the polygons into triangles makes an edge of four triangles.
    std::size_t foldedVertices = 0;
    bool closedManifoldOriented() const {
        return boundaryEdges == 0 && nonManifoldEdges == 0 && inconsistentEdges == 0 && nonManifoldVertices == 0 && foldedVertices == 0;
    }
};

MeshTopology checkTopology(const Mesh& mesh);

// Number of connected components (polygons sharing a vertex).
std::size_t countComponents(const Mesh& mesh);

} // namespace vdbsurf
