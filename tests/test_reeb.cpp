// Reeb graph, units, ring grids and B-spline patches (seed 004) on DMC meshes of shapes whose
// topology is known.
#include "support/shapes.h"
#include "support/test_support.h"

#include "vdbsurf/core/error.h"
#include "vdbsurf/density/scene_json.h"
#include "vdbsurf/dmc/mesher.h"
#include "vdbsurf/field/expression_field.h"
#include "vdbsurf/mesh/fan_triangles.h"
#include "vdbsurf/mesh/mesh_check.h"
#include "vdbsurf/mesh/mesh_io.h"
#include "vdbsurf/reeb/bspline.h"
#include "vdbsurf/reeb/patch_pipeline.h"
#include "vdbsurf/reeb/row_zip.h"

#include <catch2/catch.hpp>

#include <cmath>
#include <map>

using namespace vdbsurf;
using namespace vdbsurf::reeb;

namespace {

Mesh dmcMesh(const std::string& formula, double extent, double h) {
    ExpressionField f(formula, Box3{Vec3d(-extent, -extent, -extent), Vec3d(extent, extent, extent)});
    MeshRequest req;
    req.voxelSize = h;
    MeshReport rep;
    return meshField(f, req, rep);
}

// Torus of radii R, r around the axis (ax, ay, az) through the origin.
std::string torusFormula(double R, double r, const Vec3d& axis) {
    const Vec3d a = normalized(axis);
    auto n = [](double v) { return "(" + std::to_string(v) + ")"; };
    const std::string along = "(x*" + n(a.x) + "+y*" + n(a.y) + "+z*" + n(a.z) + ")";
    const std::string across = "sqrt(max(x*x+y*y+z*z-" + along + "*" + along + ",0))";
    return "sqrt(pow(" + across + "-" + n(R) + ",2)+" + along + "*" + along + ")-" + n(r);
}

std::string capsuleFormula() { return "sqrt(x*x+y*y+pow(max(abs(z)-1,0),2))-0.5"; }
// A tube around the lemniscate y^2 = x^2 (1 - x^2): genus 2.
std::string doubleTorusFormula() { return "sqrt(pow(x*x*(1-x*x)-y*y,2)+z*z)-0.08"; }

PatchResult patchesOf(const Mesh& mesh, const Vec3d& axis, double persistence = 0.5) {
    PatchJob job;
    job.axis = axis;
    job.persistence = persistence;
    return makePatches(mesh, "mesh", job);
}

void checkGraph(const ReebGraph& g, std::size_t minima, std::size_t maxima, std::size_t saddles, std::size_t arcs, std::size_t loops) {
    INFO("minima " << g.minima << " maxima " << g.maxima << " saddles " << g.saddles << " arcs " << g.units.size());
    CHECK(g.minima == minima);
    CHECK(g.maxima == maxima);
    CHECK(g.saddles == saddles);
    CHECK(g.nodes.size() == minima + maxima + saddles);
    CHECK(g.units.size() == arcs);
    CHECK(g.loops() == loops);
    CHECK(long(g.minima) - long(g.saddles) + long(g.maxima) == g.eulerCharacteristic);
    // Every arc climbs, and every node has the degree its type demands.
    std::vector<int> down(g.nodes.size(), 0), up(g.nodes.size(), 0);
    for (const Unit& u : g.units) {
        CHECK(g.nodes[u.lower].rank < g.nodes[u.upper].rank);
        ++up[u.lower];
        ++down[u.upper];
    }
    for (std::size_t n = 0; n < g.nodes.size(); ++n) {
        if (g.nodes[n].type == CriticalType::Minimum) CHECK((down[n] == 0 && up[n] == 1));
        if (g.nodes[n].type == CriticalType::Maximum) CHECK((down[n] == 1 && up[n] == 0));
        if (g.nodes[n].type == CriticalType::Saddle) CHECK(down[n] + up[n] == 2 + g.nodes[n].multiplicity);
    }
}

// Units partition the surface; each is a disk (one end a pole), a cylinder, or the whole sphere.
void checkUnits(const PatchResult& r, const Mesh& mesh) {
    double sum = 0;
    for (const Unit& u : r.graph.units) {
        sum += u.area;
        Mesh m;
        for (const Vec3d& p : u.points) m.points.push_back(Vec3f(p));
        m.offsets = u.offsets;
        m.indices = u.indices;
        const MeshTopology t = checkTopology(m);
        CHECK(t.nonManifoldEdges == 0);
        CHECK(t.inconsistentEdges == 0);
        CHECK((t.boundaryEdges > 0) == !(u.bottomLobes.empty() && u.topLobes.empty()));
    }
    CHECK(sum == Approx(surfaceArea(mesh)).epsilon(1e-6));
}

// Rings close (the seam step is no longer than the grid's other steps), and every inner
// section lies in its plane across the axis.
void checkRings(const PatchResult& r) {
    for (const UnitPatch& p : r.patches.patches) {
        const RingGrid& grid = p.grid;
        for (int v = 0; v < grid.V; ++v) {
            double longest = 0;
            for (int u = 0; u + 1 < grid.U; ++u) longest = std::max(longest, length(grid.at(u + 1, v) - grid.at(u, v)));
            CHECK(length(grid.at(0, v) - grid.at(grid.U - 1, v)) <= longest * 1.01 + 1e-12);
            // No twist: turning the next row by whole grid steps never brings it closer to this one.
            if (v + 1 < grid.V) {
                auto cost = [&](int k) {
                    double c = 0;
                    for (int u = 0; u < grid.U; ++u) {
                        const Vec3d d = grid.at((u + k) % grid.U, v + 1) - grid.at(u, v);
                        c += dot(d, d);
                    }
                    return c;
                };
                const double chosen = cost(0);
                for (int k = 1; k < grid.U; ++k) CHECK(chosen <= cost(k) * (1 + 1e-9) + 1e-18);
            }
            if (v > 0 && v + 1 < grid.V && grid.sectionsBlended == 0)
                for (int u = 0; u < grid.U; ++u) CHECK(dot(grid.at(u, v), r.graph.axis) == Approx(grid.heights[std::size_t(v)]).margin(1e-9));
        }
    }
}

void checkJoins(const PatchResult& r) {
    const double diagonal = length(r.preview.bounds().extent());
    CHECK(maxJoinGap(r.patches) < 1e-6 * diagonal);
    // The tessellation shares vertices along the joins: it is closed where the input is.
    const MeshTopology t = checkTopology(r.preview);
    INFO("boundary " << t.boundaryEdges << " non-manifold " << t.nonManifoldEdges << " inconsistent " << t.inconsistentEdges);
    CHECK(t.closedManifoldOriented());
    CHECK(countComponents(r.preview) == r.graph.components);
}

} // namespace

