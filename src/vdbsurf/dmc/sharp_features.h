// Sharp features, the second step of Deformed Marching Cubes (after the thin search): per cell
// with surface, the crossings c_u and their outward normals n_u (field gradient) tell whether an
// edge (θ = min n_a·n_b < edge threshold) or a corner (φ = max |n_c·(n_0×n_1)| > corner
// threshold) of the shape passes through it. A corner is the meeting point of three tangent
// planes (paper eq. 11), an edge the line where two meet; the nearest lattice node whose own
// cell Ω holds the point (or, for an edge, its projection onto the line) moves onto it.
//
// A cell may hold two features (a step or a notch less than a cell deep): its crossings are
// grouped into planes by normal and position, and every corner (or edge) the planes make is
// proposed, not only the one the two most different normals suggest. A second round moves
// further nodes onto an edge's line where another cell confirms it, to close the gaps between
// the nodes the cells chose (see placeSharpFeatures).
//
// Rules the paper leaves open, chosen so that the result does not depend on thread order:
// - normal pairs that are nearly opposite are two sheets of a thin part, not an edge, and a cell
//   holding such a pair proposes nothing (the normals of a rod or plate turn as fast as at an
//   edge); nor does a feature with less than 2 cells of solid behind it (an edge: along the mean
//   of its faces' outward normals; a corner: at one angle to its faces), which would pinch a thin
//   part into beads or cut a rod in two;
// - a corner is three planes, or four through one point (an apex of four faces: the fourth's
//   normals would otherwise read as curvature); its node may be a corner of one of the 26 cells
//   around (an acute tip pokes into a cell that sees only two of its faces), and then takes its
//   side from the lattice, not from the proposing cell's case;
// - a third plane of its own below the corner threshold (down to 0.45 of it: a chamfer's corner,
//   a fine prism's rim, a low pyramid's base) makes a corner where the surface around the point
//   lies on the three planes (the lines where they meet a cell out, the faces between them a cell
//   and a half out) and another cell's edge runs through the point, else no feature (tangent
//   planes of a surface curving about a cell meet so too);
// - on a grid meshed at 2.5 voxels a cell or more, a cell that shows a feature first gives each
//   crossing the normal of the flat face it lies on, found among samples of the cells around
//   (sampled_planes.h): the grid's own normals blend the faces within a voxel and a half of a
//   kink, which is most of a corner cell's crossings;
// - a point outside the cell's neighbourhood, or whose distance to the surface (estimated from
//   the field and its gradient) exceeds a fifth of a cell, is rejected;
// - an edge stands only where another cell nearby proposes a point on its line, or a tangent
//   line meeting it nearby at a small angle (a straight edge crosses cells, a curved one turns
//   slowly; the tangent planes of a noisy or merely curved surface meet on a line per cell);
// - a node whose six neighbours all lie on the other side stays put: it is the only thing that
//   represents a thin part (a node the thin search moved may be placed, keeping the side it
//   moved to);
// - when several cells propose to move one node, a corner beats an edge, then the proposal
//   closest to the node's place wins, then the lower cell coordinate;
// - a node the thin search moved across goes back to rest where the pass left it alone on its
//   side (its neighbour there flipped or bridged away) or where the nodes placed around it close
//   its surface off (the crossings on their edges sit on them): either way a bubble.
#pragma once
#include "vdbsurf/field/field.h"

#include <cstdint>
#include <vector>

namespace vdbsurf {

class CancelToken;
class LatticeSurface;
struct Lattice;
struct LatticeDeformation;

struct SharpOptions {
    double iso = 0;
    double edgeThreshold = 0.9;   // θ_sharp (--sharp-edge)
    double cornerThreshold = 0.7; // φ_corner (--sharp-corner)
    int searchSteps = 5;          // for bridging flipped nodes (see thin_search.h)
    const CancelToken* cancel = nullptr;
};

struct SharpStats {
    std::uint64_t edgeCells = 0, cornerCells = 0; // cells whose normals show an edge / a corner
    std::uint64_t rejected = 0;                   // features found but not placed
    std::uint64_t nodesOnEdges = 0, nodesOnCorners = 0;
    std::uint64_t nodesAlongEdges = 0; // of nodesOnEdges, placed in the second round (between the cells' choices)
    // Nodes that had no edge to the other side and changed side onto a feature's tip, and the
    // nodes moved to join them: when non-zero, cell cases changed and the surface is rebuilt.
    std::uint64_t flipped = 0, bridged = 0;
    // Nodes moved across (by the thin search, or placed across here) that a flip left alone on
    // their side, or whose surface the nodes placed around them close off — bubbles: back at rest,
    // among changedNodes.
    std::uint64_t unhung = 0;
    // Flipped and bridged nodes put back on the side they had before the flips, because together
    // they changed the inside's topology (among changedNodes).
    std::uint64_t flipsUndone = 0;
    // The flipped, bridged and unhung nodes (sorted): the cells around them changed case.
    std::vector<Vec3i> changedNodes;
    double seconds = 0;
};

// `surface` must have been built with normals on the lattice deformed by the thin search, and with
// SurfaceOptions::sharpEdgeCosine no lower than options.edgeThreshold. Adds
// the nodes it places to deformation.onSurface (with their side in insideOnSurface) and their
// offsets. Throws Error naming --sharp-edge / --sharp-corner when a threshold is out of [-1, 1].
void placeSharpFeatures(const Field& field, const Lattice& lattice, const LatticeSurface& surface, const SharpOptions& options,
                        LatticeDeformation& deformation, SharpStats* stats = nullptr);

} // namespace vdbsurf
