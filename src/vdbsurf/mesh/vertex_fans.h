// Corner-level topology of a polygon Mesh, shared by the algorithms that need a manifold,
// consistently oriented surface (subdivision, the Reeb graph): each corner's successor in its
// polygon, its partner across the edge, and the fans of polygons around each vertex.
#pragma once
#include "vdbsurf/mesh/mesh.h"

#include <cstdint>
#include <string>
#include <vector>

namespace vdbsurf {

// The next corner of the same polygon, for every corner of a polygon list.
std::vector<std::uint32_t> nextCorners(const std::vector<std::uint32_t>& offsets, std::size_t cornerCount);

// Non-manifold vertices (several fans of polygons meeting at one point, as where two blobs
// touch) are split: each further fan gets its own copy of the vertex. cornerVertex receives
// the vertex of every corner (indices into points, then the copies), partner the corner running
// the other way along each corner's edge (~0u on the boundary); returns the source vertex of
// each copy. Throws Error naming inputName when two polygons run along an edge in the same
// direction (inconsistent orientation, or an edge of three or more polygons).
std::vector<std::uint32_t> splitVertexFans(const Mesh& mesh, const std::string& inputName, std::vector<std::uint32_t>& cornerVertex,
                                           std::vector<std::uint32_t>& partner);

// Vertices among `candidates` where several fans of polygons meet (edge-manifold surfaces that
// touch at a point) get one copy per further fan, appended to points, so the mesh becomes
// vertex-manifold; the fan holding the vertex's first corner in polygon order keeps it, so the
// result is deterministic. Returns the number of copies made. When every polygon at a candidate
// is among `polygons` (ascending), only those are looked at. `scratch`, if given, is a number per
// point (or fewer: it grows), every one ~0u, and is left so: a caller's array then spares a
// fresh one's filling, which cost as much as the rest where the candidates are few.
std::size_t splitFansAt(Mesh& mesh, std::vector<std::uint32_t> candidates, const std::vector<std::uint32_t>* polygons = nullptr,
                        std::vector<std::uint32_t>* scratch = nullptr);

// How many of `candidates` have more than one fan (what splitFansAt would split).
std::size_t countSplitFans(const Mesh& mesh, std::vector<std::uint32_t> candidates);

} // namespace vdbsurf