TEST_CASE("Reeb graph of a sphere: a minimum, a maximum and one arc", "[reeb]") {
    const Mesh m = dmcMesh("sqrt(x*x+y*y+z*z)-1", 1.3, 0.08);
    const PatchResult r = patchesOf(m, Vec3d(0, 0, 1));
    checkGraph(r.graph, 1, 1, 0, 1, 0);
    CHECK(r.graph.nodes.front().height == Approx(-1).margin(0.01));
    CHECK(r.graph.nodes.back().height == Approx(1).margin(0.01));
    checkUnits(r, m);
    checkRings(r);
    checkJoins(r);
}

TEST_CASE("Reeb graph of an upright torus: 4 nodes, 4 arcs, one loop", "[reeb]") {
    const Mesh m = dmcMesh(torusFormula(1.0, 0.35, Vec3d(0, 1, 0)), 1.5, 0.06);
    const PatchResult r = patchesOf(m, Vec3d(0, 0, 1));
    checkGraph(r.graph, 1, 1, 2, 4, 1);
    // The saddles sit on the inner rim, at z = -+(R - r).
    const std::vector<ReebNode>& n = r.graph.nodes;
    CHECK(n[1].type == CriticalType::Saddle);
    CHECK(n[1].height == Approx(-0.65).margin(0.03));
    CHECK(n[2].height == Approx(0.65).margin(0.03));
    checkUnits(r, m);
    checkRings(r);
    checkJoins(r);
}

