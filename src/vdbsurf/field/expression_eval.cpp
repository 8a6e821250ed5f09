// One stack machine, four number types: double (values), Dual (value + gradient), a Boost.Interval
// type with outward rounding (natural bounds) and Centred (bounds over a box, the value at its
// centre and interval partial derivatives: the mean value form's bounds). Values at many points
// run the same program over chunks of points (runChunk). Any step whose interval result is undefined (e.g.
// 0 * inf, an empty domain) widens to the whole real line, which keeps the bounds conservative;
// the point evaluation then reports the undefined value itself.
#include "vdbsurf/field/expression.h"

#include <boost/numeric/interval.hpp>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>
#include <new>
#include <type_traits>
#include <vector>

namespace vdbsurf {

namespace {

namespace bi = boost::numeric::interval_lib;
// The "opp" policies compute every bound with the FPU rounding upward (lower bounds as negated
// upper bounds), so the rounding mode is switched once per evaluation (ProtectedInterval's
// rounding object in evalBounds) instead of around every operation.
using ProtectedInterval = boost::numeric::interval<
    double, bi::policies<bi::save_state<bi::rounded_transc_opp<double>>, bi::checking_base<double>>>;
using BInterval = bi::unprotect<ProtectedInterval>::type;

constexpr double kInf = std::numeric_limits<double>::infinity();

bool isIntegerConstant(double v) { return std::isfinite(v) && v == std::nearbyint(v) && std::fabs(v) < 1e9; }

// a^n by repeated squaring (a^2 is one correctly rounded product); a negative n divides once.
double wholePower(double a, int n) {
    double r = 1, b = a;
    for (unsigned m = n < 0 ? 0u - unsigned(n) : unsigned(n); m; m >>= 1) {
        if (m & 1u) r *= b;
        if (m > 1) b *= b;
    }
    return n < 0 ? 1 / r : r;
}

// ---- double -------------------------------------------------------------------------------
struct ScalarOps {
    using T = double;
    static T constant(double c) { return c; }
    static T var(double v, int) { return v; }
    static T add(T a, T b) { return a + b; }
    static T sub(T a, T b) { return a - b; }
    static T mul(T a, T b) { return a * b; }
    static T div(T a, T b) { return a / b; }
    static T pow(T a, T b) { return std::pow(a, b); }
    static T powInt(T a, int n) { return wholePower(a, n); }
    static T neg(T a) { return -a; }
    static T abs(T a) { return std::fabs(a); }
    static T sqrt(T a) { return std::sqrt(a); }
    static T exp(T a) { return std::exp(a); }
    static T log(T a) { return std::log(a); }
    static T sin(T a) { return std::sin(a); }
    static T cos(T a) { return std::cos(a); }
    static T tan(T a) { return std::tan(a); }
    static T min(T a, T b) { return b < a ? b : a; }
    static T max(T a, T b) { return b > a ? b : a; }
};

// ---- dual numbers: value and the three partial derivatives -------------------------------------
struct Dual {
    double v;
    Vec3d d;
};

struct DualOps {
    using T = Dual;
    static T constant(double c) { return {c, {}}; }
    static T var(const Dual& x, int axis) {
        Dual r{x.v, {}};
        r.d[std::size_t(axis)] = 1.0;
        return r;
    }
    static T add(const T& a, const T& b) { return {a.v + b.v, a.d + b.d}; }
    static T sub(const T& a, const T& b) { return {a.v - b.v, a.d - b.d}; }
    static T mul(const T& a, const T& b) { return {a.v * b.v, a.d * b.v + b.d * a.v}; }
    static T div(const T& a, const T& b) { return {a.v / b.v, (a.d * b.v - b.d * a.v) / (b.v * b.v)}; }
    static T powInt(const T& a, int n) { return {wholePower(a.v, n), a.d * (n == 0 ? 0.0 : n * wholePower(a.v, n - 1))}; }
    static T pow(const T& a, const T& b) {
        if (b.d == Vec3d() && isIntegerConstant(b.v)) {
            const double n = b.v;
            return {std::pow(a.v, n), a.d * (n == 0 ? 0.0 : n * std::pow(a.v, n - 1))};
        }
        const double v = std::pow(a.v, b.v);
        return {v, (b.d * std::log(a.v) + a.d * (b.v / a.v)) * v};
    }
    static T neg(const T& a) { return {-a.v, -a.d}; }
    static T abs(const T& a) { return a.v < 0 ? neg(a) : a; }
    static T sqrt(const T& a) {
        const double s = std::sqrt(a.v);
        return {s, a.d * (0.5 / s)};
    }
    static T exp(const T& a) {
        const double e = std::exp(a.v);
        return {e, a.d * e};
    }
    static T log(const T& a) { return {std::log(a.v), a.d / a.v}; }
    static T sin(const T& a) { return {std::sin(a.v), a.d * std::cos(a.v)}; }
    static T cos(const T& a) { return {std::cos(a.v), a.d * -std::sin(a.v)}; }
    static T tan(const T& a) {
        const double t = std::tan(a.v);
        return {t, a.d * (1.0 + t * t)};
    }
    static T min(const T& a, const T& b) { return b.v < a.v ? b : a; }
    static T max(const T& a, const T& b) { return b.v > a.v ? b : a; }
};

// ---- intervals ------------------------------------------------------------------------------
struct IntervalOps {
    using T = BInterval;
    static T whole() { return T(-kInf, kInf); }
    static T fix(const T& r) {
        if (boost::numeric::empty(r) || std::isnan(r.lower()) || std::isnan(r.upper())) return whole();
        return r;
    }
    // glibc's transcendental functions are not correctly rounded, least of all under directed
    // rounding; a few ulps outwards cover their documented error (and std::pow's, for x^y).
    static double down(double v) {
        for (int i = 0; i < 4; ++i) v = std::nextafter(v, -kInf);
        return v;
    }
    static double up(double v) {
        for (int i = 0; i < 4; ++i) v = std::nextafter(v, kInf);
        return v;
    }
    static T widen(const T& r) {
        if (boost::numeric::empty(r)) return whole();
        return T(down(r.lower()), up(r.upper()));
    }
    static T constant(double c) { return T(c); }
    static T var(const T& v, int) { return v; }
    static T add(const T& a, const T& b) { return fix(a + b); }
    static T sub(const T& a, const T& b) { return fix(a - b); }
    static T mul(const T& a, const T& b) { return fix(a * b); }
    static T div(const T& a, const T& b) {
        if (b.lower() == 0.0 && b.upper() == 0.0) return whole();
        return fix(a / b);
    }
    static T powInt(const T& a, int n) {
        if (n < 0 && boost::numeric::in_zero(a)) return whole();
        return fix(boost::numeric::pow(a, n));
    }
    static T pow(const T& a, const T& b) {
        if (boost::numeric::singleton(b) && isIntegerConstant(b.lower())) return powInt(a, int(b.lower()));
        // Real exponent: defined only for a >= 0 (points with a < 0 evaluate to NaN and are reported).
        if (a.upper() < 0.0) return whole();
        const T pos(std::max(a.lower(), 0.0), a.upper());
        return fix(exp(mul(b, log(pos))));
    }
    static T neg(const T& a) { return -a; }
    static T abs(const T& a) { return fix(boost::numeric::abs(a)); }
    static T sqrt(const T& a) {
        if (a.upper() < 0.0) return whole();
        return fix(boost::numeric::sqrt(a));
    }
    static T exp(const T& a) {
        if (a.upper() == kInf || a.lower() == -kInf) {
            // Boost's rounded exp on infinite ends is fine, but keep it explicit and monotone.
            const double lo = a.lower() == -kInf ? 0.0 : down(std::exp(a.lower()));
            const double hi = a.upper() == kInf ? kInf : up(std::exp(a.upper()));
            return T(std::max(lo, 0.0), hi);
        }
        return widen(fix(boost::numeric::exp(a)));
    }
    static T log(const T& a) {
        if (a.upper() <= 0.0) return whole();
        if (a.lower() <= 0.0) return T(-kInf, up(std::log(a.upper())));
        return widen(fix(boost::numeric::log(a)));
    }
    static T periodic(const T& a, T (*f)(const T&)) {
        if (!std::isfinite(a.lower()) || !std::isfinite(a.upper())) return T(-1.0, 1.0);
        return widen(fix(f(a)));
    }
    static T sin(const T& a) { return periodic(a, [](const T& x) { return boost::numeric::sin(x); }); }
    static T cos(const T& a) { return periodic(a, [](const T& x) { return boost::numeric::cos(x); }); }
    static T tan(const T& a) {
        if (!std::isfinite(a.lower()) || !std::isfinite(a.upper())) return whole();
        return widen(fix(boost::numeric::tan(a)));
    }
    static T min(const T& a, const T& b) { return T(std::min(a.lower(), b.lower()), std::min(a.upper(), b.upper())); }
    static T max(const T& a, const T& b) { return T(std::max(a.lower(), b.lower()), std::max(a.upper(), b.upper())); }
};

// ---- centred bounds: an interval with the formula's value at the box's centre and interval
// partial derivatives, tightened at every step -------------------------------------------------
// Every step's result is bounded two ways over the box: by its operands' bounds (natural
// interval arithmetic), and by the mean value form f(c) + Σ ∂f/∂x_i · (x_i − c_i), with f(c) from
// the operands' values at the centre and the partial derivatives bounded over the box; it keeps
// the intersection. So the value interval that a later step's derivative reads is the tight one
// too: the squared radius q = x² + y² + z² − (a·p)² of a spike a unit from the origin is, over a
// cell, q(c) ± a cell's worth, not q(c) ± a unit, and √q's derivative 1/(2√q) stays bounded
// wherever the cell is off the spike's axis. At a kink of min, max or abs inside the box, both
// sides' derivatives count (the generalized gradient of a Lipschitz function lies in their
// hull); where a derivative is unbounded (sqrt or log at 0, a pole, a division by an interval
// holding 0) it is the whole line and the step keeps its natural bounds.
struct Centred {
    BInterval v;  // over the box
    BInterval at; // at the box's centre
    BInterval d[3];
};

class CentredOps {
public:
    using T = Centred;
    using I = IntervalOps;
    // halfWidth[i]: |x_i − c_i| at most, over the box.
    explicit CentredOps(const double* halfWidth) : mHalfWidth{halfWidth[0], halfWidth[1], halfWidth[2]} {}

