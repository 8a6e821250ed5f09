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

bool sameLattice(const openvdb::math::Transform& xform, const LatticeFrame& frame) {
    if (!xform.isLinear()) return false;
    const openvdb::Vec3d o = xform.indexToWorld(openvdb::Vec3d(0, 0, 0));
    const openvdb::Vec3d dx = xform.indexToWorld(openvdb::Vec3d(1, 0, 0)) - o;
    const openvdb::Vec3d dy = xform.indexToWorld(openvdb::Vec3d(0, 1, 0)) - o;
    const openvdb::Vec3d dz = xform.indexToWorld(openvdb::Vec3d(0, 0, 1)) - o;
    const double tol = 1e-9 * frame.h;
    if ((dx - openvdb::Vec3d(frame.h, 0, 0)).length() > tol || (dy - openvdb::Vec3d(0, frame.h, 0)).length() > tol ||
        (dz - openvdb::Vec3d(0, 0, frame.h)).length() > tol)
        return false;
    // The frame's origin must be a voxel centre of the grid.
    const openvdb::Vec3d idx = xform.worldToIndex(openvdb::Vec3d(frame.origin.x, frame.origin.y, frame.origin.z));
    for (int a = 0; a < 3; ++a)
        if (std::fabs(idx[a] - std::nearbyint(idx[a])) > 1e-6) return false;
    return true;
}

template <typename GridT>
PeerMesh run(const GridT& input, double iso, const LatticeFrame* frame) {
    PeerMesh out;
    typename GridT::ConstPtr grid = openvdb::ConstPtrCast<const GridT>(input.copy());
    if (frame && !sameLattice(input.transform(), *frame)) {
        const auto t0 = Clock::now();
        auto target = GridT::create(input.background());
        target->setGridClass(input.getGridClass());
        auto xform = voxelTransform(frame->h, "--voxel-size");
        xform->postTranslate(openvdb::Vec3d(frame->origin.x, frame->origin.y, frame->origin.z));
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

PeerMesh volumeToMeshPeer(const GridBaseCPtr& grid, double iso, const LatticeFrame* frame) {
    if (auto f = openvdb::GridBase::constGrid<openvdb::FloatGrid>(grid)) return run(*f, iso, frame);
    if (auto d = openvdb::GridBase::constGrid<openvdb::DoubleGrid>(grid)) return run(*d, iso, frame);
    throw Error(grid ? grid->getName() : "grid", "volumeToMesh needs a float or double grid");
}

} // namespace vdbsurf
