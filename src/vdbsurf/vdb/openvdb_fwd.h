// Forward declarations of the OpenVDB types that appear in vdbsurf's public headers, so that
// those headers stay light; only .cpp files include OpenVDB's templates.
#pragma once
#include <openvdb/version.h>

#include <memory>

namespace openvdb {
OPENVDB_USE_VERSION_NAMESPACE
namespace OPENVDB_VERSION_NAME {
class GridBase;
namespace math {
class Transform;
} // namespace math
} // namespace OPENVDB_VERSION_NAME
} // namespace openvdb

namespace vdbsurf {
using GridBasePtr = std::shared_ptr<openvdb::GridBase>;
using GridBaseCPtr = std::shared_ptr<const openvdb::GridBase>;
} // namespace vdbsurf
