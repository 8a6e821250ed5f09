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
#include <fstream>
#include <limits>
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

TEST_CASE("OBJ reader: corner forms, negative indices, skipped statements, and errors naming the line") {
    test::TempDir dir;
    const std::string path = dir.path("in.obj");
    {
        std::ofstream out(path);
        out << "# comment\nmtllib x.mtl\no thing\nv 0 0 0\nv 1 0 0 1.0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\n"
               "g group\ns 1\nf 1/1/1 2/1/1 3/1/1\nf -4//1 -2//1 -1//1\nl 1 2\nf 1/1 3 4\r\n";
    }
    const Mesh m = readMesh(path);
    CHECK(m.points.size() == 4);
    CHECK(m.points[1] == Vec3f(1, 0, 0));
    REQUIRE(m.polygonCount() == 3);
    CHECK(std::vector<std::uint32_t>(m.polygon(0), m.polygon(0) + 3) == std::vector<std::uint32_t>{0, 1, 2});
    CHECK(std::vector<std::uint32_t>(m.polygon(1), m.polygon(1) + 3) == std::vector<std::uint32_t>{0, 2, 3});
    CHECK(std::vector<std::uint32_t>(m.polygon(2), m.polygon(2) + 3) == std::vector<std::uint32_t>{0, 2, 3});

    auto fails = [&](const std::string& text, const std::string& expected) {
        std::ofstream(path) << text;
        CHECK_THROWS_WITH(readMesh(path), Catch::Contains(path) && Catch::Contains(expected));
    };
    fails("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", "line 4: face index 4 is out of range");
    fails("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n", "line 4: a face needs at least three vertices");
    fails("v 0 0\n", "line 1: a vertex needs three numbers");
    fails("v 0 0 nan\n", "not finite");
    fails("v 0 0 0\nf 1 x 1\n", "not an index");
    fails("v 0 0 0\n", "holds no polygons");
    // A backslash at a line's end continues it (with a '\r' or blanks after it too), but not a
    // comment's; an error in a continued statement names the line it starts on.
    {
        std::ofstream(path) << "# from C:\\models\\\nv 0 0 0\nv 1 \\\n 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 \\\r\n 3 \\ \n4\nf 1 3 4\n";
        const Mesh c = readMesh(path);
        REQUIRE(c.points.size() == 4);
        CHECK(c.points[1] == Vec3f(1, 0, 0));
        REQUIRE(c.polygonCount() == 2);
        CHECK(std::vector<std::uint32_t>(c.polygon(0), c.polygon(0) + 4) == std::vector<std::uint32_t>{0, 1, 2, 3});
        CHECK(std::vector<std::uint32_t>(c.polygon(1), c.polygon(1) + 3) == std::vector<std::uint32_t>{0, 2, 3});
    }
    fails("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 \\\n2 \\\n9\nf 1 2 3\n", "line 4: face index 9 is out of range");
    fails("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 \\\n", "line 4: a face needs at least three vertices");
    CHECK_THROWS_WITH(readMesh(dir.path("missing.obj")), Catch::Contains("missing.obj"));
    CHECK_THROWS_WITH(readMesh(dir.path("in.stl")), Catch::Contains("unsupported"));
}

