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

namespace vdbsurf {

class CancelToken;

struct SurfaceFitOptions {
    double iso = 0;
    double h = 0;           // lattice spacing, world units
    double tolerance = 0.2; // in cells: how far an edge's or a polygon's middle may stray
    // Polygons left whole are finished as marching cubes finishes its loops: those of five or
    // more corners fanned from the first, quads split along the shorter diagonal if this is set.
    bool triangulate = false;
    const CancelToken* cancel = nullptr;
};

struct SurfaceFitStats {
    std::uint64_t edgesSplit = 0, centresAdded = 0;
    double seconds = 0;
};

// The mesh (marching cubes' loops, whole) with vertices added where it strays from the surface,
// and its polygons finished. Orientation, watertightness and manifoldness are kept: a split edge
// is split in every polygon that uses it, and a centre vertex fans only its own polygon.
Mesh fitToSurface(const Field& field, Mesh mesh, const SurfaceFitOptions& options, SurfaceFitStats* stats = nullptr);

} // namespace vdbsurf
