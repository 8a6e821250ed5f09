// The sharp pass's topology checks: a node placed on a sharp feature is a vertex where the
// crossings of its edges are welded, placed only where that weld leaves the surface's topology
// around it as it was; and flips whose bridges change the inside's Euler characteristic are undone
// (insideEulerAround counts it over the lattice).
#include "support/formula_text.h"
#include "support/test_support.h"

#include "vdbsurf/dmc/inside_topology.h"
#include "vdbsurf/dmc/mesher.h"
#include "vdbsurf/field/expression_field.h"
#include "vdbsurf/field/grid_field.h"
#include "vdbsurf/mesh/mesh_check.h"
#include "vdbsurf/mesh/mesh_to_vdb.h"
#include "vdbsurf/vdb/vdb_file.h"

#include <catch2/catch.hpp>

#include <array>
#include <cmath>
#include <initializer_list>
#include <cstdlib>
#include <random>
#include <string>
#include <vector>

using namespace vdbsurf;
using test::num;

namespace {


std::array<bool, 27> blockFromBits(std::uint32_t bits) {
    std::array<bool, 27> b{};
    for (std::size_t k = 0; k < 27; ++k) b[k] = (bits >> k) & 1u;
    return b;
}

} // namespace

TEST_CASE("welding a node's crossings into it keeps the surface's topology unless it cuts a tube") {
    // A row of inside nodes through the centre (a wire): marching cubes' surface is a tube round
    // it; welded into the centre it becomes two cones that meet there, split apart by the weld.
    const auto wire = test::insideBlock({{-1, 0, 0}, {0, 0, 0}, {1, 0, 0}});
    CentreWeld w = weldAtCentre(wire.data());
    CHECK(w.before == PatchTopology{1, 0});
    CHECK(w.after == PatchTopology{2, 2});
    CHECK_FALSE(w.keepsTopology());
    // The same with a second row across a face diagonal, which marching cubes never joins to
    // the first (a wedge's thin edge beside its solid: the case found, 1 of 70 random wedges).
    const auto wedgeEdge = test::insideBlock({{-1, 0, 0}, {0, 0, 0}, {1, 0, 0}, {-1, -1, 1}, {0, -1, 1}, {1, -1, 1}});
    CHECK_FALSE(weldAtCentre(wedgeEdge.data()).keepsTopology());
    // The tip of that row: a cap, welded into a cone. Nothing cut.
    const auto tip = test::insideBlock({{0, 0, 0}, {1, 0, 0}});
    w = weldAtCentre(tip.data());
    CHECK(w.before == PatchTopology{1, 1});
    CHECK(w.keepsTopology());
    // On a flat layer: one crossing, its four quads a disc before and after.
    const auto layer = test::insideBlock({{-1, -1, -1}, {0, -1, -1}, {1, -1, -1}, {-1, 0, -1}, {0, 0, -1}, {1, 0, -1},
                                          {-1, 1, -1}, {0, 1, -1}, {1, 1, -1}, {-1, -1, 0}, {0, -1, 0}, {1, -1, 0},
                                          {-1, 0, 0}, {0, 0, 0}, {1, 0, 0}, {-1, 1, 0}, {0, 1, 0}, {1, 1, 0}});
    w = weldAtCentre(layer.data());
    CHECK(w.before == PatchTopology{1, 1});
    CHECK(w.keepsTopology());
    // Outside, in a gap one node wide between two walls: the walls' sheets are made to touch at
    // the node, two discs before and two fans after.
    std::array<bool, 27> gap{};
    for (std::size_t k = 0; k < 27; ++k) gap[k] = k % 3 != 1;
    w = weldAtCentre(gap.data());
    CHECK(w.before == PatchTopology{2, 2});
    CHECK(w.keepsTopology());
    // A notch's concave corner, outside, where the gap's walls meet round the node through the
    // cells beside it (one piece before, found in a test's notch): the weld only makes the two
    // sides touch, and the corner is kept.
    CHECK(weldAtCentre(blockFromBits(0x6be5baeu).data()).keepsTopology());
    // No crossing at the centre: nothing before or after.
    std::array<bool, 27> solid;
    solid.fill(true);
    w = weldAtCentre(solid.data());
    CHECK(w.before == PatchTopology{0, 0});
    CHECK(w.keepsTopology());
}