TEST_CASE("Ring grids wider than 128 (the spectral seam search) close, lie in their planes and do not twist", "[reeb][patches]") {
    // A user's --grid-size past what units choose for themselves: each row's seam is found by
    // cross-correlation through FFTs instead of trying every shift (a 2048^2 grid on spot.obj
    // took 145 s in its ring grids, 5 s now).
    const Mesh m = dmcMesh(torusFormula(1.0, 0.35, Vec3d(0.3, 0.5, 0.81)), 1.6, 0.06);
    PatchJob job;
    job.axis = Vec3d(0, 0, 1);
    job.gridU = 160;
    job.gridV = 24;
    const PatchResult r = makePatches(m, "mesh", job);
    for (const UnitPatch& p : r.patches.patches) CHECK(p.grid.U == 160);
    checkRings(r);
    checkJoins(r);
}

TEST_CASE("Reeb graph of a tilted torus, along a tilted axis too", "[reeb]") {
    const Mesh m = dmcMesh(torusFormula(1.0, 0.35, Vec3d(0.3, 0.5, 0.81)), 1.6, 0.06);
    for (const Vec3d& axis : {Vec3d(0, 0, 1), Vec3d(0.2, -0.9, 0.4)}) {
        const PatchResult r = patchesOf(m, axis);
        checkGraph(r.graph, 1, 1, 2, 4, 1);
        checkUnits(r, m);
        checkJoins(r);
    }
}

TEST_CASE("Reeb graph of a double torus: 6 nodes, 7 arcs, two loops", "[reeb]") {
    const Mesh m = dmcMesh(doubleTorusFormula(), 1.3, 0.025);
    const PatchResult r = patchesOf(m, Vec3d(1, 0.3, 0.2));
    checkGraph(r.graph, 1, 1, 4, 7, 2);
    checkUnits(r, m);
    checkRings(r);
    checkJoins(r);
}

TEST_CASE("Plateaus of equal height: a box meshed with sharp features", "[reeb]") {
    // DMC puts the faces of the box exactly on their planes: its top and bottom are plateaus.
    const Mesh m = dmcMesh("max(abs(x),abs(y),abs(z))-1", 1.3, 0.1);
    const PatchResult r = patchesOf(m, Vec3d(0, 0, 1));
    checkGraph(r.graph, 1, 1, 0, 1, 0);
    checkUnits(r, m);
    checkJoins(r);
    // An exact plateau (the cube's faces, all corners at equal heights): ties broken linearly
    // leave no critical point inside a face, even without simplification.
    const Mesh cube = test::cubeMesh();
    const PatchResult c = patchesOf(cube, Vec3d(0, 0, 1), 0.0);
    checkGraph(c.graph, 1, 1, 0, 1, 0);
}

TEST_CASE("Simplification removes only low-persistence extrema", "[reeb]") {
    // Two overlapping balls of different sizes: two minima, two maxima and two saddles are the
    // shape's own, far above the persistence; whatever the mesh adds below it goes.
    const Mesh m = dmcMesh("min(sqrt(x*x+y*y+z*z)-1,sqrt(pow(x-1.2,2)+y*y+pow(z-0.3,2))-0.6)", 1.9, 0.05);
    const PatchResult r = patchesOf(m, Vec3d(0, 0, 1));
    checkGraph(r.graph, 2, 2, 2, 5, 0);
    CHECK(r.graph.nodes.back().height == Approx(1).margin(0.01));
    checkUnits(r, m);
    checkJoins(r);
    const PatchResult raw = patchesOf(m, Vec3d(0, 0, 1), 0.0);
    CHECK(raw.graph.nodes.size() >= r.graph.nodes.size());
    CHECK(long(raw.graph.minima) - long(raw.graph.saddles) + long(raw.graph.maxima) == 2);
}

TEST_CASE("Patches fit smooth shapes to a fraction of an edge", "[reeb][patches]") {
    struct Shape {
        std::string name, formula;
        double extent, h;
        Vec3d axis;
    };
    const std::vector<Shape> shapes{{"sphere", "sqrt(x*x+y*y+z*z)-1", 1.3, 0.06, {0, 0, 1}},
                                    {"torus", torusFormula(1.0, 0.35, Vec3d(0, 1, 0)), 1.5, 0.05, {0, 0, 1}},
                                    {"capsule", capsuleFormula(), 1.7, 0.06, {0, 0, 1}}};
    for (const Shape& s : shapes) {
        const Mesh m = dmcMesh(s.formula, s.extent, s.h);
        const PatchResult r = patchesOf(m, s.axis);
        INFO(s.name << ": RMS " << r.error.rms << " max " << r.error.max << " mean edges");
        CHECK(r.error.rms < 0.1);
        CHECK(r.error.max < 0.5);
        checkJoins(r);
    }
}

