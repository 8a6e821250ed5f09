// Vertices the mesher leaves at one point (mesh/separate_points.h): moved apart, each into its
// own fan, so that merging points by position (trimesh, Blender, Houdini) keeps meshes manifold.
#include "support/formula_text.h"
#include "support/test_support.h"

#include "vdbsurf/core/threads.h"
#include "vdbsurf/dmc/mesher.h"
#include "vdbsurf/field/expression_field.h"
#include "vdbsurf/field/grid_field.h"
#include "vdbsurf/mesh/mesh_check.h"
#include "vdbsurf/mesh/separate_points.h"
#include "vdbsurf/vdb/vdb_file.h"

#include <catch2/catch.hpp>

#include <cmath>
#include <random>

using namespace vdbsurf;
using test::num;

namespace {

// Two square pyramids, apex to apex at `apex`: bases at z = apex.z -+ 1, the apexes two vertices
// (0 and 5) at one point, as a weld that keeps two fans apart leaves them.
Mesh twoPyramidsApexToApex(const Vec3f& apex) {
    Mesh m;
    for (float side : {-1.0f, 1.0f}) {
        const std::uint32_t a = std::uint32_t(m.points.size());
        m.points.push_back(apex);
        for (int k = 0; k < 4; ++k)
            m.points.push_back(apex + Vec3f(float((k == 0 || k == 3) ? 1 : -1), float(k < 2 ? 1 : -1), side));
        // Sides and base, outward for the pyramid on its side.
        const std::uint32_t b[4] = {a + 1, a + 2, a + 3, a + 4};
        for (int k = 0; k < 4; ++k) {
            const std::uint32_t p = b[k], q = b[(k + 1) % 4];
            if (side > 0) m.addPolygon({a, p, q});
            else m.addPolygon({a, q, p});
        }
        if (side > 0) m.addPolygon({b[3], b[2], b[1], b[0]});
        else m.addPolygon({b[0], b[1], b[2], b[3]});
    }
    return m;
}

// What a tool that merges points at equal positions makes of the mesh.
MeshTopology topologyMerged(Mesh m) {
    mergeCoincidentPoints(m);
    return checkTopology(m);
}

} // namespace

TEST_CASE("separateCoincidentPoints: two pyramids touching at their apexes part, each apex into its own") {
    const Vec3f apex(0.25f, -0.5f, 2.0f);
    Mesh m = twoPyramidsApexToApex(apex);
    REQUIRE(checkTopology(m).closedManifoldOriented());
    REQUIRE(countCoincidentPoints(m) == 1);
    REQUIRE(!topologyMerged(m).closedManifoldOriented()); // merged, the apex joins two fans
    CHECK(separateCoincidentPoints(m, {0, 5, 0, 3}) == 2); // (repeats and a vertex at no other's point)
    CHECK(countCoincidentPoints(m) == 0);
    CHECK(topologyMerged(m).closedManifoldOriented());
    // Each moved 5 % of the way to its ring's centroid: straight into its own pyramid.
    CHECK(m.points[0].x == Approx(apex.x).margin(1e-6));
    CHECK(m.points[0].y == Approx(apex.y).margin(1e-6));
    CHECK(m.points[0].z == Approx(apex.z - kSeparationShare).epsilon(1e-6));
    CHECK(m.points[5].z == Approx(apex.z + kSeparationShare).epsilon(1e-6));
    // Nothing else moved.
    const Mesh before = twoPyramidsApexToApex(apex);
    for (std::size_t v : {1, 2, 3, 4, 6, 7, 8, 9}) CHECK(m.points[v] == before.points[v]);
}

