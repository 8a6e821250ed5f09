// One stack machine, three number types: double (values), Dual (value + gradient) and a
// Boost.Interval type with outward rounding (bounds). Any step whose interval result is
// undefined (e.g. 0 * inf, an empty domain) widens to the whole real line, which keeps the bounds
// conservative; the point evaluation then reports the undefined value itself.
#include "vdbsurf/field/expression.h"

#include <boost/numeric/interval.hpp>

#include <array>
#include <cmath>
#include <limits>

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
    static T pow(const T& a, const T& b) {
        if (boost::numeric::singleton(b) && isIntegerConstant(b.lower())) {
            const int n = int(b.lower());
            if (n < 0 && boost::numeric::in_zero(a)) return whole();
            return fix(boost::numeric::pow(a, n));
        }
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

template <typename Ops>
typename Ops::T run(const ExprProgram& prog, const typename Ops::T& x, const typename Ops::T& y,
                    const typename Ops::T& z) {
    using T = typename Ops::T;
    std::array<T, kMaxStack + 1> stack;
    int top = -1;
    for (const ExprInstr& in : prog.code) {
        switch (in.op) {
        case ExprOp::Const: stack[std::size_t(++top)] = Ops::constant(prog.constants[in.arg]); break;
        case ExprOp::X: stack[std::size_t(++top)] = Ops::var(x, 0); break;
        case ExprOp::Y: stack[std::size_t(++top)] = Ops::var(y, 1); break;
        case ExprOp::Z: stack[std::size_t(++top)] = Ops::var(z, 2); break;
        case ExprOp::Add: --top; stack[top] = Ops::add(stack[top], stack[top + 1]); break;
        case ExprOp::Sub: --top; stack[top] = Ops::sub(stack[top], stack[top + 1]); break;
        case ExprOp::Mul: --top; stack[top] = Ops::mul(stack[top], stack[top + 1]); break;
        case ExprOp::Div: --top; stack[top] = Ops::div(stack[top], stack[top + 1]); break;
        case ExprOp::Pow: --top; stack[top] = Ops::pow(stack[top], stack[top + 1]); break;
        case ExprOp::Neg: stack[top] = Ops::neg(stack[top]); break;
        case ExprOp::Abs: stack[top] = Ops::abs(stack[top]); break;
        case ExprOp::Sqrt: stack[top] = Ops::sqrt(stack[top]); break;
        case ExprOp::Exp: stack[top] = Ops::exp(stack[top]); break;
        case ExprOp::Log: stack[top] = Ops::log(stack[top]); break;
        case ExprOp::Sin: stack[top] = Ops::sin(stack[top]); break;
        case ExprOp::Cos: stack[top] = Ops::cos(stack[top]); break;
        case ExprOp::Tan: stack[top] = Ops::tan(stack[top]); break;
        case ExprOp::Min:
        case ExprOp::Max: {
            const int n = int(in.arg);
            T acc = stack[std::size_t(top - n + 1)];
            for (int i = top - n + 2; i <= top; ++i)
                acc = in.op == ExprOp::Min ? Ops::min(acc, stack[std::size_t(i)]) : Ops::max(acc, stack[std::size_t(i)]);
            top -= n - 1;
            stack[std::size_t(top)] = acc;
            break;
        }
        case ExprOp::Clamp:
            top -= 2;
            stack[top] = Ops::min(Ops::max(stack[top], stack[top + 1]), stack[top + 2]);
            break;
        }
    }
    return stack[0];
}

} // namespace

double evalValue(const ExprProgram& prog, const Vec3d& p) { return run<ScalarOps>(prog, p.x, p.y, p.z); }

double evalGradient(const ExprProgram& prog, const Vec3d& p, Vec3d& gradient) {
    const Dual r = run<DualOps>(prog, Dual{p.x, {}}, Dual{p.y, {}}, Dual{p.z, {}});
    gradient = r.d;
    return r.v;
}

Interval evalBounds(const ExprProgram& prog, const Box3& box) {
    ProtectedInterval::traits_type::rounding upward; // sets the rounding mode, restores it on return
    const BInterval r = run<IntervalOps>(prog, BInterval(box.min.x, box.max.x), BInterval(box.min.y, box.max.y),
                                         BInterval(box.min.z, box.max.z));
    if (boost::numeric::empty(r) || std::isnan(r.lower()) || std::isnan(r.upper())) return Interval{};
    return Interval{r.lower(), r.upper()};
}

} // namespace vdbsurf
