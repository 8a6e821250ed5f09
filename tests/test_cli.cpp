// The command line as a user meets it: info, mesh, and one clear error per kind of bad input,
// with a non-zero exit and no output file left behind.
#include "support/test_support.h"

#include "support/shapes.h"
#include "vdbsurf/core/threads.h"
#include "vdbsurf/mesh/mesh_check.h"
#include "vdbsurf/mesh/mesh_io.h"
#include "vdbsurf/reeb/bspline.h"
#include "vdbsurf/vdb/vdb_file.h"

#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>
#include <openvdb/openvdb.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

using namespace vdbsurf;
using test::runVdbsurf;

namespace {

void writeSphereFile(const std::string& path, double voxel = 0.05) {
    auto g = test::makeSphereLevelSet(1.0, {0, 0, 0}, voxel);
    g->setName("ls_sphere");
    test::writeGrids(path, {g});
}

// A failed run: non-zero exit, the message names `input` and says `what`, nothing written.
void expectFailure(const test::TempDir& dir, const std::vector<std::string>& args, const std::string& input,
                   const std::string& what, const std::vector<std::string>& filesBefore) {
    const auto r = runVdbsurf(args);
    INFO(r.output);
    CHECK(r.exitCode != 0);
    CHECK(r.exitCode != 70); // not an internal error
    CHECK(r.output.find(input) != std::string::npos);
    CHECK(r.output.find(what) != std::string::npos);
    CHECK(r.output.find("error") != std::string::npos);
    CHECK(dir.files() == filesBefore);
}

} // namespace

TEST_CASE("info lists each grid with type, class, voxel size, count and bounds") {
    test::TempDir dir;
    initializeOpenVdb();
    auto ls = test::makeSphereLevelSet(1.0, {0, 0, 0}, 0.1);
    ls->setName("ls");
    auto fog = test::makeSphereFog(0.5, 0.2, 0.1);
    auto vec = openvdb::Vec3SGrid::create();
    vec->setName("vel");
    vec->tree().setValue({0, 0, 0}, openvdb::Vec3s(1, 0, 0));
    test::writeGrids(dir.path("multi.vdb"), {ls, fog, vec});
    const auto r = runVdbsurf({"info", dir.path("multi.vdb")});
    INFO(r.output);
    REQUIRE(r.exitCode == 0);
    CHECK(r.output.find("3 grids") != std::string::npos);
    CHECK(r.output.find("level set") != std::string::npos);
    CHECK(r.output.find("fog") != std::string::npos);
    CHECK(r.output.find("vec3s") != std::string::npos);
    CHECK(r.output.find("0.1") != std::string::npos);
    CHECK(r.output.find(std::to_string(ls->activeVoxelCount())) != std::string::npos);
    const auto j = runVdbsurf({"-q", "info", "--json", dir.path("multi.vdb")});
    REQUIRE(j.exitCode == 0);
    const auto doc = nlohmann::json::parse(j.output);
    REQUIRE(doc["grids"].size() == 3);
    std::map<std::string, nlohmann::json> byName;
    for (const auto& g : doc["grids"]) byName[g["name"].get<std::string>()] = g;
    REQUIRE(byName.count("ls") == 1);
    CHECK(byName["ls"]["class"] == "level set");
    CHECK(byName["ls"]["active_voxels"] == ls->activeVoxelCount());
    // Narrow band of 3 voxels around r = 1, plus half a voxel: the voxels' extent.
    CHECK(byName["ls"]["world_bbox"][1][0].get<double>() == Approx(1.0 + 3 * 0.1 + 0.05).margin(0.11));
    CHECK(byName["density"]["class"] == "fog");
    CHECK(byName["vel"]["meshable"] == false);
    CHECK(byName["vel"]["type"] == "vec3s");
}

TEST_CASE("mesh writes OBJ, PLY and VDB, says what it chose, and writes stats") {
    test::TempDir dir;
    writeSphereFile(dir.path("s.vdb"));
    const auto r = runVdbsurf({"mesh", dir.path("s.vdb"), "-o", dir.path("s.obj"), "--stats", dir.path("s.json")});
    INFO(r.output);
    REQUIRE(r.exitCode == 0);
    CHECK(r.output.find("using grid 'ls_sphere'") != std::string::npos);
    CHECK(r.output.find("iso 0 (default for level sets") != std::string::npos);
    const auto stats = nlohmann::json::parse(test::readFile(dir.path("s.json")));
    for (const char* key : {"vertices", "triangles", "quads", "threads", "seconds", "lattice"}) CHECK(stats.contains(key));
    CHECK(stats["lattice"]["cells_visited"].get<long>() > 0);
    CHECK(stats["seconds"].contains("lattice"));
    CHECK(stats["seconds"].contains("mesh"));
    CHECK(stats["vertices"].get<long>() > 1000);

    REQUIRE(runVdbsurf({"-q", "mesh", dir.path("s.vdb"), "-o", dir.path("s.ply")}).exitCode == 0);
    CHECK(test::readFile(dir.path("s.ply")).rfind("ply\n", 0) == 0);
    REQUIRE(runVdbsurf({"-q", "mesh", dir.path("s.vdb"), "-o", dir.path("back.vdb"), "--voxel-size", "0.08"}).exitCode == 0);
    const auto info = runVdbsurf({"-q", "info", "--json", dir.path("back.vdb")});
    REQUIRE(info.exitCode == 0);
    const auto doc = nlohmann::json::parse(info.output);
    CHECK(doc["grids"][0]["class"] == "level set");
    CHECK(doc["grids"][0]["voxel_size"][0].get<double>() == Approx(0.08));

    const auto e = runVdbsurf({"mesh", "--expr", "x^2+y^2+z^2-1", "--bbox", "-2,-2,-2,2,2,2", "--voxel-size", "0.1", "-o",
                               dir.path("e.obj")});
    INFO(e.output);
    CHECK(e.exitCode == 0);
    CHECK(test::fileExists(dir.path("e.obj")));

    // A wire a third of a cell thick: its thin part simplified by default, every polygon kept
    // with --no-simplify; the note and the stats say so.
    const std::vector<std::string> wire = {"mesh", "--expr", "sqrt((y-0.013)^2+(z+0.021)^2)-0.015 + max(abs(x)-0.6, 0)",
                                           "--bbox", "-1,-1,-1,1,1,1", "--voxel-size", "0.1"};
    auto withArgs = [&](std::vector<std::string> extra) {
        std::vector<std::string> a = wire;
        a.insert(a.end(), extra.begin(), extra.end());
        return a;
    };
    const auto ws = runVdbsurf(withArgs({"-o", dir.path("wire.obj"), "--stats", dir.path("wire.json")}));
    const auto wk = runVdbsurf(withArgs({"-o", dir.path("wire_all.obj"), "--no-simplify", "--stats", dir.path("wire_all.json")}));
    INFO(ws.output << wk.output);
    REQUIRE(ws.exitCode == 0);
    REQUIRE(wk.exitCode == 0);
    CHECK(ws.output.find("thin parts simplified") != std::string::npos);
    CHECK(wk.output.find("thin parts simplified") == std::string::npos);
    const auto sj = nlohmann::json::parse(test::readFile(dir.path("wire.json")));
    const auto kj = nlohmann::json::parse(test::readFile(dir.path("wire_all.json")));
    CHECK(sj["dmc"]["simplify_collapses"].get<long>() > 0);
    CHECK(kj["dmc"]["simplify_collapses"].get<long>() == 0);
    CHECK(kj["dmc"]["simplify_thin"] == false);
    CHECK(sj["triangles"].get<long>() + 2 * sj["quads"].get<long>() < kj["triangles"].get<long>() + 2 * kj["quads"].get<long>());
    CHECK(sj["seconds"].contains("simplify"));
}

TEST_CASE("mesh says when its float coordinates are too coarse for the cells, far from the origin") {
    // Every mesh file holds float32 points (as volumeToMesh's are): 200,000 units out they step by
    // 1/64, a sixth of a 0.1 cell, and geo-referenced data lies there. The same sphere at the
    // origin gets no such note; both are meshed.
    test::TempDir dir;
    auto sphereAt = [&](double x, const std::string& out) {
        const std::string c = std::to_string(x);
        return runVdbsurf({"mesh", "--expr", "(x-" + c + ")^2+y^2+z^2-1", "--bbox",
                           std::to_string(x - 2) + ",-2,-2," + std::to_string(x + 2) + ",2,2", "--voxel-size", "0.1", "-o",
                           dir.path(out), "--stats", dir.path(out + ".json")});
    };
    const auto far = sphereAt(200000, "far.obj"), near = sphereAt(0, "near.obj");
    INFO(far.output << near.output);
    REQUIRE(far.exitCode == 0);
    REQUIRE(near.exitCode == 0);
    CHECK(far.output.find("float coordinates") != std::string::npos);
    CHECK(far.output.find("step by 0.015625") != std::string::npos);
    CHECK(near.output.find("float coordinates") == std::string::npos);
    const auto j = nlohmann::json::parse(test::readFile(dir.path("far.obj.json")));
    CHECK(j["coordinates"]["float_step"].get<double>() == 0.015625);
    CHECK(j["coordinates"]["world_spacing"].get<double>() == Approx(0.1));
}