TEST_CASE("the inside's Euler characteristic around changed nodes changes as the inside's topology does") {
    // One node: the same change as the block count gives, for random blocks.
    std::mt19937 rng(77);
    std::bernoulli_distribution coin(0.5);
    for (int trial = 0; trial < 500; ++trial) {
        std::array<bool, 27> b{};
        for (bool& v : b) v = coin(rng);
        auto side = [&](bool centre) {
            return [&b, centre](const Vec3i& n) {
                if (n == Vec3i(0, 0, 0)) return centre;
                if (std::abs(n.x) > 1 || std::abs(n.y) > 1 || std::abs(n.z) > 1) return false;
                return b[std::size_t((n.x + 1) + 3 * (n.y + 1) + 9 * (n.z + 1))];
            };
        };
        const std::vector<Vec3i> centre{Vec3i(0, 0, 0)};
        INFO("trial " << trial);
        CHECK(insideEulerAround(centre, side(false)) - insideEulerAround(centre, side(true)) == insideEulerChange(b.data()));
    }
    // Two nodes that close a ring of eight round an outside node: a handle, one lower (the
    // compactly supported count is the inside's own, negated: +1).
    auto ring = [](bool closed) {
        return [closed](const Vec3i& n) {
            if (n.z != 0 || std::abs(n.x) > 1 || std::abs(n.y) > 1 || n == Vec3i(0, 0, 0)) return false;
            return closed || n.y != -1 || n.x == -1;
        };
    };
    const std::vector<Vec3i> gap{Vec3i(0, -1, 0), Vec3i(1, -1, 0)};
    CHECK(insideEulerAround(gap, ring(true)) - insideEulerAround(gap, ring(false)) == 1);
}

TEST_CASE("pieces in a box are counted as marching cubes joins each side") {
    // A row with one node outside: two inside pieces, one outside.
    auto row = [](const Vec3i& n) { return n.x != 2; };
    CHECK(piecesInBox(Vec3i(0, 0, 0), Vec3i(4, 0, 0), true, row) == 2);
    CHECK(piecesInBox(Vec3i(0, 0, 0), Vec3i(4, 0, 0), false, row) == 1);
    // Two inside nodes across a face's diagonal: apart; the two outside ones there: joined.
    auto diagonal = [](const Vec3i& n) { return n.x == n.y; };
    CHECK(piecesInBox(Vec3i(0, 0, 0), Vec3i(1, 1, 0), true, diagonal) == 2);
    CHECK(piecesInBox(Vec3i(0, 0, 0), Vec3i(1, 1, 0), false, diagonal) == 1);
    // Across a cell's diagonal the outside is apart too.
    auto corners = [](const Vec3i& n) { return !(n == Vec3i(0, 0, 0) || n == Vec3i(1, 1, 1)); };
    CHECK(piecesInBox(Vec3i(0, 0, 0), Vec3i(1, 1, 1), false, corners) == 2);
}

