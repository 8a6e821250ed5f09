// The topology of marching cubes' inside around one lattice node, from the sides of the 3x3x3
// nodes around it (index x + 3 y + 9 z, offsets -1 .. 1, the node itself at 13). Marching cubes'
// table (cube_table.h) joins inside corners along cell edges only, never across a face or a cell
// diagonal, so its inside is the nodes inside joined along edges, with each face's and each
// cell's inside corners as many components as their edges make. What putting the centre inside
// does to that is counted here: the pieces it joins, and the change of the Euler characteristic
// that says whether it also closes a handle or fills a cavity (lone_nodes.h); and what putting
// the centre on the surface does to the surface around it (sharp_features.cpp).
#pragma once
#include "vdbsurf/core/vec3.h"

#include <functional>
#include <vector>

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

// The same count over the lattice: the compactly supported Euler characteristic of marching
// cubes' open inside over the nodes, edges, faces and cells that have one of `nodes` as a corner
// (repeats allowed), `inside` giving each node's side. Between two states that differ only at
// those nodes, its change is the change of the whole inside's: zero where pieces, handles and
// cavities stay as they were (or change in ways that cancel, which a few nodes seldom do).
int insideEulerAround(const std::vector<Vec3i>& nodes, const std::function<bool(const Vec3i&)>& inside);

// How many pieces the nodes of the box [lo, hi] on `side` (inside: true) make within it, joined
// as marching cubes joins them: inside nodes along edges, outside nodes across faces' diagonals
// too.
int piecesInBox(const Vec3i& lo, const Vec3i& hi, bool side, const std::function<bool(const Vec3i&)>& inside);

// The nodes (repeats allowed) in groups joined across any corner, each sorted (x, then y, then z),
// groups in the order of their first nodes: groups two steps apart or more share no element of
// the lattice, so their changes can be counted apart.
std::vector<std::vector<Vec3i>> groupsAcrossCorners(std::vector<Vec3i> nodes);

// What welding the crossings of the centre's six edges into it does to the surface around it,
// as the mesher's weld does where the node is placed on the surface (a sharp feature). The patch
// is the marching-cubes polygons of the eight cells around the centre (the centre on the side
// its own entry gives) with a crossing on one of those edges; welded, they are pinched where the
// centre comes back, those of fewer than three vertices and pairs folded onto each other go, and
// the fans that meet at the centre (polygons joined across edges there) get a vertex each, as
// the weld splits them. Where the patch's pieces and Euler characteristic stay, so does the
// surface's topology: two sheets of a thin gap made to touch at the node are two fans where
// they were two discs. Where they change, the weld cuts the surface: a tube of marching cubes'
// surface running through the node comes apart there (an annulus becomes two discs).
struct PatchTopology {
    int pieces = 0, euler = 0;
    bool operator==(const PatchTopology& o) const { return pieces == o.pieces && euler == o.euler; }
};
struct CentreWeld {
    PatchTopology before, after;
    bool keepsTopology() const { return before == after; }
};
CentreWeld weldAtCentre(const bool inside[27]);

} // namespace vdbsurf
