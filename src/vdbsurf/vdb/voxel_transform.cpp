#include "vdbsurf/vdb/voxel_transform.h"

#include "vdbsurf/core/error.h"

#include <openvdb/math/Math.h>
#include <openvdb/math/Transform.h>

#include <cmath>

namespace vdbsurf {

std::shared_ptr<openvdb::math::Transform> voxelTransform(double voxelSize, const std::string& what) {
    // OpenVDB's ScaleMap: |sx·sy·sz| must reach 3 × its double tolerance.
    const double smallest = std::cbrt(3.0 * openvdb::math::Tolerance<double>::value());
    if (!(voxelSize >= smallest) || !std::isfinite(voxelSize))
        throw Error(what, "a voxel size of " + messageNumber(voxelSize) + " cannot be stored in a .vdb grid (OpenVDB needs at least " +
                              messageNumber(smallest) + " world units); scale the input up or use a larger voxel size");
    return openvdb::math::Transform::createLinearTransform(voxelSize);
}

std::shared_ptr<openvdb::math::Transform> affineTransform(const AffineMap& toWorld, const LatticeFrame& frame, const std::string& what) {
    voxelTransform(frame.h, what); // the lattice's own spacing must be storable
    const double smallest = 3.0 * openvdb::math::Tolerance<double>::value();
    const double det = toWorld.determinant() * frame.h * frame.h * frame.h;
    if (!(std::fabs(det) >= smallest) || !std::isfinite(det))
        throw Error(what, "the lattice's voxels (volume " + messageNumber(std::fabs(det)) + ") cannot be stored in a .vdb grid");
    // World = index * m for OpenVDB's row vectors: node i sits at toWorld(origin + h i).
    openvdb::Mat4d m = openvdb::Mat4d::identity();
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) m(c, r) = toWorld.a[r][c] * frame.h;
    const Vec3d o = toWorld.apply(frame.origin);
    m.setTranslation(openvdb::Vec3d(o.x, o.y, o.z));
    return openvdb::math::Transform::createLinearTransform(m);
}

} // namespace vdbsurf
