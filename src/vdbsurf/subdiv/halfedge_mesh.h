// The halfedge mesh that subdivision works on: OpenMesh's polygon mesh with double-precision
// points, filled a whole level at a time through OpenMesh's kernel (assemble(), or the uniform
// step's arithmetic numbering) rather than face by face, which is what keeps a √2 step close to
// OpenSubdiv's table-driven refinement. Internal to the subdiv module; the public interface
// (sqrt2_subdivision.h) speaks Mesh, so OpenMesh's headers stay out of the rest.
#pragma once
#include "vdbsurf/mesh/mesh.h"
#include "vdbsurf/mesh/vertex_fans.h"

#include <OpenMesh/Core/Mesh/PolyMesh_ArrayKernelT.hh>
#include <tbb/parallel_for.h>

#include <string>
#include <vector>

namespace vdbsurf::subdiv {

// No status flags: meshes are assembled whole (see assemble()), never edited element by element.
struct SubdivTraits : public OpenMesh::DefaultTraitsDouble {};
using HalfedgeMesh = OpenMesh::PolyMesh_ArrayKernelT<SubdivTraits>;

// What a face carries into the next √2 step.
enum FaceKind : std::uint8_t {
    kPlain = 0,       // next face point is the vertex average
    kStoredPoint = 1, // merged quad of an odd step: next face point is the stored edge point
    kBoundaryEdge = 2 // fan triangle on a boundary edge: the even step splits that edge at the stored midpoint
};

// The per-face state of a subdivision mesh; both meshes a subdivider alternates between
// register them in the same order, so one set of handles serves both.
struct FaceProperties {
    OpenMesh::FPropHandleT<HalfedgeMesh::Point> storedPoint;
    OpenMesh::FPropHandleT<std::uint8_t> kind;
    OpenMesh::FPropHandleT<std::uint32_t> tag;
};

// f(i) for i in [0, n) over TBB; every subdivision loop writes only entry i, so the result does
// not depend on how the range is split.
template <typename F>
void parallelFor(std::size_t n, F&& f) {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 2048), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) f(i);
    });
}

// Builds the halfedge mesh of `mesh` after splitVertexFans, and returns how many vertex copies
// that made. Throws Error naming `inputName` for a polygon of fewer than three corners or with a
// repeated vertex, and as splitVertexFans does. Vertices no polygon uses are dropped.
std::size_t buildHalfedgeMesh(const Mesh& mesh, const std::string& inputName, HalfedgeMesh& out);

// Replaces the connectivity of `mesh` with the polygons given (vertex indices < vertexCount) and
// each corner's partner (the corner running the other way along its edge, or ~0u on the
// boundary), keeping registered properties. Edges are numbered in corner order, so the result is
// the same for any thread count. The polygons must form a manifold, consistently oriented surface
// (as splitVertexFans checks, and as every √2 step preserves); points are left to the caller.
void assemble(HalfedgeMesh& mesh, std::size_t vertexCount, const std::vector<std::uint32_t>& offsets,
              const std::vector<std::uint32_t>& indices, const std::vector<std::uint32_t>& partner);

// The point a √2 step puts inside face f: the stored point of a merged quad or boundary fan
// triangle on the even step, else the average of the face's vertices.
HalfedgeMesh::Point nextFacePoint(const HalfedgeMesh& mesh, const FaceProperties& props, HalfedgeMesh::FaceHandle f, bool odd);

// Frees the connectivity and the point and face-property storage of a mesh no longer needed
// (the level a full step has just refined), keeping its registered properties.
void releaseSpare(HalfedgeMesh& mesh, const FaceProperties& props);

// Positions (as float) and polygons, in the halfedge mesh's vertex and face order.
Mesh toMesh(const HalfedgeMesh& mesh);

} // namespace vdbsurf::subdiv
