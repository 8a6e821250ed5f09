// The halfedge mesh that subdivision works on: OpenMesh's polygon mesh with double-precision
// points, filled a whole level at a time through OpenMesh's kernel (assemble()) rather than
// face by face, which is what makes a √2 step as fast as OpenSubdiv's table-driven refinement. Internal to the subdiv module; the public
// interface (sqrt2_subdivision.h) speaks Mesh, so OpenMesh's headers stay out of the rest.
#pragma once
#include "vdbsurf/mesh/mesh.h"

#include <OpenMesh/Core/Mesh/PolyMesh_ArrayKernelT.hh>

#include <string>
#include <vector>

namespace vdbsurf::subdiv {

// No status flags: meshes are assembled whole (see assemble()), never edited element by element.
struct SubdivTraits : public OpenMesh::DefaultTraitsDouble {};
using HalfedgeMesh = OpenMesh::PolyMesh_ArrayKernelT<SubdivTraits>;

// Non-manifold vertices (several fans of polygons meeting at one point, as where two blobs
// touch) are split: each further fan gets its own copy of the vertex. cornerVertex receives
// the vertex of every corner (indices into points, then the copies); returns the source
// vertex of each copy.
std::vector<std::uint32_t> splitVertexFans(const Mesh& mesh, std::vector<std::uint32_t>& cornerVertex);

// Builds the halfedge mesh of `mesh` after splitVertexFans, and returns how many vertex copies
// that made. Throws Error naming `inputName` when a polygon cannot be added (repeated vertex,
// an edge used by three polygons, or two neighbours with opposite orientation). Vertices no
// polygon uses are dropped.
std::size_t buildHalfedgeMesh(const Mesh& mesh, const std::string& inputName, HalfedgeMesh& out);

// Replaces the connectivity of `mesh` with the polygons given (vertex indices < vertexCount),
// keeping registered properties. Halfedges are paired through each vertex's outgoing corners,
// edges numbered in corner order, so the result is the same for any thread count. The polygons
// must form a manifold, consistently oriented surface (as splitVertexFans checks, and as every
// √2 step preserves); points are left for the caller to set.
void assemble(HalfedgeMesh& mesh, std::size_t vertexCount, const std::vector<std::uint32_t>& offsets,
              const std::vector<std::uint32_t>& indices);

// The same, when the caller already knows each corner's partner (the corner running the other
// way along its edge, or ~0u on the boundary), as a √2 step does from the old level's structure.
void assembleWithPartners(HalfedgeMesh& mesh, std::size_t vertexCount, const std::vector<std::uint32_t>& offsets,
                          const std::vector<std::uint32_t>& indices, const std::vector<std::uint32_t>& partner);

// Positions (as float) and polygons, in the halfedge mesh's vertex and face order.
Mesh toMesh(const HalfedgeMesh& mesh);

} // namespace vdbsurf::subdiv
