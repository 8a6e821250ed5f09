// Folds (mesh/mesh_folds.h): two polygons alone around a vertex, folded onto each other. Found,
// closed where that keeps the surface an edge-manifold, and not made by the mesher.
#include "support/test_support.h"

#include "vdbsurf/core/threads.h"
#include "vdbsurf/density/scene_json.h"
#include "vdbsurf/dmc/mesher.h"
#include "vdbsurf/field/grid_field.h"
#include "vdbsurf/mesh/mesh_check.h"
#include "vdbsurf/mesh/mesh_folds.h"
#include "vdbsurf/vdb/vdb_file.h"

#include <catch2/catch.hpp>

#include <numeric>

using namespace vdbsurf;

namespace {

// A unit cube of six quads; face 0 is [0, 3, 2, 1] (z = 0, seen from below).
Mesh cube() {
    Mesh m;
    for (int i = 0; i < 8; ++i) m.points.push_back(Vec3f(float(i & 1), float((i >> 1) & 1), float((i >> 2) & 1)));
    for (const auto& f : std::vector<std::array<std::uint32_t, 4>>{{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}})
        m.addPolygon({f[0], f[1], f[2], f[3]});
    return m;
}

// The cube with face 0 [a, x, b, y] = [0, 2, 3, 1] replaced by polygons holding a new vertex v
// (8) at the face's middle between a and b, folded: `faces` in place of face 0.
Mesh cubeWithFold(const std::vector<std::vector<std::uint32_t>>& faces) {
    const Mesh c = cube();
    Mesh m;
    m.points = c.points;
    m.points.push_back(Vec3f(0.5f, 0.5f, 0.0f));
    for (const auto& f : faces) m.addPolygon(f.data(), f.size());
    for (std::size_t p = 1; p < c.polygonCount(); ++p) m.addPolygon(c.polygon(p), c.polygonSize(p));
    return m;
}

std::vector<std::uint32_t> allPolygons(const Mesh& m) {
    std::vector<std::uint32_t> all(m.polygonCount());
    std::iota(all.begin(), all.end(), 0u);
    return all;
}

} // namespace

TEST_CASE("closeFolds: two quads folded at a vertex become two triangles", "[folds]") {
    // [a, x, b, v] and [a, v, b, y]: v's only polygons, each running the other way round it.
    Mesh m = cubeWithFold({{0, 2, 3, 8}, {0, 8, 3, 1}});
    MeshTopology t = checkTopology(m);
    REQUIRE(t.boundaryEdges + t.nonManifoldEdges + t.inconsistentEdges + t.nonManifoldVertices == 0);
    CHECK(t.foldedVertices == 1);
    CHECK(!t.closedManifoldOriented());
    std::vector<std::uint32_t> scratch(3, 12345); // any contents
    const FoldStats s = closeFolds(m, allPolygons(m), scratch);
    CHECK(s.closed == 1);
    CHECK(s.removedPolygons == 0);
    CHECK(s.left == 0);
    t = checkTopology(m);
    CHECK(t.closedManifoldOriented());
    CHECK(t.unusedVertices == 0);
    CHECK(m.points.size() == 8); // v is gone, the cube's corners kept their order
    CHECK(m.points[7] == Vec3f(1, 1, 1));
    CHECK(m.polygonCount() == 7);
    CHECK(enclosedVolume(m) == Approx(1.0));
}

TEST_CASE("closeFolds: a triangle folded onto a quad goes, the quad loses the vertex", "[folds]") {
    // [a, x, b, v] and [a, v, b]; the triangle's third edge b -> a pairs with [a, b, y].
    Mesh m = cubeWithFold({{0, 2, 3, 8}, {0, 8, 3}, {0, 3, 1}});
    REQUIRE(checkTopology(m).foldedVertices == 1);
    std::vector<std::uint32_t> scratch;
    const FoldStats s = closeFolds(m, allPolygons(m), scratch);
    CHECK(s.closed == 1);
    CHECK(s.removedPolygons == 1);
    const MeshTopology t = checkTopology(m);
    CHECK(t.closedManifoldOriented());
    CHECK(t.unusedVertices == 0);
    CHECK(m.polygonCount() == 7);
    CHECK(enclosedVolume(m) == Approx(1.0));
}

TEST_CASE("closeFolds: only the listed polygons are looked at", "[folds]") {
    Mesh m = cubeWithFold({{0, 2, 3, 8}, {0, 8, 3, 1}});
    std::vector<std::uint32_t> scratch;
    CHECK(closeFolds(m, {2, 3, 4, 5, 6}, scratch).closed == 0);
    CHECK(checkTopology(m).foldedVertices == 1);
    CHECK(closeFolds(m, {0, 1}, scratch).closed == 1);
    CHECK(checkTopology(m).foldedVertices == 0);
}

