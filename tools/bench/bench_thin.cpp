// bench_thin: the quality bar of Deformed Marching Cubes on thin shapes. Each shape (a plate, a
// rod and a spherical shell t thick, and a gap t wide through a ball, at random orientations, for
// t in --widths: 0.3, 0.6 and 1 H by default) is a level-set grid of voxel H/5; it is meshed at
// spacing H by volumeToMesh (on the grid resampled to H, as vdb_tool would), vdbsurf's marching
// cubes and DMC, and at its own voxel size by volumeToMesh as the fine reference. Every mesh is
// measured against the grid's own iso surface with H as the unit: coverage within H, F-score at
// H/4, pieces, triangles. The bar:
// DMC covers >= 99 %, its F-score is within 0.05 of the fine reference's, it has the shape's
// number of pieces, and at most a tenth of the fine reference's triangles.
// The same bar on solids with concave sharp edges, the other kind the issue names (at random
// orientations too): a block with a slot t wide and 2.5 H deep, one with a notch 3 H wide and t
// deep, a slab with a step t high (its foot a concave edge, its top a convex one), and a cross
// of three bars 0.3 + t thick (concave edges and corners where they meet).
#include "bench_support.h"

#include "vdbsurf/core/threads.h"
#include "vdbsurf/field/grid_field.h"
#include "vdbsurf/mesh/mesh_check.h"
#include "vdbsurf/quality/compare.h"
#include "vdbsurf/quality/surface_quality.h"
#include "vdbsurf/vdb/level_set_from_distance.h"
#include "vdbsurf/vdb/volume_to_mesh_peer.h"

#include <CLI/CLI.hpp>

#include <cmath>
#include <functional>
#include <iostream>
#include <map>
#include <random>
#include <sstream>

using namespace vdbsurf;