TEST_CASE("Patches of a blobby scene", "[reeb][patches]") {
    const std::string scene = std::string(VDBSURF_SOURCE_DIR) + "/examples/scenes/blobby.json";
    const DensityScene field = readSceneFile(scene);
    MeshRequest req;
    req.voxelSize = 0.05;
    MeshReport rep;
    const Mesh m = meshField(field, req, rep);
    // One closed piece (DMC once left a two-triangle pillow at the rim of the hollow).
    CHECK(checkTopology(m).closedManifoldOriented());
    CHECK(countComponents(m) == 1);
    const PatchResult r = patchesOf(m, Vec3d(0, 0, 1));
    INFO("RMS " << r.error.rms << " max " << r.error.max << " nodes " << r.graph.nodes.size());
    CHECK(long(r.graph.minima) - long(r.graph.saddles) + long(r.graph.maxima) == r.graph.eulerCharacteristic);
    // The blend between the primitives curves more sharply than the spheres and tori above.
    CHECK(r.error.rms < 0.15);
    CHECK(r.error.max < 1.0);
    checkUnits(r, m);
    checkJoins(r);
}

TEST_CASE("A unit end through a saddle of three lobes follows the contour so the preview stays manifold there", "[reeb][patches]") {
    // A gyroid sheet in a ball, genus 8 (found among random meshes): a saddle of multiplicity 2
    // whose three lobes the one unit below and the one unit above each pass in one loop. Taken in
    // index order, the unit above paired each lobe's end with the start the unit below pairs it
    // with, and their patches met at the saddle in three fans (a non-manifold preview vertex).
    const std::string gyroid = "max(abs(sin(4.85574*x+4.5618)*cos(4.85574*y)+sin(4.85574*y+0.434688)*cos(4.85574*z)+"
                               "sin(4.85574*z+0.194331)*cos(4.85574*x))-0.0613163, sqrt(x^2+y^2+z^2)-0.843363)";
    // (At 0.0661 the mesh had it until DMC's bridging stopped closing a loop of 7 lattice steps:
    // its genus went from 8 to the shape's 7, and the saddle went. DMC gives it at 0.0604.)
    const Mesh m = dmcMesh(gyroid, 1.1, 0.0604);
    REQUIRE(checkTopology(m).closedManifoldOriented());
    const PatchResult r = patchesOf(m, Vec3d(0, 0, 1));
    std::size_t longEnds = 0;
    std::vector<std::uint32_t> saddles; // the nodes such ends pass through
    for (const Unit& u : r.graph.units) {
        longEnds += (u.bottomLobes.size() >= 3) + (u.topLobes.size() >= 3);
        if (u.bottomLobes.size() >= 3) saddles.push_back(u.lower);
        if (u.topLobes.size() >= 3) saddles.push_back(u.upper);
    }
    REQUIRE(longEnds >= 2);
    // The preview turns once round such a saddle (its first points are the graph's nodes), seen
    // along the axis, the surface's normal there: with the lobes' ends paired across the other
    // side's sectors the fans folded back (no turn at all) though the mesh stayed manifold.
    for (const std::uint32_t saddle : saddles) {
        const Vec3d s(r.preview.points[saddle]);
        double turn = 0;
        for (std::size_t t = 0; t < r.preview.polygonCount(); ++t) {
            const std::uint32_t* v = r.preview.polygon(t);
            for (int k = 0; k < 3; ++k) {
                if (v[k] != saddle) continue;
                const Vec3d a = Vec3d(r.preview.points[v[(k + 1) % 3]]) - s, b = Vec3d(r.preview.points[v[(k + 2) % 3]]) - s;
                turn += std::atan2(a.x * b.y - a.y * b.x, a.x * b.x + a.y * b.y);
            }
        }
        INFO("saddle node " << saddle);
        CHECK(std::abs(turn) / (2 * M_PI) == Approx(1.0).margin(1e-6));
    }
    const MeshTopology preview = checkTopology(r.preview);
    CHECK(preview.closedManifoldOriented());
    CHECK(preview.unusedVertices == 0);
    CHECK(long(r.preview.points.size()) - long(preview.edges) + long(r.preview.polygonCount()) == r.graph.eulerCharacteristic);
    checkJoins(r);
}

