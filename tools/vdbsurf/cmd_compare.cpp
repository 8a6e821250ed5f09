// vdbsurf compare: one grid meshed by OpenVDB's volumeToMesh, vdbsurf mc and vdbsurf dmc at the
// same spacing; a table of time, size and quality against the grid's own iso surface.
#include "cli_common.h"

#include "vdbsurf/core/atomic_file.h"
#include "vdbsurf/core/cancel.h"
#include "vdbsurf/core/error.h"
#include "vdbsurf/core/threads.h"
#include "vdbsurf/field/grid_field.h"
#include "vdbsurf/mesh/mesh_io.h"
#include "vdbsurf/quality/compare.h"
#include "vdbsurf/vdb/vdb_file.h"

#include <iomanip>
#include <iostream>
#include <sstream>

namespace vdbsurf::cli {

namespace {

struct CompareOptions {
    std::string input, grid, json, inside;
    std::optional<double> iso, voxelSize;
    int threads = 0, searchSteps = 5;
};

std::string fixed(double v, int digits) {
    std::ostringstream s;
    s << std::fixed << std::setprecision(digits) << v;
    return s.str();
}

void printTable(const std::vector<std::vector<std::string>>& rows) {
    std::vector<std::size_t> width;
    for (const auto& r : rows)
        for (std::size_t c = 0; c < r.size(); ++c) {
            if (width.size() <= c) width.push_back(0);
            width[c] = std::max(width[c], r[c].size());
        }
    for (std::size_t i = 0; i < rows.size(); ++i) {
        for (std::size_t c = 0; c < rows[i].size(); ++c)
            std::cout << (c ? "  " : "") << (c ? std::setw(int(width[c])) : std::setw(0)) << rows[i][c]
                      << (c ? "" : std::string(width[c] - rows[i][c].size(), ' '));
        std::cout << "\n";
        if (i == 0) {
            std::size_t total = 0;
            for (std::size_t w : width) total += w + 2;
            std::cout << std::string(total - 2, '-') << "\n";
        }
    }
}

void runCompare(const CompareOptions& o) {
    if (o.threads < 0) throw Error("--threads", "must be 0 (all cores) or a positive number");
    if (meshFormatOf(o.input) != MeshFormat::Vdb) throw Error(o.input, "unsupported input; compare takes a .vdb file");
    if (!o.json.empty()) checkWritableTarget(o.json);
    ThreadLimit threads(o.threads);
    std::optional<Inside> inside;
    if (o.inside == "below") inside = Inside::Below;
    if (o.inside == "above") inside = Inside::Above;

    const LoadedGrid loaded = readScalarGrid(o.input, o.grid);
    const std::string source = loaded.source;
    const GridField field(loaded.grid, source, inside);
    note(loaded.note + ", " + field.gridClass() + "; " + field.insideReason());

    CompareRequest req;
    req.iso = o.iso;
    req.voxelSize = o.voxelSize;
    req.searchSteps = o.searchSteps;
    req.cancel = &processCancelToken();
    const CompareReport rep = compareMeshers(field, req);

    const double h = rep.voxelSize;
    std::cout << source << ": iso " << rep.iso << " (" << rep.isoReason << "), spacing H = " << rep.voxelSize
              << (rep.resampled ? " (volumeToMesh on the grid resampled to H)" : " (the grid's voxel size)")
              << (field.ownFrame() && field.ownFrame()->curved ? " at the frustum's smallest voxels (the lattices widen with them)" : "")
              << ", "
              << threads.threads() << (threads.threads() == 1 ? " thread" : " threads") << "\n"
              << "quality against the grid's own iso surface (" << rep.surfaceSamples
              << " points at its voxel size): distances of mesh points to it, share of it within H/4 and H of the mesh\n\n";
    std::vector<std::vector<std::string>> table{{"method", "seconds", "vertices", "polygons", "pieces", "closed", "mean dist/H",
                                                 "p95 dist/H", "within H/4", "covers H/4", "covers H", "F-score H/4"}};
    for (const CompareRow& r : rep.rows) {
        // A mesher that lost the whole surface has no distances to show, and covers nothing.
        const bool empty = r.polygons == 0;
        auto ifAny = [&](std::string text) { return empty ? std::string("-") : text; };
        table.push_back({r.method, fixed(r.seconds, 3), std::to_string(r.vertices), std::to_string(r.polygons),
                         std::to_string(r.components), empty ? "empty" : r.topology.closedManifoldOriented() ? "yes" : "no",
                         ifAny(fixed(r.quality.meanDistance / h, 3)), ifAny(fixed(r.quality.p95Distance / h, 3)),
                         ifAny(fixed(r.quality.accuracyQuarter, 4)), fixed(r.quality.coverageQuarter, 4), fixed(r.quality.coverageOne, 4),
                         fixed(r.quality.fScoreQuarter, 4)});
    }
    printTable(table);
    for (const CompareRow& r : rep.rows)
        if (r.polygons == 0) note(r.method + " lost the whole surface at spacing " + fixed(h, 6) + ": its mesh is empty");

    if (!o.json.empty()) {
        nlohmann::json rows = nlohmann::json::array();
        for (const CompareRow& r : rep.rows)
            rows.push_back({{"method", r.method},
                            {"seconds", r.seconds},
                            {"seconds_resample", r.secondsResample},
                            {"vertices", r.vertices},
                            {"polygons", r.polygons},
                            {"empty", r.polygons == 0},
                            {"triangles_after_split", r.triangles},
                            {"components", r.components},
                            {"boundary_edges", r.topology.boundaryEdges},
                            {"non_manifold_edges", r.topology.nonManifoldEdges},
                            {"inconsistent_edges", r.topology.inconsistentEdges},
                            {"non_manifold_vertices", r.topology.nonManifoldVertices},
                            {"folded_vertices", r.topology.foldedVertices},
                            {"closed_manifold_oriented", r.topology.closedManifoldOriented()},
                            {"mesh_samples", r.quality.meshSamples},
                            {"mean_distance", r.quality.meanDistance},
                            {"p95_distance", r.quality.p95Distance},
                            {"max_distance_capped_2h", r.quality.maxDistance},
                            {"accuracy_quarter_h", r.quality.accuracyQuarter},
                            {"coverage_quarter_h", r.quality.coverageQuarter},
                            {"coverage_one_h", r.quality.coverageOne},
                            {"f_score_quarter_h", r.quality.fScoreQuarter}});
        writeJsonFile(o.json, {{"input", source},
                               {"iso", rep.iso},
                               {"voxel_size", rep.voxelSize},
                               {"grid_voxel_size", rep.gridVoxelSize},
                               {"resampled_for_volumeToMesh", rep.resampled},
                               {"threads", threads.threads()},
                               {"surface_samples", rep.surfaceSamples},
                               {"rows", rows}});
        note("wrote " + o.json);
    }
}

} // namespace

Action addCompareCommand(CLI::App& app) {
    auto o = std::make_shared<CompareOptions>();
    CLI::App* sub = app.add_subcommand(
        "compare", "Mesh a grid with OpenVDB volumeToMesh, vdbsurf mc and vdbsurf dmc; compare time, size and quality");
    sub->add_option("input", o->input, "Input .vdb file")->required();
    sub->add_option("--grid", o->grid, "Grid name (default: the first float/double grid)");
    sub->add_option("--iso", o->iso, "Iso value (default 0 for level sets, 0.5 for fog)");
    sub->add_option("--voxel-size", o->voxelSize, "Lattice spacing H in world units for all three (default: the grid's voxel size)");
    sub->add_option("--search-steps", o->searchSteps, "DMC thin search steps per cell (default 5)")->check(CLI::Range(1, 64));
    sub->add_option("--inside", o->inside, "Override which side is inside: below or above the iso value")
        ->check(CLI::IsMember({"below", "above"}));
    sub->add_option("--threads", o->threads, "Worker threads (0: all cores)");
    sub->add_option("--json", o->json, "Write the results as JSON to this file");
    return [o] { runCompare(*o); };
}

} // namespace vdbsurf::cli
