#include "vdbsurf/vdb/voxel_transform.h"

#include "vdbsurf/core/error.h"

#include <openvdb/math/Math.h>
#include <openvdb/math/Transform.h>

#include <cmath>

namespace vdbsurf {

namespace {
// OpenVDB's maps refuse a determinant below 3 × their double tolerance.
const double kSmallestDeterminant = 3.0 * openvdb::math::Tolerance<double>::value();

void checkVoxelSize(double voxelSize, const std::string& what) {
    const double smallest = smallestStorableVoxelSize();
    if (!(voxelSize >= smallest) || !std::isfinite(voxelSize))
        throw Error(what, "a voxel size of " + messageNumber(voxelSize) + " cannot be stored in a .vdb grid (OpenVDB needs at least " +
                              messageNumber(smallest) + " world units); scale the input up or use a larger voxel size");
}
} // namespace

double smallestStorableVoxelSize() { return std::cbrt(kSmallestDeterminant); }

std::shared_ptr<openvdb::math::Transform> voxelTransform(double voxelSize, const std::string& what) {
    checkVoxelSize(voxelSize, what);
    return openvdb::math::Transform::createLinearTransform(voxelSize);
}

std::shared_ptr<openvdb::math::Transform> latticeTransform(const LatticeFrame& frame, const OwnFrame* own, const std::string& what) {
    if (!own) {
        auto xform = voxelTransform(frame.h, what);
        xform->postTranslate(openvdb::Vec3d(frame.origin.x, frame.origin.y, frame.origin.z));
        return xform;
    }
    checkVoxelSize(frame.h, what); // the lattice's own spacing must be storable
    if (own->curved) return own->curved->latticeTransform(frame, what);
    const AffineMap* toWorld = &own->toWorld;
    const double det = toWorld->determinant() * frame.h * frame.h * frame.h;
    if (!(std::fabs(det) >= kSmallestDeterminant) || !std::isfinite(det))
        throw Error(what, "the lattice's voxels (volume " + messageNumber(std::fabs(det)) + ") cannot be stored in a .vdb grid");
    // World = index * m for OpenVDB's row vectors: node i sits at toWorld(origin + h i).
    openvdb::Mat4d m = openvdb::Mat4d::identity();
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) m(c, r) = toWorld->a[r][c] * frame.h;
    const Vec3d o = toWorld->apply(frame.origin);
    m.setTranslation(openvdb::Vec3d(o.x, o.y, o.z));
    return openvdb::math::Transform::createLinearTransform(m);
}

} // namespace vdbsurf