namespace {

struct Wedge {
    Vec3d n1, n2, back, c;
    double h;
    // Two planes meeting at an acute edge through c, cut off behind at 0.6 and round at 0.8.
    std::string formula() const {
        return "max(" + test::dotWith(n1, c) + ", " + test::dotWith(n2, c) + ", -" + test::dotWith(back, c) + "-0.6, sqrt((x-" + num(c.x) +
               ")^2+(y-" + num(c.y) + ")^2+(z-" + num(c.z) + ")^2)-0.8)";
    }
};

// The wedge meshed, written as a level set at the spacing (as `vdbsurf mesh -o w.vdb` writes
// it), read back and meshed at its own voxel size.
Mesh meshWedgeLevelSet(const Wedge& wedge, MeshMethod method, const test::TempDir& dir, MeshReport& report) {
    const Box3 box{{-1, -1, -1}, {1, 1, 1}};
    const ExpressionField formula(wedge.formula(), box);
    MeshRequest request;
    request.voxelSize = wedge.h;
    MeshReport formulaReport;
    const Mesh source = meshField(formula, request, formulaReport);
    LevelSetWriteOptions options;
    options.voxelSize = wedge.h;
    writeMeshAsLevelSet(dir.path("wedge.vdb"), source, options);
    const LoadedGrid grid = readScalarGrid(dir.path("wedge.vdb"), "surface");
    const GridField field(grid.grid, grid.source);
    MeshRequest own;
    own.method = method;
    return meshField(field, own, report);
}

Vec3d unitFrom(std::mt19937& rng) {
    std::normal_distribution<double> g;
    for (;;) {
        const Vec3d v(g(rng), g(rng), g(rng));
        if (length(v) > 1e-3) return normalized(v);
    }
}

} // namespace

TEST_CASE("a wedge's thin edge is not cut off where the sharp pass places a node on it") {
    // Found at random (a wedge of 27 degrees as a level set, meshed at its voxel size): a row of
    // inside nodes along the thin edge, joined to the solid beyond one node only along the row,
    // came off as a piece of 14 vertices once that node was placed on the edge (marching cubes
    // and volumeToMesh: one piece; --no-sharp: one piece).
    const Wedge wedge{{-0.034893691476265414, -0.63105969621937, -0.7749490887165916},
                      {0.01018157009468315, 0.9130781652881812, 0.4076574538805541},
                      {-0.05328955225176496, 0.6081484349864797, -0.7920326411482685},
                      {0.001377166318763702, 0.04524673882682695, 0.007779480780120307},
                      0.07295658659553342};
    test::TempDir dir;
    MeshReport report;
    const Mesh dmc = meshWedgeLevelSet(wedge, MeshMethod::Dmc, dir, report);
    CHECK(checkTopology(dmc).closedManifoldOriented());
    CHECK(report.nodesOnEdges > 0);
    CHECK(test::piecesWithoutHandles(dmc, 1));
}

TEST_CASE("random wedges as level sets: DMC leaves no more pieces than marching cubes") {
    // Acute wedges at their own voxel size leave nodes alone inside beside the edge; DMC joins
    // those it can and must not cut the edge's thin rows off where it places feature nodes
    // (trial 8 here, before the weld's topology was checked: 2 pieces, marching cubes 1).
    std::mt19937 rng(4);
    std::uniform_real_distribution<double> angle(20, 60), shift(-0.05, 0.05), spacing(0.05, 0.1);
    test::TempDir dir;
    for (int trial = 0; trial < 12; ++trial) {
        const double a = angle(rng) * 3.14159265358979323846 / 180;
        const Vec3d e = unitFrom(rng);
        Vec3d side = unitFrom(rng);
        side = normalized(side - e * dot(side, e));
        const Vec3d across = cross(e, side);
        Wedge wedge{side * std::sin(a / 2) + across * std::cos(a / 2), side * std::sin(a / 2) - across * std::cos(a / 2), side,
                    Vec3d(shift(rng), shift(rng), shift(rng)), spacing(rng)};
        INFO("trial " << trial << ": " << wedge.formula() << " at " << num(wedge.h));
        MeshReport dmcReport, mcReport;
        const Mesh dmc = meshWedgeLevelSet(wedge, MeshMethod::Dmc, dir, dmcReport);
        const Mesh mc = meshWedgeLevelSet(wedge, MeshMethod::MarchingCubes, dir, mcReport);
        CHECK(checkTopology(dmc).closedManifoldOriented());
        CHECK(countComponents(dmc) <= countComponents(mc));
    }
}