TEST_CASE("the same input at 1 and 2 threads gives byte-identical files") {
    test::TempDir dir;
    writeSphereFile(dir.path("s.vdb"), 0.03);
    REQUIRE(runVdbsurf({"-q", "mesh", dir.path("s.vdb"), "-o", dir.path("a.obj"), "--threads", "1"}).exitCode == 0);
    REQUIRE(runVdbsurf({"-q", "mesh", dir.path("s.vdb"), "-o", dir.path("b.obj"), "--threads", "2"}).exitCode == 0);
    const std::string a = test::readFile(dir.path("a.obj")), b = test::readFile(dir.path("b.obj"));
    CHECK(a.size() > 100000);
    CHECK(a == b);
    // More threads than the machine has: the same file, and the count that ran is reported.
    REQUIRE(runVdbsurf({"-q", "mesh", dir.path("s.vdb"), "-o", dir.path("c.obj"), "--threads", "100000", "--stats", dir.path("c.json")})
                .exitCode == 0);
    CHECK(test::readFile(dir.path("c.obj")) == a);
    CHECK(nlohmann::json::parse(test::readFile(dir.path("c.json")))["threads"] == ThreadLimit::hardwareThreads());

    // .vdb files too: OpenVDB stamps each file with a random identifier, which vdbsurf replaces
    // by one from the contents — the same grids give the same file, other grids another one.
    const std::string scene = dir.path("scene.json");
    std::ofstream(scene) << R"({"primitives": [{"core": "ellipsoid", "center": [0,0,0], "radii": [0.6,0.4,0.4], "falloff": 0.3},
        {"core": "box", "center": [0.5,0.1,0], "half_extents": [0.2,0.2,0.3], "rotation": [0,20,40], "falloff": 0.2}]})";
    std::string first;
    for (const std::string threads : {"1", "2"}) {
        for (const std::string mode : {"", "--surface-only"}) {
            std::vector<std::string> args{"-q", "rasterize", scene, "-o", dir.path("d" + mode + threads + ".vdb"), "--voxel-size", "0.01",
                                          "--threads", threads};
            if (!mode.empty()) args.push_back(mode);
            REQUIRE(runVdbsurf(args).exitCode == 0);
        }
        REQUIRE(runVdbsurf({"-q", "mesh", dir.path("s.vdb"), "-o", dir.path("m" + threads + ".obj"), "--lattice-out",
                            dir.path("l" + threads + ".vdb"), "--threads", threads})
                    .exitCode == 0);
    }
    for (const std::string name : {"d", "d--surface-only", "l"}) {
        INFO(name);
        const std::string one = test::readFile(dir.path(name + "1.vdb")), two = test::readFile(dir.path(name + "2.vdb"));
        CHECK(one.size() > 10000);
        CHECK(one == two);
    }
    const std::string full = test::readFile(dir.path("d1.vdb")), surface = test::readFile(dir.path("d--surface-only1.vdb"));
    REQUIRE(full.size() > 60);
    const std::string id = full.substr(21, 36);
    CHECK(id != surface.substr(21, 36));
    CHECK(id[8] == '-');
    CHECK(id[14] == '8'); // version 8: a vendor's own UUID (RFC 9562)
    const auto r = runVdbsurf({"info", "--verify", dir.path("d1.vdb")});
    INFO(r.output);
    CHECK(r.exitCode == 0);
}

TEST_CASE("unnamed grids are meshed and small valid files are read as valid") {
    test::TempDir dir;
    initializeOpenVdb();
    // OpenVDB's own tools (createLevelSetSphere, many converters) leave grids unnamed.
    auto unnamed = test::makeSphereLevelSet(1.0, {0, 0, 0}, 0.1);
    unnamed->setName("");
    test::writeGrids(dir.path("unnamed.vdb"), {unnamed});
    const auto r = runVdbsurf({"mesh", dir.path("unnamed.vdb"), "-o", dir.path("u.obj")});
    INFO(r.output);
    REQUIRE(r.exitCode == 0);
    CHECK(r.output.find("using grid (unnamed)") != std::string::npos);
    CHECK(test::fileExists(dir.path("u.obj")));
    const auto c = runVdbsurf({"-q", "compare", dir.path("unnamed.vdb")});
    INFO(c.output);
    CHECK(c.exitCode == 0);

    // A box of tiles alone, no voxels.
    auto tiles = openvdb::FloatGrid::create(0.f);
    tiles->setName("box");
    tiles->setGridClass(openvdb::GRID_FOG_VOLUME);
    tiles->setTransform(openvdb::math::Transform::createLinearTransform(0.1));
    tiles->tree().fill(openvdb::CoordBBox({0, 0, 0}, {127, 127, 127}), 1.f, true); // one 128³ tile
    tiles->tree().prune();
    test::writeGrids(dir.path("tiles.vdb"), {tiles});
    REQUIRE(runVdbsurf({"-q", "info", dir.path("tiles.vdb")}).exitCode == 0);
    REQUIRE(runVdbsurf({"-q", "mesh", dir.path("tiles.vdb"), "-o", dir.path("t.obj")}).exitCode == 0);
    const Mesh box = readMesh(dir.path("t.obj"));
    CHECK(checkTopology(box).closedManifoldOriented());
    // The 0.5 surface of 128 voxels runs half a voxel outside their centres: 12.8 wide.
    CHECK(box.bounds().extent().x == Approx(12.8).margin(1e-4));

    // An empty grid is valid: it is listed, and meshing it says it is empty (not "damaged"). Its
    // file is smaller than a file stream's buffer (8 KiB), which the reader once took for damage.
    auto empty = openvdb::FloatGrid::create(0.f);
    empty->setName("nothing");
    test::writeGrids(dir.path("empty.vdb"), {empty});
    REQUIRE(std::filesystem::file_size(dir.path("empty.vdb")) < 8192);
    const auto i = runVdbsurf({"info", dir.path("empty.vdb")});
    INFO(i.output);
    CHECK(i.exitCode == 0);
    CHECK(i.output.find("nothing") != std::string::npos);
    expectFailure(dir, {"mesh", dir.path("empty.vdb"), "-o", dir.path("e.obj")}, dir.path("empty.vdb"), "is empty",
                  dir.files());
}

TEST_CASE("a terrain level set, its band open at the sides of its box, is meshed where its band is") {
    // A heightfield's signed distance sampled in a box: the flood fill puts inside tiles under
    // the band, far beyond it. vdbsurf refused it ("too fine for this machine's memory"): its
    // domain spanned those tiles. Now the sheet comes out where the band is, as volumeToMesh's;
    // where the band ends open, the fill's inside meets its outside in walls of inactive voxels,
    // which are left out (they were 4.5 % of the vertices, up to 22 voxels off the sheet).
    test::TempDir dir;
    const double h = 0.02;
    auto height = [](double x, double y) { return 0.2 * std::sin(2 * x) * std::cos(3 * y); };
    auto g = test::makeLevelSetFromDistance([&](const Vec3d& p) { return p.z - height(p.x, p.y); }, Box3{{-1, -1, -0.5}, {1, 1, 0.5}}, h);
    g->setName("terrain");
    test::writeGrids(dir.path("terrain.vdb"), {g});
    const auto r = runVdbsurf({"mesh", dir.path("terrain.vdb"), "-o", dir.path("terrain.obj")});
    INFO(r.output);
    REQUIRE(r.exitCode == 0);
    const Mesh m = readMesh(dir.path("terrain.obj"));
    const Box3 b = m.bounds();
    CHECK(b.min.x > -1.0 - 0.5 * h); // (DMC's nodes move within half a cell)
    CHECK(b.max.x < 1.02 + 0.5 * h);
    CHECK(b.max.z < 0.26);
    CHECK(b.min.z > -0.26);
    // The sheet, but for a few polygons where the band's last active voxels meet the fill's
    // wrong sign (volumeToMesh meshes those edges too).
    std::size_t onSheet = 0, offSheet = 0;
    for (const Vec3f& p : m.points) {
        const double d = std::fabs(double(p.z) - height(p.x, p.y));
        onSheet += d < 0.25 * h;
        offSheet += d > 1.5 * h;
    }
    CHECK(onSheet > 0.99 * double(m.points.size()));
    CHECK(offSheet < 0.005 * double(m.points.size()));
    CHECK(m.points.size() > 10000); // the 2 x 2 sheet at 0.02: ~10,000 voxels' worth
    CHECK(r.output.find("inactive voxels") != std::string::npos);
    CHECK(r.output.find("edge of the lattice") != std::string::npos);
    // A closed level set has data in every cell with surface: nothing is left out.
    writeSphereFile(dir.path("sphere.vdb"));
    const auto s = runVdbsurf({"mesh", dir.path("sphere.vdb"), "-o", dir.path("sphere.obj")});
    INFO(s.output);
    REQUIRE(s.exitCode == 0);
    CHECK(s.output.find("inactive voxels") == std::string::npos);
    CHECK(s.output.find("edge of the lattice") == std::string::npos);
}

