// The topology of marching cubes' inside around one lattice node, from the sides of the 3x3x3
// nodes around it (index x + 3 y + 9 z, offsets -1 .. 1, the node itself at 13). Marching cubes'
// table (cube_table.h) joins inside corners along cell edges only, never across a face or a cell
// diagonal, so its inside is the nodes inside joined along edges, with each face's and each
// cell's inside corners as many components as their edges make. What putting the centre inside
// does to that is counted here: the pieces it joins, and the change of the Euler characteristic
// that says whether it also closes a handle or fills a cavity (lone_nodes.h).
#pragma once

namespace vdbsurf {

// The pieces of the block's inside (its nodes inside joined along edges, the centre and
// `leaveOut` left out) that hold a node across a face from the centre: the pieces that putting
// the centre inside joins, as far as the block can tell.
int insidePiecesAtCentre(const bool inside[27], int leaveOut = -1);

// How much the Euler characteristic of the inside changes when the centre is put inside (its
// own entry is ignored): counted over the cells that have it as a corner, as the compactly
// supported Euler characteristic of the open inside (nodes, edge intervals, and the inside
// components of faces and cells), whose negative the inside's is. Joining k pieces is 1 - k;
// closing a loop (a handle) or filling a cavity takes one more each, filling a hole that a piece
// goes round (a handle gone) or shutting a cavity in gives one back.
int insideEulerChange(const bool inside[27]);

} // namespace vdbsurf