TEST_CASE("separateCoincidentPoints: a large mesh's pairs all part, the same at any thread count") {
    // 3,000 pyramid pairs: 96,000 indices, more than one of the chunks the polygons are read in.
    Mesh m;
    std::vector<std::uint32_t> suspects;
    for (int i = 0; i < 3000; ++i) {
        const Mesh pair = twoPyramidsApexToApex(Vec3f(float(3 * (i % 60)), float(3 * (i / 60)), 2.0f));
        const std::uint32_t base = std::uint32_t(m.points.size());
        m.points.insert(m.points.end(), pair.points.begin(), pair.points.end());
        for (std::size_t f = 0; f < pair.polygonCount(); ++f) {
            std::vector<std::uint32_t> poly(pair.polygon(f), pair.polygon(f) + pair.polygonSize(f));
            for (std::uint32_t& v : poly) v += base;
            m.addPolygon(poly.data(), poly.size());
        }
        suspects.push_back(base + 5); // (in no order: later apexes first)
        suspects.insert(suspects.begin(), base);
    }
    REQUIRE(m.indices.size() > 65536);
    std::vector<Mesh> results;
    for (int threads : {1, 2}) {
        ThreadLimit limit(threads);
        Mesh copy = m;
        CHECK(separateCoincidentPoints(copy, suspects) == 6000);
        results.push_back(std::move(copy));
    }
    CHECK(results[0].points == results[1].points);
    CHECK(countCoincidentPoints(results[1]) == 0);
    int misplaced = 0; // apexes not moved straight into their own pyramid, as a pair alone's are
    for (int i = 0; i < 3000; ++i) {
        const Vec3f below = results[1].points[std::size_t(10 * i)], above = results[1].points[std::size_t(10 * i + 5)];
        const float x = float(3 * (i % 60)), y = float(3 * (i / 60));
        misplaced += !(below.x == Approx(x).margin(1e-5) && below.y == Approx(y).margin(1e-5) &&
                       below.z == Approx(2.0 - kSeparationShare).epsilon(1e-6) && above.x == Approx(x).margin(1e-5) &&
                       above.y == Approx(y).margin(1e-5) && above.z == Approx(2.0 + kSeparationShare).epsilon(1e-6));
    }
    CHECK(misplaced == 0);
}

