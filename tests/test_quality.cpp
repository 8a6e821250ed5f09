// Quality measures and the comparison behind `vdbsurf compare`: distances to an iso surface
// against the closed form, coverage of a mesh that misses half the surface, and DMC against
// OpenVDB's volumeToMesh on a plate thinner than a cell; distances to a mesh of mixed scales
// against a search of every triangle.
#include "support/test_support.h"

#include "vdbsurf/dmc/mesher.h"
#include "vdbsurf/field/expression_field.h"
#include "vdbsurf/field/grid_field.h"
#include "vdbsurf/mesh/mesh_distance.h"
#include "vdbsurf/quality/compare.h"
#include "vdbsurf/quality/surface_quality.h"

#include <catch2/catch.hpp>

#include <cmath>
#include <random>

using namespace vdbsurf;

TEST_CASE("distance to the iso surface matches the closed form of a sphere, inside and out") {
    // Not a distance field: value r^2 - 1, so a projection by the value alone would be wrong.
    const ExpressionField sphere("x^2+y^2+z^2-1", {{-2, -2, -2}, {2, 2, 2}});
    std::mt19937 rng(7);
    std::normal_distribution<double> g;
    std::uniform_real_distribution<double> offset(-0.3, 0.3);
    for (int i = 0; i < 200; ++i) {
        const Vec3d dir = normalized(Vec3d(g(rng), g(rng), g(rng)));
        const double d = offset(rng);
        const Vec3d p = dir * (1.0 + d);
        CHECK(distanceToIsoSurface(sphere, 0.0, p, 1.0) == Approx(std::fabs(d)).margin(1e-6));
    }
    // Farther than the cap: the cap.
    CHECK(distanceToIsoSurface(sphere, 0.0, {0, 0, 1.8}, 0.5) == 0.5);
}

TEST_CASE("distance to a mesh of mixed scales: as a search of every triangle, built at a spacing far below its large triangles") {
    // A patch of 20,000 triangles 1e-9 wide beside triangles a million times larger, a sliver
    // 100 long and 1e-6 wide, one far out at 1e20 and one with a point that is not finite; the
    // grid asked for at the tiny triangles' spacing (as the patches' fit error asks for four mean
    // edges). One uniform grid at that spacing would put each large triangle in ~1e35 cells.
    Mesh m;
    const double t = 1e-9;
    for (int j = 0; j <= 100; ++j)
        for (int i = 0; i <= 100; ++i) m.points.push_back(Vec3f(float(i * t), float(j * t), float(1e-10 * ((i * 7 + j * 3) % 5))));
    for (std::uint32_t j = 0; j < 100; ++j)
        for (std::uint32_t i = 0; i < 100; ++i) {
            const std::uint32_t a = j * 101 + i;
            m.addPolygon({a, a + 1, a + 102});
            m.addPolygon({a, a + 102, a + 101});
        }
    const auto triangle = [&](Vec3f a, Vec3f b, Vec3f c) {
        const auto n = std::uint32_t(m.points.size());
        m.points.insert(m.points.end(), {a, b, c});
        m.addPolygon({n, n + 1, n + 2});
    };
    triangle({-1000, -1000, 5}, {1000, -1000, 5}, {0, 1000, -5});
    triangle({2, 3, 4}, {300, 3, 4}, {2, 300, 600});
    triangle({-50, 1, 1}, {50, 1, 1}, {0, 1, 1.000001f});
    triangle({1e20f, 1e20f, 0}, {1e20f, 1.0001e20f, 0}, {1.0001e20f, 1e20f, 0});
    triangle({0, 0, 7}, {1, 0, 7}, {0, std::numeric_limits<float>::quiet_NaN(), 7});
    const MeshDistance grid(m, 4 * t);
    const auto everyTriangle = [&](const Vec3d& p, double radius) {
        double best = radius;
        for (std::size_t f = 0; f + 1 < m.polygonCount(); ++f) { // all but the one that is not finite
            const std::uint32_t* v = m.polygon(f);
            best = std::min(best, pointTriangleDistance(p, Vec3d(m.points[v[0]]), Vec3d(m.points[v[1]]), Vec3d(m.points[v[2]])));
        }
        return best;
    };
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> unit(-1, 1), exponent(-10, 21);
    int near = 0;
    for (int q = 0; q < 400; ++q) {
        // Points at every scale from the patch's to the far triangle's, radii likewise.
        const double scale = std::pow(10.0, exponent(rng)), radius = std::pow(10.0, exponent(rng));
        const Vec3d p(unit(rng) * scale, unit(rng) * scale, unit(rng) * scale);
        const double want = everyTriangle(p, radius);
        CHECK(grid.distance(p, radius) == want);
        near += want < radius;
    }
    CHECK(near > 100); // the queries found triangles, not only their radii
    // On the patch, beside it, on the sliver and at the far triangle.
    CHECK(grid.distance({50 * t, 50 * t, 1e-6}, 1e-3) == Approx(1e-6).margin(1e-9));
    CHECK(grid.distance({0, 1, 1}, 1e-3) == Approx(0).margin(1e-12));
    CHECK(grid.distance({double(1e20f), double(1e20f), 1e15}, 1e16) == Approx(1e15).epsilon(1e-9));
    CHECK(grid.distance({0, 0, 7}, 0.5) == 0.5); // only the triangle that is not finite is there
}

