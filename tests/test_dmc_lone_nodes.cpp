// Lone nodes at a grid's own voxel size: joined to the inside across a face whose bilinear saddle
// is inside, and only there, changing nothing else about the mesh's topology.
#include "support/test_support.h"

#include "vdbsurf/core/threads.h"
#include "vdbsurf/dmc/inside_topology.h"
#include "vdbsurf/dmc/lone_nodes.h"
#include "vdbsurf/dmc/mesher.h"
#include "vdbsurf/field/grid_field.h"
#include "vdbsurf/mesh/mesh_check.h"

#include <catch2/catch.hpp>
#include <openvdb/openvdb.h>

#include <initializer_list>

using namespace vdbsurf;

namespace {

Mesh meshGrid(const GridBasePtr& grid, MeshMethod method, MeshReport& report) {
    const GridField field(grid, "post");
    MeshRequest request;
    request.method = method;
    return meshField(field, request, report);
}

} // namespace

TEST_CASE("a node alone inside joins the inside across a face whose saddle is inside") {
    for (const bool fog : {false, true}) {
        INFO((fog ? "fog" : "level set"));
        // Saddle (gn gd - ga gb) / (gn - ga - gb + gd) = (1 - 0.25) / -3: inside.
        MeshReport mcReport, dmcReport;
        const Mesh mc = meshGrid(test::loneNodeBesidePost(0.5f, fog), MeshMethod::MarchingCubes, mcReport);
        CHECK(countComponents(mc) == 2); // marching cubes: the node's bubble beside the rest
        const Mesh dmc = meshGrid(test::loneNodeBesidePost(0.5f, fog), MeshMethod::Dmc, dmcReport);
        CHECK(dmcReport.thinLoneJoined == 1);
        CHECK(checkTopology(dmc).closedManifoldOriented());
        CHECK(test::piecesWithoutHandles(dmc, 1));
        {
            ThreadLimit one(1);
            MeshReport r;
            const Mesh serial = meshGrid(test::loneNodeBesidePost(0.5f, fog), MeshMethod::Dmc, r);
            CHECK(serial.points == dmc.points);
            CHECK(serial.indices == dmc.indices);
        }
        // Saddle (1 - 4) / -6: outside. The grid's field keeps the node apart, and so does DMC.
        MeshReport apartReport;
        const Mesh apart = meshGrid(test::loneNodeBesidePost(2.0f, fog), MeshMethod::Dmc, apartReport);
        CHECK(apartReport.thinLoneJoined == 0);
        CHECK(test::piecesWithoutHandles(apart, 2));
    }
}

TEST_CASE("a lone node's join goes through the face corner that closes no handle") {
    // An arm from the slab ends beside corner a: put inside, a would join the post's top and
    // the arm, which meet through the slab, a handle. Corner b joins the node alone.
    const auto grid = test::loneNodeBesidePost(0.5f, false, {{8, 10, 7}, {8, 11, 7}, {8, 12, 7}, {8, 12, 6}, {8, 12, 5}});
    MeshReport report;
    const Mesh dmc = meshGrid(grid, MeshMethod::Dmc, report);
    CHECK(report.thinLoneJoined == 1);
    CHECK(checkTopology(dmc).closedManifoldOriented());
    CHECK(test::piecesWithoutHandles(dmc, 1));
}

namespace {

constexpr int kLoneAtMinusX = 12; // offset (-1, 0, 0)
constexpr int kLoneAtMinusY = 10; // offset (0, -1, 0)

} // namespace

