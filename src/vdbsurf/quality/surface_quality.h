// How well a mesh reproduces a field's iso surface, measured against the field itself rather
// than against another mesh: points spread over the mesh are projected onto the iso surface
// (accuracy), and points on the true surface are looked up on the mesh (coverage). Owns the
// measures `vdbsurf compare`, the benchmarks and the tests report.
#pragma once
#include "vdbsurf/field/field.h"
#include "vdbsurf/mesh/mesh.h"

#include <vector>

namespace vdbsurf {

class CancelToken;

// An upper bound on the distance from p to the field's iso surface, found by a sign change along
// the gradient line through p (bisected) and by Newton steps; maxDistance when neither finds the
// surface within maxDistance.
double distanceToIsoSurface(const Field& field, double iso, const Vec3d& p, double maxDistance);

// Points on the field's iso surface: the vertices of marching cubes at spacing h on the field's
// own frame. On a grid meshed at its own voxel size those are exact crossings of the trilinear
// field, one per crossed voxel edge: the input's surface sampled at the input's resolution. Empty
// where the field has no surface at that spacing. Throws Cancelled once `cancel` is set.
std::vector<Vec3d> isoSurfaceSamples(const Field& field, double iso, double h, const CancelToken* cancel = nullptr);

struct SurfaceQuality {
    double h = 0;                     // the unit the tolerances below are in
    std::size_t meshSamples = 0, surfaceSamples = 0;
    double meanDistance = 0;          // mesh samples to the iso surface, world units
    double p95Distance = 0, maxDistance = 0; // capped at 2 h
    double accuracyQuarter = 0;       // share of mesh samples within h/4 of the surface
    double coverageQuarter = 0;       // share of surface samples within h/4 of the mesh
    double coverageOne = 0;           // ... within h
    double fScoreQuarter = 0;         // harmonic mean of accuracyQuarter and coverageQuarter
};

// Mesh samples: every vertex, every (fanned) triangle's centroid, and points at spacing about h
// inside triangles longer than 3 h. Runs in parallel; the result does not depend on the thread
// count. Throws Cancelled once `cancel` is set.
SurfaceQuality measureSurfaceQuality(const Mesh& mesh, const Field& field, double iso,
                                     const std::vector<Vec3d>& surfaceSamples, double h, const CancelToken* cancel = nullptr);

} // namespace vdbsurf