namespace {

struct Shape {
    std::string name;
    std::function<double(const Vec3d&)> sdf;
    std::size_t pieces; // of the shape's surface
    bool concave = false;
};

Vec3d randomUnit(std::mt19937& rng) {
    std::normal_distribution<double> g;
    for (;;) {
        const Vec3d v(g(rng), g(rng), g(rng));
        if (length(v) > 1e-3) return normalized(v);
    }
}

// The shapes `width` (in units of H) thick; every width draws the same orientations.
std::vector<Shape> thinShapes(double H, int trials, double width) {
    std::mt19937 rng(20261123);
    std::uniform_real_distribution<double> jitter(-0.5 * H, 0.5 * H);
    const double t = width * H, R = 0.7;
    std::vector<Shape> out;
    std::ostringstream w;
    w << " (" << width << " H)";
    for (int trial = 0; trial < trials; ++trial) {
        const Vec3d n = randomUnit(rng), c(jitter(rng), jitter(rng), jitter(rng));
        const std::string k = " " + std::to_string(trial + 1) + w.str();
        out.push_back({"plate" + k,
                       [=](const Vec3d& p) { return std::max(std::fabs(dot(n, p - c)) - t / 2, length(p - c) - R); }, 1});
        out.push_back({"rod" + k,
                       [=](const Vec3d& p) {
                           const Vec3d d = p - c;
                           const double along = dot(n, d);
                           return std::max(std::sqrt(std::max(dot(d, d) - along * along, 0.0)) - t / 2, std::fabs(along) - R);
                       },
                       1});
        // A closed shell is bounded by two surfaces, the outer and the inner sphere.
        out.push_back({"shell" + k, [=](const Vec3d& p) { return std::fabs(length(p - c) - R) - t / 2; }, 2});
        out.push_back({"gap" + k,
                       [=](const Vec3d& p) { return std::max(length(p - c) - 0.8, t / 2 - std::fabs(dot(n, p - c))); }, 2});
    }
    return out;
}

// Signed distance to the box of half extents b centred at the origin (exact inside and out).
double boxDistance(const Vec3d& q, const Vec3d& b) {
    const Vec3d d(std::fabs(q.x) - b.x, std::fabs(q.y) - b.y, std::fabs(q.z) - b.z);
    const Vec3d out(std::max(d.x, 0.0), std::max(d.y, 0.0), std::max(d.z, 0.0));
    return length(out) + std::min(std::max({d.x, d.y, d.z}), 0.0);
}

// Solids with concave sharp edges, their features `width` (in units of H) across, each in a
// random frame; every width draws the same frames (from a stream of their own: the thin shapes
// stay as they were).
std::vector<Shape> concaveShapes(double H, int trials, double width) {
    std::mt19937 rng(20261126);
    std::uniform_real_distribution<double> jitter(-0.5 * H, 0.5 * H);
    const double t = width * H;
    std::vector<Shape> out;
    std::ostringstream w;
    w << " (" << width << " H)";
    for (int trial = 0; trial < trials; ++trial) {
        const Vec3d a = randomUnit(rng), b0 = randomUnit(rng);
        const Vec3d b = normalized(b0 - a * dot(a, b0)), e = cross(a, b);
        const Vec3d c(jitter(rng), jitter(rng), jitter(rng));
        auto local = [=](const Vec3d& p) { const Vec3d d = p - c; return Vec3d(dot(a, d), dot(b, d), dot(e, d)); };
        const std::string k = " " + std::to_string(trial + 1) + w.str();
        out.push_back({"slot" + k, [=](const Vec3d& p) {
                           const Vec3d q = local(p);
                           return std::max(boxDistance(q, {0.6, 0.4, 0.4}), -boxDistance(q - Vec3d(0, 0.4, 0), {t / 2, 2.5 * H, 0.5}));
                       }, 1, true});
        out.push_back({"notch" + k, [=](const Vec3d& p) {
                           const Vec3d q = local(p);
                           return std::max(boxDistance(q, {0.6, 0.4, 0.4}), -boxDistance(q - Vec3d(0, 0.4, 0), {1.5 * H, t, 0.5}));
                       }, 1, true});
        out.push_back({"step" + k, [=](const Vec3d& p) {
                           const Vec3d q = local(p);
                           return std::min(boxDistance(q - Vec3d(0, -0.2, 0), {0.6, 0.2, 0.4}),
                                           boxDistance(q - Vec3d(0.3, (t - 0.1) / 2, 0), {0.3, (t + 0.1) / 2, 0.4}));
                       }, 1, true});
        const double r = 0.15 + t / 2;
        out.push_back({"cross" + k, [=](const Vec3d& p) {
                           const Vec3d q = local(p);
                           return std::min({boxDistance(q, {0.6, r, r}), boxDistance(q, {r, 0.6, r}), boxDistance(q, {r, r, 0.6})});
                       }, 1, true});
    }
    return out;
}

} // namespace

