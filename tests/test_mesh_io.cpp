// Mesh writers: exact round trip, atomic replacement, level-set output.
#include "support/test_support.h"

#include "vdbsurf/core/error.h"
#include "vdbsurf/field/grid_field.h"
#include "vdbsurf/mesh/mesh_io.h"
#include "vdbsurf/mesh/mesh_to_vdb.h"
#include "vdbsurf/vdb/vdb_file.h"

#include <catch2/catch.hpp>
#include <openvdb/openvdb.h>

#include <cstring>
#include <sstream>

using namespace vdbsurf;

namespace {

Mesh sampleMesh() {
    Mesh m;
    m.points = {{0, 0, 0}, {1.f / 3.f, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0.1f, 0.2f, 1e-7f}, {-2.5f, 3e5f, 7}};
    m.addPolygon({0, 1, 2});
    m.addPolygon({0, 2, 3, 4});
    m.addPolygon({1, 2, 3, 4, 5});
    return m;
}

// A small OBJ parser for the test: "v" and "f" lines only.
Mesh parseObj(const std::string& text) {
    Mesh m;
    std::istringstream in(text);
    std::string line;
    while (std::getline(in, line)) {
        std::istringstream ls(line);
        std::string tag;
        ls >> tag;
        if (tag == "v") {
            Vec3f p;
            ls >> p.x >> p.y >> p.z;
            m.points.push_back(p);
        } else if (tag == "f") {
            std::vector<std::uint32_t> f;
            std::uint32_t i;
            while (ls >> i) f.push_back(i - 1);
            m.addPolygon(f.data(), f.size());
        }
    }
    return m;
}

} // namespace

TEST_CASE("OBJ round-trips exactly") {
    test::TempDir dir;
    const Mesh m = sampleMesh();
    writeMesh(dir.path("m.obj"), m, {"made by a test"});
    const std::string text = test::readFile(dir.path("m.obj"));
    CHECK(text.rfind("# made by a test\n", 0) == 0);
    const Mesh back = parseObj(text);
    REQUIRE(back.points.size() == m.points.size());
    for (std::size_t i = 0; i < m.points.size(); ++i) CHECK(back.points[i] == m.points[i]);
    CHECK(back.offsets == m.offsets);
    CHECK(back.indices == m.indices);
    CHECK(dir.files() == std::vector<std::string>{"m.obj"}); // no temporary left behind
}

TEST_CASE("binary PLY holds the same mesh") {
    test::TempDir dir;
    const Mesh m = sampleMesh();
    writeMesh(dir.path("m.ply"), m);
    const std::string data = test::readFile(dir.path("m.ply"));
    const std::string endTag = "end_header\n";
    const std::size_t body = data.find(endTag);
    REQUIRE(body != std::string::npos);
    const std::string header = data.substr(0, body);
    CHECK(header.find("format binary_little_endian 1.0") != std::string::npos);
    CHECK(header.find("element vertex 6") != std::string::npos);
    CHECK(header.find("element face 3") != std::string::npos);
    const char* p = data.data() + body + endTag.size();
    for (const Vec3f& v : m.points) {
        float xyz[3];
        std::memcpy(xyz, p, 12);
        p += 12;
        CHECK(xyz[0] == v.x);
        CHECK(xyz[1] == v.y);
        CHECK(xyz[2] == v.z);
    }
    for (std::size_t f = 0; f < m.polygonCount(); ++f) {
        CHECK(std::uint8_t(*p++) == m.polygonSize(f));
        for (std::uint32_t i = 0; i < m.polygonSize(f); ++i) {
            std::int32_t idx;
            std::memcpy(&idx, p, 4);
            p += 4;
            CHECK(std::uint32_t(idx) == m.polygon(f)[i]);
        }
    }
    CHECK(p == data.data() + data.size());
}

TEST_CASE("a failed write leaves neither the file nor a temporary") {
    test::TempDir dir;
    Mesh m;
    m.points.resize(300);
    std::vector<std::uint32_t> big(300);
    for (std::uint32_t i = 0; i < 300; ++i) big[i] = i;
    m.addPolygon(big.data(), big.size());
    CHECK_THROWS_WITH(writeMesh(dir.path("big.ply"), m), Catch::Contains("255"));
    CHECK(dir.files().empty());
    CHECK_THROWS_WITH(writeMesh(dir.path("m.stl"), sampleMesh()), Catch::Contains("unsupported"));
    CHECK(dir.files().empty());
}

TEST_CASE("an existing file is replaced only when the new one is complete") {
    test::TempDir dir;
    writeMesh(dir.path("m.obj"), sampleMesh());
    const std::string before = test::readFile(dir.path("m.obj"));
    Mesh bad;
    bad.points.resize(300);
    std::vector<std::uint32_t> big(300);
    for (std::uint32_t i = 0; i < 300; ++i) big[i] = i;
    bad.addPolygon(big.data(), big.size());
    writeMesh(dir.path("m.obj"), bad); // OBJ takes any polygon size
    CHECK(test::readFile(dir.path("m.obj")) != before);
    CHECK_THROWS(writeMesh(dir.path("m.ply"), bad));
    CHECK(dir.files() == std::vector<std::string>{"m.obj"});
}

TEST_CASE("a mesh written as a level set reads back as one, with metadata") {
    test::TempDir dir;
    // An octahedron |x|+|y|+|z| = 1.
    Mesh m;
    m.points = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
    m.addPolygon({0, 2, 4});
    m.addPolygon({2, 1, 4});
    m.addPolygon({1, 3, 4});
    m.addPolygon({3, 0, 4});
    m.addPolygon({2, 0, 5});
    m.addPolygon({1, 2, 5});
    m.addPolygon({3, 1, 5});
    m.addPolygon({0, 3, 5});
    LevelSetWriteOptions o;
    o.voxelSize = 0.05;
    o.metadata = {{"vdbsurf_method", "mc"}};
    writeMeshAsLevelSet(dir.path("o.vdb"), m, o);
    CHECK(dir.files() == std::vector<std::string>{"o.vdb"});
    const LoadedGrid g = readScalarGrid(dir.path("o.vdb"), "");
    CHECK(g.name == "surface");
    CHECK(g.grid->getGridClass() == openvdb::GRID_LEVEL_SET);
    CHECK(g.grid->metaValue<std::string>("vdbsurf_method") == "mc");
    GridField f(g.grid, "o");
    CHECK(f.value({0, 0, 0}) < 0);
    CHECK(f.value({0.6, 0, 0}) < 0);
    CHECK(f.value({0.5, 0.5, 0.5}) > 0);
    CHECK(f.value({0.5, 0.25, 0.25}) == Approx(0.0).margin(0.01));
}