TEST_CASE("the centre of a block joins a lone node only where it changes nothing else") {
    // Its other inside neighbour joined to a layer below: one piece, joined as a bubble.
    auto b = test::insideBlock({{-1, 0, 0}, {1, 0, 0}, {0, 0, -1}, {1, 0, -1}, {0, 1, -1}, {1, 1, -1}, {0, -1, -1}, {1, -1, -1}});
    CHECK(joinsBubbleOnly(b.data(), kLoneAtMinusX));
    // Inside neighbours in two pieces of the block: they may meet beyond it (a handle).
    b = test::insideBlock({{-1, 0, 0}, {0, 1, 0}, {0, -1, 0}});
    CHECK_FALSE(joinsBubbleOnly(b.data(), kLoneAtMinusX));
    // Two pieces, though the Euler characteristic alone would pass the join (found by a search
    // over random blocks: 343 of 200,000).
    b = test::insideBlock({{-1, -1, -1}, {1, -1, -1}, {0, 0, -1}, {0, 1, -1}, {0, -1, 0}, {1, -1, 0}, {-1, 0, 0}, {1, 0, 0}, {1, 1, 0},
               {0, -1, 1}, {1, -1, 1}, {0, 0, 1}, {-1, 1, 1}, {0, 1, 1}, {1, 1, 1}});
    CHECK_FALSE(joinsBubbleOnly(b.data(), kLoneAtMinusX));
    // One piece that goes round the edge to (1, 0, 0), outside: the centre would close a loop
    // round it.
    b = test::insideBlock({{-1, 0, 0}, {0, 1, 0}, {1, 1, 0}, {1, 1, 1}, {1, 0, 1}, {1, -1, 1}, {1, -1, 0}, {0, -1, 0}});
    CHECK_FALSE(joinsBubbleOnly(b.data(), kLoneAtMinusX));
    // Six of a cell's corners round two opposite ones outside, (0, 1, 0) and (1, 0, 1), with the
    // centre: marching cubes fills the cell between them (no loop), so the join is clean.
    b = test::insideBlock({{0, -1, 0}, {1, 0, 0}, {1, 1, 0}, {0, 0, 1}, {0, 1, 1}, {1, 1, 1}});
    CHECK(joinsBubbleOnly(b.data(), kLoneAtMinusY));
    // The node is not inside, or not across a face: nothing to join.
    b = test::insideBlock({{1, 0, 0}});
    CHECK_FALSE(joinsBubbleOnly(b.data(), kLoneAtMinusX));
    b = test::insideBlock({{-1, -1, 0}, {1, 0, 0}});
    CHECK_FALSE(joinsBubbleOnly(b.data(), 9 + 0 + 0)); // offset (-1, -1, 0)
}

TEST_CASE("putting a node inside changes the inside's Euler characteristic as its topology says") {
    // Alone: a new piece, a ball.
    CHECK(insideEulerChange(test::insideBlock({}).data()) == 1);
    CHECK(insidePiecesAtCentre(test::insideBlock({}).data()) == 0);
    // On a layer: the layer grows, nothing else.
    const auto layer = test::insideBlock(
        {{-1, -1, -1}, {0, -1, -1}, {1, -1, -1}, {-1, 0, -1}, {0, 0, -1}, {1, 0, -1}, {-1, 1, -1}, {0, 1, -1}, {1, 1, -1}});
    CHECK(insideEulerChange(layer.data()) == 0);
    CHECK(insidePiecesAtCentre(layer.data()) == 1);
    // Between two nodes across from each other: two pieces joined.
    const auto two = test::insideBlock({{-1, 0, 0}, {1, 0, 0}});
    CHECK(insideEulerChange(two.data()) == -1);
    CHECK(insidePiecesAtCentre(two.data()) == 2);
    // Between two nodes of an arc round an edge the centre lies on: a loop closed, one piece.
    const auto arc = test::insideBlock({{-1, 0, 0}, {-1, 1, 0}, {-1, 1, 1}, {0, 1, 1}, {1, 1, 1}, {1, 1, 0}, {1, 0, 0}});
    CHECK(insidePiecesAtCentre(arc.data()) == 1);
    CHECK(insideEulerChange(arc.data()) == -1);
    // In the middle of a ring of eight in its plane: the ring's hole filled.
    const auto ring = test::insideBlock({{-1, -1, 0}, {0, -1, 0}, {1, -1, 0}, {-1, 0, 0}, {1, 0, 0}, {-1, 1, 0}, {0, 1, 0}, {1, 1, 0}});
    CHECK(insidePiecesAtCentre(ring.data()) == 1);
    CHECK(insideEulerChange(ring.data()) == 1);
    // In a cavity of a solid: the cavity filled.
    std::array<bool, 27> solid;
    solid.fill(true);
    CHECK(insidePiecesAtCentre(solid.data()) == 1);
    CHECK(insideEulerChange(solid.data()) == -1);
    // Leaving a node out of the pieces: the one beside it no longer counts.
    CHECK(insidePiecesAtCentre(two.data(), kLoneAtMinusX) == 1);
}
