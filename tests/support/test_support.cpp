#include "support/test_support.h"

#include "vdbsurf/mesh/mesh_check.h"
#include "vdbsurf/vdb/level_set_from_distance.h"
#include "vdbsurf/vdb/vdb_file.h"

#include <openvdb/openvdb.h>
#include <openvdb/tools/LevelSetSphere.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <sys/wait.h>
#include <unistd.h>

namespace fs = std::filesystem;

namespace vdbsurf::test {

GridBasePtr makeSphereLevelSet(double radius, const Vec3d& center, double voxelSize) {
    initializeOpenVdb();
    auto g = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(float(radius), openvdb::Vec3f(float(center.x), float(center.y), float(center.z)),
                                                                      float(voxelSize), 3.0f);
    g->setName("sphere");
    return g;
}

GridBasePtr makeLevelSetFromDistance(const std::function<double(const Vec3d&)>& sdf, const Box3& box, double voxelSize) {
    return levelSetFromDistance(sdf, box, voxelSize);
}

GridBasePtr makeTorusLevelSet(double R, double r, const Vec3d& center, double voxelSize) {
    const Vec3d reach(R + r + 4 * voxelSize, R + r + 4 * voxelSize, r + 4 * voxelSize);
    auto g = makeLevelSetFromDistance(
        [&](const Vec3d& p) {
            const Vec3d d = p - center;
            const double q = std::sqrt(d.x * d.x + d.y * d.y) - R;
            return std::sqrt(q * q + d.z * d.z) - r;
        },
        {center - reach, center + reach}, voxelSize);
    g->setName("torus");
    return g;
}

std::array<bool, 27> insideBlock(std::initializer_list<std::array<int, 3>> inside) {
    std::array<bool, 27> b{};
    for (const auto& o : inside) b[std::size_t((o[0] + 1) + 3 * (o[1] + 1) + 9 * (o[2] + 1))] = true;
    return b;
}

GridBasePtr loneNodeBesidePost(float between, bool fog, const std::vector<std::array<int, 3>>& more) {
    initializeOpenVdb();
    auto grid = openvdb::FloatGrid::create(fog ? 0.0f : 1.0f);
    grid->setTransform(openvdb::math::Transform::createLinearTransform(0.1));
    grid->setGridClass(fog ? openvdb::GRID_FOG_VOLUME : openvdb::GRID_LEVEL_SET);
    auto acc = grid->getAccessor();
    auto put = [&](int x, int y, int z, float g) { acc.setValue(openvdb::Coord(x, y, z), fog ? 0.5f - 0.25f * g : g); };
    // Every voxel of the box around the shape is active, so that the grid's domain holds it.
    for (int x = 0; x <= 16; ++x)
        for (int y = 0; y <= 16; ++y)
            for (int z = 0; z <= 12; ++z) put(x, y, z, 1.0f);
    for (int x = 2; x <= 14; ++x)
        for (int y = 2; y <= 14; ++y)
            for (int z = 2; z <= 4; ++z) put(x, y, z, -1.0f);
    put(8, 9, 5, -1.0f);
    put(8, 9, 6, -1.0f);   // the post's top, d
    put(8, 8, 7, -1.0f);   // the lone node, n
    put(8, 9, 7, between); // a
    put(8, 8, 6, between); // b
    for (const auto& c : more) put(c[0], c[1], c[2], -1.0f);
    return grid;
}

GridBasePtr makeSphereFog(double radius, double ramp, double voxelSize) {
    initializeOpenVdb();
    auto g = openvdb::FloatGrid::create(0.0f);
    g->setTransform(openvdb::math::Transform::createLinearTransform(voxelSize));
    g->setGridClass(openvdb::GRID_FOG_VOLUME);
    g->setName("density");
    auto acc = g->getAccessor();
    const int n = int(std::ceil((radius + ramp) / voxelSize)) + 2;
    for (int i = -n; i <= n; ++i)
        for (int j = -n; j <= n; ++j)
            for (int k = -n; k <= n; ++k) {
                const double d = voxelSize * std::sqrt(double(i * i + j * j + k * k)) - radius;
                const double t = std::clamp(d / ramp, 0.0, 1.0);
                const float v = float(1.0 - t * t * (3 - 2 * t)); // smoothstep down
                if (v > 0) acc.setValue(openvdb::Coord(i, j, k), v);
            }
    return g;
}

TempDir::TempDir() {
    std::string tmpl = (fs::temp_directory_path() / "vdbsurf-test-XXXXXX").string();
    std::vector<char> buf(tmpl.begin(), tmpl.end());
    buf.push_back('\0');
    if (!::mkdtemp(buf.data())) throw std::runtime_error("mkdtemp failed");
    mPath = buf.data();
}

TempDir::~TempDir() {
    std::error_code ec;
    fs::remove_all(mPath, ec);
}

std::vector<std::string> TempDir::files() const {
    std::vector<std::string> out;
    for (const auto& e : fs::directory_iterator(mPath)) out.push_back(e.path().filename().string());
    std::sort(out.begin(), out.end());
    return out;
}

namespace {
std::string shellQuote(const std::string& s) {
    std::string q = "'";
    for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
    return q + "'";
}
} // namespace

RunResult runVdbsurf(const std::vector<std::string>& args) {
    std::vector<std::string> all{VDBSURF_BIN};
    all.insert(all.end(), args.begin(), args.end());
    return runProgram(all);
}

RunResult runProgram(const std::vector<std::string>& args, const std::string& workingDir) {
    std::string cmd = workingDir.empty() ? std::string() : "cd " + shellQuote(workingDir) + " && ";
    for (std::size_t i = 0; i < args.size(); ++i) cmd += (i ? " " : "") + shellQuote(args[i]);
    cmd += " 2>&1";
    RunResult r;
    FILE* pipe = ::popen(cmd.c_str(), "r");
    if (!pipe) return r;
    std::array<char, 4096> buf;
    std::size_t n;
    while ((n = std::fread(buf.data(), 1, buf.size(), pipe)) > 0) r.output.append(buf.data(), n);
    const int status = ::pclose(pipe);
    r.exitCode = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
    return r;
}

std::string readFile(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
}

bool fileExists(const std::string& path) { return fs::exists(path); }

bool onPath(const std::string& program) {
    return std::system(("command -v " + shellQuote(program) + " > /dev/null 2>&1").c_str()) == 0;
}

std::string sharedData(const std::string& relative) {
    const fs::path p = fs::path(VDBSURF_SHARED_DATA) / relative;
    return fs::exists(p) ? p.string() : std::string();
}

void writeGrids(const std::string& path, const std::vector<GridBasePtr>& grids) { writeVdbFile(path, grids); }

long eulerCharacteristic(const Mesh& m) { return long(m.points.size()) - long(checkTopology(m).edges) + long(m.polygonCount()); }

bool piecesWithoutHandles(const Mesh& m, std::size_t pieces) { return countComponents(m) == pieces && eulerCharacteristic(m) == 2 * long(pieces); }

} // namespace vdbsurf::test
