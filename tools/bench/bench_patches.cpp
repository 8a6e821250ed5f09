// bench_patches: the stages of `vdbsurf patches` (closed surface, height function and
// simplification, Reeb graph and units, ring grids, patch fit, tessellation, fit error) timed on
// a ~1 M-triangle DMC mesh of an upright torus, and on the shared real meshes, with the graph's
// size and the fit error.
#include "bench_support.h"

#include "vdbsurf/core/threads.h"
#include "vdbsurf/dmc/mesher.h"
#include "vdbsurf/field/expression_field.h"
#include "vdbsurf/mesh/mesh_io.h"
#include "vdbsurf/reeb/patch_pipeline.h"

#include <CLI/CLI.hpp>

#include <iostream>

using namespace vdbsurf;

int main(int argc, char** argv) {
    CLI::App app{"vdbsurf patches: stage timings on a 1 M-triangle mesh and the shared meshes"};
    int repeat = 1;
    bool quick = false;
    std::string json;
    std::vector<std::string> extra;
    app.add_option("--repeat", repeat, "Runs per measurement (median time)");
    app.add_flag("--quick", quick, "A ~100 k-triangle torus instead of ~1 M");
    app.add_option("--mesh", extra, "Further closed .obj/.ply meshes to include (repeatable)");
    app.add_option("--json", json, "Write the results as JSON");
    CLI11_PARSE(app, argc, argv);

    struct Case {
        std::string name;
        Mesh mesh;
        Vec3d axis;
    };
    std::vector<Case> cases;
    {
        // Upright torus (R 1, r 0.35, around y; height z): area 13.8, so spacing h gives about
        // 2 * 13.8 / h^2 triangles.
        const double h = quick ? 0.0166 : 0.0063;
        ExpressionField torus("sqrt(pow(sqrt(x*x+z*z)-1,2)+y*y)-0.35", Box3{Vec3d(-1.5, -1.5, -1.5), Vec3d(1.5, 1.5, 1.5)});
        MeshRequest req;
        req.voxelSize = h;
        req.triangulate = true;
        MeshReport rep;
        cases.push_back({"DMC torus h " + bench::fixed(h, 5), meshField(torus, req, rep), Vec3d(0, 0, 1)});
    }
    for (const char* f : {"mesh/spot.obj", "mesh/horse_quad.obj"}) {
        const std::string path = bench::sharedData(f);
        if (path.empty()) std::cerr << "bench_patches: skipped " << f << ": ../shared/data is absent\n";
        else cases.push_back({std::string(f).substr(5), readMesh(path), Vec3d(0, 1, 0)});
    }
    for (const std::string& path : extra) cases.push_back({path.substr(path.find_last_of('/') + 1), readMesh(path), Vec3d(0, 0, 1)});

    std::vector<std::string> columns{"mesh", "triangles", "nodes", "arcs"};
    for (const auto& stage : reeb::PatchTimings{}.stages()) columns.push_back(std::string(stage.first) + " s");
    columns.insert(columns.end(), {"total s", "RMS (edges)", "max (edges)"});
    bench::Table table(columns);
    for (const Case& c : cases) {
        reeb::PatchJob job;
        job.axis = c.axis;
        reeb::PatchResult r;
        const bench::Measure m = bench::measureMedian(repeat, [&] { r = reeb::makePatches(c.mesh, c.name, job); });
        std::vector<std::string> row{c.name, std::to_string(r.surface.triangleCount()), std::to_string(r.graph.nodes.size()),
                                     std::to_string(r.graph.units.size())};
        nlohmann::json seconds;
        for (const auto& [stage, s] : r.seconds.stages()) {
            row.push_back(bench::fixed(s, 3));
            seconds[stage] = s;
        }
        seconds["total"] = m.seconds;
        row.insert(row.end(), {bench::fixed(m.seconds, 3), bench::fixed(r.error.rms, 3), bench::fixed(r.error.max, 3)});
        table.add(row, {{"mesh", c.name},
                        {"triangles", r.surface.triangleCount()},
                        {"nodes", r.graph.nodes.size()},
                        {"arcs", r.graph.units.size()},
                        {"loops", r.graph.loops()},
                        {"seconds", seconds},
                        {"peak_mib", m.peakMiB},
                        {"fit_error_rms_edges", r.error.rms},
                        {"fit_error_max_edges", r.error.max}});
    }
    table.print();
    if (!json.empty()) table.writeJson(json, "bench_patches", {{"repeat", repeat}, {"threads", ThreadLimit(0).threads()}});
    return 0;
}