TEST_CASE("mesh says where a formula's shape passes its box and the mesh is open there: one edge per cell face") {
    // A ball of radius 1.2 in the box [-1, 1]^3 is cut by the box's faces; the mesh is open along
    // them. Said, with the count, rather than left for the user to find; a ball inside says nothing.
    test::TempDir dir;
    auto ball = [&](const std::string& radius, const std::string& method, const std::string& out) {
        return runVdbsurf({"mesh", "--expr", "sqrt(x^2+y^2+z^2)-" + radius, "--bbox", "-1,-1,-1,1,1,1", "--voxel-size", "0.1", "--method", method,
                           "-o", dir.path(out), "--stats", dir.path(out + ".json")});
    };
    for (const std::string method : {"dmc", "mc"}) {
        const auto cut = ball("1.2", method, "cut.obj"), whole = ball("0.9", method, "whole.obj");
        INFO(method << ": " << cut.output << whole.output);
        REQUIRE(cut.exitCode == 0);
        REQUIRE(whole.exitCode == 0);
        const MeshTopology t = checkTopology(readMesh(dir.path("cut.obj")));
        REQUIRE(t.boundaryEdges > 0);
        const auto j = nlohmann::json::parse(test::readFile(dir.path("cut.obj.json")));
        CHECK(j["lattice"]["faces_open_at_lattice_edge"].get<std::size_t>() == t.boundaryEdges);
        CHECK(cut.output.find("through " + std::to_string(t.boundaryEdges) + " cell faces: the mesh is open there; widen --bbox") !=
              std::string::npos);
        CHECK(checkTopology(readMesh(dir.path("whole.obj"))).closedManifoldOriented());
        CHECK(whole.output.find("edge of the lattice") == std::string::npos);
        CHECK(nlohmann::json::parse(test::readFile(dir.path("whole.obj.json")))["lattice"]["faces_open_at_lattice_edge"] == 0);
    }
}

TEST_CASE("a camera frustum's grid is listed as one, meshed on its voxels and mapped through its frustum") {
    // A fog ball in a frustum whose voxels widen with depth (taper 0.5), as renderers' camera
    // volumes are: vdbsurf refused it by name; vdb_tool meshed it (volumeToMesh maps its points).
    test::TempDir dir;
    initializeOpenVdb();
    auto xf = openvdb::math::Transform::createFrustumTransform(openvdb::BBoxd(openvdb::Vec3d(0), openvdb::Vec3d(47)), 0.5, 1.5, 2.4);
    xf->postTranslate(openvdb::Vec3d(0, 0, 1));
    const openvdb::Vec3d c = xf->indexToWorld(openvdb::Vec3d(23.5));
    const double radius = 0.5;
    auto fog = openvdb::FloatGrid::create(0.0f);
    fog->setTransform(xf);
    fog->setGridClass(openvdb::GRID_FOG_VOLUME);
    fog->setName("density");
    auto acc = fog->getAccessor();
    for (int i = 0; i < 48; ++i)
        for (int j = 0; j < 48; ++j)
            for (int k = 0; k < 48; ++k) {
                const double d = (xf->indexToWorld(openvdb::Coord(i, j, k)) - c).length() - radius;
                if (d < 0.2) acc.setValue(openvdb::Coord(i, j, k), float(std::clamp(0.5 - d / 0.2, 0.0, 1.0)));
            }
    test::writeGrids(dir.path("camera.vdb"), {fog});

    const auto info = runVdbsurf({"info", dir.path("camera.vdb")});
    INFO(info.output);
    REQUIRE(info.exitCode == 0);
    CHECK(info.output.find("density: a camera frustum's transform") != std::string::npos);
    const auto j = runVdbsurf({"-q", "info", "--json", dir.path("camera.vdb")});
    REQUIRE(j.exitCode == 0);
    CHECK(nlohmann::json::parse(j.output)["grids"][0]["transform"] == "frustum");

    for (const char* method : {"dmc", "mc"}) {
        const auto r = runVdbsurf({"mesh", dir.path("camera.vdb"), "-o", dir.path("ball.obj"), "--method", method});
        INFO(r.output);
        REQUIRE(r.exitCode == 0);
        CHECK(r.output.find("a frustum grid") != std::string::npos);
        const Mesh m = readMesh(dir.path("ball.obj"));
        CHECK(checkTopology(m).closedManifoldOriented());
        // Density 0.5 on the ball's surface (the ramp's middle), whatever the voxels' size.
        double worst = 0;
        for (const Vec3f& p : m.points)
            worst = std::max(worst, std::fabs(length(Vec3d(p) - Vec3d(c.x(), c.y(), c.z())) - radius));
        CHECK(worst < 0.01);
    }
    const auto lat = runVdbsurf({"-q", "mesh", dir.path("camera.vdb"), "-o", dir.path("ball.ply"), "--voxel-size", "0.1",
                                 "--lattice-out", dir.path("lattice.vdb")});
    INFO(lat.output);
    REQUIRE(lat.exitCode == 0);
    const auto latInfo = runVdbsurf({"-q", "info", "--json", dir.path("lattice.vdb")});
    REQUIRE(latInfo.exitCode == 0);
    for (const auto& g : nlohmann::json::parse(latInfo.output)["grids"]) CHECK(g["transform"] == "frustum");
    const auto cmp = runVdbsurf({"compare", dir.path("camera.vdb")});
    INFO(cmp.output);
    REQUIRE(cmp.exitCode == 0);
    CHECK(cmp.output.find("frustum's smallest voxels") != std::string::npos);
}

TEST_CASE("mesh says how many lone nodes DMC joined, in its log and its stats") {
    // A voxel alone inside beside a post's top, the grid's face between them joined at its saddle:
    // marching cubes leaves it a bubble of its own, DMC joins it (test_dmc_lone_nodes.cpp).
    test::TempDir dir;
    test::writeGrids(dir.path("post.vdb"), {test::loneNodeBesidePost(0.5f, false)});
    const auto r = runVdbsurf({"mesh", dir.path("post.vdb"), "-o", dir.path("post.obj"), "--stats", dir.path("post.json")});
    INFO(r.output);
    REQUIRE(r.exitCode == 0);
    CHECK(r.output.find("1 nodes moved into thin parts (1 of them to join a node alone inside to the rest across a face)") !=
          std::string::npos);
    CHECK(nlohmann::json::parse(test::readFile(dir.path("post.json")))["dmc"]["nodes_moved_lone_joins"] == 1);
    CHECK(countComponents(readMesh(dir.path("post.obj"))) == 1);
    // Without the thin search, as marching cubes: the bubble stays, and the log does not say it.
    const auto apart = runVdbsurf({"mesh", dir.path("post.vdb"), "-o", dir.path("apart.obj"), "--no-thin", "--stats", dir.path("apart.json")});
    REQUIRE(apart.exitCode == 0);
    CHECK(apart.output.find("alone inside") == std::string::npos);
    CHECK(nlohmann::json::parse(test::readFile(dir.path("apart.json")))["dmc"]["nodes_moved_lone_joins"] == 0);
    CHECK(countComponents(readMesh(dir.path("apart.obj"))) == 2);
}