int main(int argc, char** argv) {
    CLI::App app{"DMC vs volumeToMesh on thin shapes: quality at spacing H against a 5x finer grid"};
    int trials = 2;
    std::vector<double> widths{0.3, 0.6, 1.0};
    std::string json;
    app.add_option("--trials", trials, "Random orientations per shape");
    app.add_option("--widths", widths, "Thicknesses of the thin shapes and sizes of the concave features, in lattice spacings H")->delimiter(',')->check(CLI::Range(0.05, 2.0));
    app.add_option("--json", json, "Write the results as JSON");
    CLI11_PARSE(app, argc, argv);
    ThreadLimit limit(0);

    const double H = 0.1, fine = H / 5;
    const Box3 box{{-1.1, -1.1, -1.1}, {1.1, 1.1, 1.1}};
    bench::Table table({"shape", "method", "spacing", "triangles", "vs fine", "pieces", "covers 1H", "F at H/4", "seconds"});
    // Passed and total by family (thin, concave) and width.
    struct Tally {
        int passed = 0, total = 0;
        std::map<double, std::pair<int, int>> byWidth;
    } tally[2];
    std::vector<std::pair<Shape, double>> shapes;
    for (double w : widths)
        for (Shape& s : thinShapes(H, trials, w)) shapes.emplace_back(std::move(s), w);
    for (double w : widths)
        for (Shape& s : concaveShapes(H, trials, w)) shapes.emplace_back(std::move(s), w);
    for (const auto& entry : shapes) {
        const Shape& s = entry.first;
        const double width = entry.second;
        const GridBasePtr grid = levelSetFromDistance(s.sdf, box, fine);
        const GridField field(grid, s.name);
        CompareRequest req;
        req.voxelSize = H;
        const CompareReport coarse = compareMeshers(field, req);

        // The fine reference: volumeToMesh at the grid's own voxels, measured in units of H.
        const PeerMesh ref = volumeToMeshPeer(grid, 0.0, nullptr);
        const SurfaceQuality refQ = measureSurfaceQuality(ref.mesh, field, 0.0, isoSurfaceSamples(field, 0.0, fine), H);
        const std::size_t refTriangles = ref.mesh.fannedTriangleCount(), refPieces = countComponents(ref.mesh);

        auto add = [&](const std::string& method, const std::string& spacing, std::size_t tris, std::size_t pieces, const SurfaceQuality& q,
                       double seconds) {
            table.add({s.name, method, spacing, std::to_string(tris), bench::fixed(double(tris) / double(refTriangles), 3),
                       std::to_string(pieces) + "/" + std::to_string(s.pieces), bench::fixed(q.coverageOne, 3),
                       bench::fixed(q.fScoreQuarter, 3), bench::fixed(seconds, 3)},
                      {{"shape", s.name}, {"width_h", width}, {"method", method}, {"spacing", spacing}, {"triangles", tris},
                       {"triangles_vs_fine", double(tris) / double(refTriangles)}, {"pieces", pieces}, {"expected_pieces", s.pieces},
                       {"coverage_one_h", q.coverageOne}, {"f_score_quarter_h", q.fScoreQuarter}, {"seconds", seconds}});
        };
        add("volumeToMesh", "H/5", refTriangles, refPieces, refQ, ref.secondsMesh);
        const CompareRow* dmc = nullptr;
        for (const CompareRow& r : coarse.rows) {
            add(r.method, "H", r.triangles, r.components, r.quality, r.seconds);
            if (r.method == "vdbsurf dmc") dmc = &r;
        }
        if (dmc) {
            const bool ok = dmc->quality.coverageOne >= 0.99 && std::fabs(dmc->quality.fScoreQuarter - refQ.fScoreQuarter) <= 0.05 &&
                            dmc->components == s.pieces && dmc->triangles * 10 <= refTriangles && dmc->topology.closedManifoldOriented();
            Tally& t = tally[s.concave ? 1 : 0];
            t.passed += ok;
            ++t.total;
            t.byWidth[width].first += ok;
            ++t.byWidth[width].second;
        }
    }
    std::cout << "bench_thin: thin shapes and solids with concave edges on level sets of voxel H/5 (H = " << H << "), " << trials
              << " orientations each, " << limit.threads() << " threads\n";
    table.print();
    for (int family = 0; family < 2; ++family) {
        const Tally& t = tally[family];
        std::cout << "DMC meets the bar (covers >= 0.99, F within 0.05 of the fine reference, the shape's pieces, closed and manifold,"
                     " <= 1/10 of its triangles) on "
                  << t.passed << " of " << t.total << (family ? " solids with concave edges" : " thin shapes");
        const char* separator = " (";
        for (const auto& [w, counts] : t.byWidth) {
            std::cout << separator << counts.first << " of " << counts.second << " at " << w << " H";
            separator = ", ";
        }
        std::cout << (t.byWidth.empty() ? "" : ")") << "\n";
    }
    if (!json.empty())
        table.writeJson(json, "bench_thin",
                        {{"H", H}, {"fine", fine}, {"widths", widths}, {"passed", tally[0].passed}, {"total", tally[0].total},
                         {"concave_passed", tally[1].passed}, {"concave_total", tally[1].total}});
    return 0;
}
