// Welding the vertices that sit on one lattice node. A node whose value is exactly the iso value
// (data, or a node placed on a sharp feature) carries the crossing of each of its edges at the
// node itself; those vertices become one, the polygons that collapse are removed, and so are
// the closed zero-volume pillows (a polygon and its reverse) that welding can leave. Where
// welding a node would make an edge shared by more than two polygons (or twice in one
// direction), that node keeps its vertices apart, as plain marching cubes would. Where separate
// fans of polygons then meet at a welded vertex, each further fan gets its own copy, so the mesh
// stays vertex-manifold. Where two polygons are left alone around a vertex, folded onto each
// other, the fold is closed (mesh/mesh_folds.h). Vertices left sharing a point (a node's kept
// apart, a split one's copies, or one of them and a vertex the surface fit put on a feature point)
// are moved apart a little, each into its own fan (mesh/separate_points.h). Unused vertices are
// removed.
//
// Only polygons through a node vertex can change; the work is done on them alone, in parallel
// over fixed chunks, so the output does not depend on the number of threads.
#pragma once
#include "vdbsurf/core/vec3.h"
#include "vdbsurf/mesh/mesh.h"

#include <cstdint>
#include <utility>
#include <vector>

namespace vdbsurf {

struct NodeWeldStats {
    std::uint64_t weldedVertices = 0;    // vertices merged into their node's first vertex
    std::uint64_t collapsedPolygons = 0; // polygons that lost their area (pillows included)
    std::uint64_t splitVertices = 0;     // welded vertices given one copy per further fan
    std::uint64_t foldsClosed = 0;       // vertices whose fan two polygons closed alone (mesh/mesh_folds.h)
    std::uint64_t separatedVertices = 0; // vertices left on one point, moved apart (mesh/separate_points.h)
};

// Which entries of atNode share a node: per entry, its node's representative (the first vertex
// listed for the node) and how many entries the node has. (A sort of the entries by node: found
// once, for verticesToWeld and the weld.)
struct NodeGroups {
    std::vector<std::uint32_t> representative, listed;
};
NodeGroups groupByNode(const std::vector<std::pair<std::uint32_t, Vec3i>>& atNode);

// `atNode` lists (vertex, node) for every vertex on a node, in a fixed order: the first vertex
// listed for a node represents it. `rounded` (empty, or one flag per entry of atNode) marks the
// vertices put on their node because they rounded to it (the node is within rounding of the iso
// value): a node that has only such vertices, and whose polygons would all collapse, keeps them
// apart. Throws std::logic_error if no choice of nodes to keep apart leaves an edge-manifold mesh
// within a few attempts (not seen on marching-cubes meshes).
// `alsoSuspect`: further vertices that may lie on a node's point (the surface fit's).
// `polygonsToWeld`, if given, lists (ascending) the polygons through a vertex verticesToWeld
// names, as the mesher finds them while it makes the polygons, and says that every point lies on
// a polygon (each of the mesher's vertices is the crossing of an edge that its owner cell's
// polygon passes through): then only the points of those polygons are looked at for removal.
// Else the mesh is scanned for them, and points no polygon used before are removed too.
// `groups`, if given, is groupByNode(atNode), found before (the mesher needs it first).
NodeWeldStats weldNodeVertices(Mesh& mesh, const std::vector<std::pair<std::uint32_t, Vec3i>>& atNode,
                               const std::vector<std::uint8_t>& rounded = {}, const std::vector<std::uint32_t>& alsoSuspect = {},
                               const std::vector<std::uint32_t>* polygonsToWeld = nullptr, const NodeGroups* groups = nullptr);

// The vertices of atNode that the weld may merge: those whose node has two or more, ascending.
std::vector<std::uint32_t> verticesToWeld(const std::vector<std::pair<std::uint32_t, Vec3i>>& atNode, const NodeGroups& groups);
std::vector<std::uint32_t> verticesToWeld(const std::vector<std::pair<std::uint32_t, Vec3i>>& atNode);

} // namespace vdbsurf
