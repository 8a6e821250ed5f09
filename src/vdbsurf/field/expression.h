// A user formula in x, y, z compiled to a small stack program that can be evaluated on plain
// numbers (values), on intervals (conservative bounds over a box, via Boost.Interval) and on
// dual numbers (exact gradients). Written here rather than taken from an expression library
// because none of the Debian ones (muparser, exprtk) evaluates one parsed formula over all three
// number types, and bounds over a box are what the sparse lattice rests on.
#pragma once
#include "vdbsurf/core/vec3.h"
#include "vdbsurf/field/field.h"

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace vdbsurf {

enum class ExprOp : std::uint8_t {
    Const, X, Y, Z,
    Add, Sub, Mul, Div, Pow, Neg,
    PowInt, // a power by a small whole constant (arg: the exponent as a signed 32-bit value)
    Abs, Sqrt, Exp, Log, Sin, Cos, Tan,
    Min, Max, Clamp
};

struct ExprInstr {
    ExprOp op;
    std::uint32_t arg = 0; // constant index for Const, argument count for Min/Max, exponent for PowInt
};

// Evaluators keep their stack in a fixed array; the parser refuses formulas that need more.
constexpr int kMaxStack = 256;

// How a step ends a min's or max's second or later argument (the bounds fold it in there).
enum class ExprFold : std::uint8_t { None, Min, Max };

struct ExprProgram {
    std::string source;
    std::vector<ExprInstr> code;
    std::vector<double> constants;
    int maxStack = 0;
    // Per step (parseExpression fills them): where a min's or max's second or later argument
    // starts, the index of its last step (-1 elsewhere); at that last step, the fold. The bounds
    // skip such an argument where its natural bounds show it cannot change the min or max.
    std::vector<std::int32_t> argumentEnd;
    std::vector<ExprFold> foldAfter;
    bool skippableArguments = false; // any min or max of two or more arguments
    std::uint64_t id = 0; // unique to each parse (copies share it): keys evalNaturalBoundsKept's steps
};

// Parses + - * / ^, unary minus, parentheses, numbers, x y z, pi, and the functions abs, min,
// max (two or more arguments), sqrt, exp, log, sin, cos, tan, pow, clamp. Throws Error naming
// `input` with the column of the fault and a caret under it.
ExprProgram parseExpression(const std::string& text, const std::string& input = "--expr");

double evalValue(const ExprProgram& prog, const Vec3d& p);
// evalValue at each of n points, bit for bit, several times faster: the program runs over chunks
// of points (see runChunk).
void evalValues(const ExprProgram& prog, const Vec3d* points, std::size_t n, double* out);
// Value and gradient (forward-mode automatic differentiation).
double evalGradient(const ExprProgram& prog, const Vec3d& p, Vec3d& gradient);

// Conservative bounds of the formula over the closed box, with outward rounding:
// - natural: every operation on intervals. Exact for one use of each variable, but a variable
//   used twice is treated as two independent ones, so x^2 + y^2 + z^2 - (a·p)^2 (a spike's or a
//   cylinder's squared radius) over a cell a few units from the origin spans a whole unit where
//   the formula varies by a cell's worth: wide enough that most cells of a CSG formula look as
//   if the surface could pass through them, and the thin search samples them all;
// - evalBounds: at every step also the mean value form f(c) + Σ ∂f/∂x_i (box) · (x_i − c_i), c
//   the box's centre, the partial derivatives bounded over the box by interval forward-mode
//   differentiation, and the intersection of the two kept. Its width shrinks with the box's, so
//   a cell's bounds follow the formula's variation over the cell. Holds the natural bounds.
Interval evalNaturalBounds(const ExprProgram& prog, const Box3& box);
Interval evalBounds(const ExprProgram& prog, const Box3& box);
// The two in stages, for a caller that needs the tight bounds only where the natural ones do not
// decide: evalNaturalBoundsKept gives evalNaturalBounds' value and keeps every step's natural
// bounds (in a buffer of the calling thread); evalBoundsAfterNatural then gives evalBounds' value,
// skipping the min and max arguments that those show cannot be the min or max anywhere in the box
// (a CSG union of 20 spikes: most of its cones, in most boxes). If the kept steps are of another
// program or box, it computes them again.
Interval evalNaturalBoundsKept(const ExprProgram& prog, const Box3& box);
Interval evalBoundsAfterNatural(const ExprProgram& prog, const Box3& box);
// Keeps the natural bounds of every step over `around` (a buffer of the calling thread) for the
// evalNaturalBoundsKept calls over boxes inside it that follow: they skip the min and max
// arguments those rule out (a step's natural bounds over a box lie within its bounds over a box
// around it), with the same results. Until it is called again on this thread.
void keepNaturalStepsAround(const ExprProgram& prog, const Box3& around);

} // namespace vdbsurf
