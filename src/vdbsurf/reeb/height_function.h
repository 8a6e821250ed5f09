// The height function of the Reeb graph: h(v) = v · axis on the vertices of a closed surface,
// made a strict total order (simulation of simplicity), and optionally cleaned of extremum-
// saddle pairs whose persistence is below a threshold (the mesh's noise, not its shape).
#pragma once
#include "vdbsurf/reeb/closed_surface.h"

#include <cstdint>
#include <string>
#include <vector>

namespace vdbsurf::reeb {

struct HeightFunction {
    Vec3d axis;                      // unit length
    std::vector<double> height;      // v · axis
    std::vector<double> tie1, tie2;  // v · e1, v · e2 (e1, e2 generic directions across the axis)
    std::vector<std::uint32_t> rank; // the total order the sweep uses
    std::vector<std::uint32_t> byRank;
};

// A fixed generic unit direction perpendicular to the unit axis: the first tie-break, and where
// ring grids of units without a saddle put their seam.
Vec3d acrossAxis(const Vec3d& axis);

// Ties in height are broken by two fixed generic directions across the axis, then by index.
// Breaking ties linearly keeps a flat plateau free of critical points inside it (a linear
// function on a plane has none); breaking them by index alone would scatter spurious minima
// and saddles over every plateau. Throws Error naming "--axis" for a zero or non-finite axis.
HeightFunction makeHeightFunction(const ClosedSurface& surface, const Vec3d& axis);

// Throws Error naming inputName where a piece of the surface has all its vertices at one height
// (flat across the axis, or every point at one position): its level sets along the axis hold no
// contours, so there is no Reeb graph to fit patches to, only the tie-breaks' order.
void requirePiecesSpanHeights(const ClosedSurface& surface, const HeightFunction& f, const std::string& inputName);

struct SimplifyReport {
    std::size_t minimaRemoved = 0, maximaRemoved = 0, passes = 0;
};

// Removes every minimum (maximum) whose sub-level (super-level) component merges into an older
// one less than `persistence` higher (lower) in height, by re-ordering vertices so that each one
// but the kept extrema has a lower (higher) neighbour: a sweep from the kept extrema in the
// current order (Tierny & Pascucci, "Generalized topological simplification of scalar fields on
// surfaces", 2012), alternated for minima and maxima until neither changes. Heights stay as they
// are; only the order (rank) changes, so the cut follows the geometry to within `persistence`.
SimplifyReport simplifyExtrema(const ClosedSurface& surface, HeightFunction& f, double persistence);

// Where the level of vertex `levelVertex` crosses the edge a-b, as a parameter from a (0) to b
// (1): by heights, or where they tie by the two tie-break directions; clamped to [0, 1], since
// simplification can order a vertex against its height.
double levelParameter(const HeightFunction& f, std::uint32_t levelVertex, std::uint32_t a, std::uint32_t b);

} // namespace vdbsurf::reeb
