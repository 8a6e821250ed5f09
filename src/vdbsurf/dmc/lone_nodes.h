// Lone nodes: where the lattice's cells hide nothing from their corners (a grid meshed at its own
// voxel size, or a whole number of cells a voxel), the thin search has nothing to look for, yet a
// node inside whose six neighbours all lie outside (Lattice::loneInsideNodes) is a bubble of its
// own to marching cubes, whose table never joins inside corners across a face. The grid's field
// is bilinear on a lattice face, and where the saddle of a face between the node and an inside
// node across its diagonal is inside, the field joins them there: an acute edge of a level set
// leaves such nodes beside it (the armadillo file has one). This module owns that join.
#pragma once
#include "vdbsurf/field/field.h"

#include <cstdint>
#include <vector>

namespace vdbsurf {

struct Lattice;
struct LatticeDeformation;
struct ThinSearchOptions;

// Joins each lone inside node to the inside across a face whose saddle is inside, by moving one
// of that face's two outside corners (within its Ω) onto the face, to a point inside from which
// the segments to both inside corners stay inside — nearest the saddle — if the move keeps what
// the corner's edges show (EdgeRuns::moveEffect) and changes nothing else about the inside's
// topology: the corner joins the node's bubble to one piece and leaves no handle or cavity behind
// (joinsBubbleOnly). Faces are tried deepest saddle first.
// Proposed in parallel on the lattice at rest, applied in node order (one near a move applied
// before it is proposed again), so the result does not depend on thread order. Returns the nodes
// moved; adds the field evaluations to *samples.
std::vector<Vec3i> joinLoneNodes(const Field& field, const Lattice& lattice, const ThinSearchOptions& options,
                                 LatticeDeformation& deformation, std::uint64_t* samples = nullptr);

// Would putting the centre of a 3x3x3 block (index x + 3 y + 9 z; its own entry ignored) inside
// join the node at index `lone` (a neighbour across a face, inside, with no other inside neighbour
// of its own) to the rest of the block's inside and do nothing else, as marching cubes meshes it
// (inside nodes joined along edges only)? The centre's other inside neighbours across faces must
// lie in one piece of the block, so that two pieces become one and no handle closes, and the
// inside's Euler characteristic must drop by exactly the bubble's 1.
bool joinsBubbleOnly(const bool inside[27], int lone);

} // namespace vdbsurf