TEST_CASE("Ctrl-C stops every long command: exit 130, one message, no output file") {
    // SIGINT half a second in (as a terminal's Ctrl-C or a farm's SIGTERM would come); each job
    // below runs for 10 s or more here (up to 2.4 GB). patches ran on and wrote its files.
    test::TempDir dir, inputs;
    const std::string spot = test::sharedData("mesh/spot.obj");
    const std::string out = dir.path("out");
    auto sphere = test::makeSphereLevelSet(1.0, {0, 0, 0}, 0.005); // 3 M voxels: compare measures for 20 s
    sphere->setName("ls");
    test::writeGrids(inputs.path("sphere.vdb"), {sphere});
    std::vector<std::vector<std::string>> jobs{
        {"compare", inputs.path("sphere.vdb"), "--json", out + ".json"},
        {"mesh", "--expr", "x^2+y^2+z^2-1", "--bbox", "-1.1,-1.1,-1.1,1.1,1.1,1.1", "--voxel-size", "0.002", "-o", out + ".ply"},
        {"rasterize", std::string(VDBSURF_SOURCE_DIR) + "/examples/scenes/blobby.json", "--voxel-size", "0.003", "-o", out + ".vdb"}};
    if (spot.empty()) {
        WARN("shared data absent (mesh/spot.obj): subdivide and patches are not interrupted");
    } else {
        jobs.push_back({"subdivide", spot, "--steps", "11", "-o", out + ".ply"});
        jobs.push_back({"subdivide", spot, "--camera-pos", "0,0,4", "--camera-target", "0,0,0", "--front-depth", "12",
                        "--silhouette-depth", "12", "--stop-pixels", "0", "-o", out + ".ply"});
        jobs.push_back({"patches", spot, "--grid-size", "2048,2048", "-o", out + ".obj", "--preview", out + "_preview.ply"});
    }
    for (const auto& job : jobs) {
        // (killed 20 s later, exit 137, should the signal go unheeded)
        std::vector<std::string> args{"timeout", "--preserve-status", "-s", "INT", "-k", "20", "0.5", VDBSURF_BIN};
        args.insert(args.end(), job.begin(), job.end());
        const auto r = test::runProgram(args);
        INFO(job[0] << ": " << r.output);
        CHECK(r.exitCode == 130);
        CHECK(r.output.find("vdbsurf: cancelled; no output written") != std::string::npos);
        CHECK(dir.files().empty());
    }
}

TEST_CASE("bad input: one clear error naming the input, non-zero exit, no output") {
    test::TempDir dir;
    writeSphereFile(dir.path("good.vdb"));
    const std::string out = dir.path("out.obj");

    // Files the user might hand over by mistake.
    std::ofstream(dir.path("text.vdb")) << "this is not a volume\n";
    {
        const std::string full = test::readFile(dir.path("good.vdb"));
        std::ofstream(dir.path("truncated.vdb"), std::ios::binary) << full.substr(0, full.size() / 2);
        std::ofstream(dir.path("header_only.vdb"), std::ios::binary) << full.substr(0, 200);
    }
    initializeOpenVdb();
    {
        auto nan = openvdb::FloatGrid::create(0.f);
        nan->setName("density");
        nan->setGridClass(openvdb::GRID_FOG_VOLUME);
        nan->tree().setValue({1, 2, 3}, 0.7f);
        nan->tree().setValue({2, 2, 3}, std::numeric_limits<float>::quiet_NaN());
        test::writeGrids(dir.path("nan.vdb"), {nan});
        auto inf = openvdb::FloatGrid::create(0.f);
        inf->setName("density");
        inf->tree().setValue({1, 2, 3}, std::numeric_limits<float>::infinity());
        test::writeGrids(dir.path("inf.vdb"), {inf});
        auto empty = openvdb::FloatGrid::create(0.f);
        empty->setName("nothing");
        test::writeGrids(dir.path("empty.vdb"), {empty});
        auto vec = openvdb::Vec3SGrid::create();
        vec->setName("velocity");
        vec->tree().setValue({0, 0, 0}, openvdb::Vec3s(1, 0, 0));
        test::writeGrids(dir.path("vector.vdb"), {vec});
    }
    const auto before = dir.files();

    expectFailure(dir, {"mesh", dir.path("missing.vdb"), "-o", out}, "missing.vdb", "no such file", before);
    expectFailure(dir, {"mesh", dir.path("text.vdb"), "-o", out}, "text.vdb", "not an OpenVDB file", before);
    expectFailure(dir, {"mesh", dir.path("truncated.vdb"), "-o", out}, "truncated.vdb", "truncated", before);
    expectFailure(dir, {"mesh", dir.path("header_only.vdb"), "-o", out}, "header_only.vdb", "truncated", before);
    expectFailure(dir, {"info", dir.path("truncated.vdb")}, "truncated.vdb", "truncated", before);
    expectFailure(dir, {"info", "--verify", dir.path("truncated.vdb")}, "truncated.vdb", "truncated", before);
    CHECK(runVdbsurf({"info", "--verify", dir.path("good.vdb")}).exitCode == 0);
    expectFailure(dir, {"mesh", dir.path("good.vdb"), "--grid", "nope", "-o", out}, "good.vdb", "no grid named 'nope'; grids: 'ls_sphere'", before);
    expectFailure(dir, {"mesh", dir.path("vector.vdb"), "-o", out}, "vector.vdb", "no float or double grid", before);
    expectFailure(dir, {"mesh", dir.path("vector.vdb"), "--grid", "velocity", "-o", out}, "vector.vdb", "vec3s", before);
    expectFailure(dir, {"mesh", dir.path("nan.vdb"), "-o", out}, "nan.vdb", "NaN", before);
    expectFailure(dir, {"mesh", dir.path("inf.vdb"), "-o", out}, "inf.vdb", "infinite", before);
    expectFailure(dir, {"mesh", dir.path("empty.vdb"), "-o", out}, "empty.vdb", "empty", before);
    expectFailure(dir, {"mesh", dir.path("good.vdb"), "--voxel-size", "0", "-o", out}, "--voxel-size", "positive", before);
    expectFailure(dir, {"mesh", dir.path("good.vdb"), "--voxel-size", "-0.1", "-o", out}, "--voxel-size", "positive", before);
    expectFailure(dir, {"mesh", dir.path("good.vdb"), "--voxel-size", "1e-9", "-o", out}, "--voxel-size", "at most", before);
    expectFailure(dir, {"mesh", dir.path("good.vdb"), "--voxel-size", "1e-5", "-o", out}, "--voxel-size", "too fine", before);
    // A spacing wider than the input (1e300 walked a lattice edge voxel by voxel for ever, and
    // sampled at index coordinates past an int: a crash).
    for (const char* h : {"7", "1e6", "1e300"})
        expectFailure(dir, {"mesh", dir.path("good.vdb"), "--voxel-size", h, "-o", out}, "--voxel-size", "is wider than all of", before);
    expectFailure(dir, {"compare", dir.path("good.vdb"), "--voxel-size", "1e300"}, "--voxel-size", "is wider than all of", before);
    expectFailure(dir, {"mesh", dir.path("good.vdb"), "--iso", "7", "-o", out}, "good.vdb", "no surface", before);
    expectFailure(dir, {"mesh", dir.path("good.vdb"), "--sharp-noise", "0", "-o", out}, "--sharp-noise", "(0, 1]", before);
    expectFailure(dir, {"mesh", dir.path("good.vdb"), "--method", "mc", "--no-simplify", "-o", out}, "--no-simplify",
                  "applies only to --method dmc", before);
    expectFailure(dir, {"mesh", dir.path("good.vdb"), "--no-simplify", "--simplify-tolerance", "0.2", "-o", out},
                  "--simplify-tolerance", "has no effect with --no-simplify", before);
    expectFailure(dir, {"mesh", dir.path("good.vdb"), "--no-thin", "--simplify-tolerance", "0.2", "-o", out},
                  "--simplify-tolerance", "--no-thin", before);
    expectFailure(dir, {"mesh", "--expr", "x^2 + * 2", "--bbox", "-1,-1,-1,1,1,1", "--voxel-size", "0.1", "-o", out}, "--expr",
                  "column 7", before);
    expectFailure(dir, {"mesh", "--expr", "sqrt(x) - 0.5", "--bbox", "-1,-1,-1,1,1,1", "--voxel-size", "0.1", "-o", out},
                  "sqrt(x) - 0.5", "undefined (NaN)", before);
    expectFailure(dir, {"mesh", "--expr", "x", "--voxel-size", "0.1", "-o", out}, "--bbox", "required", before);
    expectFailure(dir, {"mesh", "--expr", "x", "--bbox", "1,2,3", "--voxel-size", "0.1", "-o", out}, "--bbox", "6", before);
    expectFailure(dir, {"mesh", dir.path("good.vdb"), "-o", dir.path("out.stl")}, "out.stl", "unsupported", before);
    expectFailure(dir, {"mesh", dir.path("good.vdb"), "-o", dir.path("no/such/folder/out.obj")}, "out.obj", "does not exist", before);
    expectFailure(dir, {"compare", dir.path("missing.vdb")}, "missing.vdb", "no such file", before);
    expectFailure(dir, {"compare", dir.path("text.vdb")}, "text.vdb", "not an OpenVDB file", before);
    expectFailure(dir, {"compare", dir.path("good.obj")}, "good.obj", "compare takes a .vdb", before);
    expectFailure(dir, {"compare", dir.path("vector.vdb")}, "vector.vdb", "no float or double grid", before);
    expectFailure(dir, {"compare", dir.path("good.vdb"), "--voxel-size", "-0.1"}, "--voxel-size", "positive", before);
    expectFailure(dir, {"compare", dir.path("good.vdb"), "--iso", "7"}, "good.vdb", "no surface", before);
    expectFailure(dir, {"compare", dir.path("good.vdb"), "--json", dir.path("no/such/folder/r.json")}, "r.json", "does not exist",
                  before);
}

