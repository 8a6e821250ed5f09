// The halfedge mesh that subdivision works on: OpenMesh's polygon mesh with double-precision
// points and the status flags that edge removal needs. Internal to the subdiv module; the public
// interface (sqrt2_subdivision.h) speaks Mesh, so OpenMesh's headers stay out of the rest.
#pragma once
#include "vdbsurf/mesh/mesh.h"

#include <OpenMesh/Core/Mesh/PolyMesh_ArrayKernelT.hh>

#include <string>
#include <vector>

namespace vdbsurf::subdiv {

struct SubdivTraits : public OpenMesh::DefaultTraitsDouble {
    VertexAttributes(OpenMesh::Attributes::Status);
    EdgeAttributes(OpenMesh::Attributes::Status);
    FaceAttributes(OpenMesh::Attributes::Status);
};
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

// Positions (as float) and polygons, in the halfedge mesh's vertex and face order.
Mesh toMesh(const HalfedgeMesh& mesh);

} // namespace vdbsurf::subdiv
