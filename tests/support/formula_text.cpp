#include "support/formula_text.h"

#include <cmath>
#include <sstream>

namespace vdbsurf::test {

std::string num(double v) {
    std::ostringstream s;
    s.precision(17);
    s << v;
    return "(" + s.str() + ")";
}

std::string dotWith(const Vec3d& n, const Vec3d& c) {
    return "(" + num(n.x) + "*(x-" + num(c.x) + ")+" + num(n.y) + "*(y-" + num(c.y) + ")+" + num(n.z) + "*(z-" + num(c.z) + "))";
}

Rotation eulerRotation(double ax, double ay, double az) {
    const double cx = std::cos(ax), sx = std::sin(ax), cy = std::cos(ay), sy = std::sin(ay), cz = std::cos(az), sz = std::sin(az);
    return {{{cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx},
             {sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx},
             {-sy, cy * sx, cy * cx}}};
}

Vec3d inFrame(const Rotation& R, const Vec3d& c, const Vec3d& q) {
    return c + Vec3d(R[0][0] * q.x + R[0][1] * q.y + R[0][2] * q.z, R[1][0] * q.x + R[1][1] * q.y + R[1][2] * q.z,
                     R[2][0] * q.x + R[2][1] * q.y + R[2][2] * q.z);
}

} // namespace vdbsurf::test