TEST_CASE("compare prints volumeToMesh, mc and dmc side by side and writes JSON") {
    test::TempDir dir;
    initializeOpenVdb();
    writeSphereFile(dir.path("sphere.vdb"), 0.05);
    const auto r = runVdbsurf({"compare", dir.path("sphere.vdb"), "--voxel-size", "0.15", "--json", dir.path("r.json")});
    INFO(r.output);
    REQUIRE(r.exitCode == 0);
    for (const char* word : {"volumeToMesh", "vdbsurf mc", "vdbsurf dmc", "covers H", "F-score", "resampled"})
        CHECK(r.output.find(word) != std::string::npos);
    const auto j = nlohmann::json::parse(test::readFile(dir.path("r.json")));
    CHECK(j["voxel_size"].get<double>() == Approx(0.15));
    CHECK(j["grid_voxel_size"].get<double>() == Approx(0.05));
    REQUIRE(j["rows"].size() == 3);
    for (const auto& row : j["rows"]) {
        INFO(row.dump());
        CHECK(row["coverage_one_h"].get<double>() > 0.999);
        CHECK(row["f_score_quarter_h"].get<double>() > 0.95);
        CHECK(row["components"].get<int>() == 1);
        CHECK(row["polygons"].get<int>() > 500); // a sphere of radius 1 at H = 0.15: about 800
    }
}

TEST_CASE("compare shows a mesher that lost the whole surface as an empty row") {
    // A rod 0.3 H across midway between the nodes of the lattice at H: marching cubes sees nothing.
    test::TempDir dir;
    initializeOpenVdb();
    const double H = 0.1;
    auto rod = test::makeLevelSetFromDistance(
        [&](const Vec3d& p) { return std::max(std::hypot(p.x - 0.5 * H, p.y - 0.5 * H) - 0.15 * H, std::fabs(p.z) - 0.5); },
        {{-0.3, -0.3, -0.7}, {0.3, 0.3, 0.7}}, H / 5);
    rod->setName("rod");
    test::writeGrids(dir.path("rod.vdb"), {rod});
    const auto r = runVdbsurf({"compare", dir.path("rod.vdb"), "--voxel-size", "0.1", "--json", dir.path("r.json")});
    INFO(r.output);
    REQUIRE(r.exitCode == 0);
    CHECK(r.output.find("empty") != std::string::npos);
    CHECK(r.output.find("vdbsurf mc lost the whole surface") != std::string::npos);
    const auto j = nlohmann::json::parse(test::readFile(dir.path("r.json")));
    REQUIRE(j["rows"].size() == 3);
    CHECK(j["rows"][1]["empty"].get<bool>());
    CHECK_FALSE(j["rows"][2]["empty"].get<bool>());
    CHECK(j["rows"][2]["coverage_one_h"].get<double>() > 0.99);
}

