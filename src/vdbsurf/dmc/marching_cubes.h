// Marching cubes over a sparse Lattice, in parallel over its VDB leaves (one leaf = one TBB work
// unit). Each lattice edge with a crossing gets exactly one vertex, computed by the leaf of the
// cell that owns the edge, so vertices are shared between leaves without duplicates; vertices
// and polygons are numbered leaf by leaf in tree order, so the output does not depend on the
// number of threads.
#pragma once
#include "vdbsurf/field/field.h"
#include "vdbsurf/lattice/lattice.h"
#include "vdbsurf/mesh/mesh.h"

namespace vdbsurf {

class CancelToken;

struct MarchingCubesOptions {
    double iso = 0;
    bool triangulate = false; // split quads (shorter diagonal) so the output is triangles only
    const CancelToken* cancel = nullptr;
};

struct MarchingCubesStats {
    std::uint64_t cellsWithSurface = 0;
    std::uint64_t leaves = 0;
    double seconds = 0;
};

// Polygons are oriented with normals pointing from inside to outside (Field::inside()).
// Crossings: linear interpolation where the field is linear along lattice edges (a grid at its
// own voxel size), otherwise Field::edgeCrossing on the true field.
Mesh marchingCubes(const Field& field, const Lattice& lattice, const MarchingCubesOptions& options,
                   MarchingCubesStats* stats = nullptr);

} // namespace vdbsurf
