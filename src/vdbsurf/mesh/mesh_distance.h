// Distance from points to a triangle mesh, for quality measures (compare, benchmarks, tests):
// the mesh's triangles in a uniform hash grid, queried up to a radius. Exact point-triangle
// distances; beyond the radius a query answers the radius itself.
#pragma once
#include "vdbsurf/mesh/mesh.h"

#include <cstdint>
#include <unordered_map>
#include <vector>

namespace vdbsurf {

class MeshDistance {
public:
    // cell: the hash grid's spacing (about the largest query radius works well).
    MeshDistance(const Mesh& mesh, double cell);

    // Distance from p to the nearest triangle, or maxRadius when none is closer.
    double distance(const Vec3d& p, double maxRadius) const;

private:
    struct Tri {
        Vec3d a, b, c;
    };
    std::int64_t key(std::int64_t i, std::int64_t j, std::int64_t k) const;
    std::vector<Tri> mTris;
    double mCell;
    std::unordered_map<std::int64_t, std::vector<std::uint32_t>> mGrid;
};

double pointTriangleDistance(const Vec3d& p, const Vec3d& a, const Vec3d& b, const Vec3d& c);

} // namespace vdbsurf
