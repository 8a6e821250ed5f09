// The meshing job as the command line, the benchmarks and the service run it: choose the lattice
// (spacing, where its nodes sit), the iso value, build the sparse lattice, run the mesher, and
// report what happened. Holds no algorithm of its own.
#pragma once
#include "vdbsurf/core/lattice_frame.h"
#include "vdbsurf/field/field.h"
#include "vdbsurf/mesh/mesh.h"

#include <cstdint>
#include <functional>
#include <optional>
#include <string>

namespace vdbsurf {

class CancelToken;
struct Lattice;
struct LatticeDeformation;

// Dmc: Deformed Marching Cubes (thin search, sharp features, marching cubes on the deformed
// lattice); MarchingCubes: plain marching cubes on the lattice's corner signs.
enum class MeshMethod { MarchingCubes, Dmc };

const char* methodName(MeshMethod m);

struct MeshRequest {
    std::optional<double> iso;       // default: Field::defaultIso()
    std::optional<double> voxelSize; // lattice spacing in world units; default: the field's own
    MeshMethod method = MeshMethod::Dmc;
    bool triangulate = false;
    // Deformed Marching Cubes only.
    bool thin = true;  // search for parts thinner than a cell
    bool sharp = true; // place nodes on sharp edges and corners
    // Add vertices where the mesh strays more than fitTolerance cells from the surface
    // (dmc/surface_fit). Only on lattices coarser than the field's own detail (not a grid at its
    // own voxel size), and only with the thin search or the sharp pass on: without both, DMC is
    // plain marching cubes.
    bool fit = true;
    double fitTolerance = 0.2;
    // Collapse edges where the thin search moved nodes while the mesh stays within
    // simplifyTolerance cells of the surface (dmc/thin_simplify): a wire thinner than a cell
    // comes out as a tube of lattice-sized polygons otherwise.
    bool simplifyThin = true;
    double simplifyTolerance = 0.1;
    int searchSteps = 5;
    double sharpEdge = 0.9, sharpCorner = 0.7;
    // On a grid at its own voxel size, lattice leaves where at least this share of the surface
    // cells may hold an edge are noise and get no sharp features (--sharp-noise; in (0, 1]).
    double sharpNoiseShare = 0.95;
    // After nodes flip onto feature tips, recompute only the lattice leaves around them (false:
    // build the whole surface again; same mesh, for tests).
    bool patchAfterFlips = true;
    // A mesher that loses the whole surface (marching cubes on a part thinner than a cell) is a
    // result for `compare`, not an error: return the empty mesh instead of throwing.
    bool allowEmpty = false;
    // Called with the deformed lattice before the final surface is built (--lattice-out); the
    // lattice lies in the field's own frame, mapped to world by `frame` where not null.
    std::function<void(const Lattice&, const LatticeDeformation&, const OwnFrame* frame)> deformedLattice;
    // Bytes the mesh may take while it is made (buildLattice's estimate); 0: 80 % of the memory
    // free when meshing starts.
    double memoryLimit = 0;
    const CancelToken* cancel = nullptr;
};

struct MeshReport {
    double iso = 0;
    std::string isoReason;
    double voxelSize = 0;
    std::string voxelSizeReason;
    LatticeFrame frame;                  // the lattice, in the field's own frame where it has one
    const OwnFrame* ownFrame = nullptr;  // that frame and its map to world (the field's: valid while it lives), if any
    std::uint64_t upperNodesTested = 0, leafBlocksTested = 0, leafBlocksVisited = 0;
    std::uint64_t cellsExamined = 0, cellsActive = 0, cellsWithSurface = 0;
    // Cell faces on the lattice's outer boundary that the surface crosses: the mesh is open
    // there, cut where the lattice ends (a formula's shape reaching past its box).
    std::uint64_t facesOpenAtLatticeEdge = 0;
    std::uint64_t hiddenCells = 0, thinCandidates = 0, thinSamples = 0, thinNodesMoved = 0;
    std::uint64_t thinEdgesSplit = 0; // of the nodes moved, those an edge or face diagonal hid a part from
    std::uint64_t thinNodesCentred = 0; // moved within their side to the middle of a thin part (centreThinParts)
    std::uint64_t thinLoneJoined = 0;   // of the nodes moved, those that join a node alone inside to the rest (lone_nodes.h)
    std::uint64_t sharpEdgeCells = 0, sharpCornerCells = 0, sharpRejected = 0, nodesOnEdges = 0, nodesOnCorners = 0;
    std::uint64_t nodesAlongEdges = 0; // of nodesOnEdges, placed between the cells' choices (second round)
    // Lattice leaves the sharp pass skipped: nearly every surface cell's normals may turn past the
    // edge threshold, so the surface is not resolved there (noise; grids at their voxel size only).
    std::uint64_t unresolvedLeaves = 0;
    std::uint64_t weldedVertices = 0, collapsedPolygons = 0, splitVertices = 0;
    std::uint64_t foldsClosed = 0; // by the weld and the thin simplification (mesh/mesh_folds.h)
    // Vertices that the weld or a split left at one point with another, moved apart a little
    // (mesh/separate_points.h): the mesh is manifold where points are merged by position too.
    std::uint64_t separatedVertices = 0;
    // Cells whose values are all the field's fill (LatticeStats::cellsWithoutData), and the polygons
    // left out there: a grid's inactive inside meeting its outside where a band ends open.
    std::uint64_t cellsWithoutData = 0, polygonsWithoutData = 0;
    std::uint64_t nodesFlipped = 0; // sharp-feature nodes that changed side onto a tip (cases changed around them)
    std::uint64_t flipsUndone = 0;       // flipped and bridged nodes put back: together they changed the inside's topology
    std::uint64_t thinCrossedUndone = 0; // thin-search moves put back where moves to both sides crossed (crossed_moves.h)
    std::uint64_t thinTunnelsUndone = 0; // thin-search moves out put back where a join across a face tunnelled (crossed_moves.h)
    std::uint64_t fitEdgesSplit = 0, fitCentres = 0; // vertices the surface fit added on edges and in polygons
    std::uint64_t fitFeatureCentres = 0;             // of the centres: on sharp edges and corners
    std::uint64_t simplifyRegionTriangles = 0, simplifyCollapses = 0; // thin parts' triangles, vertices removed there
    double secondsLattice = 0, secondsThin = 0, secondsSharp = 0, secondsMesh = 0, secondsFit = 0, secondsSimplify = 0;
    // A mesh's points are float32 (as every mesh file and volumeToMesh's are): far from the origin
    // their step is coarse. The largest |coordinate| of the mesh in world units, the step of a
    // float there, and the lattice spacing in world units near the mesh (a grid's own frame may
    // scale it): a step above a small share of the spacing coarsens the shape.
    double farthestCoordinate = 0, coordinateStep = 0, worldSpacing = 0;
    std::size_t vertices = 0, triangles = 0, quads = 0, otherPolygons = 0;
};

// Throws Error naming the input when the request cannot be met or the result would be empty.
Mesh meshField(const Field& field, const MeshRequest& request, MeshReport& report);

} // namespace vdbsurf
