// Critical points, the Reeb graph and its units (seed 004 §3, §4.1). A vertex is a minimum,
// maximum or saddle by the sign changes around its link (Banchoff); the critical contour of a
// saddle (the component of its level set through it) is traced and cut out of the surface, and
// what is left falls apart into one unit per Reeb graph arc: pieces are joined across uncut edges
// with union-find, the equivalent of a sweep that tracks contour components. Each unit runs from
// its lowest critical point to its highest, which are the arc's ends.
#pragma once
#include "vdbsurf/reeb/closed_surface.h"
#include "vdbsurf/reeb/height_function.h"

#include <cstdint>
#include <string>
#include <vector>

namespace vdbsurf::reeb {

enum class CriticalType : std::uint8_t { Regular, Minimum, Maximum, Saddle };
const char* criticalTypeName(CriticalType t);

struct ReebNode {
    CriticalType type = CriticalType::Regular;
    int multiplicity = 1; // saddles: number of sign-change pairs around the link minus one
    std::uint32_t vertex = 0; // in the ClosedSurface
    std::uint32_t rank = 0;
    double height = 0;
    Vec3d position;
};

// One loop of a saddle's critical contour, from the saddle back to it, oriented like every
// contour here (the surface's outward side on the same hand). unitBelow and unitAbove are the
// units on either side.
struct Lobe {
    std::uint32_t node = 0;
    std::vector<Vec3d> points; // first and last are the saddle
    std::uint32_t unitBelow = ~0u, unitAbove = ~0u;
    double length() const;
};

// One Reeb graph arc's piece of the surface, as its own polygon mesh (cut polygons are
// triangles, quads or pentagons), in double precision.
struct Unit {
    std::vector<Vec3d> points;
    std::vector<std::uint32_t> offsets{0}, indices;
    std::vector<std::uint32_t> inputPolygons; // the input polygons it covers, sorted, in part or whole
    std::uint32_t lower = 0, upper = 0;       // node indices (the arc's ends)
    std::vector<std::uint32_t> bottomLobes, topLobes; // boundary loops at the lower / upper saddle, in order
    double area = 0;
    std::size_t inputVertices = 0; // input vertices inside the unit
    std::size_t polygonCount() const { return offsets.size() - 1; }
};

struct ReebGraph {
    Vec3d axis;
    long eulerCharacteristic = 0;
    std::size_t components = 0;
    std::vector<ReebNode> nodes; // in height order
    std::vector<Unit> units;     // arc i is unit i: nodes[units[i].lower] to nodes[units[i].upper]
    std::vector<Lobe> lobes;
    SimplifyReport simplified;
    std::size_t minima = 0, maxima = 0, saddles = 0; // saddles counted with multiplicity
    // The graph's independent loops: the genus of the surface, less the handles a saddle of
    // multiplicity 2 or more keeps within its own level (one arc below and one above it, on a
    // gyroid's mesh: one handle the graph does not show).
    std::size_t loops() const { return units.size() + components - nodes.size(); }
};

// Classifies every vertex in the order of f. Throws std::logic_error when minima - saddles +
// maxima differs from the Euler characteristic (which would be a bug, not bad input).
std::vector<ReebNode> criticalPoints(const ClosedSurface& surface, const HeightFunction& f);

// The whole decomposition of a closed surface along f.
ReebGraph buildReebGraph(const ClosedSurface& surface, const HeightFunction& f);

} // namespace vdbsurf::reeb
