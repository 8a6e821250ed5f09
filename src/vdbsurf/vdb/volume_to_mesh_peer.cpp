#include "vdbsurf/vdb/volume_to_mesh_peer.h"

#include "vdbsurf/core/error.h"
#include "vdbsurf/vdb/voxel_transform.h"

#include <openvdb/openvdb.h>
#include <openvdb/tools/GridTransformer.h>
#include <openvdb/tools/VolumeToMesh.h>

#include <chrono>
#include <cmath>

namespace vdbsurf {

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

// Do the two transforms put every voxel centre of `a` on one of `b`'s, with the same steps?
bool sameLattice(const openvdb::math::Transform& a, const openvdb::math::Transform& b) {
    if (!a.isLinear() || !b.isLinear()) return false;
    const openvdb::Vec3d o = b.indexToWorld(openvdb::Vec3d(0, 0, 0));
    const double tol = 1e-9 * b.voxelSize().length();
    for (int axis = 0; axis < 3; ++axis) {
        openvdb::Vec3d e(0, 0, 0);
        e[axis] = 1;
        if (((a.indexToWorld(e) - a.indexToWorld(openvdb::Vec3d(0, 0, 0))) - (b.indexToWorld(e) - o)).length() > tol) return false;
    }
    const openvdb::Vec3d idx = a.worldToIndex(o);
    for (int i = 0; i < 3; ++i)
        if (std::fabs(idx[i] - std::nearbyint(idx[i])) > 1e-6) return false;
    return true;
}

template <typename GridT>
PeerMesh run(const GridT& input, double iso, const LatticeFrame* frame, const OwnFrame* own) {
    PeerMesh out;
    typename GridT::ConstPtr grid = openvdb::ConstPtrCast<const GridT>(input.copy());
    const auto xform = frame ? latticeTransform(*frame, own, "--voxel-size") : nullptr;
    if (xform && !sameLattice(input.transform(), *xform)) {
        const auto t0 = Clock::now();
        auto target = GridT::create(input.background());
        target->setGridClass(input.getGridClass());
        target->setTransform(xform);
        openvdb::tools::resampleToMatch<openvdb::tools::BoxSampler>(input, *target);
        grid = target;
        out.resampled = true;
        out.secondsResample = since(t0);
    }
    const auto t0 = Clock::now();
    std::vector<openvdb::Vec3s> points;
    std::vector<openvdb::Vec3I> tris;
    std::vector<openvdb::Vec4I> quads;
    openvdb::tools::volumeToMesh(*grid, points, tris, quads, iso, 0.0);
    out.secondsMesh = since(t0);

    Mesh& m = out.mesh;
    m.points.reserve(points.size());
    for (const auto& p : points) m.points.emplace_back(p.x(), p.y(), p.z());
    m.indices.reserve(3 * tris.size() + 4 * quads.size());
    m.offsets.reserve(tris.size() + quads.size() + 1);
    for (const auto& q : quads) m.addPolygon({q[0], q[1], q[2], q[3]});
    for (const auto& t : tris) m.addPolygon({t[0], t[1], t[2]});
    return out;
}

} // namespace

PeerMesh volumeToMeshPeer(const GridBaseCPtr& grid, double iso, const LatticeFrame* frame, const OwnFrame* own) {
    if (auto f = openvdb::GridBase::constGrid<openvdb::FloatGrid>(grid)) return run(*f, iso, frame, own);
    if (auto d = openvdb::GridBase::constGrid<openvdb::DoubleGrid>(grid)) return run(*d, iso, frame, own);
    throw Error(grid ? grid->getName() : "grid", "volumeToMesh needs a float or double grid");
}

} // namespace vdbsurf
