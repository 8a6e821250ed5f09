#include "vdbsurf/dmc/mesher.h"

#include "vdbsurf/core/cancel.h"
#include "vdbsurf/core/error.h"
#include "vdbsurf/dmc/crossed_moves.h"
#include "vdbsurf/dmc/lattice_deformation.h"
#include "vdbsurf/dmc/lattice_surface.h"
#include "vdbsurf/dmc/sharp_features.h"
#include "vdbsurf/dmc/surface_fit.h"
#include "vdbsurf/dmc/thin_search.h"
#include "vdbsurf/dmc/thin_simplify.h"
#include "vdbsurf/lattice/lattice.h"
#include "vdbsurf/mesh/separate_points.h"
#include "vdbsurf/mesh/vertex_fans.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <memory>
#include <numeric>

namespace vdbsurf {

namespace {

// The mesh without the polygons that touch a vertex without data (Field::pointsWithData): those
// on the fill's own surface, and where it meets the data, the polygons that would hang from it.
Mesh withoutPolygonsOffData(const Mesh& mesh, const Field& field) {
    std::vector<std::uint8_t> hasData(mesh.points.size());
    field.pointsWithData(mesh.points.data(), mesh.points.size(), hasData.data());
    std::vector<std::uint8_t> keep(mesh.polygonCount(), 1);
    for (std::size_t p = 0; p < mesh.polygonCount(); ++p)
        for (std::uint32_t i = mesh.offsets[p]; i < mesh.offsets[p + 1]; ++i) keep[p] &= hasData[mesh.indices[i]];
    return keepPolygons(mesh, keep);
}

// Faces on the lattice's outer boundary whose corners lie on both sides: the surface leaves the
// lattice there, and the mesh is open along them (a formula's shape passing its --bbox). Nodes
// on the outer faces keep their side in every step of DMC, so their values at rest decide. Only
// the leaves of cells that touch the boundary are visited.
std::uint64_t facesOpenAtLatticeEdge(const Field& field, const Lattice& lattice, double iso) {
    const openvdb::CoordBBox& range = lattice.cellRange;
    const Inside side = field.inside();
    std::uint64_t open = 0;
    for (auto leaf = lattice.cells->cbeginLeaf(); leaf; ++leaf) {
        const openvdb::CoordBBox box = leaf->getNodeBoundingBox();
        bool touches = false;
        for (int a = 0; a < 3; ++a) touches = touches || box.min()[a] <= range.min()[a] || box.max()[a] >= range.max()[a];
        if (!touches) continue;
        for (auto it = leaf->cbeginValueOn(); it; ++it) {
            const openvdb::Coord c = it.getCoord();
            for (int a = 0; a < 3; ++a)
                for (const bool high : {false, true}) {
                    if (c[a] != (high ? range.max()[a] : range.min()[a])) continue;
                    Vec3i first(c.x(), c.y(), c.z()), dims(2, 2, 2);
                    first[std::size_t(a)] += high ? 1 : 0;
                    dims[std::size_t(a)] = 1;
                    double v[4];
                    field.sampleNodes(lattice.frame, first, dims, nullptr, v);
                    int inside = 0;
                    for (const double x : v) inside += isInside(x, iso, side);
                    open += inside > 0 && inside < 4;
                }
        }
    }
    return open;
}

} // namespace

const char* methodName(MeshMethod m) {
    switch (m) {
    case MeshMethod::MarchingCubes: return "mc";
    case MeshMethod::Dmc: return "dmc";
    }
    return "?";
}

namespace {
void measureCoordinateStep(const Mesh& mesh, MeshReport& report) {
    // (In parallel: a serial pass over every point was a serial tail of every mesh. A maximum
    // does not depend on the order it is taken in.)
    const float farthest = tbb::parallel_reduce(
        tbb::blocked_range<std::size_t>(0, mesh.points.size(), 8192), 0.0f,
        [&](const tbb::blocked_range<std::size_t>& r, float m) {
            for (std::size_t i = r.begin(); i != r.end(); ++i)
                for (std::size_t a = 0; a < 3; ++a)
                    if (std::isfinite(mesh.points[i][a])) m = std::max(m, std::fabs(mesh.points[i][a]));
            return m;
        },
        [](float x, float y) { return std::max(x, y); });
    report.farthestCoordinate = farthest;
    report.coordinateStep = double(std::nextafter(farthest, INFINITY)) - double(farthest);
}
} // namespace

Mesh meshField(const Field& field, const MeshRequest& request, MeshReport& report) {
    if (const OwnFrame* own = field.ownFrame()) {
        MeshRequest inFrame = request;
        if (request.deformedLattice)
            inFrame.deformedLattice = [&](const Lattice& lattice, const LatticeDeformation& deformation, const OwnFrame*) {
                request.deformedLattice(lattice, deformation, own);
            };
        Mesh mesh = meshField(*own->field, inFrame, report);
        report.ownFrame = own;
        if (!own->spacingNote.empty()) report.voxelSizeReason += "; " + own->spacingNote;
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, mesh.points.size(), 4096), [&](const auto& r) {
            for (std::size_t i = r.begin(); i != r.end(); ++i) mesh.points[i] = Vec3f(own->apply(Vec3d(mesh.points[i])));
        });
        if (own->mirrors())
            for (std::size_t f = 0; f < mesh.polygonCount(); ++f)
                std::reverse(mesh.indices.begin() + mesh.offsets[f], mesh.indices.begin() + mesh.offsets[f + 1]);
        // The lattice's world spacing: the shortest of a cell's three edges at the frame's origin
        // (an affine map scales alike everywhere; a frustum's cells widen with depth).
        if (!mesh.points.empty()) {
            const Vec3d p = report.frame.origin;
            const double h = report.frame.h;
            report.worldSpacing = std::min({length(own->offsetToWorld(p, {h, 0, 0})), length(own->offsetToWorld(p, {0, h, 0})),
                                            length(own->offsetToWorld(p, {0, 0, h}))});
        }
        measureCoordinateStep(mesh, report);
        return mesh;
    }
    if (request.iso) {
        if (!std::isfinite(*request.iso)) throw Error("--iso", "must be a finite number");
        report.iso = *request.iso;
        report.isoReason = "given";
    } else {
        report.iso = field.defaultIso();
        report.isoReason = field.inside() == Inside::Below ? "default for level sets and formulas" : "default for fog volumes";
    }
    if (request.voxelSize) {
        if (!(*request.voxelSize > 0) || !std::isfinite(*request.voxelSize))
            throw Error("--voxel-size", "must be a positive number of world units, not " + messageNumber(*request.voxelSize));
        report.voxelSize = *request.voxelSize;
        report.voxelSizeReason = "given";
    } else if (auto h = field.naturalSpacing()) {
        report.voxelSize = *h;
        report.voxelSizeReason = "the grid's voxel size";
    } else {
        throw Error("--voxel-size", "is required for " + field.describe());
    }
    report.frame = field.naturalFrame(report.voxelSize);

    const bool dmc = request.method == MeshMethod::Dmc;
    const bool fit = dmc && request.fit && (request.thin || request.sharp) && !field.edgesAreLinear(report.frame);
    if (dmc && request.sharp && !(request.sharpNoiseShare > 0 && request.sharpNoiseShare <= 1))
        throw Error("--sharp-noise", "must be a share of a leaf's surface cells in (0, 1], not " + messageNumber(request.sharpNoiseShare));
    if (fit && !(request.fitTolerance > 0 && request.fitTolerance <= 1))
        throw Error("--fit-tolerance", "must be a number of cells in (0, 1], not " + messageNumber(request.fitTolerance));
    const bool simplify = dmc && request.thin && request.simplifyThin;
    if (simplify && !(request.simplifyTolerance > 0 && request.simplifyTolerance <= 1))
        throw Error("--simplify-tolerance", "must be a number of cells in (0, 1], not " + messageNumber(request.simplifyTolerance));
    const openvdb::CoordBBox range = latticeCellRange(field, report.frame);
    // DMC needs every cell the surface may pass, also those whose corners miss it.
    Lattice lattice = buildLattice(field, report.frame, range, report.iso,
                                   dmc && request.thin ? CellTest::Bounds : CellTest::CornerSigns, request.cancel,
                                   request.memoryLimit);
    report.upperNodesTested = lattice.stats.upperNodesTested;
    report.leafBlocksTested = lattice.stats.leafBlocksTested;
    report.leafBlocksVisited = lattice.stats.leafBlocksVisited;
    report.cellsExamined = lattice.stats.cellsExamined;
    report.cellsActive = lattice.stats.cellsActive;
    report.secondsLattice = lattice.stats.seconds;
    report.facesOpenAtLatticeEdge = facesOpenAtLatticeEdge(field, lattice, report.iso);

    LatticeDeformation deformation;
    ThinSearchOptions to;
    to.iso = report.iso;
    to.steps = request.searchSteps;
    to.cancel = request.cancel;
    std::vector<Vec3i> crowded; // for centring, the last move
    std::vector<Vec3i> thinNodes; // moved or centred by the thin search, for the simplification
    auto centre = [&] {
        const auto t = std::chrono::steady_clock::now();
        std::vector<Vec3i> centred = centreThinParts(field, lattice, to, deformation, crowded, &report.thinSamples);
        thinNodes.insert(thinNodes.end(), centred.begin(), centred.end());
        report.thinNodesCentred = centred.size();
        report.secondsThin += std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
        return centred;
    };
    if (dmc && request.thin) {
        ThinSearchStats ts;
        std::vector<Vec3i> loneJoins;
        thinSearch(field, lattice, to, deformation, &ts, &crowded, &loneJoins);
        std::sort(loneJoins.begin(), loneJoins.end(), lessXYZ);
        const auto crossedStart = std::chrono::steady_clock::now();
        report.thinCrossedUndone = undoCrossedMoves(field, lattice.frame, report.iso, deformation, loneJoins).size();
        report.thinTunnelsUndone = undoTunnelJoins(field, lattice.frame, report.iso, to.steps, deformation, loneJoins).size();
        const double crossedSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - crossedStart).count();
        activateCellsAroundMovedNodes(lattice, deformation);
        // (Before the sharp pass moves nodes of its own.) A lone node's join is a neck of a few
        // polygons, nothing to simplify (on the armadillo, the simplification's passes over the
        // whole mesh took 8 ms for its one join).
        for (auto it = deformation.offsets->cbeginValueOn(); it; ++it) {
            const Vec3i n(it.getCoord().x(), it.getCoord().y(), it.getCoord().z());
            if (!std::binary_search(loneJoins.begin(), loneJoins.end(), n, lessXYZ)) thinNodes.push_back(n);
        }
        report.thinLoneJoined = ts.loneJoined;
        report.hiddenCells = ts.hiddenCells;
        report.thinCandidates = ts.candidates;
        report.thinSamples = ts.samples;
        report.thinNodesMoved = ts.nodesMoved;
        report.thinEdgesSplit = ts.edgesSplit;
        report.secondsThin = ts.seconds + crossedSeconds;
        // Without the sharp pass nothing moves after it: centred before the surface is built.
        if (!request.sharp) centre();
    }

    SurfaceOptions so;
    so.iso = report.iso;
    so.triangulate = request.triangulate;
    so.keepLoops = fit; // the fit fans them
    so.normals = dmc && request.sharp;
    so.sharpEdgeCosine = request.sharpEdge;
    so.unresolvedShare = request.sharpNoiseShare;
    so.cancel = request.cancel;
    auto surface = std::make_unique<LatticeSurface>(field, lattice, &deformation, so);
    report.unresolvedLeaves = surface->stats().unresolvedLeaves; // (a rebuilt surface has no normals)
    if (dmc && request.sharp) {
        SharpOptions sh;
        sh.iso = report.iso;
        sh.edgeThreshold = request.sharpEdge;
        sh.cornerThreshold = request.sharpCorner;
        sh.searchSteps = request.searchSteps;
        sh.cancel = request.cancel;
        SharpStats ss;
        placeSharpFeatures(field, lattice, *surface, sh, deformation, &ss);
        const std::vector<Vec3i> centred = request.thin ? centre() : std::vector<Vec3i>();
        const auto t = std::chrono::steady_clock::now();
        if (ss.flipped > 0 || ss.unhung > 0 || ss.flipsUndone > 0 || !centred.empty()) {
            // Nodes changed side: cell cases changed around them; centred nodes moved their
            // edges. The leaves there are computed again (or, for tests, the whole surface).
            activateCellsAround(lattice, ss.changedNodes);
            if (request.patchAfterFlips) {
                std::vector<Vec3i> changed = ss.changedNodes;
                changed.insert(changed.end(), centred.begin(), centred.end());
                surface->rebuildAround(changed, deformation);
                surface->moveCrossingsToFeatureNodes(deformation);
            } else {
                so.normals = false;
                surface.reset();
                surface = std::make_unique<LatticeSurface>(field, lattice, &deformation, so);
            }
        } else {
            surface->moveCrossingsToFeatureNodes(deformation);
        }
        report.sharpEdgeCells = ss.edgeCells;
        report.sharpCornerCells = ss.cornerCells;
        report.sharpRejected = ss.rejected;
        report.nodesOnEdges = ss.nodesOnEdges;
        report.nodesAlongEdges = ss.nodesAlongEdges;
        report.nodesOnCorners = ss.nodesOnCorners;
        report.nodesFlipped = ss.flipped;
        report.flipsUndone = ss.flipsUndone;
        report.secondsSharp = ss.seconds + std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
    }
    if (request.deformedLattice) request.deformedLattice(lattice, deformation, nullptr);
    // The fit refines marching cubes' polygons before the crossings at nodes are welded, so that
    // the weld sees every edge the mesh will have.
    std::function<void(Mesh&, const std::vector<std::uint32_t>&)> fitBeforeWeld;
    if (fit)
        fitBeforeWeld = [&](Mesh& m, const std::vector<std::uint32_t>& toWeld) {
            SurfaceFitOptions fo;
            fo.iso = report.iso;
            fo.h = report.frame.h;
            fo.tolerance = request.fitTolerance;
            fo.features = request.sharp;
            fo.edgeCosine = request.sharpEdge;
            fo.cornerThreshold = request.sharpCorner;
            fo.cancel = request.cancel;
            SurfaceFitStats fs;
            m = fitToSurface(field, std::move(m), toWeld, fo, &fs);
            report.fitEdgesSplit = fs.edgesSplit;
            report.fitCentres = fs.centresAdded;
            report.fitFeatureCentres = fs.featureCentres;
            report.secondsFit = fs.seconds;
        };
    // Where the thin search's nodes are now (the sharp pass may have moved some again), for the
    // simplification below; then the deformation is done with, and its trees are freed while the
    // surface makes the mesh (whose weld leaves the other threads idle at times), not after it.
    std::vector<Vec3d> thinWhere;
    if (simplify && !thinNodes.empty()) {
        thinWhere.reserve(thinNodes.size());
        const openvdb::tree::ValueAccessor<const OffsetTree> offsets(*deformation.offsets);
        for (const Vec3i& n : thinNodes) {
            const openvdb::Vec3f o = offsets.getValue(openvdb::Coord(n.x, n.y, n.z));
            thinWhere.push_back(report.frame.nodeWorld(n) + Vec3d(o.x(), o.y(), o.z()));
        }
    }
    Mesh mesh;
    tbb::parallel_invoke([&] { mesh = surface->mesh(fitBeforeWeld); }, [&] { deformation.release(); });
    report.cellsWithSurface = surface->stats().cellsWithSurface;
    report.weldedVertices = surface->stats().weldedVertices;
    report.collapsedPolygons = surface->stats().collapsedPolygons;
    report.splitVertices = surface->stats().splitVertices;
    report.foldsClosed = surface->stats().foldsClosed;
    report.separatedVertices = surface->stats().separatedVertices;
    report.secondsMesh = surface->stats().seconds;
    report.cellsWithoutData = lattice.stats.cellsWithoutData;
    if (report.cellsWithoutData > 0) {
        const std::size_t before = mesh.polygonCount();
        mesh = withoutPolygonsOffData(mesh, field);
        report.polygonsWithoutData = before - mesh.polygonCount();
        // The mesh is open where the data ends (cells the lattice dropped, polygons left out
        // here), and two holes meeting diagonally leave the surface between them touching itself
        // at a vertex: split it, one per fan, as the weld does, so what leaves is vertex-manifold.
        std::vector<std::uint32_t> everyVertex(mesh.points.size());
        std::iota(everyVertex.begin(), everyVertex.end(), 0u);
        const std::size_t beforeSplit = mesh.points.size();
        report.splitVertices += splitFansAt(mesh, everyVertex);
        if (mesh.points.size() > beforeSplit) {
            // The copies and the vertices they came from (every vertex: the copies do not say).
            for (std::size_t v = beforeSplit; v < mesh.points.size(); ++v) everyVertex.push_back(std::uint32_t(v));
            report.separatedVertices += separateCoincidentPoints(mesh, std::move(everyVertex));
        }
    }
    if (simplify && !thinNodes.empty()) {
        ThinSimplifyOptions tso;
        tso.iso = report.iso;
        tso.tolerance = request.simplifyTolerance;
        tso.cancel = request.cancel;
        ThinSimplifyStats tss;
        mesh = simplifyThinParts(field, report.frame, thinWhere, std::move(mesh), tso, &tss);
        report.simplifyRegionTriangles = tss.regionTriangles;
        report.simplifyCollapses = tss.collapses;
        report.foldsClosed += tss.foldsClosed;
        report.secondsSimplify = tss.seconds;
    }

    if (mesh.empty() && !request.allowEmpty) {
        throw Error(field.describe(), "has no surface at iso " + messageNumber(report.iso) + " on a lattice of spacing " +
                                          messageNumber(report.voxelSize) + " (" + valueRangeText(field) +
                                          "); choose another --iso or a smaller --voxel-size");
    }
    report.worldSpacing = report.voxelSize;
    measureCoordinateStep(mesh, report);
    report.vertices = mesh.points.size();
    report.triangles = mesh.countPolygonsOfSize(3);
    report.quads = mesh.countPolygonsOfSize(4);
    report.otherPolygons = mesh.polygonCount() - report.triangles - report.quads;
    return mesh;
}

} // namespace vdbsurf
