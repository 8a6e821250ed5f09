// Folds: two polygons that share both edges at a vertex v (a → v → b in one, b → v → a in the
// other) close v's fan between the two of them — a fin of no area, folded over at v. A viewer
// shows it as a flap; fanning the polygons into triangles turns it into an edge of four
// triangles, which the Reeb graph, subdivision and most tools refuse. Welding marching-cubes
// vertices onto lattice nodes leaves one where the polygons between two others collapse, and
// the thin simplification where a polygon goes out whole beside a collapse. Owns finding and
// closing them.
#pragma once
#include "vdbsurf/mesh/mesh.h"

#include <cstddef>
#include <cstdint>
#include <vector>

namespace vdbsurf {

struct FoldStats {
    std::size_t closed = 0;          // folds closed
    std::size_t removedPolygons = 0; // polygons left with fewer than three vertices
    std::size_t left = 0;            // folds left: closing them would double an edge
};

// Closes the folds at corners of `polygons` (ascending polygon numbers; the only ones looked
// at): v leaves both polygons, so the one becomes a → b and the other b → a. A polygon left
// with two vertices goes: a triangle folded against a larger polygon leaves that polygon's
// new edge paired with the edge the triangle shared with its third neighbour, and two
// triangles folded against each other are a closed pillow, both gone. Two larger polygons
// share the new edge a-b; where a-b is an edge already, the fold is left and counted. Points
// no polygon uses any more are dropped, the others keep their order.
// `scratch` is working space of a number per point, whatever it holds (a caller's array it no
// longer needs spares a fresh one's page faults).
FoldStats closeFolds(Mesh& mesh, std::vector<std::uint32_t> polygons, std::vector<std::uint32_t>& scratch);

// The vertices of the whole mesh whose only two polygons are folded onto each other, ascending.
std::vector<std::uint32_t> foldedVertices(const Mesh& mesh);

} // namespace vdbsurf
