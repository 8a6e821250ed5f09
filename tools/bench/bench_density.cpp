// bench_density: seed 003's experiment on this machine. One scene of three primitives (the
// paper's experiment shape: two ellipsoids and a box), at 128³ and 512³ over its bounding box:
// dense evaluation of every voxel (the paper's "all space") against sparse rasterization and
// --surface-only; a one-primitive edit against a full rebuild; 1 against 2 threads. Then one
// blob of a 40-primitive creature moved, edit against rebuild, and the scene's largest primitive
// moved at 1024³ (an edit that redoes most of the surface).
#include "bench_support.h"

#include "vdbsurf/core/threads.h"
#include "vdbsurf/density/rasterize.h"
#include "vdbsurf/dmc/mesher.h"
#include "vdbsurf/vdb/vdb_file.h"

#include <CLI/CLI.hpp>

#include <cmath>
#include <iostream>
#include <random>

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

// A blobby creature a TD might build: 40 primitives (spheres, ellipsoids, a few boxes) along a
// curling spine, overlapping their neighbours. Moving one of many shows how an edit scales with
// what moved rather than with the scene.
std::vector<Primitive> creatureScene() {
    std::vector<Primitive> prims;
    for (int i = 0; i < 40; ++i) {
        const double t = i / 39.0, a = 5.0 * t;
        const Vec3d c(2.0 * t - 1.0, 0.35 * std::sin(a), 0.35 * std::cos(a) - 0.35);
        const double r = 0.12 + 0.06 * std::sin(3.0 * a);
        if (i % 10 == 9) prims.push_back(prim(CoreShape::Box, c, {r, 0.6 * r, 0.8 * r}, 0.08, {10.0 * i, 7.0 * i, 0}));
        else if (i % 3 == 0) prims.push_back(prim(CoreShape::Ellipsoid, c, {1.4 * r, r, 0.8 * r}, 0.1, {0, 0, 9.0 * i}));
        else prims.push_back(prim(CoreShape::Ellipsoid, c, {r, r, r}, 0.1));
    }
    return prims;
}

void addRow(bench::Table& table, int n, const std::string& method, int threads, double seconds, std::uint64_t voxels,
            std::uint64_t updated, std::uint64_t leaves, std::uint64_t tiles, double speedup, const std::string& against) {
    table.add({std::to_string(n) + "^3", method, std::to_string(threads), bench::fixed(seconds, 4), std::to_string(voxels),
               std::to_string(updated), std::to_string(leaves), std::to_string(tiles), bench::fixed(speedup, 1) + "x " + against},
              {{"resolution", n}, {"method", method}, {"threads", threads}, {"seconds", seconds}, {"voxels_evaluated", voxels},
               {"voxels_updated", updated}, {"leaves_evaluated", leaves}, {"tiles", tiles}, {"speedup", speedup},
               {"speedup_against", against}});
}

