// vdbsurf mesh: a .vdb grid or a formula to an .obj, .ply or .vdb surface.
#include "cli_common.h"

#include "vdbsurf/core/atomic_file.h"
#include "vdbsurf/core/cancel.h"
#include "vdbsurf/core/error.h"
#include "vdbsurf/core/threads.h"
#include "vdbsurf/dmc/lattice_deformation.h"
#include "vdbsurf/density/scene_json.h"
#include "vdbsurf/dmc/mesher.h"
#include "vdbsurf/lattice/lattice.h"
#include "vdbsurf/field/expression_field.h"
#include "vdbsurf/field/grid_field.h"
#include "vdbsurf/mesh/mesh_io.h"
#include "vdbsurf/mesh/mesh_to_vdb.h"
#include "vdbsurf/vdb/vdb_file.h"

#include <nlohmann/json.hpp>

#include <fstream>
#include <sstream>

namespace vdbsurf::cli {

namespace {

std::string num(double v) {
    std::ostringstream s;
    s.precision(9);
    s << v;
    return s.str();
}

struct MeshOptions {
    std::string input, output, expr, bbox, grid, stats, method = "dmc", inside, latticeOut;
    std::optional<double> iso, voxelSize;
    int threads = 0, searchSteps = 5;
    double sharpEdge = 0.9, sharpCorner = 0.7, sharpNoise = 0.95;
    std::optional<double> fitTolerance, simplifyTolerance;
    bool triangles = false, noThin = false, noSharp = false, noFit = false, noSimplify = false;
};

void runMesh(const MeshOptions& o) {
    const auto t0 = Clock::now();
    if (o.input.empty() == o.expr.empty())
        throw Error("mesh", o.input.empty() ? "give an input .vdb file or --expr FORMULA" : "give either an input file or --expr, not both");
    if (!o.expr.empty() && o.bbox.empty()) throw Error("--bbox", "is required with --expr (X0,Y0,Z0,X1,Y1,Z1)");
    if (o.expr.empty() && !o.bbox.empty()) throw Error("--bbox", "applies only to --expr");
    if (!o.expr.empty() && !o.grid.empty()) throw Error("--grid", "applies only to .vdb input");
    if (o.threads < 0) throw Error("--threads", "must be 0 (all cores) or a positive number");
    const MeshFormat format = meshFormatOf(o.output);
    if (format == MeshFormat::Unknown)
        throw Error(o.output, "unsupported output format; use .obj, .ply, .pov (a POV-Ray scene) or .vdb (a level set)");
    checkWritableTarget(o.output);
    if (!o.stats.empty()) checkWritableTarget(o.stats);
    const bool dmc = o.method == "dmc";
    if (!dmc && (o.noThin || o.noSharp || o.noFit || o.fitTolerance || o.noSimplify || o.simplifyTolerance || !o.latticeOut.empty()))
        throw Error(o.noThin              ? "--no-thin"
                    : o.noSharp           ? "--no-sharp"
                    : o.noFit             ? "--no-fit"
                    : o.fitTolerance      ? "--fit-tolerance"
                    : o.noSimplify        ? "--no-simplify"
                    : o.simplifyTolerance ? "--simplify-tolerance"
                                          : "--lattice-out",
                    "applies only to --method dmc");
    if (o.noFit && o.fitTolerance) throw Error("--fit-tolerance", "has no effect with --no-fit; give one or the other");
    if (o.noSimplify && o.simplifyTolerance)
        throw Error("--simplify-tolerance", "has no effect with --no-simplify; give one or the other");
    if (o.noThin && (o.noSimplify || o.simplifyTolerance))
        throw Error(o.noSimplify ? "--no-simplify" : "--simplify-tolerance", "applies to thin parts, which --no-thin does not search for");
    if (!o.latticeOut.empty()) {
        if (meshFormatOf(o.latticeOut) != MeshFormat::Vdb) throw Error(o.latticeOut, "--lattice-out must name a .vdb file");
        checkWritableTarget(o.latticeOut);
    }

    ThreadLimit threads(o.threads);
    std::optional<Inside> inside;
    if (o.inside == "below") inside = Inside::Below;
    if (o.inside == "above") inside = Inside::Above;

    std::unique_ptr<Field> field;
    std::string source;
    if (!o.expr.empty()) {
        field = std::make_unique<ExpressionField>(o.expr, parseBox("--bbox", o.bbox));
        source = "expr: " + o.expr;
    } else {
        const bool scene = o.input.size() > 5 && o.input.substr(o.input.size() - 5) == ".json";
        if (scene) {
            if (!o.grid.empty()) throw Error("--grid", "applies only to .vdb input");
            if (inside) throw Error("--inside", "applies only to .vdb input (a scene is dense inside)");
            field = std::make_unique<DensityScene>(readSceneFile(o.input));
            source = o.input;
        } else if (meshFormatOf(o.input) != MeshFormat::Vdb) {
            throw Error(o.input, "unsupported input; give a .vdb file, a scene .json or --expr FORMULA");
        }
    }
    if (!field) {
        const LoadedGrid loaded = readScalarGrid(o.input, o.grid);
        source = loaded.source;
        auto gf = std::make_unique<GridField>(loaded.grid, source, inside);
        note(loaded.note + ", " + gf->gridClass() + "; " + gf->insideReason());
        field = std::move(gf);
    }
    const double secondsRead = since(t0);

    MeshRequest req;
    req.iso = o.iso;
    req.voxelSize = o.voxelSize;
    req.triangulate = o.triangles;
    req.method = dmc ? MeshMethod::Dmc : MeshMethod::MarchingCubes;
    req.thin = !o.noThin;
    req.sharp = !o.noSharp;
    req.fit = !o.noFit;
    if (o.fitTolerance) req.fitTolerance = *o.fitTolerance;
    req.simplifyThin = !o.noSimplify;
    if (o.simplifyTolerance) req.simplifyTolerance = *o.simplifyTolerance;
    req.searchSteps = o.searchSteps;
    req.sharpEdge = o.sharpEdge;
    req.sharpCorner = o.sharpCorner;
    req.sharpNoiseShare = o.sharpNoise;
    req.cancel = &processCancelToken();
    // The lattice is kept until the mesh is written, so that a run cancelled or failing in
    // between leaves no file at all.
    std::vector<GridBasePtr> lattice;
    std::uint64_t latticeMoved = 0;
    if (!o.latticeOut.empty())
        req.deformedLattice = [&](const Lattice& l, const LatticeDeformation& deformation, const OwnFrame* frame) {
            lattice = latticeGrids(l, deformation,
                                   {{"vdbsurf_version", VDBSURF_VERSION}, {"vdbsurf_source", source}, {"vdbsurf_content", "DMC deformed lattice"}},
                                   frame, o.latticeOut);
            latticeMoved = deformation.movedNodes();
        };
    MeshReport rep;
    Mesh mesh = meshField(*field, req, rep);
    note("iso " + num(rep.iso) + " (" + rep.isoReason + "), lattice spacing " + num(rep.voxelSize) + " (" + rep.voxelSizeReason +
         ")");
    // Float32 points (every mesh format's, and volumeToMesh's) step by more than 1/64 of a cell
    // where the mesh lies far from the origin: say so rather than write a coarsened shape unasked.
    if (rep.coordinateStep > rep.worldSpacing / 64)
        note("the mesh reaches " + num(rep.farthestCoordinate) + " from the origin, where its float coordinates (those of every " +
             "mesh file) step by " + num(rep.coordinateStep) + ", " + num(rep.coordinateStep / rep.worldSpacing) +
             " of a cell: its shape is coarsened by that much; mesh a grid moved nearer the origin (its transform) to keep it");
    // A shape that passes its box is cut there: an open mesh, said rather than left to be found.
    if (rep.facesOpenAtLatticeEdge > 0)
        note("the surface reaches the edge of the lattice (" + std::string(o.expr.empty() ? "the grid's bounds" : "--bbox") + ") through " +
             std::to_string(rep.facesOpenAtLatticeEdge) + " cell faces: the mesh is open there" +
             (o.expr.empty() ? std::string() : "; widen --bbox past the shape to close it"));
    if (rep.polygonsWithoutData > 0)
        note("left out " + std::to_string(rep.polygonsWithoutData) + " polygons on inactive voxels alone (the grid's fill, whose " +
             "inside meets its outside where a band ends open; " + std::to_string(rep.cellsWithoutData) + " cells read nothing else)");
    if (dmc)
        note("dmc: " + std::to_string(rep.thinNodesMoved) + " nodes moved into thin parts" +
             (rep.thinLoneJoined > 0 ? " (" + std::to_string(rep.thinLoneJoined) + " of them to join a node alone inside to the rest across a face)"
                                     : std::string()) +
             ", " + std::to_string(rep.thinNodesCentred) +
             " centred in them, " + std::to_string(rep.nodesOnCorners) + " onto corners, " + std::to_string(rep.nodesOnEdges) +
             " onto edges" +
             (rep.unresolvedLeaves > 0 ? " (" + std::to_string(rep.unresolvedLeaves) +
                                             " leaves too noisy for sharp features at this spacing)"
                                       : std::string()) +
             (rep.fitEdgesSplit + rep.fitCentres > 0 ? "; fit: " + std::to_string(rep.fitEdgesSplit) + " edges split and " +
                                                           std::to_string(rep.fitCentres) + " centres added on the surface (" +
                                                           std::to_string(rep.fitFeatureCentres) + " on sharp edges or corners)"
                                                     : std::string()) +
             (rep.simplifyCollapses > 0 ? "; thin parts simplified: " + std::to_string(rep.simplifyCollapses) + " of their vertices removed (" +
                                              std::to_string(rep.simplifyRegionTriangles) + " triangles there before)"
                                        : std::string()));

    const auto tWrite = Clock::now();
    const std::vector<std::string> provenance = {
        std::string("vdbsurf ") + VDBSURF_VERSION, "source: " + source, "method: " + std::string(methodName(req.method)),
        "iso: " + num(rep.iso), "voxel_size: " + num(rep.voxelSize)};
    processCancelToken().check();
    if (format == MeshFormat::Vdb) {
        LevelSetWriteOptions lw;
        lw.voxelSize = rep.voxelSize;
        lw.metadata = {{"vdbsurf_version", VDBSURF_VERSION}, {"vdbsurf_source", source},
                       {"vdbsurf_method", methodName(req.method)}, {"vdbsurf_iso", num(rep.iso)},
                       {"vdbsurf_voxel_size", num(rep.voxelSize)}};
        writeMeshAsLevelSet(o.output, mesh, lw);
    } else {
        writeMesh(o.output, mesh, provenance);
    }
    if (!lattice.empty()) {
        writeVdbFile(o.latticeOut, lattice);
        note("wrote " + o.latticeOut + ": the deformed lattice (" + std::to_string(latticeMoved) + " nodes moved)");
    }
    const double secondsWrite = since(tWrite);

    std::ostringstream summary;
    summary << "wrote " << o.output << ": " << rep.vertices << " vertices, " << rep.triangles << " triangles, " << rep.quads
            << " quads" << (rep.otherPolygons ? ", " + std::to_string(rep.otherPolygons) + " other polygons" : std::string())
            << " (" << num(since(t0)) << " s, " << threads.threads() << (threads.threads() == 1 ? " thread)" : " threads)");
    note(summary.str());

    if (!o.stats.empty()) {
        nlohmann::json j{{"input", source},
                         {"output", o.output},
                         {"method", methodName(req.method)},
                         {"iso", rep.iso},
                         {"voxel_size", rep.voxelSize},
                         {"threads", threads.threads()},
                         {"vertices", rep.vertices},
                         {"triangles", rep.triangles},
                         {"quads", rep.quads},
                         {"other_polygons", rep.otherPolygons},
                         {"coordinates", {{"farthest", rep.farthestCoordinate}, {"float_step", rep.coordinateStep}, {"world_spacing", rep.worldSpacing}}},
                         {"lattice",
                          {{"upper_nodes_tested", rep.upperNodesTested},
                           {"leaf_blocks_tested", rep.leafBlocksTested},
                           {"leaf_blocks_visited", rep.leafBlocksVisited},
                           {"cells_visited", rep.cellsExamined},
                           {"cells_active", rep.cellsActive},
                           {"cells_with_surface", rep.cellsWithSurface},
                           {"cells_without_data", rep.cellsWithoutData},
                           {"polygons_without_data", rep.polygonsWithoutData},
                           {"faces_open_at_lattice_edge", rep.facesOpenAtLatticeEdge}}},
                         {"dmc",
                          {{"thin_search", !o.noThin && dmc},
                           {"sharp_features", !o.noSharp && dmc},
                           {"search_steps", o.searchSteps},
                           {"hidden_cells", rep.hiddenCells},
                           {"thin_candidates", rep.thinCandidates},
                           {"thin_samples", rep.thinSamples},
                           {"nodes_moved_thin", rep.thinNodesMoved},
                           {"nodes_moved_hidden_edges", rep.thinEdgesSplit},
                           {"nodes_moved_lone_joins", rep.thinLoneJoined},
                           {"nodes_moved_thin_crossed_undone", rep.thinCrossedUndone},
                           {"nodes_moved_thin_tunnel_undone", rep.thinTunnelsUndone},
                           {"nodes_centred_thin", rep.thinNodesCentred},
                           {"sharp_edge_cells", rep.sharpEdgeCells},
                           {"sharp_corner_cells", rep.sharpCornerCells},
                           {"sharp_rejected", rep.sharpRejected},
                           {"nodes_on_edges", rep.nodesOnEdges},
                           {"nodes_on_edges_second_round", rep.nodesAlongEdges},
                           {"nodes_on_corners", rep.nodesOnCorners},
                           {"nodes_flipped", rep.nodesFlipped},
                           {"nodes_flips_undone", rep.flipsUndone},
                           {"sharp_unresolved_leaves", rep.unresolvedLeaves},
                           {"welded_vertices", rep.weldedVertices},
                           {"collapsed_polygons", rep.collapsedPolygons},
                           {"split_vertices", rep.splitVertices},
                           {"separated_vertices", rep.separatedVertices},
                           {"folds_closed", rep.foldsClosed},
                           {"fit_edges_split", rep.fitEdgesSplit},
                           {"fit_centres", rep.fitCentres},
                           {"fit_feature_centres", rep.fitFeatureCentres},
                           {"simplify_thin", !o.noSimplify && !o.noThin && dmc},
                           {"simplify_region_triangles", rep.simplifyRegionTriangles},
                           {"simplify_collapses", rep.simplifyCollapses}}},
                         {"seconds",
                          {{"read", secondsRead},
                           {"lattice", rep.secondsLattice},
                           {"thin_search", rep.secondsThin},
                           {"sharp_features", rep.secondsSharp},
                           {"mesh", rep.secondsMesh},
                           {"fit", rep.secondsFit},
                           {"simplify", rep.secondsSimplify},
                           {"write", secondsWrite},
                           {"total", since(t0)}}}};
        writeJsonFile(o.stats, j);
    }
}

} // namespace

Action addMeshCommand(CLI::App& app) {
    auto o = std::make_shared<MeshOptions>();
    CLI::App* sub = app.add_subcommand("mesh", "Mesh a float/double grid of a .vdb file, or a formula, to .obj, .ply or .vdb");
    sub->add_option("input", o->input, "Input .vdb file (or use --expr)");
    sub->add_option("-o,--output", o->output, "Output mesh: .obj, .ply, or .vdb (level set via OpenVDB meshToVolume)")->required();
    sub->add_option("--expr", o->expr, "Formula in x, y, z, negative inside (iso 0), e.g. \"x^2+y^2+z^2-1\"");
    sub->add_option("--bbox", o->bbox, "Box for --expr: X0,Y0,Z0,X1,Y1,Z1 (world units)");
    sub->add_option("--grid", o->grid, "Grid name (default: the first float/double grid)");
    sub->add_option("--iso", o->iso, "Iso value (default 0 for level sets and formulas, 0.5 for fog)");
    sub->add_option("--voxel-size", o->voxelSize, "Lattice spacing in world units (default: the grid's voxel size)");
    sub->add_option("--method", o->method, "Mesher: dmc (Deformed Marching Cubes, default) or mc (plain marching cubes)")
        ->check(CLI::IsMember({"dmc", "mc"}));
    sub->add_option("--search-steps", o->searchSteps, "DMC thin search: parts at least 1/k of a cell wide are kept (default 5)")
        ->check(CLI::Range(1, 64));
    sub->add_option("--sharp-edge", o->sharpEdge, "DMC: normals whose cosine is below this make an edge (default 0.9)")
        ->check(CLI::Range(-1.0, 1.0));
    sub->add_option("--sharp-corner", o->sharpCorner, "DMC: a third normal this aligned with the edge makes a corner (default 0.7; down to 0.45 of it where the corner's edges show on the surface)")
        ->check(CLI::Range(0.0, 1.0));
    sub->add_option("--sharp-noise", o->sharpNoise,
                    "DMC, a grid at its own voxel size: lattice leaves where at least this share of the surface cells may hold "
                    "an edge are taken as noise and get no sharp features (default 0.95; 1: only where all may)")
        ->check(CLI::Range(0.0, 1.0));
    sub->add_flag("--no-thin", o->noThin, "DMC: skip the thin-part search");
    sub->add_flag("--no-sharp", o->noSharp, "DMC: skip sharp edges and corners");
    sub->add_flag("--no-fit", o->noFit, "DMC: add no vertices where the mesh strays from the surface");
    sub->add_option("--fit-tolerance", o->fitTolerance,
                    "DMC: cells an edge's or polygon's middle may stray from the surface before a vertex is added (default 0.2)")
        ->check(CLI::Range(0.001, 1.0));
    sub->add_flag("--no-simplify", o->noSimplify, "DMC: keep every polygon of thin parts (no edge collapses there)");
    sub->add_option("--simplify-tolerance", o->simplifyTolerance,
                    "DMC: cells the mesh of a thin part may move from the surface as its edges are collapsed (default 0.1)")
        ->check(CLI::Range(0.001, 1.0));
    sub->add_option("--lattice-out", o->latticeOut, "DMC: write the deformed lattice (Vec3f node offsets) to this .vdb");
    sub->add_option("--inside", o->inside, "Override which side is inside: below or above the iso value")
        ->check(CLI::IsMember({"below", "above"}));
    sub->add_option("--threads", o->threads, "Worker threads (0: all cores)");
    sub->add_flag("--triangles", o->triangles, "Split quads so the output holds triangles only");
    sub->add_option("--stats", o->stats, "Write statistics as JSON to this file");
    return [o] { runMesh(*o); };
}

} // namespace vdbsurf::cli
