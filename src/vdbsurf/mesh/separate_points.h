// Separating vertices that a mesher leaves at one point on purpose. Where two sheets of a surface
// touch at a lattice node (two blobs meeting exactly at an iso node, a feature node between two
// fans, a node whose crossings are kept apart so that no edge gets three polygons), the mesh keeps
// one vertex per sheet so that it stays manifold — but those vertices share a position, and a tool
// that merges points by position (trimesh on loading, Blender's Merge by Distance, Houdini's Fuse)
// welds them back into a vertex whose edges hold four polygons. Moving each a little into its own
// fan makes the surface an embedded one, which such tools leave as it is.
#pragma once
#include "vdbsurf/mesh/mesh.h"

#include <cstddef>
#include <cstdint>
#include <vector>

namespace vdbsurf {

// How far a vertex moves, as a share of the way to the centroid of its neighbours (its polygons'
// other vertices): a lattice cell's hundredth or so, far below any error the mesher promises.
constexpr double kSeparationShare = 0.05;

// Among `suspects` (vertex indices, in any order, repeats allowed), the used vertices at exactly
// one position with another are each moved kSeparationShare of the way to the centroid of their
// neighbours, so that no two share a position (where rounding to float or symmetric neighbours
// leave two together, the later one moves further, and at least one float step). Only the
// suspects' polygons are read, and only when some coincide: a mesh without such vertices costs
// one sort of the suspects. Deterministic: the result depends on the mesh alone. Returns how
// many vertices moved.
std::size_t separateCoincidentPoints(Mesh& mesh, std::vector<std::uint32_t> suspects);

} // namespace vdbsurf