TEST_CASE("scenes: rasterize, edit and mesh from the command line, and malformed scenes leave no file") {
    test::TempDir dir;
    const std::string scene = dir.path("scene.json");
    {
        std::ofstream(scene) << R"({"primitives": [
            {"core": "ellipsoid", "center": [0,0,0], "radii": [0.6,0.4,0.4], "rotation": [0,0,30], "falloff": 0.3},
            {"core": "box", "center": [0.6,0,0], "half_extents": [0.2,0.2,0.2], "falloff": 0.2, "name": "nose"},
            {"core": "capsule", "center": [-0.3,0.4,0], "half_length": 0.25, "radius": 0.08, "rotation": [0,0,60], "falloff": 0.15, "name": "arm"}]})";
    }
    auto r = runVdbsurf({"rasterize", scene, "-o", dir.path("d.vdb"), "--voxel-size", "0.02"});
    INFO(r.output);
    REQUIRE(r.exitCode == 0);
    r = runVdbsurf({"info", dir.path("d.vdb")});
    CHECK(r.output.find("density") != std::string::npos);
    CHECK(r.output.find("fog") != std::string::npos);
    // The raster's scene, numbered as edit numbers it; and the scene file itself.
    CHECK(r.output.find("from a scene of 3 primitives") != std::string::npos);
    CHECK(r.output.find("2  arm   capsule    half length 0.25, radius 0.08") != std::string::npos);
    r = runVdbsurf({"info", scene});
    INFO(r.output);
    CHECK(r.exitCode == 0);
    CHECK(r.output.find("a density scene of 3 primitives (3 adding, 0 subtracting)") != std::string::npos);
    CHECK(r.output.find("1  nose  box        half extents (0.2, 0.2, 0.2)") != std::string::npos);
    CHECK(r.output.find("need --voxel-size") != std::string::npos);
    r = runVdbsurf({"-q", "info", "--json", scene});
    {
        const auto j = nlohmann::json::parse(r.output);
        CHECK(j["kind"] == "density scene");
        REQUIRE(j["primitives"].size() == 3);
        CHECK(j["primitives"][2]["core"] == "capsule");
        CHECK(j["primitives"][2]["index"] == 2);
        CHECK(j["primitives"][2]["half_length"].get<double>() == 0.25);
        CHECK(j["influence_bbox"][1][0].get<double>() == Approx(1.0)); // the box: 0.6 + 0.2 core + 0.2 falloff
    }

    r = runVdbsurf({"mesh", scene, "-o", dir.path("direct.obj"), "--voxel-size", "0.05"});
    INFO(r.output);
    CHECK(r.exitCode == 0);
    CHECK(test::fileExists(dir.path("direct.obj")));

    // Move the box and lengthen the capsule, then compare with rasterizing the edited scene from scratch.
    r = runVdbsurf({"edit", dir.path("d.vdb"), "--set", "1.center=0.7,0.1,0", "--set", "2.half_length=0.35", "--scene-out",
                    dir.path("edited.json"), "-o", dir.path("e.vdb")});
    INFO(r.output);
    REQUIRE(r.exitCode == 0);
    CHECK(r.output.find("leaves recomputed") != std::string::npos);
    r = runVdbsurf({"rasterize", dir.path("edited.json"), "-o", dir.path("full.vdb"), "--voxel-size", "0.02"});
    REQUIRE(r.exitCode == 0);
    const auto e = openvdb::GridBase::grid<openvdb::FloatGrid>(readScalarGrid(dir.path("e.vdb"), "density").grid);
    const auto f = openvdb::GridBase::grid<openvdb::FloatGrid>(readScalarGrid(dir.path("full.vdb"), "density").grid);
    CHECK(e->activeVoxelCount() == f->activeVoxelCount());
    // Active voxels of a (tiles voxel by voxel) whose value b lacks, or has not active.
    auto differing = [](const openvdb::FloatGrid& a, const openvdb::FloatGrid& b) {
        auto ba = b.getConstAccessor();
        std::size_t n = 0;
        for (auto it = a.cbeginValueOn(); it; ++it) {
            openvdb::CoordBBox bb;
            it.getBoundingBox(bb);
            for (auto c = bb.begin(); c; ++c) n += ba.getValue(*c) != *it || !ba.isValueOn(*c);
        }
        return n;
    };
    CHECK(differing(*e, *f) == 0);
    r = runVdbsurf({"-q", "info", "--json", dir.path("e.vdb")});
    {
        const auto j = nlohmann::json::parse(r.output);
        REQUIRE(j["grids"].size() == 1);
        CHECK_FALSE(j["grids"][0]["scene"]["surface_only"].get<bool>());
        CHECK(j["grids"][0]["scene"]["primitives"][2]["half_length"].get<double>() == 0.35);
    }
    // A subtracting primitive added alone carves a hole (it was refused: parsed as a scene of its
    // own, it had no "add" primitive), and the result is the edited scene's raster.
    r = runVdbsurf({"edit", dir.path("e.vdb"), "--add",
                    R"({"core": "ellipsoid", "center": [0.1, 0, 0], "radii": [0.2, 0.2, 0.2], "falloff": 0.1, "op": "subtract"})",
                    "--scene-out", dir.path("carved.json"), "-o", dir.path("carved.vdb")});
    INFO(r.output);
    REQUIRE(r.exitCode == 0);
    r = runVdbsurf({"rasterize", dir.path("carved.json"), "-o", dir.path("carved_full.vdb"), "--voxel-size", "0.02"});
    REQUIRE(r.exitCode == 0);
    {
        const auto c = openvdb::GridBase::grid<openvdb::FloatGrid>(readScalarGrid(dir.path("carved.vdb"), "density").grid);
        const auto cf = openvdb::GridBase::grid<openvdb::FloatGrid>(readScalarGrid(dir.path("carved_full.vdb"), "density").grid);
        CHECK(c->activeVoxelCount() == cf->activeVoxelCount());
        CHECK(differing(*c, *cf) == 0);
        CHECK(differing(*c, *e) > 0); // carved
        const auto j = nlohmann::json::parse(test::readFile(dir.path("carved.json")));
        REQUIRE(j["primitives"].size() == 4);
        CHECK(j["primitives"][3]["op"] == "subtract");
    }

    const auto before = dir.files();
    auto bad = [&](const std::string& name, const std::string& text, const std::string& what) {
        {
            std::ofstream(dir.path(name)) << text;
        }
        const auto now = dir.files();
        expectFailure(dir, {"rasterize", dir.path(name), "-o", dir.path("bad.vdb"), "--voxel-size", "0.05"}, name, what, now);
        expectFailure(dir, {"mesh", dir.path(name), "-o", dir.path("bad.obj"), "--voxel-size", "0.05"}, name, what, now);
        expectFailure(dir, {"info", dir.path(name)}, name, what, now);
    };
    bad("flat.json", R"({"primitives": [{"core": "capsule", "center": [0,0,0], "half_length": 1, "radius": 0, "falloff": 0.3}]})",
        "primitive 0 (capsule): 'radius' must be positive");
    bad("neg.json", R"({"primitives": [{"core": "ellipsoid", "center": [0,0,0], "radii": [-1,1,1], "falloff": 0.3}]})",
        "primitive 0 (ellipsoid): 'radii' must be positive");
    bad("zero.json", R"({"primitives": [{"core": "box", "center": [0,0,0], "half_extents": [1,1,1], "falloff": 0}]})",
        "'falloff' must be positive");
    bad("type.json", R"({"primitives": [{"core": "box", "center": "origin", "half_extents": [1,1,1], "falloff": 1}]})",
        "'center' must be an array of 3 numbers");
    bad("unknown.json", R"({"primitives": [{"core": "box", "center": [0,0,0], "half_extents": [1,1,1], "falloff": 1, "colour": 2}]})",
        "'colour' is not a field");
    bad("broken.json", "{\"primitives\": [", "not valid JSON");
    const auto now = dir.files();
    expectFailure(dir, {"rasterize", dir.path("missing.json"), "-o", dir.path("bad.vdb"), "--voxel-size", "0.05"}, "missing.json",
                  "cannot open", now);
    expectFailure(dir, {"rasterize", scene, "-o", dir.path("bad.vdb")}, "--voxel-size", "required", now);
    expectFailure(dir, {"rasterize", scene, "-o", dir.path("bad.vdb"), "--voxel-size", "1e300"}, "--voxel-size", "is wider than all of",
                  now);
    // Below about 1.44e-5 OpenVDB's transforms refuse the scale (an ArithmeticError naming nothing).
    expectFailure(dir, {"rasterize", scene, "-o", dir.path("bad.vdb"), "--voxel-size", "1e-5"}, "--voxel-size",
                  "cannot be stored in a .vdb grid", now);
    expectFailure(dir,
                  {"mesh", "--expr", "x^2+y^2+z^2-1e-8", "--bbox", "-2e-4,-2e-4,-2e-4,2e-4,2e-4,2e-4", "--voxel-size", "1e-5",
                   "-o", dir.path("bad.vdb")},
                  "bad.vdb", "cannot be stored in a .vdb grid", now);
    expectFailure(dir, {"edit", dir.path("d.vdb"), "--set", "5.center=0,0,0", "-o", dir.path("bad.vdb")}, "5.center", "no primitive 5",
                  now);
    expectFailure(dir, {"edit", dir.path("d.vdb"), "--set", "0.radii=1,0,1", "-o", dir.path("bad.vdb")}, "0.radii",
                  "'radii' must be positive", now);
    // --remove counts by the scene's own numbers, whatever else is removed with it.
    expectFailure(dir, {"edit", dir.path("d.vdb"), "--remove", "1", "--remove", "3", "-o", dir.path("bad.vdb")}, "--remove",
                  "no primitive 3 (the scene has 3,", now);
    expectFailure(dir, {"edit", dir.path("d.vdb"), "--remove", "0", "--remove", "0", "-o", dir.path("bad.vdb")}, "--remove",
                  "primitive 0 is given twice", now);
    expectFailure(dir, {"edit", dir.path("d.vdb"), "--remove", "0", "--remove", "1", "--remove", "2", "-o", dir.path("bad.vdb")}, "d.vdb",
                  "no primitive with op \"add\"", now);
    // A scene whose weights never add up to the surface's 0.5: kept only near that surface, it keeps
    // nothing, which is an error naming the scene (no empty file); in full it is its density, said
    // to have no surface.
    {
        std::ofstream(dir.path("faint.json")) << R"({"primitives": [{"core": "ellipsoid", "center": [0,0,0], "radii": [0.3,0.2,0.2], "falloff": 0.4, "weight": 0.3}]})";
    }
    const auto beforeFaint = dir.files();
    expectFailure(dir, {"rasterize", dir.path("faint.json"), "-o", dir.path("faint.vdb"), "--voxel-size", "0.05", "--surface-only"},
                  "faint.json", "has no surface: no density reaches 0.5 (values lie within 0 .. 0.3)", beforeFaint);
    r = runVdbsurf({"rasterize", dir.path("faint.json"), "-o", dir.path("faint.vdb"), "--voxel-size", "0.05"});
    CHECK(r.exitCode == 0);
    CHECK(r.output.find("no density reaches 0.5") != std::string::npos);
    CHECK(test::fileExists(dir.path("faint.vdb")));
    // So is an edit that leaves a surface-only raster no surface.
    {
        std::ofstream(dir.path("single.json")) << R"({"primitives": [{"core": "ellipsoid", "center": [0,0,0], "radii": [0.3,0.2,0.2], "falloff": 0.4}]})";
    }
    r = runVdbsurf({"rasterize", dir.path("single.json"), "-o", dir.path("single.vdb"), "--voxel-size", "0.05", "--surface-only"});
    REQUIRE(r.exitCode == 0);
    expectFailure(dir, {"edit", dir.path("single.vdb"), "--set", "0.weight=0.3", "-o", dir.path("faded.vdb")}, "single.vdb:density, edited",
                  "has no surface: no density reaches 0.5", dir.files());
    writeSphereFile(dir.path("plain.vdb"));
    const auto now2 = dir.files();
    expectFailure(dir, {"edit", dir.path("plain.vdb"), "--set", "0.falloff=1", "-o", dir.path("bad.vdb")}, "plain.vdb",
                  "no grid named 'density'", now2);
}

namespace {

struct Image {
    int width = 0, height = 0;
    std::vector<unsigned char> rgb;
    bool background(int x, int y) const {
        const unsigned char* p = &rgb[3 * (std::size_t(y) * std::size_t(width) + std::size_t(x))];
        return p[0] > 245 && p[1] > 245 && p[2] > 245;
    }
};

// Binary PPM (P6, 8 bit), as POV-Ray writes with +FP.
Image readPpm(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    auto token = [&] { // header tokens, skipping "# ..." comment lines
        std::string t;
        while (in >> t && t[0] == '#') std::getline(in, t);
        return t;
    };
    Image img;
    const std::string magic = token();
    img.width = std::stoi(token());
    img.height = std::stoi(token());
    const int maxValue = std::stoi(token());
    in.get();
    REQUIRE(magic == "P6");
    REQUIRE(maxValue == 255);
    img.rgb.resize(std::size_t(img.width) * std::size_t(img.height) * 3);
    in.read(reinterpret_cast<char*>(img.rgb.data()), std::streamsize(img.rgb.size()));
    REQUIRE(in);
    return img;
}

} // namespace

