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

} // namespace vdbsurf