// An edit from `before` to `after` against a full rebuild of `after`, 2 threads, both keeping
// sums (what an interactive session holds): two rows.
void editAgainstRebuild(bench::Table& table, const DensityScene& before, const DensityScene& after, int n, double h, bool surfaceOnly,
                        int repeat, const std::string& what) {
    ThreadLimit limit(2);
    RasterOptions o;
    o.voxelSize = h;
    o.surfaceOnly = surfaceOnly;
    o.keepSums = true;
    RasterStats rebuildStats, editStats;
    // In turn, once a round (as bench::measureInterleaved does): a rebuild, then an edit of a
    // raster of `before` built untimed; the speed-up is the median of the rounds' ratios.
    std::vector<double> rebuildTimes, editTimes, ratios;
    for (int round = 0; round < std::max(1, repeat); ++round) {
        const bench::Measure rebuild = bench::measure([&] { rebuildStats = DensityRaster(after, o).stats(); });
        DensityRaster raster(before, o);
        editStats = raster.update(after);
        rebuildTimes.push_back(rebuild.seconds);
        editTimes.push_back(editStats.seconds);
        ratios.push_back(rebuild.seconds / editStats.seconds);
    }
    const double rebuild = bench::median(rebuildTimes), edit = bench::median(editTimes), speedup = bench::median(ratios);
    const std::string mode = surfaceOnly ? ", surface only" : "";
    const RasterStats& r = rebuildStats;
    const RasterStats& e = editStats;
    addRow(table, n, "rebuild, " + what + mode, 2, rebuild, r.voxelsEvaluated, r.voxelsUpdated, r.leavesEvaluated,
           r.leafTiles + r.nodeTiles, 1.0, "");
    addRow(table, n, "edit, " + what + mode, 2, edit, e.voxelsEvaluated, e.voxelsUpdated, e.leavesEvaluated, e.leafTiles + e.nodeTiles,
           speedup, "vs rebuild");
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
    const double extent = d.longestSide();

    bench::Table table(
        {"resolution", "method", "threads", "seconds", "voxels evaluated", "voxels updated", "leaves evaluated", "tiles", "speed-up"});
    for (int n : quick ? std::vector<int>{128} : std::vector<int>{128, 512}) {
        const double h = extent / n;
        Vec3i first, last;
        sceneVoxelRange(scene, h, first, last);
        const Vec3i dims = last - first + Vec3i(1, 1, 1);
        auto row = [&](const std::string& method, int threads, double seconds, std::uint64_t voxels, std::uint64_t leaves,
                       std::uint64_t tiles, double speedup, const std::string& against) {
            addRow(table, n, method, threads, seconds, voxels, 0, leaves, tiles, speedup, against);
        };

        // One thread and two in turn, once a round (bench::measureInterleaved): the drift of a
        // shared machine falls on both alike, and the speed-up is the median of the rounds' ratios.
        std::vector<float> dense(std::size_t(dims.x) * dims.y * dims.z);
        const bench::Interleaved d = bench::measureInterleaved(n > 128 ? 1 : repeat, {bench::withThreads(1, [&] { evaluateDense(scene, h, first, dims, dense.data()); }),
                                                                                         bench::withThreads(2, [&] { evaluateDense(scene, h, first, dims, dense.data()); })});
        const double denseSeconds[3] = {0, d.medians[0].seconds, d.medians[1].seconds};
        row("dense (every voxel)", 1, denseSeconds[1], dense.size(), 0, 0, 1.0, "");
        row("dense (every voxel)", 2, denseSeconds[2], dense.size(), 0, 0, d.medianRatio(0, 1), "vs 1 thread");
        dense = {};
        for (bool surfaceOnly : {false, true}) {
            RasterOptions o;
            o.voxelSize = h;
            o.surfaceOnly = surfaceOnly;
            RasterStats st;
            const bench::Interleaved t = bench::measureInterleaved(repeat, {bench::withThreads(1, [&] { st = DensityRaster(scene, o).stats(); }),
                                                                            bench::withThreads(2, [&] { st = DensityRaster(scene, o).stats(); })});
            const std::string method = surfaceOnly ? "sparse, surface only" : "sparse";
            for (int threads : {1, 2})
                row(method, threads, t.medians[threads - 1].seconds, st.voxelsEvaluated, st.leavesEvaluated, st.leafTiles + st.nodeTiles,
                    denseSeconds[threads] / t.medians[threads - 1].seconds, "vs dense");
            row(method, 2, t.medians[1].seconds, st.voxelsEvaluated, st.leavesEvaluated, st.leafTiles + st.nodeTiles, t.medianRatio(0, 1),
                "vs 1 thread");
            editAgainstRebuild(table, scene, edited, n, h, surfaceOnly, repeat, "one primitive moved");
        }
    }
    // One blob of the 40-primitive creature moved: edit against rebuild, both modes.
    const std::vector<Primitive> creature = creatureScene();
    std::vector<Primitive> creatureMoved = creature;
    creatureMoved[17].center = creatureMoved[17].center + Vec3d(0.03, -0.02, 0.02);
    const DensityScene before(creature, "creature"), after(creatureMoved, "creature, one blob moved");
    const Box3 cd = before.domain();
    const int n = quick ? 128 : 512;
    for (bool surfaceOnly : {false, true})
        editAgainstRebuild(table, before, after, n, cd.longestSide() / n, surfaceOnly, repeat,
                           "creature (40), one blob moved");
    // The worst case for an edit: the body, most of the surface, moved at 1024³. An edit then redoes
    // about what a rebuild does, and should cost no more.
    if (!quick) {
        std::vector<Primitive> bodyMoved = prims;
        bodyMoved[0].center = bodyMoved[0].center + Vec3d(0.1, -0.05, 0.08);
        editAgainstRebuild(table, scene, DensityScene(bodyMoved, "paper scene, body moved"), 1024, extent / 1024, true, repeat,
                           "the body (largest) moved");
    }
    // Many small blobs (a particle system as metaballs): the primitive index against scanning
    // every primitive, rasterized surface-only (the same grid both ways; tested).
    {
        std::mt19937 rng(3);
        std::uniform_real_distribution<double> u(-1, 1), r(0.01, 0.03);
        std::vector<Primitive> blobs;
        for (int i = 0; i < 2000; ++i) blobs.push_back(prim(CoreShape::Ellipsoid, {u(rng), u(rng), u(rng)}, {r(rng), r(rng), r(rng)}, r(rng)));
        const DensityScene indexed(blobs, "2000 blobs");
        DensityScene scanned(blobs, "2000 blobs");
        scanned.dropIndex();
        const int nb = quick ? 128 : 512;
        const Box3 bd = indexed.domain();
        RasterOptions o;
        o.voxelSize = bd.longestSide() / nb;
        o.surfaceOnly = true;
        ThreadLimit limit(2);
        RasterStats si, ss;
        const bench::Measure scan = bench::measureMedian(quick ? repeat : 1, [&] { ss = DensityRaster(scanned, o).stats(); });
        const bench::Measure idx = bench::measureMedian(repeat, [&] { si = DensityRaster(indexed, o).stats(); });
        addRow(table, nb, "2000 blobs, surface only, every primitive scanned", 2, scan.seconds, ss.voxelsEvaluated, 0, ss.leavesEvaluated,
               ss.leafTiles + ss.nodeTiles, 1.0, "");
        addRow(table, nb, "2000 blobs, surface only, primitive index", 2, idx.seconds, si.voxelsEvaluated, 0, si.leavesEvaluated,
               si.leafTiles + si.nodeTiles, scan.seconds / idx.seconds, "vs scan");
        // Meshing the scene itself (DMC, no grid): every sample of the field is a sum over primitives.
        // Coarse, because scanning takes most of a minute even so.
        const int nm = 96;
        MeshRequest req;
        req.voxelSize = bd.longestSide() / nm;
        MeshReport rep;
        std::size_t polys = 0;
        const bench::Measure meshScan = bench::measureMedian(1, [&] { polys = meshField(scanned, req, rep).polygonCount(); });
        const bench::Measure meshIdx = bench::measureMedian(repeat, [&] { polys = meshField(indexed, req, rep).polygonCount(); });
        const std::string what = "2000 blobs, mesh (dmc, " + std::to_string(polys) + " polygons), ";
        addRow(table, nm, what + "every primitive scanned", 2, meshScan.seconds, 0, 0, 0, 0, 1.0, "");
        addRow(table, nm, what + "primitive index", 2, meshIdx.seconds, 0, 0, 0, 0, meshScan.seconds / meshIdx.seconds, "vs scan");
    }
    std::cout << "bench_density: the paper's 3-primitive scene, a 40-primitive creature for edits, 2000 blobs for the index; median of " << repeat
              << " runs (dense at 512^3: one run; 1 and 2 threads in turn, as are edits and rebuilds, each speed-up the median of the rounds' ratios)\n";
    table.print();
    if (!json.empty()) table.writeJson(json, "bench_density", {{"repeat", repeat}});
    return 0;
}
