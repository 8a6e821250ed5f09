// bench_density: seed 003's experiment on this machine. One scene of three primitives (the
// paper's experiment shape: two ellipsoids and a box), at 128³ and 512³ over its bounding box:
// dense evaluation of every voxel (the paper's "all space") against sparse rasterization and
// --surface-only; a one-primitive edit against a full rebuild; 1 against 2 threads.
#include "bench_support.h"

#include "vdbsurf/core/threads.h"
#include "vdbsurf/density/rasterize.h"
#include "vdbsurf/vdb/vdb_file.h"

#include <CLI/CLI.hpp>

#include <iostream>

using namespace vdbsurf;

namespace {

Primitive prim(CoreShape core, Vec3d c, Vec3d size, double falloff, Vec3d rot = {}) {
    Primitive p;
    p.core = core;
    p.center = c;
    p.size = size;
    p.falloff = falloff;
    p.rotationDegrees = rot;
    return p;
}

std::vector<Primitive> paperScene() {
    return {prim(CoreShape::Ellipsoid, {0, 0, 0}, {1.0, 0.6, 0.6}, 0.5, {0, 0, 30}),
            prim(CoreShape::Ellipsoid, {1.2, 0.8, 0}, {0.4, 0.4, 0.4}, 0.4),
            prim(CoreShape::Box, {0, -0.9, 0}, {0.9, 0.2, 0.6}, 0.4, {0, 20, 0})};
}

} // namespace

int main(int argc, char** argv) {
    CLI::App app{"vdbsurf density rasterization: dense vs sparse vs surface-only, edit vs rebuild"};
    int repeat = 3;
    bool quick = false;
    std::string json;
    app.add_option("--repeat", repeat, "Runs per measurement (median time)");
    app.add_flag("--quick", quick, "128^3 only");
    app.add_option("--json", json, "Write the results as JSON");
    CLI11_PARSE(app, argc, argv);
    initializeOpenVdb();

    const std::vector<Primitive> prims = paperScene();
    const DensityScene scene(prims, "paper scene");
    std::vector<Primitive> moved = prims;
    moved[1].center = moved[1].center + Vec3d(0.1, -0.05, 0.08);
    const DensityScene edited(moved, "paper scene, head moved");
    const Box3 d = scene.domain();
    const double extent = std::max({d.extent().x, d.extent().y, d.extent().z});

    bench::Table table(
        {"resolution", "method", "threads", "seconds", "voxels evaluated", "voxels updated", "leaves evaluated", "tiles", "speed-up"});
    for (int n : quick ? std::vector<int>{128} : std::vector<int>{128, 512}) {
        const double h = extent / n;
        Vec3i first, last;
        sceneVoxelRange(scene, h, first, last);
        const Vec3i dims = last - first + Vec3i(1, 1, 1);
        const std::string res = std::to_string(n) + "^3";
        auto row = [&](const std::string& method, int threads, double seconds, std::uint64_t voxels, std::uint64_t leaves,
                       std::uint64_t tiles, double speedup, const std::string& against, std::uint64_t updated = 0) {
            table.add({res, method, std::to_string(threads), bench::fixed(seconds, 4), std::to_string(voxels), std::to_string(updated),
                       std::to_string(leaves), std::to_string(tiles), bench::fixed(speedup, 1) + "x " + against},
                      {{"resolution", n}, {"method", method}, {"threads", threads}, {"seconds", seconds}, {"voxels_evaluated", voxels},
                       {"voxels_updated", updated}, {"leaves_evaluated", leaves}, {"tiles", tiles}, {"speedup", speedup},
                       {"speedup_against", against}});
        };

        std::vector<double> denseSeconds(3);
        for (int threads : {1, 2}) {
            ThreadLimit limit(threads);
            std::vector<float> dense(std::size_t(dims.x) * dims.y * dims.z);
            const bench::Measure m = bench::measureMedian(n > 128 ? 1 : repeat, [&] { evaluateDense(scene, h, first, dims, dense.data()); });
            denseSeconds[threads] = m.seconds;
            row("dense (every voxel)", threads, m.seconds, dense.size(), 0, 0, threads == 2 ? denseSeconds[1] / m.seconds : 1.0,
                threads == 2 ? "vs 1 thread" : "");
        }
        for (bool surfaceOnly : {false, true}) {
            std::vector<double> seconds(3);
            for (int threads : {1, 2}) {
                ThreadLimit limit(threads);
                RasterOptions o;
                o.voxelSize = h;
                o.surfaceOnly = surfaceOnly;
                RasterStats st;
                const bench::Measure m = bench::measureMedian(repeat, [&] { st = DensityRaster(scene, o).stats(); });
                seconds[threads] = m.seconds;
                row(surfaceOnly ? "sparse, surface only" : "sparse", threads, m.seconds, st.voxelsEvaluated, st.leavesEvaluated,
                    st.leafTiles + st.nodeTiles, denseSeconds[threads] / m.seconds, "vs dense");
                if (threads == 2)
                    row(surfaceOnly ? "sparse, surface only" : "sparse", 2, m.seconds, st.voxelsEvaluated, st.leavesEvaluated,
                        st.leafTiles + st.nodeTiles, seconds[1] / m.seconds, "vs 1 thread");
            }
            // One primitive moved: edit against a full rebuild of the edited scene, 2 threads, both
            // keeping sums (what an interactive session holds).
            ThreadLimit limit(2);
            RasterOptions o;
            o.voxelSize = h;
            o.surfaceOnly = surfaceOnly;
            o.keepSums = true;
            RasterStats rebuildStats, editStats;
            const bench::Measure rebuild = bench::measureMedian(repeat, [&] { rebuildStats = DensityRaster(edited, o).stats(); });
            std::vector<double> editTimes;
            for (int r = 0; r < repeat; ++r) {
                DensityRaster raster(scene, o);
                editStats = raster.update(edited);
                editTimes.push_back(editStats.seconds);
            }
            std::sort(editTimes.begin(), editTimes.end());
            const double edit = editTimes[editTimes.size() / 2];
            const std::string mode = surfaceOnly ? ", surface only" : "";
            row("rebuild after a move" + mode, 2, rebuild.seconds, rebuildStats.voxelsEvaluated, rebuildStats.leavesEvaluated,
                rebuildStats.leafTiles + rebuildStats.nodeTiles, 1.0, "");
            row("edit: one primitive moved" + mode, 2, edit, editStats.voxelsEvaluated, editStats.leavesEvaluated,
                editStats.leafTiles + editStats.nodeTiles, rebuild.seconds / edit, "vs rebuild", editStats.voxelsUpdated);
        }
    }
    std::cout << "bench_density: the paper's 3-primitive scene; median of " << repeat << " runs (dense at 512^3: one run)\n";
    table.print();
    if (!json.empty()) table.writeJson(json, "bench_density", {{"repeat", repeat}});
    return 0;
}
