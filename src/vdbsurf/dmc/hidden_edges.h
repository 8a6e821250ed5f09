// The thin search's last phase: lattice edges whose two ends lie on one side while a thin part
// crosses the edge between them. Marching cubes sees no crossing on such an edge, so whatever the
// part separates there (the cavity and the outside of a thin shell, the two halves of a ball cut
// by a crack) is joined through it — and the first phase never looks, because a cell with
// corners on both sides is not "hidden". Each such edge is sampled at steps shorter than h/k (so
// a part at least h/k wide is found, as in Ω), and one of its ends that has not moved goes to the
// middle of the crossing run, where that lies in its own Ω (an edge whose ends a bent path joins
// is left alone: the run is the other side's surface bulging across it; see edge_runs.h); where
// the one end whose Ω holds the run may not go there, the other end goes into the part beside the
// edge, within its own Ω (a crack near its rim). The moves are then bridged like the
// first phase's, and the edges around every node that moved are examined again, until none hides
// a part. Proposals are made in parallel from one state and applied in node order, so the result
// does not depend on thread order.
#pragma once
#include <cstdint>

namespace vdbsurf {

class Field;
struct Lattice;
struct LatticeDeformation;
struct ThinSearchOptions;

struct HiddenEdgeStats {
    std::uint64_t edgesExamined = 0; // edges sampled (their bounds straddle the iso value)
    std::uint64_t edgesSplit = 0;    // nodes moved onto a part an edge hid
    std::uint64_t bridged = 0;       // further nodes moved by bridging after them
    std::uint64_t samples = 0;
};

// Examines the edges of the lattice's active cells, with `deformation` as the earlier phases left
// it, and adds the moves. Does nothing on a field whose cell bounds are its corners' range.
void splitHiddenEdges(const Field& field, const Lattice& lattice, const ThinSearchOptions& options,
                      LatticeDeformation& deformation, HiddenEdgeStats* stats = nullptr);

} // namespace vdbsurf
