// bench_mesh: vdbsurf's marching cubes against OpenVDB's volumeToMesh (adaptivity 0) on the same
// grid, iso value and thread count, in one run: seconds (median of --repeat), peak memory added,
// vertices, polygons. The methods run in turn within each round (bench::measureInterleaved) and
// ratios are the median of each round's ratio. Cases: level-set spheres of about 0.2 M, 3 M and
// 12 M active voxels, and the scalar grids of ../shared/data/vdb when present.
#include "bench_support.h"

#include "vdbsurf/core/threads.h"
#include "vdbsurf/dmc/mesher.h"
#include "vdbsurf/field/grid_field.h"
#include "vdbsurf/vdb/vdb_file.h"

#include <CLI/CLI.hpp>
#include <openvdb/openvdb.h>
#include <openvdb/tools/LevelSetSphere.h>
#include <openvdb/tools/Statistics.h>
#include <openvdb/tools/VolumeToMesh.h>

#include <cmath>
#include <iostream>

using namespace vdbsurf;

namespace {

struct Case {
    std::string name;
    openvdb::GridBase::Ptr grid;
};

openvdb::GridBase::Ptr sphereWithActiveVoxels(double target) {
    // A narrow band of 3 voxels each side holds about 4 pi r^2 * 6 active voxels.
    const double r = std::sqrt(target / (24.0 * 3.14159265358979));
    auto g = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(float(r), openvdb::Vec3f(0.37f, -0.21f, 0.13f), 1.0f, 3.0f);
    g->setName("sphere");
    return g;
}

std::string millions(double n) { return bench::fixed(n / 1e6, 2) + " M"; }

} // namespace

int main(int argc, char** argv) {
    CLI::App app{"vdbsurf marching cubes vs OpenVDB volumeToMesh"};
    int threads = 0, repeat = 3;
    bool quick = false;
    std::string json;
    app.add_option("--threads", threads, "Threads for both (0: all cores)");
    app.add_option("--repeat", repeat, "Runs per measurement (median time)");
    app.add_flag("--quick", quick, "Skip the 12 M-voxel sphere");
    app.add_option("--json", json, "Write the results as JSON");
    CLI11_PARSE(app, argc, argv);

    initializeOpenVdb();
    ThreadLimit limit(threads);

    std::vector<Case> cases;
    for (double n : quick ? std::vector<double>{0.2e6, 3e6} : std::vector<double>{0.2e6, 3e6, 12e6})
        cases.push_back({"sphere " + millions(n), sphereWithActiveVoxels(n)});
    for (const char* f : {"vdb/sphere_levelset.vdb", "vdb/cube_levelset_sharp.vdb", "vdb/armadillo_levelset.vdb",
                          "vdb/smoke_fog.vdb", "vdb/blender_smoke_multigrid.vdb"}) {
        const std::string path = bench::sharedData(f);
        if (path.empty()) {
            std::cerr << "bench_mesh: ../shared/data/" << f << " absent, skipped\n";
            continue;
        }
        const LoadedGrid g = readScalarGrid(path, "");
        cases.push_back({std::string(f).substr(4) + ":" + g.name, g.grid});
    }

    bench::Table table({"case", "active voxels", "iso", "method", "seconds", "peak MiB", "vertices", "polygons", "time ratio", "vs 1 thread"});
    for (const Case& c : cases) {
        const auto grid = openvdb::gridPtrCast<openvdb::FloatGrid>(c.grid);
        double iso = 0.0;
        if (grid->getGridClass() == openvdb::GRID_FOG_VOLUME) {
            // 0.5 as a user would, unless the densities never reach it (Blender's smoke: max 0.13).
            const auto ext = openvdb::tools::minMax(grid->tree());
            iso = std::min(0.5, 0.5 * double(ext.max()));
        }
        const std::uint64_t active = grid->activeVoxelCount();

        std::size_t refPolys = 0, refVerts = 0;
        auto reference = [&] {
            // Fresh arrays each run, freed at its end, as our meshes are.
            std::vector<openvdb::Vec3s> points;
            std::vector<openvdb::Vec3I> tris;
            std::vector<openvdb::Vec4I> quads;
            openvdb::tools::volumeToMesh(*grid, points, tris, quads, iso, 0.0);
            refPolys = tris.size() + quads.size();
            refVerts = points.size();
        };
        std::size_t mcVerts = 0, mcPolys = 0, dmcVerts = 0, dmcPolys = 0;
        auto ours = [&](MeshMethod method, std::size_t& verts, std::size_t& polys) {
            GridField field(c.grid, c.name);
            MeshRequest req;
            req.iso = iso;
            req.method = method;
            MeshReport rep;
            const Mesh m = meshField(field, req, rep);
            verts = m.points.size();
            polys = m.polygonCount();
        };
        enum { kRef, kMc, kDmc, kRefOne, kDmcOne };
        std::vector<std::function<void()>> runs{reference, [&] { ours(MeshMethod::MarchingCubes, mcVerts, mcPolys); },
                                                [&] { ours(MeshMethod::Dmc, dmcVerts, dmcPolys); }};
        // volumeToMesh's own speed-up on this machine, beside DMC's: a 2-thread target is only as
        // good as the machine's cores, which these shared VMs do not always give in full.
        if (limit.threads() > 1) {
            runs.push_back(bench::withThreads(1, reference));
            runs.push_back(bench::withThreads(1, [&] {
                std::size_t v1 = 0, p1 = 0;
                ours(MeshMethod::Dmc, v1, p1);
            }));
        }
        const bench::Interleaved t = bench::measureInterleaved(repeat, runs);
        const bool speedups = runs.size() > kRefOne;

        // Ratios round by round (bench::Interleaved), their median.
        auto row = [&](const std::string& method, int run, int oneThreadRun, std::size_t v, std::size_t p) {
            const bench::Measure& m = t.medians[run];
            const double ratio = t.medianRatio(run, kRef);
            const double speedup = speedups && oneThreadRun >= 0 ? t.medianRatio(oneThreadRun, run) : 0;
            nlohmann::json record{{"case", c.name}, {"active_voxels", active}, {"iso", iso}, {"method", method}, {"seconds", m.seconds},
                                  {"peak_mib", m.peakMiB}, {"vertices", v}, {"polygons", p}, {"threads", limit.threads()},
                                  {"time_ratio_vs_volumeToMesh", ratio}};
            if (speedup > 0) record["speedup_vs_1_thread"] = speedup;
            table.add({c.name, std::to_string(active), bench::fixed(iso, 3), method, bench::fixed(m.seconds, 3), bench::fixed(m.peakMiB, 1),
                       std::to_string(v), std::to_string(p), bench::fixed(ratio, 2), speedup > 0 ? bench::fixed(speedup, 2) : "-"},
                      record);
        };
        row("volumeToMesh", kRef, kRefOne, refVerts, refPolys);
        row("vdbsurf mc", kMc, -1, mcVerts, mcPolys);
        row("vdbsurf dmc", kDmc, kDmcOne, dmcVerts, dmcPolys);
    }
    std::cout << "bench_mesh: " << limit.threads() << " threads, median of " << repeat
              << " rounds (each method once a round, in turn; ratios are the median of the rounds' ratios)\n";
    table.print();
    if (!json.empty()) table.writeJson(json, "bench_mesh", {{"threads", limit.threads()}, {"repeat", repeat}});
    return 0;
}