TEST_CASE("Open and non-manifold input is refused naming the problem", "[reeb]") {
    CHECK_THROWS_WITH(buildClosedSurface(test::openCubeMesh(), "open.obj"), Catch::Contains("open.obj") && Catch::Contains("open"));
    Mesh bowtie = test::octahedronMesh();
    // A second octahedron touching the first at one vertex: a non-manifold vertex.
    Mesh two = bowtie;
    const Vec3f top = bowtie.points[0];
    for (Vec3f p : bowtie.points) two.points.push_back(Vec3f(p.x, p.y, p.z) + (top - bowtie.points[1]) * 1.0f);
    const std::uint32_t n = std::uint32_t(bowtie.points.size());
    for (std::size_t f = 0; f < bowtie.polygonCount(); ++f) {
        std::vector<std::uint32_t> vs(bowtie.polygon(f), bowtie.polygon(f) + bowtie.polygonSize(f));
        for (std::uint32_t& v : vs) v = v == 1 ? 0 : v + n; // its vertex 1 lands on the first one's vertex 0
        two.addPolygon(vs.data(), vs.size());
    }
    CHECK_THROWS_WITH(buildClosedSurface(two, "two.obj"), Catch::Contains("two.obj") && Catch::Contains("non-manifold vertex"));
    CHECK_THROWS_WITH(makeHeightFunction(buildClosedSurface(bowtie, "o.obj"), Vec3d(0, 0, 0)), Catch::Contains("--axis"));
    // A direction in huge or tiny numbers is still that direction (its length overflowed to inf,
    // or underflowed to 0, and was refused as no direction).
    const ClosedSurface octahedron = buildClosedSurface(bowtie, "o.obj");
    const HeightFunction diagonal = makeHeightFunction(octahedron, Vec3d(1, 1, 0));
    CHECK(makeHeightFunction(octahedron, Vec3d(1e300, 1e300, 0)).rank == diagonal.rank);
    CHECK(makeHeightFunction(octahedron, Vec3d(1e300, 1e300, 0)).axis.x == Approx(diagonal.axis.x));
    CHECK(makeHeightFunction(octahedron, Vec3d(1e-320, 0, 0)).axis == Vec3d(1, 0, 0));
    CHECK_THROWS_WITH(makeHeightFunction(octahedron, Vec3d(std::nan(""), 1, 0)), Catch::Contains("--axis"));
    // The cube with its bottom face [0, 3, 2, 1] as two quads folded at a new vertex 8 between 0
    // and 2: closed and manifold, but vertex 8's two polygons run opposite ways round it.
    const Mesh cube = test::cubeMesh();
    Mesh folded;
    folded.points = cube.points;
    folded.points.push_back(Vec3f(0.5f, 0.5f, 0.0f));
    folded.addPolygon({0, 3, 2, 8});
    folded.addPolygon({0, 8, 2, 1});
    for (std::size_t f = 1; f < cube.polygonCount(); ++f) folded.addPolygon(cube.polygon(f), cube.polygonSize(f));
    CHECK_THROWS_WITH(buildClosedSurface(folded, "fold.obj"), Catch::Contains("fold.obj") && Catch::Contains("vertex 8 is a fold"));
}

