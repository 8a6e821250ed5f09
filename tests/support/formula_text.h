// Formula text for ExpressionField test shapes: numbers written exactly, planes through a point,
// and the rotated frames the random sharp-shape tests place their boxes in.
#pragma once
#include "vdbsurf/core/vec3.h"

#include <string>

namespace vdbsurf::test {

// v with 17 significant digits, in parentheses (so a negative value can follow an operator).
std::string num(double v);

// n · (p - c) for the point p = (x, y, z), in parentheses.
std::string dotWith(const Vec3d& n, const Vec3d& c);

// A rotation matrix; a rotated frame's local axes are its columns.
struct Rotation {
    double m[3][3];
    const double* operator[](int r) const { return m[r]; }
};

// Rotation from Euler angles (about x, then y, then z).
Rotation eulerRotation(double ax, double ay, double az);

// Point q of a frame rotated by R and moved by c, in world coordinates.
Vec3d inFrame(const Rotation& R, const Vec3d& c, const Vec3d& q);

} // namespace vdbsurf::test
