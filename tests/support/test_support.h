// Helpers shared by the tests: closed-form level sets, temporary folders, running the CLI,
// and the shared real-data folder (tests skip with a message when it is absent).
#pragma once
#include "vdbsurf/mesh/mesh.h"
#include "vdbsurf/vdb/openvdb_fwd.h"

#include <array>
#include <cstddef>
#include <functional>
#include <initializer_list>
#include <string>
#include <vector>

namespace vdbsurf::test {

// Narrow-band level sets (half width 3 voxels), inside negative, made through OpenVDB.
GridBasePtr makeSphereLevelSet(double radius, const Vec3d& center, double voxelSize);
// Torus around the z axis (major radius R, minor radius r), from its exact signed distance.
GridBasePtr makeTorusLevelSet(double R, double r, const Vec3d& center, double voxelSize);
// Level set of any signed distance function over a box: exact values within 3 voxels of the
// surface, signs flooded elsewhere.
GridBasePtr makeLevelSetFromDistance(const std::function<double(const Vec3d&)>& sdf, const Box3& box, double voxelSize);
// Fog volume: 1 inside the sphere, smooth ramp to 0 over `ramp` world units outside.
GridBasePtr makeSphereFog(double radius, double ramp, double voxelSize);
// A slab of inside voxels (0.1 apart) with a post on it, and a voxel alone inside beside the
// post's top, across the diagonal of a face whose two other corners hold `between`. Values are
// written as g (negative inside): a level set holds g, a fog 0.5 - g / 4 (inside above its iso
// 0.5). `more`: further inside voxels (index coordinates).
GridBasePtr loneNodeBesidePost(float between, bool fog, const std::vector<std::array<int, 3>>& more = {});

// A 3x3x3 block of lattice sides (index x + 3 y + 9 z, offsets -1 .. 1, the centre at 13), as
// dmc/inside_topology.h reads it, with these offsets inside.
std::array<bool, 27> insideBlock(std::initializer_list<std::array<int, 3>> inside);

// A fresh empty folder under the system temp folder, removed when the object dies.
class TempDir {
public:
    TempDir();
    ~TempDir();
    std::string path(const std::string& name) const { return mPath + "/" + name; }
    const std::string& root() const { return mPath; }
    std::vector<std::string> files() const; // names in the folder

private:
    std::string mPath;
};

struct RunResult {
    int exitCode = -1;
    std::string output; // stdout and stderr together
};
// Runs build/bin/vdbsurf with the arguments (shell-quoted here).
RunResult runVdbsurf(const std::vector<std::string>& args);
// Runs any program (args[0], found on PATH) in workingDir (or the current folder).
RunResult runProgram(const std::vector<std::string>& args, const std::string& workingDir = "");
bool onPath(const std::string& program);

std::string readFile(const std::string& path);
bool fileExists(const std::string& path);

// ../shared/data/<relative>, or "" when the shared folder is absent.
std::string sharedData(const std::string& relative);

void writeGrids(const std::string& path, const std::vector<GridBasePtr>& grids);

// The Euler characteristic V - E + F of a mesh.
long eulerCharacteristic(const Mesh& m);
// Is the closed mesh m `pieces` pieces, none with a handle (Euler characteristic 2 each)?
bool piecesWithoutHandles(const Mesh& m, std::size_t pieces);

} // namespace vdbsurf::test
