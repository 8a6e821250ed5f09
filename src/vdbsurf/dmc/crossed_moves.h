// Moves of both sides that cross: the thin search moves nodes into thin parts of the inside and
// of the outside independently, and where a thick part's convex and concave features meet within
// a cell or two (the rim of a hole through a box, where the hole's concave edge reaches the top
// face), a node moved in can bridge over a passage that nodes moved out opened: a handle the
// shape does not have. This module owns undoing one side of such a group of moves, and undoing a
// move out that marching cubes joins across a face to the outside through a part of the inside.
#pragma once
#include "vdbsurf/core/vec3.h"
#include "vdbsurf/field/field.h"

#include <vector>

namespace vdbsurf {

struct LatticeDeformation;
struct LatticeFrame;

// Groups the nodes moved across (deformation.offsets; joined across any corner) and, in each
// group that holds moves to both sides, where the moves of either side alone leave the inside's
// Euler characteristic as it was at rest (insideEulerAround) and together change it without
// changing how many pieces either side makes around the group (a handle made or lost), puts the
// moves of the side with fewer back at rest. A thin part of either side changes the lattice's
// topology on its own (a plate's holes filled, a crack's halves parted): that is what the thin
// search is for, and it stays. `keep`: nodes never put back (sorted). Returns the nodes put back,
// sorted.
std::vector<Vec3i> undoCrossedMoves(const Field& field, const LatticeFrame& frame, double iso, LatticeDeformation& deformation,
                                    const std::vector<Vec3i>& keep);

// Joins across faces that tunnel: marching cubes joins two outside nodes diagonal across a face
// whose other two corners are inside, whatever the field does on the face. A node moved out of
// the inside (into a hole's concave edge a cell from its mouth) is so joined to the outside
// beyond the mouth's rim, where the lattice joins the two already through the hole: a tunnel
// through the rim. Each node moved out with such a face, where the inside joins the face's two
// inside corners on the face itself (sampled at h/(2k), k = `steps`), goes back to rest where
// that raises the inside's Euler characteristic and changes the pieces of neither side within
// two steps of it: a tunnel through the inside gone, nothing parted (a crack's node at its rim
// parts the halves; a tunnel under a cell wide that only such a join opens at its mouth parts
// the outside in the hole from the outside beyond; both stay). Judged on the thin search's end
// state: a crack's moves pass through such states on their way to parting the halves. Nodes in
// order, each judged with those before it put back; `keep`: nodes never put back (sorted).
// Returns the nodes put back, sorted.
std::vector<Vec3i> undoTunnelJoins(const Field& field, const LatticeFrame& frame, double iso, int steps, LatticeDeformation& deformation,
                                   const std::vector<Vec3i>& keep);

} // namespace vdbsurf