TEST_CASE("PLY reader: our binary files, ascii, big-endian, extra properties, and errors") {
    test::TempDir dir;
    const Mesh m = sampleMesh();
    writeMesh(dir.path("m.ply"), m);
    const Mesh back = readMesh(dir.path("m.ply"));
    CHECK(back.points == m.points);
    CHECK(back.indices == m.indices);
    CHECK(back.offsets == m.offsets);

    const std::string ascii = dir.path("a.ply");
    std::ofstream(ascii) << "ply\nformat ascii 1.0\ncomment x\nelement vertex 4\nproperty double x\nproperty double y\n"
                            "property double z\nproperty uchar red\nelement face 2\nproperty list uchar uint vertex_index\n"
                            "property float quality\nelement edge 1\nproperty int a\nproperty int b\nend_header\n"
                            "0 0 0 255\n1 0 0 0\n1 1 0 0\n0 1 0 0\n3 0 1 2 0.5\n3 0 2 3 0.5\n0 1\n";
    const Mesh a = readMesh(ascii);
    CHECK(a.points.size() == 4);
    CHECK(a.polygonCount() == 2);
    CHECK(a.points[2] == Vec3f(1, 1, 0));

    // Big-endian: one triangle, float coordinates and int indices.
    std::string be = "ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                      "element face 1\nproperty list uchar int vertex_indices\nend_header\n";
    auto putBE = [&](std::uint32_t w) {
        for (int s = 24; s >= 0; s -= 8) be.push_back(char((w >> s) & 0xff));
    };
    const float coords[9] = {0, 0, 0, 2, 0, 0, 0, 3, 0};
    for (float f : coords) {
        std::uint32_t w;
        std::memcpy(&w, &f, 4);
        putBE(w);
    }
    be.push_back(char(3));
    for (std::uint32_t i : {0u, 1u, 2u}) putBE(i);
    std::ofstream(dir.path("be.ply"), std::ios::binary) << be;
    const Mesh b = readMesh(dir.path("be.ply"));
    CHECK(b.points[1] == Vec3f(2, 0, 0));
    CHECK(b.points[2] == Vec3f(0, 3, 0));
    CHECK(b.polygonCount() == 1);

    std::ofstream(dir.path("short.ply"), std::ios::binary) << be.substr(0, be.size() - 5);
    CHECK_THROWS_WITH(readMesh(dir.path("short.ply")), Catch::Contains("short.ply") && Catch::Contains("ends before"));
    std::ofstream(dir.path("range.ply")) << "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                                            "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
                                            "0 0 0\n3 0 0 5\n";
    CHECK_THROWS_WITH(readMesh(dir.path("range.ply")), Catch::Contains("out of range"));
    std::ofstream(dir.path("nomagic.ply")) << "solid x\n";
    CHECK_THROWS_WITH(readMesh(dir.path("nomagic.ply")), Catch::Contains("not a PLY"));
    // A damaged count is refused by the bytes left, before any memory is sized by it (a header
    // asking for 4e9 vertices ended in "out of memory" with no file named).
    std::string huge = be;
    huge.replace(huge.find("element vertex 3"), 16, "element vertex 4000000000");
    std::ofstream(dir.path("huge.ply"), std::ios::binary) << huge;
    CHECK_THROWS_WITH(readMesh(dir.path("huge.ply")), Catch::Contains("huge.ply") && Catch::Contains("4000000000 vertex rows"));
    std::ofstream(dir.path("hugeascii.ply")) << "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\n"
                                                "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
                                                "0 0 0\n1 0 0\n0 1 0\n0 0 1\n1 1 1\n3 0 1 2";
    CHECK(readMesh(dir.path("hugeascii.ply")).polygonCount() == 1); // the shortest rows, no newline at the end: taken
    std::ofstream(dir.path("hugeascii2.ply")) << "ply\nformat ascii 1.0\nelement vertex 7\nproperty float x\nproperty float y\n"
                                                 "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
                                                 "0 0 0\n1 0 0\n0 1 0\n0 0 1\n1 1 1\n3 0 1 2";
    CHECK_THROWS_WITH(readMesh(dir.path("hugeascii2.ply")), Catch::Contains("7 vertex rows"));
}

TEST_CASE("mergeCoincidentPoints: equal positions become the first point; unused and non-finite points are left") {
    const float nan = std::numeric_limits<float>::quiet_NaN();
    Mesh m;
    m.points = {{1, 2, 3}, {0, 0, 0}, {1, 2, 3}, {-0.f, 0, 0}, {nan, 0, 0}, {nan, 0, 0}, {1, 2, 3}, {1, 2, 3.0000002f}, {0, 0, 0}};
    m.addPolygon({0, 1, 7});
    m.addPolygon({2, 3, 4});
    m.addPolygon({6, 5, 7});
    // Point 8 lies at point 1 but no polygon uses it: not counted.
    const std::vector<std::uint32_t> given = m.indices;
    CHECK(countCoincidentPoints(m) == 3);
    CHECK(m.indices == given);
    CHECK(mergeCoincidentPoints(m) == 3); // 2 and 6 into 0, -0 (3) into 1
    CHECK(m.indices == std::vector<std::uint32_t>{0, 1, 7, 0, 1, 4, 0, 5, 7});
    CHECK(m.points.size() == 9);
    CHECK(mergeCoincidentPoints(m) == 0);
}
