// A Field given by a user formula over a box: negative inside, surface at iso 0 by default.
#pragma once
#include "vdbsurf/field/expression.h"
#include "vdbsurf/field/field.h"

namespace vdbsurf {

class ExpressionField final : public Field {
public:
    // Throws Error naming "--expr" (with the column) or "--bbox".
    ExpressionField(const std::string& formula, const Box3& box);

    double value(const Vec3d& p) const override { return evalValue(mProgram, p); }
    // Many points at once (evalValues): the same values, several times faster; lattice blocks
    // come through it too (Field::sampleNodes).
    void values(const Box3& box, const Vec3d* points, std::size_t n, double* out) const override;
    Vec3d gradient(const Vec3d& p) const override;
    Interval bounds(const Box3& box) const override { return evalBounds(mProgram, box); }
    // The natural bounds first: where they already rule the iso value out (most boxes away from
    // the surface), the derivatives of evalBounds are not needed.
    bool mayStraddle(const Box3& box, double iso) const override;
    // The natural bounds of every step over `around` first: in the boxes inside it, the min and
    // max arguments those show cannot matter are skipped (cells beside one spike of a union of
    // twenty evaluate a fifth of it).
    void mayStraddleWithin(const Box3& around, const Box3* boxes, std::size_t n, double iso, std::uint8_t* out) const override;
    bool mayHoldOtherSide(const Box3& box, bool inside, double iso) const override;
    Inside inside() const override { return Inside::Below; }
    Box3 domain() const override { return mBox; }
    std::string describe() const override { return "--expr \"" + mProgram.source + "\""; }
    const ExprProgram& program() const { return mProgram; }

private:
    ExprProgram mProgram;
    Box3 mBox;
};

} // namespace vdbsurf
