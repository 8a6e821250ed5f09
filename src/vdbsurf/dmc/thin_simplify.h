// Simplifying the mesh where the thin search moved nodes. A part thinner than a cell comes out of
// marching cubes on the deformed lattice as a tube or a sheet of lattice-sized polygons around
// its chain of moved nodes (a rod a third of a cell thick: ~8 triangles a link, 1.5 to 1.7
// links a cell of its length), several times what its shape needs, and a fine mesh of the same
// rod has few more. There, and only there, edges are collapsed, each vertex onto a neighbour (so
// every vertex left is one the mesher put on the surface), cheapest first by quadric error, while
//  - the topology stays (the link condition; no vertex left with fewer than three neighbours),
//  - no triangle turns over,
//  - every new triangle lies within the tolerance of the field's surface at its centroid and
//    edge midpoints (|f - iso| / |grad f|), and
//  - every vertex removed so far lies within the tolerance of the triangles that replace it.
// Vertices on a polygon outside the thin region, on an open border or on an edge of more than
// two polygons stay. Untouched polygons keep their shape (quads stay quads). In parallel over
// blocks of the lattice (two grids of them, the second shifted by half a block, then one serial
// run for what is left where their faces cross), each block's collapses in a fixed order: the
// output does not depend on the number of threads.
#pragma once
#include "vdbsurf/core/lattice_frame.h"
#include "vdbsurf/core/vec3.h"
#include "vdbsurf/mesh/mesh.h"

#include <cstdint>
#include <vector>

namespace vdbsurf {

class CancelToken;
class Field;

struct ThinSimplifyOptions {
    double iso = 0;
    double tolerance = 0.1; // in lattice cells
    // The edge of the blocks collapsed in parallel, in lattice cells; 0: one serial run over the
    // whole region (the greedy order everywhere; for comparisons).
    double blockCells = 16;
    const CancelToken* cancel = nullptr;
};

struct ThinSimplifyStats {
    std::uint64_t regionTriangles = 0; // triangles (polygons fanned) in the thin region before
    std::uint64_t collapses = 0;       // vertices removed
    std::uint64_t foldsClosed = 0;     // folds closed where a polygon went out whole (mesh/mesh_folds.h)
    double seconds = 0;
};

// `thinNodes`: where the nodes the thin search moved are (world units, in the frame of the
// lattice `frame`). The region is every polygon whose vertices all lie within 3/4 of a cell of
// one of them along every axis.
Mesh simplifyThinParts(const Field& field, const LatticeFrame& frame, const std::vector<Vec3d>& thinNodes, Mesh mesh,
                       const ThinSimplifyOptions& options, ThinSimplifyStats* stats = nullptr);

} // namespace vdbsurf