TEST_CASE("A piece flat across the axis, or of one point, is refused naming it; the rest of the mesh does not matter", "[reeb][patches]") {
    // A torus beside a torus pressed flat to z = 0.2, and beside one whose every point is at one
    // position: closed and manifold, but the flat piece has no contours along z and the point
    // none at all. (The point piece made patches of nothing and blended sections towards the
    // origin; beside a piece a million times smaller its fit error's grid filled the memory.)
    const Mesh torus = test::quadTorusMesh(16, 8, 1.0, 0.3);
    const auto withPiece = [&](auto move) {
        Mesh two = torus;
        const auto n = std::uint32_t(torus.points.size());
        for (const Vec3f& p : torus.points) two.points.push_back(move(p));
        for (std::size_t f = 0; f < torus.polygonCount(); ++f) {
            std::vector<std::uint32_t> vs(torus.polygon(f), torus.polygon(f) + torus.polygonSize(f));
            for (std::uint32_t& v : vs) v += n;
            two.addPolygon(vs.data(), vs.size());
        }
        return two;
    };
    const Mesh flat = withPiece([](Vec3f p) { return Vec3f(p.x + 3, p.y, 0.2f); });
    const Mesh point = withPiece([](Vec3f) { return Vec3f(3, 3, 3); });
    const Mesh tiny = withPiece([](Vec3f p) { return p * 1e-6f + Vec3f(3, 0, 0); });
    const std::string first = "the piece of vertex " + std::to_string(torus.points.size()) + " (" + std::to_string(torus.points.size()) + " vertices)";
    CHECK_THROWS_WITH(patchesOf(flat, {0, 0, 1}), Catch::Contains("mesh: " + first + " lies flat across the height axis (0, 0, 1)") &&
                                                       Catch::Contains("every point at height 0.2") && Catch::Contains("choose another --axis"));
    CHECK_THROWS_WITH(patchesOf(point, {0, 0, 1}), Catch::Contains("mesh: " + first + " has every point at one position, (3, 3, 3)"));
    CHECK_THROWS_WITH(patchesOf(point, {1, 0, 0}), Catch::Contains("every point at one position"));
    // Along x the pressed torus spans heights: taken, both pieces fitted.
    const PatchResult across = patchesOf(flat, {1, 0, 0});
    CHECK(across.graph.units.size() >= 2);
    // A piece a million times smaller is no fault of its own: taken along z, its fit error measured.
    const PatchResult small = patchesOf(tiny, {0, 0, 1});
    CHECK(small.error.meanEdgeLength > 0);
    CHECK(small.error.rms < 0.5);
}

TEST_CASE("A quad whose opposite corners share an edge elsewhere is fanned across its other diagonal", "[reeb]") {
    // Every edge of the fanned mesh, with how many triangles use it.
    auto edgeUses = [](const Mesh& tris) {
        std::map<std::uint64_t, int> uses;
        for (std::size_t p = 0; p < tris.polygonCount(); ++p)
            for (std::uint32_t k = 0; k < 3; ++k) ++uses[undirectedEdgeKey(tris.polygon(p)[k], tris.polygon(p)[(k + 1) % 3])];
        return uses;
    };
    // A closed manifold sphere of six vertices: the quad [0, 1, 2, 3], and six triangles round
    // 4 and 5 on the other side, two of which share the edge 0-2 between the quad's opposite
    // corners (edge collapses in a thin part left such a pinch in a DMC mesh of random noise).
    // Fanned from vertex 0, the quad put that edge in four triangles and patches refused the mesh
    // as non-manifold.
    Mesh pinch;
    pinch.points = {Vec3f(0, 0, 0), Vec3f(1, 0, 0.2f), Vec3f(1, 1, 0), Vec3f(0, 1, 0.2f), Vec3f(0.8f, 0.2f, -0.6f), Vec3f(0.2f, 0.8f, -0.6f)};
    pinch.addPolygon({0, 1, 2, 3});
    for (const auto& t : std::vector<std::array<std::uint32_t, 3>>{{1, 0, 4}, {2, 1, 4}, {0, 2, 4}, {3, 2, 5}, {0, 3, 5}, {2, 0, 5}})
        pinch.addPolygon({t[0], t[1], t[2]});
    std::vector<std::uint32_t> polygonOf;
    const Mesh tris = fanIntoTriangles(pinch, &polygonOf);
    REQUIRE(tris.polygonCount() == 8);
    CHECK(polygonOf == std::vector<std::uint32_t>{0, 0, 1, 2, 3, 4, 5, 6});
    CHECK(std::vector<std::uint32_t>(tris.indices.begin(), tris.indices.begin() + 6) == std::vector<std::uint32_t>{1, 2, 3, 1, 3, 0});
    const std::map<std::uint64_t, int> uses = edgeUses(tris);
    CHECK(uses.size() == 12);
    for (const auto& [edge, n] : uses) CHECK(n == 2);
    const ClosedSurface surface = buildClosedSurface(pinch, "pinch.obj");
    CHECK(surface.vertex.size() == 24);
    // A diagonal fanned before counts as an edge too: two quads over the same four vertices.
    Mesh pillow;
    pillow.points = {Vec3f(0, 0, 0), Vec3f(1, 0, 0.5f), Vec3f(1, 1, 0), Vec3f(0, 1, 0.5f)};
    pillow.addPolygon({0, 1, 2, 3});
    pillow.addPolygon({2, 1, 0, 3});
    for (const auto& [edge, n] : edgeUses(fanIntoTriangles(pillow))) CHECK(n == 2);
    // Without such pinches every polygon is fanned from its first corner, as before.
    const Mesh cube = test::cubeMesh();
    const Mesh cubeTris = fanIntoTriangles(cube);
    REQUIRE(cubeTris.polygonCount() == 2 * cube.polygonCount());
    for (std::size_t p = 0; p < cube.polygonCount(); ++p) {
        CHECK(cubeTris.polygon(2 * p)[0] == cube.polygon(p)[0]);
        CHECK(cubeTris.polygon(2 * p + 1)[0] == cube.polygon(p)[0]);
    }
}

