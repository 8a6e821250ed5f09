// Surface fit: Deformed Marching Cubes' last step on a lattice coarser than the field's detail.
// Marching cubes joins the crossings of a cell by straight chords, and where a part is about a
// cell across (a wire one or two cells thick) one polygon can span more than half of its round
// and cut through it. Here an edge of the mesh whose midpoint lies farther than a tolerance from
// the surface gains a vertex on the surface (the midpoint projected along the gradient), and a
// polygon whose centre does gains a centre vertex; polygons given new vertices become fans of
// triangles. A mesh and a field in, a mesh out: no lattice state. Decided in parallel and
// numbered in edge and polygon order, so the output does not depend on the threads.
#pragma once
#include "vdbsurf/field/field.h"
#include "vdbsurf/mesh/mesh.h"

#include <cstdint>
#include <vector>

namespace vdbsurf {

class CancelToken;

struct SurfaceFitOptions {
    double iso = 0;
    double h = 0;           // lattice spacing, world units
    double tolerance = 0.2; // in cells: how far an edge's or a polygon's middle may stray
    // A polygon that strays across a sharp edge or corner the lattice could not place a node on
    // (a cube's corner whose cell holds no node that could reach it) is fanned round the feature
    // point its faces' planes meet at: `features` on; the thresholds as the sharp pass's.
    bool features = false;
    double edgeCosine = 0.9, cornerThreshold = 0.7;
    const CancelToken* cancel = nullptr;
};

struct SurfaceFitStats {
    std::uint64_t edgesSplit = 0, centresAdded = 0, featureCentres = 0; // (features among the centres)
    double seconds = 0;
};

// The mesh with vertices added where it strays from the surface. Polygons of five or more
// corners (marching cubes' loops left whole: SurfaceOptions::keepLoops) are fanned round a centre
// on the surface where that fan fits, else from their first corner as marching cubes fans them.
// Orientation, watertightness and manifoldness are kept: a split edge is split in every polygon
// that uses it, and a centre vertex fans only its own polygon.
// `fixed`: vertices the fit must leave as marching cubes joined them (crossings at a node that a
// weld will join after it): their edges are not split, and their polygons get a new vertex only
// on a sharp edge or corner (`features`), and only where no two of their crossings at one node
// lie apart in the ring.
Mesh fitToSurface(const Field& field, Mesh mesh, const std::vector<std::uint32_t>& fixed, const SurfaceFitOptions& options,
                  SurfaceFitStats* stats = nullptr);

} // namespace vdbsurf