    T constant(double c) const { return {BInterval(c), BInterval(c), {BInterval(0.0), BInterval(0.0), BInterval(0.0)}}; }
    T var(const T& x, int axis) const {
        T r{x.v, x.at, {BInterval(0.0), BInterval(0.0), BInterval(0.0)}};
        r.d[axis] = BInterval(1.0);
        return r;
    }
    T add(const T& a, const T& b) const {
        return tight({I::add(a.v, b.v), I::add(a.at, b.at), {I::add(a.d[0], b.d[0]), I::add(a.d[1], b.d[1]), I::add(a.d[2], b.d[2])}});
    }
    T sub(const T& a, const T& b) const {
        return tight({I::sub(a.v, b.v), I::sub(a.at, b.at), {I::sub(a.d[0], b.d[0]), I::sub(a.d[1], b.d[1]), I::sub(a.d[2], b.d[2])}});
    }
    T mul(const T& a, const T& b) const {
        // A constant factor (a formula's coefficients): its derivatives are zero.
        if (constantIn(b)) return scaled(a, b.v, b.at);
        if (constantIn(a)) return scaled(b, a.v, a.at);
        T r{I::mul(a.v, b.v), I::mul(a.at, b.at), {}};
        for (int i = 0; i < 3; ++i) r.d[i] = I::add(I::mul(a.d[i], b.v), I::mul(a.v, b.d[i]));
        return tight(r);
    }
    T div(const T& a, const T& b) const {
        T r{I::div(a.v, b.v), I::div(a.at, b.at), {}};
        if (boost::numeric::in_zero(b.v)) return unbounded(r);
        // (a' − (a/b)·b') / b: every point's quotient rule, with a/b taken from its bounds.
        for (int i = 0; i < 3; ++i) r.d[i] = I::div(I::sub(a.d[i], I::mul(r.v, b.d[i])), b.v);
        return tight(r);
    }
    T powInt(const T& a, int n) const {
        if (n == 0) return constant(1.0);
        if (n == 1) return a;
        if (n == 2) return chain(I::powInt(a.v, 2), I::powInt(a.at, 2), I::add(a.v, a.v), a);
        return chain(I::powInt(a.v, n), I::powInt(a.at, n), I::mul(BInterval(double(n)), I::powInt(a.v, n - 1)), a);
    }
    T pow(const T& a, const T& b) const {
        if (boost::numeric::singleton(b.v) && isIntegerConstant(b.v.lower()) && constantIn(b)) return powInt(a, int(b.v.lower()));
        T r{I::pow(a.v, b.v), I::pow(a.at, b.at), {}};
        if (!(a.v.lower() > 0.0)) return unbounded(r);
        // a^b = exp(b log a): (a^b)' = a^b (b' log a + b a'/a).
        const BInterval logA = I::log(a.v);
        for (int i = 0; i < 3; ++i) r.d[i] = I::mul(r.v, I::add(I::mul(b.d[i], logA), I::mul(b.v, I::div(a.d[i], a.v))));
        return tight(r);
    }
    T neg(const T& a) const { return {-a.v, -a.at, {-a.d[0], -a.d[1], -a.d[2]}}; }
    T abs(const T& a) const {
        if (a.v.lower() >= 0.0) return a;
        if (a.v.upper() <= 0.0) return neg(a);
        return tight({I::abs(a.v), I::abs(a.at), {hull(a.d[0], -a.d[0]), hull(a.d[1], -a.d[1]), hull(a.d[2], -a.d[2])}});
    }
    T sqrt(const T& a) const {
        const BInterval r = I::sqrt(a.v), at = I::sqrt(a.at);
        if (constantIn(a)) return {r, at, {a.d[0], a.d[1], a.d[2]}};
        if (!(a.v.lower() > 0.0)) return unbounded({r, at, {}});
        return chain(r, at, I::div(BInterval(0.5), r), a);
    }
    T exp(const T& a) const {
        const BInterval r = I::exp(a.v);
        return chain(r, I::exp(a.at), r, a);
    }
    T log(const T& a) const {
        const BInterval r = I::log(a.v), at = I::log(a.at);
        if (!(a.v.lower() > 0.0)) return unbounded({r, at, {}});
        return chain(r, at, I::div(BInterval(1.0), a.v), a);
    }
    T sin(const T& a) const { return chain(I::sin(a.v), I::sin(a.at), I::cos(a.v), a); }
    T cos(const T& a) const { return chain(I::cos(a.v), I::cos(a.at), -I::sin(a.v), a); }
    T tan(const T& a) const {
        const BInterval r = I::tan(a.v);
        return chain(r, I::tan(a.at), I::add(BInterval(1.0), I::mul(r, r)), a);
    }
    // One side throughout the box, or both sides' derivatives where the box holds the kink.
    T min(const T& a, const T& b) const {
        if (a.v.upper() < b.v.lower()) return a;
        if (b.v.upper() < a.v.lower()) return b;
        return tight({I::min(a.v, b.v), I::min(a.at, b.at), {hull(a.d[0], b.d[0]), hull(a.d[1], b.d[1]), hull(a.d[2], b.d[2])}});
    }
    T max(const T& a, const T& b) const {
        if (a.v.lower() > b.v.upper()) return a;
        if (b.v.lower() > a.v.upper()) return b;
        return tight({I::max(a.v, b.v), I::max(a.at, b.at), {hull(a.d[0], b.d[0]), hull(a.d[1], b.d[1]), hull(a.d[2], b.d[2])}});
    }

private:
    double mHalfWidth[3];

