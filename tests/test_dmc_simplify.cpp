// DMC's simplification of thin parts (dmc/thin_simplify): rods thinner than a cell come out as a
// few triangles, closed and in one piece, every vertex one the mesher made, every vertex it
// removed within the tolerance of what is left; thick parts beside them are not touched.
#include "support/formula_text.h"

#include "vdbsurf/core/threads.h"
#include "vdbsurf/dmc/lattice_deformation.h"
#include "vdbsurf/dmc/mesher.h"
#include "vdbsurf/dmc/thin_simplify.h"
#include "vdbsurf/field/expression_field.h"
#include "vdbsurf/lattice/lattice.h"
#include "vdbsurf/mesh/mesh_check.h"
#include "vdbsurf/mesh/mesh_distance.h"
#include "vdbsurf/mesh/mesh_folds.h"
#include "vdbsurf/quality/surface_quality.h"

#include <catch2/catch.hpp>

#include <cmath>
#include <map>
#include <random>
#include <set>
#include <sstream>
#include <tuple>
#include <vector>

using namespace vdbsurf;
using test::num;

namespace {

constexpr double kH = 0.1;
const Box3 kBox{{-1.05, -1.05, -1.05}, {1.05, 1.05, 1.05}};

// Distance to the segment c ± halfLength d, minus the radius: a capsule.
std::string capsule(const Vec3d& c, const Vec3d& d, double halfLength, double radius) {
    const std::string px = "(x-" + num(c.x) + ")", py = "(y-" + num(c.y) + ")", pz = "(z-" + num(c.z) + ")";
    const std::string s = "min(max(" + px + "*" + num(d.x) + "+" + py + "*" + num(d.y) + "+" + pz + "*" + num(d.z) + ", " +
                          num(-halfLength) + "), " + num(halfLength) + ")";
    return "sqrt((" + px + "-" + s + "*" + num(d.x) + ")^2+(" + py + "-" + s + "*" + num(d.y) + ")^2+(" + pz + "-" + s + "*" +
           num(d.z) + ")^2)-" + num(radius);
}

Vec3d randomUnit(std::mt19937& rng) {
    std::normal_distribution<double> n(0, 1);
    for (;;) {
        const Vec3d v(n(rng), n(rng), n(rng));
        const double l = length(v);
        if (l > 1e-3) return v / l;
    }
}

Mesh meshAt(const Field& field, bool simplify, MeshReport& report, double tolerance = 0.1) {
    MeshRequest req;
    req.voxelSize = kH;
    req.simplifyThin = simplify;
    req.simplifyTolerance = tolerance;
    return meshField(field, req, report);
}

std::set<std::tuple<float, float, float>> pointSet(const Mesh& m) {
    std::set<std::tuple<float, float, float>> s;
    for (const Vec3f& p : m.points) s.emplace(p.x, p.y, p.z);
    return s;
}

} // namespace

TEST_CASE("thin rods at random orientations come out as a few triangles within the tolerance") {
    std::mt19937 rng(2035);
    std::uniform_real_distribution<double> offset(-0.5 * kH, 0.5 * kH);
    for (int trial = 0; trial < 6; ++trial)
        for (double thickness : {0.3 * kH, 0.6 * kH}) {
            const Vec3d d = randomUnit(rng), c(offset(rng), offset(rng), offset(rng));
            const std::string f = capsule(c, d, 0.7, thickness / 2);
            INFO("trial " << trial << ", " << thickness / kH << " H: " << f);
            ExpressionField field(f, kBox);
            MeshReport plainReport, report;
            const Mesh plain = meshAt(field, false, plainReport);
            const Mesh simple = meshAt(field, true, report);
            CHECK(plainReport.simplifyCollapses == 0);
            CHECK(report.simplifyCollapses > 0);
            CHECK(checkTopology(simple).closedManifoldOriented());
            CHECK(checkTopology(simple).unusedVertices == 0);
            CHECK(countComponents(simple) == 1);
            // A tube along the rod's nodes is ~8 triangles a link: a quarter of that at most for a
            // rod 0.3 H thick (0.07-0.14 seen), 0.6 of it at 0.6 H (0.18-0.48: a wider tube bends
            // farther from its chords).
            CHECK(double(simple.fannedTriangleCount()) <= (thickness < 0.5 * kH ? 0.25 : 0.6) * double(plain.fannedTriangleCount()));
            // Vertices are only taken away, never made or moved.
            const auto before = pointSet(plain);
            for (const Vec3f& p : simple.points) CHECK(before.count({p.x, p.y, p.z}) == 1);
            // Every vertex taken away lies within the tolerance of what is left.
            const MeshDistance distance(simple, 0.5 * kH);
            double farthest = 0;
            for (const Vec3f& p : plain.points) farthest = std::max(farthest, distance.distance(Vec3d(p), 0.5 * kH));
            CHECK(farthest <= 0.1 * kH * (1 + 1e-6));
            // And the rod's surface stays covered (the thin-shape bar's measures).
            const SurfaceQuality q = measureSurfaceQuality(simple, field, 0.0, isoSurfaceSamples(field, 0.0, kH / 10), kH);
            CHECK(q.coverageOne >= 0.99);
            CHECK(q.fScoreQuarter >= 0.95);
        }
}

