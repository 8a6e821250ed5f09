// Marching-cubes case table, generated at start-up from the cube's faces rather than typed in:
// on every face the crossing segments separate each run of inside corners from the outside
// (inside corners never join across a face diagonal), segments are oriented so that the
// surface normal points from inside to outside, and segments chain into closed loops. Because a
// face's segments depend only on that face's four corners, two cells sharing a face always agree:
// the surface is watertight, manifold and consistently oriented by construction.
//
// Numbering: corner c sits at offset (c & 1, (c >> 1) & 1, (c >> 2) & 1); bit c of a case is set
// when corner c is inside. Edge e runs along axis a = e / 4 from its min corner; q = e % 4 gives
// the corner's bits on the two other axes u = (a+1)%3 (bit 0 of q) and v = (a+2)%3 (bit 1 of q).
#pragma once
#include "vdbsurf/core/vec3.h"

#include <cstdint>

namespace vdbsurf {

struct CubeCase {
    std::uint8_t loopCount = 0;
    std::uint8_t loopSize[4] = {};
    // Loops one after another, each in outward (counter-clockwise) order, rotated so that a fan
    // from its first vertex never draws a diagonal between two edges of one cube face: such a
    // diagonal could be drawn again by the neighbour across that face, making a non-manifold edge.
    // Every loop of this table has such a vertex (the table refuses to build otherwise).
    std::uint8_t edges[12] = {};
    std::uint16_t edgeMask = 0;   // edges with a crossing
};

// Do edges a and b lie on a common face of the cube?
bool cubeEdgesShareFace(int a, int b);

// The 256 cases, built on first use.
const CubeCase* cubeCaseTable();

// Inline: a surface cell asks for its case once or more in every pass (a call each was a few
// percent of marching cubes).
inline const CubeCase& cubeCase(unsigned config) {
    static const CubeCase* const table = cubeCaseTable();
    return table[config & 255u];
}

constexpr int cubeEdgeAxis(int e) { return e >> 2; }

// Offset of edge e's min corner within the cell.
inline Vec3i cubeEdgeOrigin(int e) {
    // axis x: q bits on (y, z); axis y: on (z, x); axis z: on (x, y).
    static constexpr int table[12][3] = {{0, 0, 0}, {0, 1, 0}, {0, 0, 1}, {0, 1, 1}, {0, 0, 0}, {0, 0, 1},
                                         {1, 0, 0}, {1, 0, 1}, {0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}};
    return {table[e][0], table[e][1], table[e][2]};
}

// The edge along `axis` whose min corner is at offset `origin` (each component 0 or 1).
inline int cubeEdgeIndex(int axis, const Vec3i& origin) {
    return axis * 4 + origin[std::size_t((axis + 1) % 3)] + 2 * origin[std::size_t((axis + 2) % 3)];
}

} // namespace vdbsurf