TEST_CASE("A mesh stored a point per polygon corner is merged where points coincide and gives the same patches", "[reeb][patches]") {
    // What a file written per corner, or split at texture seams, looks like: open along every
    // edge as given. Merged at equal positions it is the torus again; a hole stays refused.
    const Mesh m = dmcMesh(torusFormula(1.0, 0.35, Vec3d(0, 1, 0)), 1.5, 0.06);
    const Mesh perCorner = test::pointPerCorner(m);
    const PatchResult a = patchesOf(m, Vec3d(0, 0, 1)), b = patchesOf(perCorner, Vec3d(0, 0, 1));
    CHECK(a.surface.mergedPoints == 0);
    CHECK(b.surface.mergedPoints == m.indices.size() - m.points.size());
    checkGraph(b.graph, 1, 1, 2, 4, 1);
    CHECK(b.preview.indices == a.preview.indices);
    CHECK(b.preview.points == a.preview.points);
    REQUIRE(b.patches.patches.size() == a.patches.patches.size());
    for (std::size_t i = 0; i < a.patches.patches.size(); ++i) CHECK(b.patches.patches[i].surface.ctrl == a.patches.patches[i].surface.ctrl);
    // Each node's input vertex lies at its position (the first of the points merged there).
    for (std::size_t i = 0; i < b.graph.nodes.size(); ++i) {
        const Vec3f& p = perCorner.points[b.surface.inputVertex[b.graph.nodes[i].vertex]];
        CHECK(p == m.points[a.surface.inputVertex[a.graph.nodes[i].vertex]]);
    }

    Mesh holed;
    holed.points = perCorner.points;
    for (std::size_t f = 1; f < perCorner.polygonCount(); ++f) holed.addPolygon(perCorner.polygon(f), perCorner.polygonSize(f));
    CHECK_THROWS_WITH(buildClosedSurface(holed, "holed.ply"), Catch::Contains("holed.ply: the surface is open") && Catch::Contains("does not mend it"));
}

TEST_CASE("subCurve: an end a hair from a knot is cut at the knot, leaving no hair-thin span", "[reeb][bspline]") {
    // A patch's boundary is cut from a lobe curve at its seam, found as a fraction of a length:
    // it can land on a knot but for the last bits. The span of that hair, once the part is
    // mapped onto its share of u, rounded to nothing — a knot equal to the end, past the
    // degree — and the patch's knot merge failed with an internal error.
    BSplineCurve curve;
    curve.knots = clampedUniformKnots(12, 0.0, 1.0); // interior knots j / 9
    for (int i = 0; i < 12; ++i) curve.ctrl.push_back(Vec3d(std::cos(0.5 * i), std::sin(0.7 * i), 0.1 * i * i));
    const double knot = curve.knots[8]; // 5 / 9
    REQUIRE(knot == Approx(5.0 / 9.0));
    for (const auto& [a, b] : std::vector<std::pair<double, double>>{{0.0, std::nextafter(knot, 1.0)},
                                                                      {std::nextafter(knot, 0.0), 1.0},
                                                                      {0.2, knot + 1e-12},
                                                                      {knot - 1e-12, 0.9}}) {
        INFO("cut " << a << " .. " << b);
        const BSplineCurve part = subCurve(curve, a, b);
        const double span = part.end() - part.begin();
        REQUIRE(std::count(part.knots.begin(), part.knots.end(), part.begin()) == 4);
        REQUIRE(std::count(part.knots.begin(), part.knots.end(), part.end()) == 4);
        for (double k : part.knots)
            if (k != part.begin() && k != part.end()) CHECK(std::min(k - part.begin(), part.end() - k) > 1e-6 * span);
        // Still the curve itself over the part.
        for (int s = 0; s <= 20; ++s) {
            const double t = part.begin() + span * s / 20;
            CHECK(length(part.eval(t) - curve.eval(t)) < 1e-12);
        }
        // Mapped onto a sliver of u and joined to the rest, as a patch's end curve is, then
        // refined to the knots it shares with another curve over the same u.
        const BSplineCurve mapped = reparameterized(part, 0.999, 1.0);
        const BSplineCurve end = joined({reparameterized(curve, 0.0, 0.999), mapped});
        const BSplineCurve other = reparameterized(curve, 0.0, 1.0);
        const std::vector<double> merged = mergeKnots(end.knots, other.knots);
        CHECK_NOTHROW(refineTo(end, merged));
        CHECK_NOTHROW(refineTo(other, merged));
    }
}

