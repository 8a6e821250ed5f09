#include "vdbsurf/field/expression_field.h"

#include "vdbsurf/core/error.h"

#include <cmath>

namespace vdbsurf {

ExpressionField::ExpressionField(const std::string& formula, const Box3& box)
    : mProgram(parseExpression(formula, "--expr")), mBox(box) {
    for (int a = 0; a < 3; ++a) {
        if (!std::isfinite(box.min[a]) || !std::isfinite(box.max[a]))
            throw Error("--bbox", "bounds must be finite numbers");
        if (!(box.max[a] > box.min[a]))
            throw Error("--bbox", "each maximum must be larger than its minimum (X0,Y0,Z0,X1,Y1,Z1)");
    }
}

void ExpressionField::values(const Box3&, const Vec3d* points, std::size_t n, double* out) const {
    evalValues(mProgram, points, n, out);
}

bool ExpressionField::mayStraddle(const Box3& box, double iso) const {
    const Interval natural = evalNaturalBoundsKept(mProgram, box);
    if (!straddles(natural, iso)) return false;
    return straddles(evalBoundsAfterNatural(mProgram, box), iso);
}

void ExpressionField::mayStraddleWithin(const Box3& around, const Box3* boxes, std::size_t n, double iso, std::uint8_t* out) const {
    if (n > 1) keepNaturalStepsAround(mProgram, around);
    for (std::size_t i = 0; i < n; ++i) out[i] = mayStraddle(boxes[i], iso);
}

bool ExpressionField::mayHoldOtherSide(const Box3& box, bool inside, double iso) const {
    return mayBeOtherSide(inside, evalNaturalBoundsKept(mProgram, box), iso, Inside::Below) &&
           mayBeOtherSide(inside, evalBoundsAfterNatural(mProgram, box), iso, Inside::Below);
}

Vec3d ExpressionField::gradient(const Vec3d& p) const {
    Vec3d g;
    evalGradient(mProgram, p, g);
    return g;
}

} // namespace vdbsurf
