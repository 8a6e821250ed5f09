// B-spline patches over the units (seed 004 §4.2 and its first open problem, continuity across
// unit joins). Each saddle lobe gets one clamped cubic curve, fitted to the contour; a unit's
// patch takes as its bottom and top rows exactly those curves (cut at the unit's seam, joined,
// and refined to the patch's knots by knot insertion), so neighbouring patches share their
// boundary curves and meet without gaps. The rows in between are fitted to the unit's ring grid
// by least squares; the patch is closed in u (the first and last control columns are one), and
// a unit holding a minimum or maximum has that point as its whole first or last control row.
#pragma once
#include "vdbsurf/reeb/bspline.h"
#include "vdbsurf/reeb/ring_grid.h"

#include <vector>

namespace vdbsurf::reeb {

// A stretch of a lobe curve, lobe parameter [t0, t1], as the patch's row over u in [u0, u1].
struct BoundaryPiece {
    std::uint32_t lobe = 0;
    double t0 = 0, t1 = 1, u0 = 0, u1 = 1;
    bool top = false;
};

struct UnitPatch {
    BSplinePatch surface; // u, v in [0, 1]; v = 0 at the unit's lower end
    RingGrid grid;
    std::vector<BoundaryPiece> boundary;
    bool bottomPole = false, topPole = false;
};

struct PatchOptions {
    int gridU = 0, gridV = 0; // ring grid size; 0: from each unit
    const CancelToken* cancel = nullptr; // checked between sections and units (throws Cancelled)
};

struct PatchSet {
    std::vector<BSplineCurve> lobeCurves; // lobe parameter in [0, 1], from the saddle back to it
    std::vector<UnitPatch> patches;       // one per unit (arc)
    std::size_t sectionsWithSeveralLoops = 0, sectionsBlended = 0;
};

// One ring grid per unit (in unit order). Shows progress on a terminal.
std::vector<RingGrid> ringGrids(const ReebGraph& graph, const PatchOptions& options = {});
// Patches over the units from their ring grids (consumed). Shows progress on a terminal; throws
// Cancelled between units once `cancel` is set.
PatchSet fitPatches(const ReebGraph& graph, std::vector<RingGrid> grids, const CancelToken* cancel = nullptr);

// Largest distance between a patch's boundary row and the lobe curve it shares with the
// neighbouring patch, over `samples` points per piece: zero up to rounding when the patches join.
double maxJoinGap(const PatchSet& patches, int samples = 64);

} // namespace vdbsurf::reeb
