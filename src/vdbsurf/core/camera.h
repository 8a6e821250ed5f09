// A pinhole camera as users give it (position, target, up, horizontal field of view, image
// size in pixels), and its projection to pixels. Shared by view-dependent subdivision and the
// POV-Ray writer, so a refined mesh is rendered from the camera it was refined for.
#pragma once
#include "vdbsurf/core/vec3.h"

#include <string>

namespace vdbsurf {

struct ViewCamera {
    Vec3d position{0, 0, 5};
    Vec3d target{0, 0, 0};
    Vec3d up{0, 1, 0};
    double fovDegrees = 45; // horizontal, as POV-Ray's `angle` and Houdini's aperture
    int width = 640, height = 480;
};

// Throws Error naming `input` when the camera cannot form an image (target at the position,
// up along the view direction, fov outside (0, 180), image size not positive).
void validateCamera(const ViewCamera& camera, const std::string& input);

// A camera that sees the whole box from the front-right-above (+x, +y, +z side), for output
// that needs a camera when the user gave none.
ViewCamera framingCamera(const Box3& box, int width = 640, int height = 480);

class CameraProjection {
public:
    explicit CameraProjection(const ViewCamera& camera);
    // Camera space: x right, y up, z along the view direction (depth).
    Vec3d toCamera(const Vec3d& p) const;
    // Pixel coordinates of a camera-space point with positive depth.
    double pixelX(const Vec3d& c) const { return (0.5 + c.x / (c.z * 2 * mTanX)) * mWidth; }
    double pixelY(const Vec3d& c) const { return (0.5 - c.y / (c.z * 2 * mTanY)) * mHeight; }
    double tanHalfX() const { return mTanX; }
    double tanHalfY() const { return mTanY; }
    const Vec3d& eye() const { return mEye; }

private:
    Vec3d mEye, mRight, mUp, mForward;
    double mTanX, mTanY, mWidth, mHeight;
};

} // namespace vdbsurf