TEST_CASE("info describes a mesh: counts, topology, genus, and what subdivide and patches make of it") {
    test::TempDir dir;
    writeMesh(dir.path("torus.ply"), test::quadTorusMesh(24, 12, 1.0, 0.3));
    auto r = runVdbsurf({"info", dir.path("torus.ply")});
    INFO(r.output);
    REQUIRE(r.exitCode == 0);
    CHECK(r.output.find("a mesh of 288 vertices and 288 polygons (0 triangles, 288 quads, 0 larger)") != std::string::npos);
    CHECK(r.output.find("closed, manifold and oriented, genus 1") != std::string::npos);
    CHECK(r.output.find("subdivide: takes it") != std::string::npos);
    CHECK(r.output.find("patches: takes it") != std::string::npos);

    auto json = [&](const std::string& file) {
        const auto j = runVdbsurf({"-q", "info", "--json", dir.path(file)});
        INFO(j.output);
        REQUIRE(j.exitCode == 0);
        return nlohmann::json::parse(j.output);
    };
    writeMesh(dir.path("cube.obj"), test::cubeMesh());
    writeMesh(dir.path("corners.obj"), test::pointPerCorner(test::cubeMesh()));
    writeMesh(dir.path("open.obj"), test::openCubeMesh());
    const auto cube = json("cube.obj"), corners = json("corners.obj"), open = json("open.obj");
    CHECK(cube["kind"] == "mesh");
    CHECK(cube["edges"] == 12);
    CHECK(cube["euler_characteristic"] == 2);
    CHECK(cube["genus"] == 0);
    CHECK(cube["patches"] == true);
    CHECK(cube["patches_merged_points"] == 0);
    CHECK(corners["vertices"] == 24);
    CHECK(corners["boundary_edges"] == 24);
    CHECK(corners["components"] == 6);
    CHECK(corners["coincident_points"] == 16);
    CHECK(corners["genus"] == nullptr);
    CHECK(corners["patches"] == true);
    CHECK(corners["patches_merged_points"] == 16);
    CHECK(open["boundary_edges"] == 4);
    CHECK(open["subdivide"] == true);
    CHECK(open["patches"].get<std::string>().find("the surface is open") != std::string::npos);
    // patches as it runs by default, along z: a cube pressed flat across z is refused, and
    // patches itself says the same, naming the file; along x it is taken.
    Mesh pressed = test::cubeMesh();
    for (Vec3f& p : pressed.points) p.z = 0.5f;
    writeMesh(dir.path("pressed.obj"), pressed);
    const auto flat = json("pressed.obj");
    CHECK(flat["subdivide"] == true);
    CHECK(flat["patches"].get<std::string>().find("lies flat across the height axis (0, 0, 1)") != std::string::npos);
    expectFailure(dir, {"patches", dir.path("pressed.obj"), "-o", dir.path("pf.obj")}, "pressed.obj", "lies flat across the height axis",
                  dir.files());
    CHECK(runVdbsurf({"-q", "patches", dir.path("pressed.obj"), "-o", dir.path("px.obj"), "--axis", "x"}).exitCode == 0);

    // A mesh no job takes says why each refuses it; a bad file is one error naming it.
    Mesh three = test::cubeMesh();
    three.addPolygon({0, 1, 2}); // cube edges 0-1 and 1-2 get a third polygon
    writeMesh(dir.path("three.obj"), three);
    const auto bad = json("three.obj");
    CHECK(bad["non_manifold_edges"] == 2);
    CHECK(bad["subdivide"].is_string());
    CHECK(bad["patches"].is_string());
    std::ofstream(dir.path("broken.obj")) << "v 0 0 0\nf 1 2 3\n";
    expectFailure(dir, {"info", dir.path("broken.obj")}, "broken.obj", "", dir.files());
}

TEST_CASE("subdivide: levels and steps, stats, view-dependent refinement, and clear errors") {
    test::TempDir dir;
    const Mesh cube = test::cubeMesh();
    writeMesh(dir.path("cube.obj"), cube);

    auto r = runVdbsurf({"subdivide", dir.path("cube.obj"), "-o", dir.path("l2.obj"), "--levels", "2", "--stats", dir.path("s.json")});
    INFO(r.output);
    REQUIRE(r.exitCode == 0);
    CHECK(r.output.find("4 sqrt2 steps (2 Catmull-Clark levels)") != std::string::npos);
    auto stats = nlohmann::json::parse(test::readFile(dir.path("s.json")));
    CHECK(stats["output_polygons"] == 96);
    CHECK(stats["steps"] == 4);
    r = runVdbsurf({"subdivide", dir.path("cube.obj"), "-o", dir.path("s3.ply"), "--steps", "3", "--stats", dir.path("s3.json")});
    REQUIRE(r.exitCode == 0);
    CHECK(nlohmann::json::parse(test::readFile(dir.path("s3.json")))["output_polygons"] == 48); // 6 -> 12 -> 24 -> 48

    r = runVdbsurf({"subdivide", dir.path("cube.obj"), "-o", dir.path("view.obj"), "--camera-pos", "0.5,0.5,6", "--camera-target",
                    "0.5,0.5,0.5", "--front-depth", "2", "--silhouette-depth", "4", "--stats", dir.path("v.json")});
    INFO(r.output);
    REQUIRE(r.exitCode == 0);
    stats = nlohmann::json::parse(test::readFile(dir.path("v.json")));
    CHECK(stats["mode"] == "view");
    CHECK(stats["view"]["refined_per_step"].size() == 4);
    CHECK(stats["output_polygons"] > 24);  // the front faces went past the 24 of one level
    CHECK(stats["output_polygons"] < 384); // fewer than uniform to the silhouette depth

    // The cube stored a point per corner: each face is refined as a boundary of its own (said),
    // unless --merge-points joins the points first; then it is the cube's surface again.
    writeMesh(dir.path("corners.obj"), test::pointPerCorner(cube));
    r = runVdbsurf({"subdivide", dir.path("corners.obj"), "-o", dir.path("c.obj"), "--levels", "2", "--stats", dir.path("c.json")});
    INFO(r.output);
    REQUIRE(r.exitCode == 0);
    CHECK(r.output.find("16 points lie exactly where an earlier one does") != std::string::npos);
    CHECK(r.output.find("--merge-points joins them") != std::string::npos);
    CHECK(checkTopology(readMesh(dir.path("c.obj"))).boundaryEdges > 0);
    r = runVdbsurf({"subdivide", dir.path("corners.obj"), "-o", dir.path("cm.obj"), "--levels", "2", "--merge-points", "--stats",
                    dir.path("cm.json")});
    INFO(r.output);
    REQUIRE(r.exitCode == 0);
    CHECK(nlohmann::json::parse(test::readFile(dir.path("cm.json")))["merged_points"] == 16);
    const Mesh merged = readMesh(dir.path("cm.obj")), plain = readMesh(dir.path("l2.obj"));
    CHECK(checkTopology(merged).closedManifoldOriented());
    CHECK(merged.polygonCount() == plain.polygonCount());
    CHECK(enclosedVolume(merged) == Approx(enclosedVolume(plain)).epsilon(1e-6));

    const std::vector<std::string> before = dir.files();
    expectFailure(dir, {"subdivide", dir.path("cube.obj"), "-o", dir.path("x.stl")}, "x.stl", "unsupported output format", before);
    expectFailure(dir, {"subdivide", dir.path("cube.obj"), "-o", dir.path("x.obj"), "--levels", "1", "--steps", "2"}, "--levels",
                  "not both", before);
    expectFailure(dir, {"subdivide", dir.path("cube.obj"), "-o", dir.path("x.obj"), "--camera-pos", "0,0,5"}, "--camera-target",
                  "needs both", before);
    expectFailure(dir, {"subdivide", dir.path("cube.obj"), "-o", dir.path("x.obj"), "--camera-pos", "0,0,5", "--camera-target", "0,0,5"},
                  "camera", "target is at the camera position", before);
    expectFailure(dir, {"subdivide", dir.path("missing.obj"), "-o", dir.path("x.obj")}, "missing.obj", "cannot open", before);
    Mesh fin = cube;
    fin.points.emplace_back(0.5f, -1.f, -1.f);
    fin.addPolygon({0, 1, 8});
    writeMesh(dir.path("fin.obj"), fin);
    const std::vector<std::string> withFin = dir.files();
    expectFailure(dir, {"subdivide", dir.path("fin.obj"), "-o", dir.path("x.obj")}, "fin.obj", "same direction", withFin);
}

TEST_CASE("out of memory: one error naming the command and what to change, nothing written") {
    // Under a 400 MB address-space limit, four levels of a 20,000-quad torus (5.1 M polygons,
    // ~0.8 GB) pass the subdivider's own check against free memory and fail to allocate. The
    // message named no command and told every command to try a larger --voxel-size.
    test::TempDir dir;
    writeMesh(dir.path("torus.obj"), test::quadTorusMesh(200, 100, 1.0, 0.3));
    const std::vector<std::string> before = dir.files();
    const auto r = test::runProgram({"sh", "-c", "ulimit -v 400000 && exec \"$0\" subdivide \"$1\" -o \"$2\" --levels 4", VDBSURF_BIN,
                                     dir.path("torus.obj"), dir.path("smooth.obj")});
    INFO(r.output);
    CHECK(r.exitCode == 1);
    CHECK(r.output.find("vdbsurf: error: subdivide: out of memory (try fewer --levels or --steps") != std::string::npos);
    CHECK(r.output.find("--voxel-size") == std::string::npos);
    CHECK(dir.files() == before);
}

