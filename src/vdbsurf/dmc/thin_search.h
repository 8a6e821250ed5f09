// Thin search, the first step of Deformed Marching Cubes: lattice nodes move, each within its own
// cell Ω = node + [-h/2, h/2)^3, into parts of the shape that no node reaches — solid parts
// thinner than a cell, and (symmetrically) gaps and cracks thinner than a cell inside a solid.
//
// Which nodes search is decided from the field's bounds, not by flooding from a seed: a cell
// whose bounds straddle the iso value although its eight corners lie on one side ("hidden") may
// hold a part the corners miss, and its corners search the parts of their Ω that lie in such
// cells. Cells that already have a corner on the other side are left alone, so a smooth thick
// surface is meshed exactly as plain marching cubes meshes it. Every node decides from the
// undeformed lattice only, so the search runs in parallel and does not depend on thread order.
// A move must keep what the node's edges show (edge_runs.h); the moves are applied in node order
// and checked again where a node near them moved before (two nodes of a crack must not move into
// the two halves beside them at once), which is order-free too. Last, after the sharp pass,
// nodes that are all the lattice has of a wire's cross-section move to its middle, on their own
// side (centreThinParts).
//
// Sampling: a body-centred cubic pattern of spacing a = h/m with m = ceil(k·√5/2) per axis,
// aligned so that the samples of all Ω together form one global lattice. Its covering radius
// a·√5/4 <= h/(2k) guarantees that any ball of diameter h/k — so any part at least h/k wide —
// contains a sample.
#pragma once
#include "vdbsurf/field/field.h"

#include <cstdint>
#include <vector>

namespace vdbsurf {

class CancelToken;
struct Lattice;
struct LatticeDeformation;

struct ThinSearchOptions {
    double iso = 0;
    int steps = 5; // k: parts at least h/k wide are found
    // Bridging only (the sharp pass's, after flips): a node whose edges to the other side cross
    // faces meeting at an edge (two crossings' normals below this cosine) is not moved across.
    // -1: every node may move.
    double keepFeatureNodes = -1;
    const CancelToken* cancel = nullptr;
};

struct ThinSearchStats {
    std::uint64_t hiddenCells = 0;  // active cells with all corners on one side
    std::uint64_t candidates = 0;   // nodes that searched
    std::uint64_t samples = 0;      // field evaluations spent searching
    std::uint64_t nodesMoved = 0;
    std::uint64_t bridged = 0;      // of those, moved to join a thin part's nodes across a diagonal
    std::uint64_t edgesSplit = 0;   // of those, moved onto a part that crossed an edge between two nodes of one side
    std::uint64_t loneJoined = 0;   // of those, moved to join a node alone inside to the rest (lone_nodes.h)
    double seconds = 0;
};

// Samples per axis of Ω for `steps`.
int thinSearchSamplesPerAxis(int steps);

// Adds the moves it finds to `deformation` (whose offsets must be empty). Throws Error naming
// --search-steps when steps is out of range (1 .. 64). `crowded` receives the nodes that may
// have at least 4 of their six neighbours across the surface, for centreThinParts; `loneJoins`
// the nodes moved to join a lone node (lone_nodes.h), a neck of a few polygons, no thin part.
void thinSearch(const Field& field, const Lattice& lattice, const ThinSearchOptions& options, LatticeDeformation& deformation,
                ThinSearchStats* stats = nullptr, std::vector<Vec3i>* crowded = nullptr, std::vector<Vec3i>* loneJoins = nullptr);

// Centring, the last move, after the sharp pass: a node at least 4 of whose six neighbours lie
// across the surface is all the lattice has of a thin part's cross-section there (a wire about
// a cell thick, a tunnel), and marching cubes puts the crossings where the lattice lines through
// the node meet the part's surface. Off the part's middle they crowd on one side, and the
// polygons between them cut through the part (wires 0.8-1 cell thick at random orientations:
// F-score at H/4 down to 0.78). Such a node, if it did not move before and no neighbour is on a
// feature, moves within its Ω to the centroid of the samples of its own side there, keeping its
// side (cell cases do not change), where those samples are thin across two directions (a smooth
// surface passing the node leaves half of Ω on its side, which is not), unless one of its edges
// would then hide more than it did.
// Only the nodes in `crowded` (from thinSearch) are examined, so a lattice whose cells hide
// nothing (a grid at its own voxel size) is meshed as marching cubes meshes it. Decided with
// the nodes as they stood, applied in node order (a node beside one centred before it is
// checked again). Returns the nodes centred.
std::vector<Vec3i> centreThinParts(const Field& field, const Lattice& lattice, const ThinSearchOptions& options,
                                   LatticeDeformation& deformation, const std::vector<Vec3i>& crowded, std::uint64_t* samples = nullptr);

// The second phase on its own: starting from the nodes `from`, moves nodes between two nodes of
// one side that marching cubes would separate across a diagonal although the field joins them,
// and neighbours of a node alone on its side that find its part in their Ω. Also used after
// sharp features flip a node onto a corner it had no edge to. Adds the evaluations to *samples
// and the nodes it moves to *moved.
std::uint64_t bridgeThinParts(const Field& field, const Lattice& lattice, const ThinSearchOptions& options,
                              LatticeDeformation& deformation, const std::vector<Vec3i>& from, std::uint64_t* samples = nullptr,
                              std::vector<Vec3i>* moved = nullptr);

// Bridging and the hidden-edge phase move nodes to join what marching cubes would separate, each
// checked with the nodes around it as they stood; later moves around one can leave it inside with
// no inside neighbour of its own, a bubble of a thick part that joins nothing (a crack node
// bridged into the half beside it after its six neighbours had moved into the crack: 8 triangles
// alone beside the crack). Each inside piece (6-connected, as marching cubes joins inside nodes)
// made only of nodes among `joins` that moved goes back to rest (also off a sharp feature, for the
// nodes the sharp pass flipped; the sharp pass then puts one the thin search had moved back where
// the thin search put it); the first phase's moves are not joins (a small part alone in its
// cells is what they are for). So does a join whose one inside neighbour is a node on the surface
// that has other inside neighbours: it meets them at that node's point only, a bubble of its own.
// Decided on one state for every piece, then applied; returns the nodes restored.
std::vector<Vec3i> restoreLoneJoins(const Field& field, const LatticeFrame& frame, double iso, const std::vector<Vec3i>& joins,
                                    LatticeDeformation& deformation);

} // namespace vdbsurf