TEST_CASE("a tighter tolerance removes fewer vertices and keeps its own bound") {
    const std::string f = capsule({0.01, -0.02, 0.015}, normalized(Vec3d(1, 0.6, 0.3)), 0.7, 0.02);
    ExpressionField field(f, kBox);
    MeshReport r1, r2;
    const Mesh loose = meshAt(field, true, r1, 0.2), tight = meshAt(field, true, r2, 0.03);
    MeshReport r0;
    const Mesh plain = meshAt(field, false, r0);
    CHECK(r2.simplifyCollapses < r1.simplifyCollapses);
    CHECK(tight.fannedTriangleCount() > loose.fannedTriangleCount());
    const MeshDistance distance(tight, 0.5 * kH);
    for (const Vec3f& p : plain.points) CHECK(distance.distance(Vec3d(p), 0.5 * kH) <= 0.03 * kH * (1 + 1e-6));
}

TEST_CASE("the simplification leaves thick parts beside a thin rod as they were") {
    // A ball with a rod 0.3 H thick standing out of it.
    const Vec3d d = normalized(Vec3d(0.3, 1, 0.2));
    const std::string f = "min(sqrt(x^2+y^2+z^2)-0.45, " + capsule(d * 0.75, d, 0.3, 0.015) + ")";
    ExpressionField field(f, kBox);
    MeshReport plainReport, report;
    const Mesh plain = meshAt(field, false, plainReport), simple = meshAt(field, true, report);
    CHECK(report.simplifyCollapses > 0);
    CHECK(simple.fannedTriangleCount() < plain.fannedTriangleCount());
    CHECK(checkTopology(simple).closedManifoldOriented());
    CHECK(countComponents(simple) == 1);
    // Polygons farther than two cells from the rod's nodes (the rod starts at 0.45 from the
    // centre; its region reaches 3/4 of a cell) are the same, point for point.
    auto farPolygons = [&](const Mesh& m) {
        std::multiset<std::vector<float>> out;
        for (std::size_t p = 0; p < m.polygonCount(); ++p) {
            std::vector<float> key;
            bool far = true;
            for (std::uint32_t i = m.offsets[p]; i < m.offsets[p + 1]; ++i) {
                const Vec3d q(m.points[m.indices[i]]);
                const double along = dot(q, d);
                const double off = length(q - d * along);
                far = far && (off > 2 * kH || along < 0.45 - 2 * kH);
                key.insert(key.end(), {float(q.x), float(q.y), float(q.z)});
            }
            if (far) out.insert(key);
        }
        return out;
    };
    const auto a = farPolygons(plain), b = farPolygons(simple);
    CHECK(a.size() > 300);
    CHECK(a == b);
}

TEST_CASE("thin parts are simplified in blocks the same way at any thread count, and as far as in one run") {
    // A half shell a fifth of a cell thick, 18 cells across: with blocks of 4 cells, most of its
    // vertices lie in a block and many on the blocks' faces.
    const ExpressionField field("max(x^2+y^2+z^2-0.81, 0.7719-x^2-y^2-z^2, y-0.013)", kBox);
    MeshRequest req;
    req.voxelSize = kH;
    req.simplifyThin = false;
    std::vector<Vec3d> thinNodes; // where the thin search put its nodes (no sharp features here)
    LatticeFrame frame;
    req.deformedLattice = [&](const Lattice& lattice, const LatticeDeformation& deformation, const OwnFrame*) {
        frame = lattice.frame;
        for (auto it = deformation.offsets->cbeginValueOn(); it; ++it) {
            const openvdb::Coord c = it.getCoord();
            const openvdb::Vec3f o = *it;
            thinNodes.push_back(lattice.frame.nodeWorld(Vec3i(c.x(), c.y(), c.z())) + Vec3d(o.x(), o.y(), o.z()));
        }
    };
    MeshReport report;
    const Mesh plain = meshField(field, req, report);
    REQUIRE(thinNodes.size() > 500);
    REQUIRE(report.nodesOnEdges + report.nodesOnCorners == 0);
    const MeshDistance plainDistance(plain, kH);

    std::map<double, std::size_t> triangles;
    for (double blockCells : {0.0, 4.0, 16.0}) {
        INFO("blocks of " << blockCells << " cells");
        ThinSimplifyOptions options;
        options.blockCells = blockCells;
        Mesh out[2];
        ThinSimplifyStats stats[2];
        for (int threads : {1, 2}) {
            ThreadLimit limit(threads);
            out[threads - 1] = simplifyThinParts(field, frame, thinNodes, plain, options, &stats[threads - 1]);
        }
        CHECK(out[0].points == out[1].points);
        CHECK(out[0].indices == out[1].indices);
        CHECK(out[0].offsets == out[1].offsets);
        CHECK(stats[0].collapses == stats[1].collapses);
        const Mesh& m = out[0];
        CHECK(stats[0].collapses > plain.points.size() / 3);
        CHECK(checkTopology(m).closedManifoldOriented());
        CHECK(checkTopology(m).unusedVertices == 0);
        CHECK(foldedVertices(m).empty());
        CHECK(countComponents(m) == countComponents(plain));
        // Every vertex taken away lies within the tolerance of what is left.
        const MeshDistance distance(m, 0.5 * kH);
        double farthest = 0;
        for (const Vec3f& p : plain.points) farthest = std::max(farthest, distance.distance(Vec3d(p), 0.5 * kH));
        CHECK(farthest <= 0.1 * kH * (1 + 1e-6));
        triangles[blockCells] = m.fannedTriangleCount();
    }
    // The blocks' borders are collapsed later, in another order: about as far as in one run.
    INFO("triangles: one run " << triangles[0] << ", blocks of 4 cells " << triangles[4] << ", of 16 " << triangles[16]);
    CHECK(double(triangles[4]) <= 1.05 * double(triangles[0]));
    CHECK(double(triangles[16]) <= 1.05 * double(triangles[0]));
}