TEST_CASE("subdivide writes a POV-Ray scene that povray renders as the camera sees it") {
    if (!test::onPath("povray")) {
        WARN("skipped: povray is not installed (scripts/dev deps installs it)");
        return;
    }
    test::TempDir dir;
    // A cube up and to the right of the view axis: it must land in the upper right of the picture
    // (POV-Ray is left-handed; a mirrored scene would put it on the left).
    Mesh cube = test::cubeMesh();
    for (auto& p : cube.points) p = p + Vec3f(1.2f, 0.8f, 0);
    writeMesh(dir.path("cube.obj"), cube);
    auto r = runVdbsurf({"subdivide", dir.path("cube.obj"), "-o", dir.path("scene.pov"), "--levels", "3", "--camera-pos", "0,0,8",
                         "--camera-target", "0,0,0", "--fov", "50", "--image", "96,72"});
    INFO(r.output);
    REQUIRE(r.exitCode == 0);
    const std::string pov = test::readFile(dir.path("scene.pov"));
    CHECK(pov.find("mesh2") != std::string::npos);
    CHECK(pov.find("vertex_vectors") != std::string::npos);
    CHECK(pov.find("normal_vectors") != std::string::npos);
    CHECK(pov.find("face_indices") != std::string::npos);

    r = test::runProgram({"povray", "+Iscene.pov", "+Oimage.ppm", "+FP", "+W96", "+H72", "-D", "-V", "+A0.1"}, dir.root());
    INFO(r.output);
    REQUIRE(r.exitCode == 0);
    const Image img = readPpm(dir.path("image.ppm"));
    REQUIRE(img.width == 96);
    REQUIRE(img.height == 72);
    std::size_t object = 0;
    double sx = 0, sy = 0;
    for (int y = 0; y < img.height; ++y)
        for (int x = 0; x < img.width; ++x)
            if (!img.background(x, y)) {
                ++object;
                sx += x;
                sy += y;
            }
    CHECK(img.background(0, 0));
    CHECK(img.background(img.width - 1, img.height - 1));
    REQUIRE(object > 100);
    CHECK(object < std::size_t(img.width * img.height / 2));
    CHECK(sx / double(object) > img.width / 2.0);  // right of centre
    CHECK(sy / double(object) < img.height / 2.0); // above centre (image rows grow downwards)
}

namespace {

// The OBJ free-form surfaces of a patches file, read back on their own terms.
std::vector<reeb::BSplinePatch> readFreeFormObj(const std::string& path) {
    std::ifstream in(path);
    std::vector<Vec3d> v;
    std::vector<reeb::BSplinePatch> patches;
    std::vector<std::size_t> refs;
    std::string line;
    while (std::getline(in, line)) {
        std::istringstream s(line);
        std::string key;
        s >> key;
        if (key == "v") {
            Vec3d p;
            s >> p.x >> p.y >> p.z;
            v.push_back(p);
        } else if (key == "deg") {
            int du = 0, dv = 0;
            s >> du >> dv;
            CHECK((du == 3 && dv == 3));
        } else if (key == "surf") {
            double range[4];
            s >> range[0] >> range[1] >> range[2] >> range[3];
            refs.clear();
            for (std::size_t i; s >> i;) refs.push_back(i);
            patches.emplace_back();
        } else if (key == "parm") {
            std::string dir;
            s >> dir;
            std::vector<double>& knots = dir == "u" ? patches.back().knotsU : patches.back().knotsV;
            for (double k; s >> k;) knots.push_back(k);
        } else if (key == "end") {
            reeb::BSplinePatch& p = patches.back();
            p.nu = int(p.knotsU.size()) - 4;
            p.nv = int(p.knotsV.size()) - 4;
            REQUIRE(refs.size() == std::size_t(p.nu * p.nv));
            for (std::size_t i : refs) p.ctrl.push_back(v.at(i - 1));
        }
    }
    return patches;
}

} // namespace

TEST_CASE("patches: B-spline patches, Reeb graph JSON and preview from a DMC mesh, the same at any thread count") {
    test::TempDir dir;
    auto r = runVdbsurf({"mesh", "--expr", "sqrt(pow(sqrt(x*x+z*z)-1,2)+y*y)-0.35", "--bbox", "-1.5,-1.5,-1.5,1.5,1.5,1.5", "--voxel-size",
                         "0.06", "-o", dir.path("torus.obj"), "-q"});
    REQUIRE(r.exitCode == 0);
    for (const std::string threads : {"1", "2"}) {
        r = runVdbsurf({"patches", dir.path("torus.obj"), "-o", dir.path("p" + threads + ".obj"), "--reeb", dir.path("r" + threads + ".json"),
                        "--preview", dir.path("prev" + threads + ".obj"), "--stats", dir.path("s.json"), "--threads", threads});
        INFO(r.output);
        REQUIRE(r.exitCode == 0);
        CHECK(r.output.find("4 nodes, 4 arcs, 1 loops") != std::string::npos);
    }
    for (const std::string name : {"p", "r", "prev"}) {
        const std::string ext = name == "r" ? ".json" : ".obj";
        CHECK(test::readFile(dir.path(name + "1" + ext)) == test::readFile(dir.path(name + "2" + ext)));
    }
    const Mesh input = readMesh(dir.path("torus.obj"));
    const auto reebJson = nlohmann::json::parse(test::readFile(dir.path("r1.json")));
    CHECK(reebJson["nodes"].size() == 4);
    CHECK(reebJson["arcs"].size() == 4);
    CHECK(reebJson["nodes"][0]["type"] == "minimum");
    CHECK(reebJson["nodes"][3]["type"] == "maximum");
    std::vector<char> covered(input.polygonCount(), 0);
    for (const auto& arc : reebJson["arcs"])
        for (std::size_t f : arc["faces"].get<std::vector<std::size_t>>()) covered.at(f) = 1;
    CHECK(std::count(covered.begin(), covered.end(), 1) == std::ptrdiff_t(input.polygonCount()));
    const auto stats = nlohmann::json::parse(test::readFile(dir.path("s.json")));
    CHECK(stats["fit_error_rms"].get<double>() < 0.1);

    // The free-form surfaces as a reader sees them lie on the torus.
    const std::vector<reeb::BSplinePatch> patches = readFreeFormObj(dir.path("p1.obj"));
    REQUIRE(patches.size() == 4);
    const double meanEdge = stats["mean_edge_length"].get<double>();
    for (const reeb::BSplinePatch& p : patches)
        for (int i = 0; i <= 10; ++i)
            for (int j = 0; j <= 10; ++j) {
                const Vec3d q = p.eval(i / 10.0, j / 10.0);
                const double torus = std::sqrt(std::pow(std::sqrt(q.x * q.x + q.z * q.z) - 1, 2) + q.y * q.y) - 0.35;
                CHECK(std::abs(torus) < meanEdge);
            }
    const Mesh preview = readMesh(dir.path("prev1.obj"));
    CHECK(checkTopology(preview).closedManifoldOriented());

    // The same torus stored a point per corner (as files split at seams store them): merged,
    // said so, the same patches.
    const Mesh perCorner = test::pointPerCorner(input);
    writeMesh(dir.path("corners.ply"), perCorner);
    r = runVdbsurf({"patches", dir.path("corners.ply"), "-o", dir.path("pc.obj")});
    INFO(r.output);
    REQUIRE(r.exitCode == 0);
    CHECK(r.output.find(std::to_string(input.indices.size() - input.points.size()) + " points of " + dir.path("corners.ply") +
                        " lie exactly where an earlier one does") != std::string::npos);
    const auto afterComments = [](const std::string& text) { return text.substr(text.find("\nv ")); };
    CHECK(afterComments(test::readFile(dir.path("pc.obj"))) == afterComments(test::readFile(dir.path("p1.obj"))));

    const std::vector<std::string> before = dir.files();
    writeMesh(dir.path("open.obj"), test::openCubeMesh());
    const std::vector<std::string> withOpen = dir.files();
    expectFailure(dir, {"patches", dir.path("open.obj"), "-o", dir.path("x.obj")}, "open.obj", "open", withOpen);
    expectFailure(dir, {"patches", dir.path("torus.obj"), "-o", dir.path("x.ply")}, "x.ply", "use .obj", withOpen);
    expectFailure(dir, {"patches", dir.path("torus.obj"), "-o", dir.path("x.obj"), "--axis", "0,0,0"}, "--axis", "non-zero", withOpen);
    expectFailure(dir, {"patches", dir.path("torus.obj"), "-o", dir.path("x.obj"), "--grid-size", "2,x"}, "--grid-size", "", withOpen);
    expectFailure(dir, {"patches", dir.path("torus.obj"), "-o", dir.path("x.obj"), "--grid-size", "2,2"}, "--grid-size", "U from 4",
                  withOpen);
}