TEST_CASE("closeFolds: each corner is compared with the first polygon listed at its vertex however far apart", "[folds]") {
    // At vertex 0: a triangle, then (thousands of polygons later, in other tasks) two quads
    // folded onto each other there (at 0 alone: their other corners differ). A fold between a
    // vertex's second and third polygons is not one (the vertex is not vertex-manifold):
    // compared with the first, neither is folded. Without the triangle the fold is closed.
    Mesh m;
    m.points = {Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0), Vec3f(0, 0, 1), Vec3f(1, 1, 1), Vec3f(2, 1, 1), Vec3f(1, 2, 1)};
    m.offsets = {0};
    auto filler = [&](int count) { // apart from everything
        for (int t = 0; t < count; ++t) {
            const std::uint32_t b = std::uint32_t(m.points.size());
            for (int k = 0; k < 3; ++k) m.points.push_back(Vec3f(10.0f + float(b), float(k == 1), float(k == 2)));
            m.addPolygon({b, b + 1, b + 2});
        }
    };
    m.addPolygon({0, 1, 2});
    filler(1500);
    m.addPolygon({0, 3, 5, 4});
    filler(1500);
    m.addPolygon({0, 4, 6, 3});
    ThreadLimit two(2);
    for (const bool withTriangle : {true, false}) {
        Mesh start = m;
        if (!withTriangle) { // polygon 0 dropped
            start.indices.erase(start.indices.begin(), start.indices.begin() + 3);
            start.offsets.erase(start.offsets.begin() + 1);
            for (std::uint32_t& o : start.offsets) o = o == 0 ? 0 : o - 3;
        }
        std::vector<std::uint32_t> all(start.polygonCount());
        std::iota(all.begin(), all.end(), 0u);
        for (int run = 0; run < 10; ++run) {
            Mesh copy = start;
            std::vector<std::uint32_t> scratch;
            INFO("with the triangle: " << withTriangle << ", run " << run);
            CHECK(closeFolds(copy, all, scratch).closed == (withTriangle ? 0u : 1u));
            CHECK(copy.polygonCount() == start.polygonCount());
            CHECK((copy.indices == start.indices) == withTriangle);
        }
    }
}

TEST_CASE("closeFolds: a pillow of two triangles goes, and a fold whose new edge exists stays", "[folds]") {
    Mesh pillow;
    pillow.points = {Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)};
    pillow.addPolygon({0, 1, 2});
    pillow.addPolygon({2, 1, 0});
    std::vector<std::uint32_t> scratch;
    FoldStats s = closeFolds(pillow, allPolygons(pillow), scratch);
    CHECK(s.closed == 1);
    CHECK(s.removedPolygons == 2);
    CHECK(pillow.empty());
    CHECK(pillow.points.empty());

    // Three quads folded about a (0) and b (1): [a, v, b, p], [b, v, a, q], [a, p, b, q]; and a
    // tetrahedron on a, b, c, d, which has the edge a-b every fold would make.
    Mesh m;
    for (int i = 0; i < 7; ++i) m.points.push_back(Vec3f(float(i), float(i * i % 5), float(i % 3)));
    const std::uint32_t a = 0, b = 1, v = 2, p = 3, q = 4, c = 5, d = 6;
    for (const auto& f : std::vector<std::vector<std::uint32_t>>{
             {a, v, b, p}, {b, v, a, q}, {a, p, b, q}, {a, b, c}, {a, c, d}, {a, d, b}, {b, d, c}})
        m.addPolygon(f.data(), f.size());
    const Mesh before = m;
    s = closeFolds(m, allPolygons(m), scratch);
    CHECK(s.closed == 0);
    CHECK(s.left == 3);
    CHECK(m.indices == before.indices);
    CHECK(m.points.size() == before.points.size());
}

TEST_CASE("DMC leaves no folds where the weld collapsed the polygons between two others", "[folds]") {
    // A box with an ellipsoid taken out of it (found among random scenes meshed for the Reeb
    // graph, which refused the mesh): nodes on the sharp rim weld, two polygons at a crossing
    // collapse, and the other two were left folded onto each other.
    const DensityScene scene = parseSceneText(R"({"primitives": [
        {"core": "box", "center": [-0.39283449881704058, -0.16735534284426595, -0.49127057435707905],
         "half_extents": [0.24737636349554198, 0.35064003554906792, 0.11597266806976572],
         "falloff": 0.071953140498357979, "weight": 1.6303289794583289},
        {"core": "ellipsoid", "center": [-0.15803013120889026, -0.32400800283600689, -0.17954575727895566],
         "radii": [0.38873897446727351, 0.40303164197784458, 0.30356615994025754],
         "falloff": 0.018899401254398297, "weight": 1.0708165095296074, "op": "subtract"}]})",
                                              "fold.json");
    MeshRequest req;
    req.voxelSize = 0.023612766943482938;
    MeshReport report;
    const Mesh m = meshField(scene, req, report);
    const MeshTopology t = checkTopology(m);
    CHECK(t.closedManifoldOriented());
    CHECK(t.foldedVertices == 0);
    CHECK(t.unusedVertices == 0);
}

TEST_CASE("DMC leaves no folds on a real fog volume meshed coarser than its voxels", "[folds]") {
    // smoke_fog.vdb at these spacings came out with one to three folds a mesh (session 36's CLI),
    // left by the simplification of its wisps, thinner than a cell there.
    const std::string path = test::sharedData("vdb/smoke_fog.vdb");
    if (path.empty()) {
        WARN("../shared/data absent: smoke_fog case skipped");
        return;
    }
    const GridField field(readScalarGrid(path, "").grid, "smoke");
    for (const auto& [iso, h] : std::vector<std::pair<double, double>>{{0.5, 0.45}, {0.2, 0.7}}) {
        INFO("iso " << iso << ", voxel size " << h);
        MeshRequest req;
        req.iso = iso;
        req.voxelSize = h;
        MeshReport report;
        const Mesh m = meshField(field, req, report);
        const MeshTopology t = checkTopology(m);
        CHECK(t.foldedVertices == 0);
        CHECK(t.closedManifoldOriented());
        CHECK(report.foldsClosed > 0); // (they were there to close)
    }
}