TEST_CASE("surface quality: a full sphere mesh is accurate and covers, half of it covers half") {
    const ExpressionField sphere("x^2+y^2+z^2-1", {{-1.3, -1.3, -1.3}, {1.3, 1.3, 1.3}});
    const double h = 0.1;
    MeshRequest req;
    req.voxelSize = h;
    req.method = MeshMethod::MarchingCubes;
    MeshReport rep;
    const Mesh full = meshField(sphere, req, rep);
    const std::vector<Vec3d> surface = isoSurfaceSamples(sphere, 0.0, h / 4);
    REQUIRE(surface.size() > 1000);

    const SurfaceQuality q = measureSurfaceQuality(full, sphere, 0.0, surface, h);
    CHECK(q.coverageOne == 1.0);
    CHECK(q.coverageQuarter > 0.99);
    CHECK(q.accuracyQuarter > 0.99);
    CHECK(q.meanDistance < 0.05 * h);
    CHECK(q.fScoreQuarter > 0.99);

    Mesh half; // the polygons whose first vertex has z > 0
    half.points = full.points;
    for (std::size_t p = 0; p < full.polygonCount(); ++p)
        if (full.points[full.polygon(p)[0]].z > 0) half.addPolygon(full.polygon(p), full.polygonSize(p));
    const SurfaceQuality hq = measureSurfaceQuality(half, sphere, 0.0, surface, h);
    CHECK(hq.coverageOne == Approx(0.5).margin(0.06));
    CHECK(hq.accuracyQuarter > 0.99); // what is there is still on the surface
    CHECK(hq.fScoreQuarter < 0.75);

    Mesh shifted = full; // moved by half a cell: accurate nowhere within h/4, covered within h
    for (Vec3f& p : shifted.points) p.x += float(0.5 * h);
    const SurfaceQuality sq = measureSurfaceQuality(shifted, sphere, 0.0, surface, h);
    CHECK(sq.coverageOne == 1.0);
    CHECK(sq.coverageQuarter < 0.8);
    CHECK(sq.meanDistance > 0.2 * h);
}

