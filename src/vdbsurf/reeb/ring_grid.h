// Ring quad grids (seed 004 §4.2): a unit is cut into V sections by planes across the axis, each
// section resampled at U points evenly spaced along its contour; the section heights are then
// moved so that consecutive sections are evenly spaced along the surface, and each section's
// starting point is turned to sit under the previous one, so the grid does not twist. Every
// section is a closed ring: P(U - 1, v) joins P(0, v).
#pragma once
#include "vdbsurf/reeb/reeb_graph.h"

#include <cstdint>
#include <vector>

namespace vdbsurf {
class CancelToken;
class Progress;
} // namespace vdbsurf

namespace vdbsurf::reeb {

// One end of a unit: a pole (a unit holding a minimum or maximum) or a closed contour at the
// saddle's height (the unit's lobes there, joined in order).
struct UnitEnd {
    bool pole = true;
    Vec3d point;               // the pole
    std::vector<Vec3d> loop;   // the contour, first point repeated at the end
    double height = 0;
};

UnitEnd unitEnd(const ReebGraph& graph, const Unit& unit, bool top);

struct RingGrid {
    int U = 0, V = 0;
    std::vector<Vec3d> points;   // row v (bottom to top) holds U points
    std::vector<double> heights; // of each row
    // Where u = 0 sits on each end's contour, as a fraction of its length from the contour's start.
    double bottomSeam = 0, topSeam = 0;
    std::size_t sectionsWithSeveralLoops = 0; // noise: the longest loop was used
    std::size_t sectionsBlended = 0;          // no contour (a flat unit): blended from the rows beside
    const Vec3d& at(int u, int v) const { return points[std::size_t(v) * std::size_t(U) + std::size_t(u)]; }
};

// U, V <= 0 choose the size from the unit: about one grid point per four of the unit's input
// vertices, spaced alike in both directions (U in [8, 128], V in [4, 128]).
// The sections are cut up to kSectionPasses times (their heights re-spaced between passes);
// `progress`, where given, advances by V a pass and by ringGridProgressUnits(V) in all. Throws
// Cancelled between sections once `cancel` is set.
constexpr int kSectionPasses = 4, kMaxAutoV = 128;
inline std::uint64_t ringGridProgressUnits(int V) { return std::uint64_t(kSectionPasses) * std::uint64_t(V > 0 ? V : kMaxAutoV); }
RingGrid ringGrid(const ReebGraph& graph, const Unit& unit, int U = 0, int V = 0, const CancelToken* cancel = nullptr,
                  Progress* progress = nullptr);

// Closed polyline (first point repeated last) resampled at n points evenly spaced by length,
// starting `offset` (a fraction of the length) from its start.
std::vector<Vec3d> resampleLoop(const std::vector<Vec3d>& loop, int n, double offset);
double loopLength(const std::vector<Vec3d>& loop);

} // namespace vdbsurf::reeb
