// Polygons into triangles for algorithms that need a triangle mesh with the polygon mesh's
// topology (the Reeb graph): each polygon is fanned from a corner none of whose diagonals is
// already an edge of the mesh or a diagonal fanned before.
#pragma once
#include "vdbsurf/mesh/mesh.h"

#include <cstdint>
#include <vector>

namespace vdbsurf {

// Triangles of every polygon, in polygon order; polygonOf (if given) receives the polygon each
// came from. A polygon is fanned from its first corner unless a diagonal from there joins two
// vertices that an edge of the mesh (or a diagonal chosen for an earlier polygon) joins already:
// a quad whose opposite corners also share an edge elsewhere — a pinch that edge collapses leave
// in a closed manifold mesh — fanned across that edge would put four triangles on it. Then the
// first corner whose diagonals are all new is the fan's apex; where there is none, the first
// corner is kept (the caller's manifold checks then report the edge).
Mesh fanIntoTriangles(const Mesh& mesh, std::vector<std::uint32_t>* polygonOf = nullptr);

} // namespace vdbsurf