TEST_CASE("compare: on a plate a third of a cell thick DMC covers what volumeToMesh loses") {
    // A disk of thickness 0.3 H at an oblique angle, as a level set at H/5, meshed at H.
    const double H = 0.1;
    const Vec3d n = normalized(Vec3d(0.3, 0.5, 0.8));
    auto grid = test::makeLevelSetFromDistance(
        [&](const Vec3d& p) {
            const double across = std::fabs(dot(p, n)) - 0.15 * H;
            const double radial = length(p - n * dot(p, n)) - 0.6;
            return std::max(across, radial);
        },
        {{-0.8, -0.8, -0.8}, {0.8, 0.8, 0.8}}, H / 5);
    const GridField field(grid, "plate");
    CompareRequest req;
    req.voxelSize = H;
    const CompareReport rep = compareMeshers(field, req);
    REQUIRE(rep.rows.size() == 3);
    CHECK(rep.resampled);
    CHECK(rep.surfaceSamples > 5000);
    for (const CompareRow& r : rep.rows)
        WARN(r.method << ": coverage H/4 " << r.quality.coverageQuarter << " H " << r.quality.coverageOne << " accuracy H/4 "
                      << r.quality.accuracyQuarter << " F " << r.quality.fScoreQuarter << " pieces " << r.components);
    const CompareRow& vtm = rep.rows[0];
    const CompareRow& mc = rep.rows[1];
    const CompareRow& dmc = rep.rows[2];
    CHECK(vtm.method == "volumeToMesh");
    CHECK(dmc.method == "vdbsurf dmc");
    INFO("coverage within H: volumeToMesh " << vtm.quality.coverageOne << ", mc " << mc.quality.coverageOne << ", dmc "
                                            << dmc.quality.coverageOne);
    CHECK(dmc.quality.coverageOne >= 0.99);
    CHECK(vtm.quality.coverageOne < 0.95);
    // Within H/4 the difference is stark: marching cubes only meets the plate where a node lies in it.
    CHECK(dmc.quality.fScoreQuarter > 0.95);
    CHECK(vtm.quality.fScoreQuarter < 0.5);
    CHECK(mc.quality.fScoreQuarter < 0.5);
    CHECK(vtm.components > 1);
    CHECK(dmc.components == 1);
    CHECK(dmc.topology.closedManifoldOriented());
    CHECK(dmc.quality.p95Distance < 0.5 * H);
}

TEST_CASE("compare at the grid's own voxel size: every mesher is exact on a sphere level set") {
    auto grid = test::makeSphereLevelSet(1.0, {0.013, -0.021, 0.007}, 0.05);
    const GridField field(grid, "sphere");
    const CompareReport rep = compareMeshers(field, {});
    CHECK_FALSE(rep.resampled);
    CHECK(rep.voxelSize == Approx(0.05));
    for (const CompareRow& r : rep.rows) {
        INFO(r.method);
        CHECK(r.quality.coverageQuarter > 0.999);
        CHECK(r.quality.accuracyQuarter > 0.999);
        CHECK(r.components == 1);
    }
    // Same lattice, same field: volumeToMesh and our marching cubes put vertices at the same places.
    CHECK(double(rep.rows[0].vertices) == Approx(double(rep.rows[1].vertices)).epsilon(0.001));
}

TEST_CASE("compare: a mesher that loses the whole surface is a row of its own, not an error") {
    // A rod 0.3 H across along z, midway between lattice nodes: no node is inside, so marching
    // cubes (ours and volumeToMesh) finds nothing, while DMC's thin search finds the rod.
    const double H = 0.1;
    auto grid = test::makeLevelSetFromDistance(
        [&](const Vec3d& p) {
            const double across = std::hypot(p.x - 0.5 * H, p.y - 0.5 * H) - 0.15 * H;
            return std::max(across, std::fabs(p.z) - 0.5);
        },
        {{-0.3, -0.3, -0.7}, {0.3, 0.3, 0.7}}, H / 5);
    const GridField field(grid, "rod");
    CompareRequest req;
    req.voxelSize = H;
    const CompareReport rep = compareMeshers(field, req);
    REQUIRE(rep.rows.size() == 3);
    CHECK(rep.surfaceSamples > 200);
    for (const CompareRow& r : rep.rows) {
        if (r.method == "vdbsurf dmc") continue;
        INFO(r.method);
        CHECK(r.polygons == 0);
        CHECK(r.components == 0);
        CHECK(r.quality.coverageOne == 0);
        CHECK(r.quality.fScoreQuarter == 0);
    }
    const CompareRow& dmc = rep.rows[2];
    CHECK(dmc.components == 1);
    CHECK(dmc.quality.coverageOne >= 0.99);
    CHECK(dmc.topology.closedManifoldOriented());

    // Where the input itself has no surface there is nothing to compare: one error naming it.
    req.iso = 5.0;
    CHECK_THROWS_WITH(compareMeshers(field, req), Catch::Contains("rod") && Catch::Contains("has no surface at iso 5"));
}
