// Distance from points to a triangle mesh, for quality measures (compare, patches' fit error,
// benchmarks, tests): the mesh's triangles in hash grids, queried up to a radius. Exact
// point-triangle distances; beyond the radius a query answers the radius itself. The grids only
// prune (the answer does not depend on them), and they come in levels: a triangle goes to the
// first level whose cells, 4^L times the asked spacing, it spans at most 4 of a side, so a mesh
// of mixed scales (a tiny piece beside a large one, one long sliver) costs a few cells a triangle
// to build and a few cells a level to query.
#pragma once
#include "vdbsurf/mesh/mesh.h"

#include <cstdint>
#include <unordered_map>
#include <vector>

namespace vdbsurf {

class MeshDistance {
public:
    // cell: the finest grid's spacing (about the largest query radius works well).
    MeshDistance(const Mesh& mesh, double cell);

    // Distance from p to the nearest triangle, or maxRadius when none is closer.
    double distance(const Vec3d& p, double maxRadius) const;

private:
    struct Tri {
        Vec3d a, b, c;
    };
    struct Level {
        double cell = 0;
        std::vector<std::uint32_t> tris;
        std::unordered_map<std::int64_t, std::vector<std::uint32_t>> cells;
    };
    static std::int64_t key(std::int64_t i, std::int64_t j, std::int64_t k);
    double nearest(const std::vector<std::uint32_t>& tris, const Vec3d& p, double best) const;
    std::vector<Tri> mTris;
    std::vector<Level> mLevels;
    std::vector<std::uint32_t> mLoose; // finite triangles beyond every level's cell indices
};

double pointTriangleDistance(const Vec3d& p, const Vec3d& a, const Vec3d& b, const Vec3d& c);

} // namespace vdbsurf