namespace {

// How many triangles use each undirected edge.
std::map<std::uint64_t, int> edgeUses(const std::vector<std::uint32_t>& tris) {
    std::map<std::uint64_t, int> uses;
    for (std::size_t t = 0; t < tris.size(); t += 3)
        for (int k = 0; k < 3; ++k) ++uses[undirectedEdgeKey(tris[t + k], tris[t + (k + 1) % 3])];
    return uses;
}

std::vector<RowVertex> uniformRow(std::uint32_t first, int n) { // closes on its first vertex
    std::vector<RowVertex> row;
    for (int i = 0; i < n; ++i) row.push_back({first + std::uint32_t(i), double(i) / n});
    row.push_back({first, 1.0});
    return row;
}

} // namespace

TEST_CASE("zipRows: a row passing twice through a saddle around a narrow lobe stays manifold", "[reeb][patches]") {
    // An end row (vertices 100…): seam vertex 100, the saddle 102 before and after a lobe far
    // narrower in u than the interior row's spacing (1/8), as a unit's end with a tiny second
    // contour has. Each pass through the saddle must fan to its own vertices of the other row.
    const std::vector<RowVertex> end{{100, 0.0},    {101, 0.3},    {102, 0.5},   {103, 0.5001},
                                     {104, 0.5002}, {102, 0.5003}, {105, 0.8},   {100, 1.0}};
    const std::vector<RowVertex> inner = uniformRow(0, 8);
    for (bool endBelow : {false, true}) {
        INFO((endBelow ? "end row below" : "end row above"));
        std::vector<std::uint32_t> tris;
        if (endBelow) zipRows(end, inner, tris);
        else zipRows(inner, end, tris);
        CHECK(tris.size() == 3 * (inner.size() - 1 + end.size() - 1)); // one triangle per step, none degenerate
        for (const auto& [key, n] : edgeUses(tris)) {
            INFO("edge " << (key >> 32) << "-" << (key & 0xffffffffu));
            CHECK(n <= 2);
        }
        // Every edge along a row borders one triangle here (the next zip gives its other).
        const auto uses = edgeUses(tris);
        for (const auto& row : {end, inner})
            for (std::size_t k = 0; k + 1 < row.size(); ++k) CHECK(uses.at(undirectedEdgeKey(row[k].id, row[k + 1].id)) == 1);
    }
}

TEST_CASE("zipRows: a pole fans to every vertex of the row once", "[reeb][patches]") {
    const std::vector<RowVertex> pole{{50, 0.0}, {50, 1.0}};
    const std::vector<RowVertex> inner = uniformRow(0, 8);
    std::vector<std::uint32_t> tris;
    zipRows(inner, pole, tris);
    REQUIRE(tris.size() == 3 * 8);
    for (std::size_t t = 0; t < tris.size(); t += 3) {
        CHECK(tris[t] == std::uint32_t(t / 3));
        CHECK(tris[t + 1] == std::uint32_t((t / 3 + 1) % 8));
        CHECK(tris[t + 2] == 50);
    }
}

