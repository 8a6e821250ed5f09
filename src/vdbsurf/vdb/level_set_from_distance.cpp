#include "vdbsurf/vdb/level_set_from_distance.h"

#include "vdbsurf/vdb/vdb_file.h"
#include "vdbsurf/vdb/voxel_transform.h"

#include <openvdb/openvdb.h>
#include <openvdb/tools/SignedFloodFill.h>

#include <cmath>

namespace vdbsurf {

GridBasePtr levelSetFromDistance(const std::function<double(const Vec3d&)>& sdf, const Box3& box, double voxelSize, double halfWidth) {
    initializeOpenVdb();
    const float band = float(halfWidth * voxelSize);
    auto g = openvdb::FloatGrid::create(band);
    g->setTransform(voxelTransform(voxelSize, "voxel size"));
    g->setGridClass(openvdb::GRID_LEVEL_SET);
    g->setName("surface");
    auto acc = g->getAccessor();
    const openvdb::Coord lo = openvdb::Coord::floor(openvdb::Vec3d(box.min.x, box.min.y, box.min.z) / voxelSize);
    const openvdb::Coord hi = openvdb::Coord::floor(openvdb::Vec3d(box.max.x, box.max.y, box.max.z) / voxelSize) + openvdb::Coord(1);
    for (int i = lo.x(); i <= hi.x(); ++i)
        for (int j = lo.y(); j <= hi.y(); ++j)
            for (int k = lo.z(); k <= hi.z(); ++k) {
                const openvdb::Vec3d p = g->indexToWorld(openvdb::Coord(i, j, k));
                const float d = float(sdf(Vec3d(p.x(), p.y(), p.z())));
                if (std::fabs(d) < band) acc.setValue(openvdb::Coord(i, j, k), d);
            }
    openvdb::tools::signedFloodFill(g->tree());
    return g;
}

} // namespace vdbsurf
