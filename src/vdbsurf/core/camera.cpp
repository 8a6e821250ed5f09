#include "vdbsurf/core/camera.h"

#include "vdbsurf/core/error.h"

#include <algorithm>
#include <cmath>

namespace vdbsurf {

void validateCamera(const ViewCamera& c, const std::string& input) {
    const Vec3d forward = c.target - c.position;
    if (!(length(forward) > 0)) throw Error(input, "the camera target is at the camera position");
    if (!(length(cross(forward, c.up)) > 1e-9 * length(forward) * length(c.up))) throw Error(input, "the camera's up vector is along its view direction (or zero)");
    if (!(c.fovDegrees > 0 && c.fovDegrees < 180)) throw Error(input, "the field of view must be between 0 and 180 degrees");
    if (c.width <= 0 || c.height <= 0) throw Error(input, "the image size must be positive");
}

ViewCamera framingCamera(const Box3& box, int width, int height) {
    ViewCamera c;
    c.width = width;
    c.height = height;
    c.target = (box.min + box.max) * 0.5;
    const double radius = std::max(0.5 * length(box.max - box.min), 1e-9);
    c.fovDegrees = 40;
    const double vertical = 2 * std::atan(std::tan(c.fovDegrees * M_PI / 360) * height / width);
    const double distance = radius / std::sin(0.5 * std::min(vertical, c.fovDegrees * M_PI / 180)) * 1.05;
    c.position = c.target + normalized(Vec3d(0.45, 0.35, 1.0)) * distance;
    return c;
}

CameraProjection::CameraProjection(const ViewCamera& c) {
    mEye = c.position;
    mForward = normalized(c.target - c.position);
    mRight = normalized(cross(mForward, c.up));
    mUp = cross(mRight, mForward);
    mTanX = std::tan(c.fovDegrees * M_PI / 360);
    mTanY = mTanX * double(c.height) / double(c.width);
    mWidth = c.width;
    mHeight = c.height;
}

Vec3d CameraProjection::toCamera(const Vec3d& p) const {
    const Vec3d d = p - mEye;
    return {dot(d, mRight), dot(d, mUp), dot(d, mForward)};
}

} // namespace vdbsurf
