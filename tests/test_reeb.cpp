// Reeb graph, units, ring grids and B-spline patches (seed 004) on DMC meshes of shapes whose
// topology is known.
#include "support/shapes.h"
#include "support/test_support.h"

#include "vdbsurf/core/error.h"
#include "vdbsurf/dmc/mesher.h"
#include "vdbsurf/field/expression_field.h"
#include "vdbsurf/mesh/mesh_check.h"
#include "vdbsurf/reeb/reeb_graph.h"

#include <catch2/catch.hpp>

#include <cmath>

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

ReebGraph reebOf(const Mesh& mesh, const Vec3d& axis, double persistence) {
    const ClosedSurface s = buildClosedSurface(mesh, "mesh");
    HeightFunction f = makeHeightFunction(s, axis);
    simplifyExtrema(s, f, persistence * s.meanEdgeLength());
    return buildReebGraph(s, f);
}

void checkGraph(const ReebGraph& g, std::size_t nodes, std::size_t arcs, std::size_t loops) {
    INFO("minima " << g.minima << " maxima " << g.maxima << " saddles " << g.saddles << " units " << g.units.size());
    CHECK(g.nodes.size() == nodes);
    CHECK(g.units.size() == arcs);
    CHECK(g.loops() == loops);
}

} // namespace

TEST_CASE("Reeb graph of a sphere: a minimum, a maximum and one arc", "[reeb]") {
    const Mesh m = dmcMesh("sqrt(x*x+y*y+z*z)-1", 1.3, 0.1);
    const ReebGraph g = reebOf(m, Vec3d(0, 0, 1), 0.5);
    checkGraph(g, 2, 1, 0);
}

TEST_CASE("Reeb graph of an upright torus: 4 nodes, 4 arcs, one loop", "[reeb]") {
    const Mesh m = dmcMesh(torusFormula(1.0, 0.35, Vec3d(0, 1, 0)), 1.5, 0.06);
    const ReebGraph g = reebOf(m, Vec3d(0, 0, 1), 0.5);
    checkGraph(g, 4, 4, 1);
}

#include "vdbsurf/reeb/patch_fit.h"

TEST_CASE("Patches of a torus join without gaps", "[reeb][patches]") {
    const Mesh m = dmcMesh(torusFormula(1.0, 0.35, Vec3d(0, 1, 0.3)), 1.5, 0.06);
    const ReebGraph g = reebOf(m, Vec3d(0, 0, 1), 0.5);
    const PatchSet set = fitPatches(g, ringGrids(g));
    CHECK(maxJoinGap(set) < 1e-9);
    for (const UnitPatch& p : set.patches) {
        INFO("U " << p.grid.U << " V " << p.grid.V << " nu " << p.surface.nu << " nv " << p.surface.nv << " pieces " << p.boundary.size());
        CHECK(p.grid.points.size() == std::size_t(p.grid.U * p.grid.V));
        double err = 0;
        for (int v = 0; v < p.grid.V; ++v)
            for (int u = 0; u < p.grid.U; ++u)
                err = std::max(err, length(p.surface.eval(double(u) / p.grid.U, double(v) / (p.grid.V - 1)) - p.grid.at(u, v)));
        CHECK(err < 0.05);
    }
}