TEST_CASE("separateCoincidentPoints: only listed vertices move, and never onto each other") {
    SECTION("a coincident pair not among the suspects stays") {
        Mesh m = twoPyramidsApexToApex(Vec3f(0, 0, 0));
        CHECK(separateCoincidentPoints(m, {0, 1, 2}) == 0);
        CHECK(countCoincidentPoints(m) == 1);
    }
    SECTION("copies whose neighbours have one centroid part all the same") {
        // Three copies of a quad's corner, each alone in a triangle with the same two neighbours:
        // the same target, so the later ones go further.
        Mesh m;
        m.points = {{0, 0, 0}, {0, 0, 0}, {0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
        for (std::uint32_t c : {0u, 1u, 2u}) m.addPolygon({c, 3, 4});
        CHECK(separateCoincidentPoints(m, {0, 1, 2}) == 3);
        CHECK(countCoincidentPoints(m) == 0);
        for (std::uint32_t c : {0u, 1u, 2u}) {
            CHECK(m.points[c].x > 0);
            CHECK(m.points[c].x == m.points[c].y);
            CHECK(m.points[c].x < 0.5f);
        }
    }
    SECTION("far from the origin, where 5 % of the way rounds to nothing in floats, a float step") {
        const float far = 1e7f; // float steps of 1 here: 5 % of a unit pyramid's height rounds away
        Mesh m = twoPyramidsApexToApex(Vec3f(far, far, far));
        CHECK(separateCoincidentPoints(m, {0, 5}) == 2);
        CHECK(m.points[0].z == far - 1);
        CHECK(m.points[5].z == far + 1);
    }
}

TEST_CASE("no two vertices of a DMC or marching-cubes mesh share a point: merged by position, it stays manifold") {
    // Random rotated sharp shapes (a box with a box cut out of it, two boxes joined, a knife edge)
    // and a real fog volume left vertices at one point: crossings at a node kept apart so that no
    // edge holds three polygons, copies of a vertex where two fans touch, a feature point the
    // surface fit put where a node stood. Before, 20 of these 80 shapes (DMC's) had some, and the
    // smoke with either mesher; merged by position, none of them was manifold.
    std::mt19937 rng(20261126);
    std::uniform_real_distribution<double> u(0, 1);
    // (A rotation from a random unit quaternion; its rows are the rotated frame's axes here.)
    auto randomRotation = [&] {
        double q[4], n = 0;
        for (double& c : q) c = u(rng) - 0.5, n += c * c;
        for (double& c : q) c /= std::sqrt(n);
        const double x = q[0], y = q[1], z = q[2], w = q[3];
        return test::Rotation{{{1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)},
                               {2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)},
                               {2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)}}};
    };
    auto row = [](const test::Rotation& r, int i) { return Vec3d(r[i][0], r[i][1], r[i][2]); };
    // A rotated box as a formula: max over its axes of |axis . (p - c)| - half extent.
    auto box = [&](const Vec3d& c, const Vec3d& h) {
        const test::Rotation r = randomRotation();
        std::string f = "max(";
        for (int i = 0; i < 3; ++i) f += std::string(i ? ", " : "") + "abs" + test::dotWith(row(r, i), c) + "-" + num(h[i]);
        return f + ")";
    };
    auto knifeEdge = [&](double angle) {
        const test::Rotation r = randomRotation();
        auto axis = [&](int i) { return test::dotWith(row(r, i), Vec3d(0, 0, 0)); };
        const double c = std::cos(angle / 2), s = std::sin(angle / 2);
        return "max(" + num(c) + "*" + axis(1) + "-" + num(s) + "*" + axis(0) + ", -" + num(c) + "*" + axis(1) + "-" + num(s) + "*" +
               axis(0) + ", sqrt(x^2+y^2+z^2)-0.6)";
    };
    const Box3 bounds{{-1, -1, -1}, {1, 1, 1}};
    std::size_t separated = 0;
    for (int shape = 0; shape < 80; ++shape) {
        std::string f;
        switch (shape % 3) {
        case 0: f = "max(" + box({0, 0, 0}, {0.3 + 0.3 * u(rng), 0.3 + 0.3 * u(rng), 0.3 + 0.3 * u(rng)}) + ", -(" +
                    box({0.8 * u(rng) - 0.4, 0.8 * u(rng) - 0.4, 0.8 * u(rng) - 0.4}, {0.15 + 0.2 * u(rng), 0.15 + 0.2 * u(rng), 0.15 + 0.2 * u(rng)}) + "))";
            break;
        case 1: f = "min(" + box({0, 0, 0}, {0.2 + 0.3 * u(rng), 0.2 + 0.3 * u(rng), 0.2 + 0.3 * u(rng)}) + ", " +
                    box({0.6 * u(rng) - 0.3, 0.6 * u(rng) - 0.3, 0.6 * u(rng) - 0.3}, {0.2 + 0.3 * u(rng), 0.2 + 0.3 * u(rng), 0.2 + 0.3 * u(rng)}) + ")";
            break;
        default: f = knifeEdge((30 + 120 * u(rng)) * 3.14159265358979 / 180);
        }
        const double h = 0.05 + 0.07 * u(rng);
        const MeshMethod method = shape % 4 == 3 ? MeshMethod::MarchingCubes : MeshMethod::Dmc;
        INFO("shape " << shape << " (" << methodName(method) << ", H " << h << "): " << f);
        const ExpressionField field(f, bounds);
        MeshRequest req;
        req.voxelSize = h;
        req.method = method;
        MeshReport rep;
        const Mesh m = meshField(field, req, rep);
        CHECK(checkTopology(m).closedManifoldOriented());
        CHECK(countCoincidentPoints(m) == 0);
        const MeshTopology merged = topologyMerged(m);
        CHECK(merged.closedManifoldOriented());
        CHECK(merged.degeneratePolygons == 0);
        separated += rep.separatedVertices;
    }
    CHECK(separated > 0); // (there were some to separate)

    const std::string path = test::sharedData("vdb/smoke_fog.vdb");
    if (path.empty()) {
        WARN("../shared/data absent: smoke_fog case skipped");
        return;
    }
    // Fog values exactly at 0.5 put crossings on nodes where sheets of smoke touch.
    const GridField smoke(readScalarGrid(path, "").grid, "smoke");
    for (MeshMethod method : {MeshMethod::MarchingCubes, MeshMethod::Dmc}) {
        INFO("smoke_fog.vdb, " << methodName(method));
        MeshRequest req;
        req.method = method;
        MeshReport rep;
        const Mesh m = meshField(smoke, req, rep);
        CHECK(rep.separatedVertices > 0);
        CHECK(countCoincidentPoints(m) == 0);
        CHECK(topologyMerged(m).closedManifoldOriented());
    }
}