    static BInterval hull(const BInterval& a, const BInterval& b) {
        return BInterval(std::min(a.lower(), b.lower()), std::max(a.upper(), b.upper()));
    }
    static bool constantIn(const T& a) {
        for (const BInterval& d : a.d)
            if (d.lower() != 0.0 || d.upper() != 0.0) return false;
        return true;
    }
    static T unbounded(T r) {
        for (BInterval& d : r.d) d = I::whole();
        return r;
    }
    // a·k for a constant k (bounds kv over the box, kc at the centre): linear, so the mean value
    // form of the product is k times a's and tightens nothing a's own did not.
    T scaled(const T& a, const BInterval& kv, const BInterval& kc) const {
        return {I::mul(a.v, kv), I::mul(a.at, kc), {I::mul(a.d[0], kv), I::mul(a.d[1], kv), I::mul(a.d[2], kv)}};
    }
    // Value r over the box and rc at the centre; each derivative s·a.d[i] (the chain rule through
    // a function of one argument whose derivative over the box is s).
    T chain(const BInterval& r, const BInterval& rc, const BInterval& s, const T& a) const {
        return tight({r, rc, {I::mul(s, a.d[0]), I::mul(s, a.d[1]), I::mul(s, a.d[2])}});
    }
    // The step's bounds intersected with its mean value form, at ± Σ |∂f/∂x_i| w_i (each x_i − c_i
    // lies within ± w_i). Those hold the exact values; a value computed at a point carries its
    // own rounding, which a long sum of large terms makes far larger than an ulp of the result:
    // `at`, the same operations on the centre, is as wide as that rounding there, so the form is
    // widened by it (and by a few ulps of the result, where `at` happens to be exact). Rounding is
    // upward, so every sum and product here is rounded outwards; lo − r rounds down as −(r − lo).
    T tight(T r) const {
        double reach = 0;
        for (int i = 0; i < 3; ++i) reach += std::max(-r.d[i].lower(), r.d[i].upper()) * mHalfWidth[i];
        const double atLo = r.at.lower(), atHi = r.at.upper();
        reach += 4 * (atHi - atLo) + (std::max(-atLo, atHi) + reach) * 0x1p-48;
        if (!(reach < kInf)) return r; // an unbounded derivative, or a NaN
        const double lo = std::max(r.v.lower(), -(reach - atLo)), hi = std::min(r.v.upper(), atHi + reach);
        if (lo <= hi) r.v = BInterval(lo, hi);
        return r;
    }
};

// One step of the program on the stack (top: its top slot). A min or max of n arguments folds
// them left to right; with `folded`, each was folded in at its own end (runSkipping) and
// the step has nothing left to do.
template <typename Ops>
inline void step(const Ops& ops, const ExprProgram& prog, const ExprInstr& in, typename Ops::T* stack, int& top,
                 const typename Ops::T& x, const typename Ops::T& y, const typename Ops::T& z, bool folded = false) {
    using T = typename Ops::T;
    auto push = [&](const T& v) { new (stack + ++top) T(v); };
    switch (in.op) {
    case ExprOp::Const: push(ops.constant(prog.constants[in.arg])); break;
    case ExprOp::X: push(ops.var(x, 0)); break;
    case ExprOp::Y: push(ops.var(y, 1)); break;
    case ExprOp::Z: push(ops.var(z, 2)); break;
    case ExprOp::Add: --top; stack[top] = ops.add(stack[top], stack[top + 1]); break;
    case ExprOp::Sub: --top; stack[top] = ops.sub(stack[top], stack[top + 1]); break;
    case ExprOp::Mul: --top; stack[top] = ops.mul(stack[top], stack[top + 1]); break;
    case ExprOp::Div: --top; stack[top] = ops.div(stack[top], stack[top + 1]); break;
    case ExprOp::Pow: --top; stack[top] = ops.pow(stack[top], stack[top + 1]); break;
    case ExprOp::PowInt: stack[top] = ops.powInt(stack[top], int(std::int32_t(in.arg))); break;
    case ExprOp::Neg: stack[top] = ops.neg(stack[top]); break;
    case ExprOp::Abs: stack[top] = ops.abs(stack[top]); break;
    case ExprOp::Sqrt: stack[top] = ops.sqrt(stack[top]); break;
    case ExprOp::Exp: stack[top] = ops.exp(stack[top]); break;
    case ExprOp::Log: stack[top] = ops.log(stack[top]); break;
    case ExprOp::Sin: stack[top] = ops.sin(stack[top]); break;
    case ExprOp::Cos: stack[top] = ops.cos(stack[top]); break;
    case ExprOp::Tan: stack[top] = ops.tan(stack[top]); break;
    case ExprOp::Min:
    case ExprOp::Max: {
        if (folded) break;
        const int n = int(in.arg);
        T acc = stack[top - n + 1];
        for (int i = top - n + 2; i <= top; ++i) acc = in.op == ExprOp::Min ? ops.min(acc, stack[i]) : ops.max(acc, stack[i]);
        top -= n - 1;
        stack[top] = acc;
        break;
    }
    case ExprOp::Clamp:
        top -= 2;
        stack[top] = ops.min(ops.max(stack[top], stack[top + 1]), stack[top + 2]);
        break;
    }
}

// The stack as raw storage, each slot constructed when pushed (and only assigned to while it is
// on the stack, never destroyed): the number types' default constructors would otherwise zero all
// kMaxStack slots (8 KB for a dual number) at every evaluation, most of which a formula never
// reaches.
template <typename T> struct RawStack {
    static_assert(std::is_trivially_destructible_v<T>);
    alignas(T) std::byte storage[sizeof(T) * (kMaxStack + 1)];
    T* slots() { return reinterpret_cast<T*>(storage); }
};

// The program on one number type; with `steps`, each step's result is kept there too (the
// natural bounds that runSkipping reads).
template <typename Ops>
typename Ops::T run(const Ops& ops, const ExprProgram& prog, const typename Ops::T& x, const typename Ops::T& y,
                    const typename Ops::T& z, typename Ops::T* steps = nullptr) {
    RawStack<typename Ops::T> raw;
    typename Ops::T* const stack = raw.slots();
    int top = -1;
    for (std::size_t i = 0; i < prog.code.size(); ++i) {
        step(ops, prog, prog.code[i], stack, top, x, y, z);
        if (steps) steps[i] = stack[top];
    }
    return stack[0];
}

// A step's bounds over the box, whichever the number type.
inline const BInterval& boundsOf(const BInterval& v) { return v; }
inline const BInterval& boundsOf(const Centred& v) { return v.v; }

// run with bounds of every step over the box, or over a box around it, at hand (`known`): a
// min's or max's second or later argument whose known bounds lie wholly above the min of the
// arguments before it (below their max) is skipped, and the arguments are folded in as each ends,
// in run's order. The same value as run: min and max return their first operand alone where the
// second's bounds lie above it (below, for max), and a step's bounds lie within its known ones —
// centred bounds within natural ones over the same box (the natural operation on narrower
// operands, intersected with the mean value form), natural bounds over a box within natural
// bounds over a box around it (each operation is inclusion-monotone). Where an argument is
// undefined over a whole box (a square root of a wholly negative value) its bounds there may be
// the whole line while the known ones are not; skipped, it bounds the min more tightly — still
// soundly, as the point values ignore an undefined argument (ScalarOps::min keeps its first
// operand). With `steps`, each step's bounds are kept there (an argument's own, before it is
// folded in; a skipped argument's steps as known).
template <typename Ops>
typename Ops::T runSkipping(const Ops& ops, const ExprProgram& prog, const typename Ops::T& x, const typename Ops::T& y,
                            const typename Ops::T& z, const BInterval* known, BInterval* steps = nullptr) {
    using T = typename Ops::T;
    RawStack<T> raw;
    T* const stack = raw.slots();
    int top = -1;
    for (std::size_t i = 0; i < prog.code.size(); ++i) {
        const std::int32_t end = prog.argumentEnd[i];
        if (end >= 0) {
            const BInterval& before = boundsOf(stack[top]); // the arguments before this one, folded
            const BInterval& arg = known[end];
            if (prog.foldAfter[std::size_t(end)] == ExprFold::Min ? before.upper() < arg.lower() : before.lower() > arg.upper()) {
                if (steps) std::copy(known + i, known + end + 1, steps + i);
                i = std::size_t(end);
                continue;
            }
        }
        step(ops, prog, prog.code[i], stack, top, x, y, z, true);
        if (steps) steps[i] = boundsOf(stack[top]);
        switch (prog.foldAfter[i]) {
        case ExprFold::None: break;
        case ExprFold::Min: --top; stack[top] = ops.min(stack[top], stack[top + 1]); break;
        case ExprFold::Max: --top; stack[top] = ops.max(stack[top], stack[top + 1]); break;
        }
    }
    return stack[0];
}

// Values at a chunk of points, the stack one row of kChunk values a slot: each instruction runs
// as a loop over the chunk, so the interpreter's dispatch is paid once a chunk instead of once a
// point and the arithmetic runs in loops the compiler vectorises. Each point gets ScalarOps'
// operations in the same order: the same bits as run(ScalarOps) (no contraction into fused
// multiply-adds: ISO C++ mode).
constexpr std::size_t kChunk = 64;

void runChunk(const ExprProgram& prog, const Vec3d* points, std::size_t n, double* out) {
    thread_local std::vector<double> storage;
    storage.resize(std::size_t(prog.maxStack + 1) * kChunk);
    double* const base = storage.data();
    auto slot = [&](int i) { return base + std::size_t(i) * kChunk; };
    int top = -1;
    auto unary = [&](auto f) {
        double* a = slot(top);
        for (std::size_t i = 0; i < n; ++i) a[i] = f(a[i]);
    };
    auto binary = [&](auto f) {
        --top;
        double* a = slot(top);
        const double* b = slot(top + 1);
        for (std::size_t i = 0; i < n; ++i) a[i] = f(a[i], b[i]);
    };
    for (const ExprInstr& in : prog.code) {
        switch (in.op) {
        case ExprOp::Const: {
            double* a = slot(++top);
            const double c = prog.constants[in.arg];
            for (std::size_t i = 0; i < n; ++i) a[i] = c;
            break;
        }
        case ExprOp::X:
        case ExprOp::Y:
        case ExprOp::Z: {
            double* a = slot(++top);
            const std::size_t axis = in.op == ExprOp::X ? 0 : (in.op == ExprOp::Y ? 1 : 2);
            for (std::size_t i = 0; i < n; ++i) a[i] = points[i][axis];
            break;
        }
        case ExprOp::Add: binary([](double a, double b) { return ScalarOps::add(a, b); }); break;
        case ExprOp::Sub: binary([](double a, double b) { return ScalarOps::sub(a, b); }); break;
        case ExprOp::Mul: binary([](double a, double b) { return ScalarOps::mul(a, b); }); break;
        case ExprOp::Div: binary([](double a, double b) { return ScalarOps::div(a, b); }); break;
        case ExprOp::Pow: binary([](double a, double b) { return ScalarOps::pow(a, b); }); break;
        case ExprOp::PowInt: {
            const int e = int(std::int32_t(in.arg));
            if (e == 2) unary([](double a) { return ScalarOps::mul(a, a); }); // wholePower's one product
            else unary([e](double a) { return wholePower(a, e); });
            break;
        }
        case ExprOp::Neg: unary([](double a) { return ScalarOps::neg(a); }); break;
        case ExprOp::Abs: unary([](double a) { return ScalarOps::abs(a); }); break;
        case ExprOp::Sqrt: unary([](double a) { return ScalarOps::sqrt(a); }); break;
        case ExprOp::Exp: unary([](double a) { return ScalarOps::exp(a); }); break;
        case ExprOp::Log: unary([](double a) { return ScalarOps::log(a); }); break;
        case ExprOp::Sin: unary([](double a) { return ScalarOps::sin(a); }); break;
        case ExprOp::Cos: unary([](double a) { return ScalarOps::cos(a); }); break;
        case ExprOp::Tan: unary([](double a) { return ScalarOps::tan(a); }); break;
        case ExprOp::Min:
        case ExprOp::Max: {
            const int args = int(in.arg);
            double* acc = slot(top - args + 1);
            for (int j = top - args + 2; j <= top; ++j) {
                const double* b = slot(j);
                if (in.op == ExprOp::Min)
                    for (std::size_t i = 0; i < n; ++i) acc[i] = ScalarOps::min(acc[i], b[i]);
                else
                    for (std::size_t i = 0; i < n; ++i) acc[i] = ScalarOps::max(acc[i], b[i]);
            }
            top -= args - 1;
            break;
        }
        case ExprOp::Clamp: {
            top -= 2;
            double* v = slot(top);
            const double *lo = slot(top + 1), *hi = slot(top + 2);
            for (std::size_t i = 0; i < n; ++i) v[i] = ScalarOps::min(ScalarOps::max(v[i], lo[i]), hi[i]);
            break;
        }
        }
    }
    std::copy_n(slot(0), n, out);
}

Interval toInterval(const BInterval& r) {
    if (boost::numeric::empty(r) || std::isnan(r.lower()) || std::isnan(r.upper())) return Interval{};
    return Interval{r.lower(), r.upper()};
}

} // namespace

double evalValue(const ExprProgram& prog, const Vec3d& p) { return run(ScalarOps{}, prog, p.x, p.y, p.z); }

void evalValues(const ExprProgram& prog, const Vec3d* points, std::size_t n, double* out) {
    for (std::size_t first = 0; first < n; first += kChunk) runChunk(prog, points + first, std::min(kChunk, n - first), out + first);
}

double evalGradient(const ExprProgram& prog, const Vec3d& p, Vec3d& gradient) {
    const Dual r = run(DualOps{}, prog, Dual{p.x, {}}, Dual{p.y, {}}, Dual{p.z, {}});
    gradient = r.d;
    return r.v;
}

namespace {

BInterval boxSide(const Box3& box, std::size_t a) { return BInterval(box.min[a], box.max[a]); }

// The natural bounds of every step of one program over one box.
struct KeptSteps {
    std::uint64_t program = 0;
    Box3 box;
    std::vector<BInterval> steps;
    bool covers(const ExprProgram& prog, const Box3& b) const {
        return program == prog.id && prog.id != 0 && steps.size() == prog.code.size() && box.contains(b.min) && box.contains(b.max);
    }
};
// This thread's: the last box's (evalBoundsAfterNatural reads them), and those of the box
// around the boxes asked now (keepNaturalStepsAround).
thread_local KeptSteps tKept, tAround;

// Rounding upward must be on.
BInterval naturalSteps(const ExprProgram& prog, const Box3& box, KeptSteps& into, const KeptSteps* around) {
    into.steps.resize(prog.code.size());
    into.program = prog.id;
    into.box = box;
    const BInterval x = boxSide(box, 0), y = boxSide(box, 1), z = boxSide(box, 2);
    if (around) return runSkipping(IntervalOps{}, prog, x, y, z, around->steps.data(), into.steps.data());
    return run(IntervalOps{}, prog, x, y, z, into.steps.data());
}

BInterval naturalKept(const ExprProgram& prog, const Box3& box) {
    return naturalSteps(prog, box, tKept, tAround.covers(prog, box) ? &tAround : nullptr);
}

// Rounding upward must be on. Skips min and max arguments where `natural` (every step's) is given.
Interval centred(const ExprProgram& prog, const Box3& box, const BInterval* natural) {
    const Vec3d c = (box.min + box.max) * 0.5;
    double halfWidth[3];
    Centred var[3];
    for (std::size_t a = 0; a < 3; ++a) {
        halfWidth[a] = std::max(c[a] - box.min[a], box.max[a] - c[a]); // rounded up
        var[a] = Centred{boxSide(box, a), BInterval(c[a]), {}};
    }
    const CentredOps ops(halfWidth);
    return toInterval((natural ? runSkipping(ops, prog, var[0], var[1], var[2], natural) : run(ops, prog, var[0], var[1], var[2])).v);
}

bool hasArgumentsToSkip(const ExprProgram& prog) {
    return prog.skippableArguments && prog.argumentEnd.size() == prog.code.size() && prog.foldAfter.size() == prog.code.size();
}

} // namespace

Interval evalNaturalBounds(const ExprProgram& prog, const Box3& box) {
    ProtectedInterval::traits_type::rounding upward; // sets the rounding mode, restores it on return
    return toInterval(run(IntervalOps{}, prog, boxSide(box, 0), boxSide(box, 1), boxSide(box, 2)));
}

// (The kept steps give the same bits as steps computed afresh: see runSkipping.)
Interval evalBounds(const ExprProgram& prog, const Box3& box) { return evalBoundsAfterNatural(prog, box); }

Interval evalNaturalBoundsKept(const ExprProgram& prog, const Box3& box) {
    if (!hasArgumentsToSkip(prog)) return evalNaturalBounds(prog, box);
    ProtectedInterval::traits_type::rounding upward;
    return toInterval(naturalKept(prog, box));
}

Interval evalBoundsAfterNatural(const ExprProgram& prog, const Box3& box) {
    ProtectedInterval::traits_type::rounding upward;
    if (!hasArgumentsToSkip(prog)) return centred(prog, box, nullptr);
    const bool kept = tKept.covers(prog, box) && tKept.box.min == box.min && tKept.box.max == box.max;
    if (!kept) naturalKept(prog, box);
    return centred(prog, box, tKept.steps.data());
}

void keepNaturalStepsAround(const ExprProgram& prog, const Box3& around) {
    if (!hasArgumentsToSkip(prog)) return;
    ProtectedInterval::traits_type::rounding upward;
    naturalSteps(prog, around, tAround, nullptr);
}

} // namespace vdbsurf
