// Cubic B-spline curves and tensor-product patches with clamped knot vectors: evaluation,
// knot insertion (Boehm), splitting, joining and least-squares fitting. Written here because
// none of the Debian libraries we use has B-splines that can insert knots and join curves
// (Eigen's unsupported Splines module cannot); the linear algebra is Eigen's.
#pragma once
#include "vdbsurf/core/vec3.h"

#include <vector>

namespace vdbsurf::reeb {

constexpr int kDegree = 3;

struct BSplineCurve {
    std::vector<double> knots; // ctrl.size() + 4, clamped (first and last value four times)
    std::vector<Vec3d> ctrl;
    Vec3d eval(double t) const;
    double begin() const { return knots.front(); }
    double end() const { return knots.back(); }
};

struct BSplinePatch {
    std::vector<double> knotsU, knotsV;
    int nu = 0, nv = 0;
    std::vector<Vec3d> ctrl; // u fastest: ctrl[j * nu + i]
    Vec3d eval(double u, double v) const;
};

// Index k of the span with knots[k] <= t < knots[k + 1] (the last span for t at the end).
int findSpan(const std::vector<double>& knots, int nCtrl, double t);
// The four non-zero cubic basis functions at t in span k: N[k-3 .. k].
void basisFunctions(const std::vector<double>& knots, int span, double t, double N[4]);

std::vector<double> clampedUniformKnots(int nCtrl, double a, double b);
// The union of two clamped knot vectors over the same interval (each value as often as in the
// one that holds it more often).
std::vector<double> mergeKnots(const std::vector<double>& a, const std::vector<double>& b);

// The same curve with more knots: every knot of `target` (a superset of the curve's knots).
BSplineCurve refineTo(const BSplineCurve& curve, const std::vector<double>& target);
// The part of the curve over [a, b] (inside its interval), exactly, by knot insertion. An end
// within 1e-9 of the interval's length of a knot is taken at that knot (no hair-thin span).
BSplineCurve subCurve(const BSplineCurve& curve, double a, double b);
// The same curve over [a, b] (an affine change of parameter).
BSplineCurve reparameterized(const BSplineCurve& curve, double a, double b);
// Curves meeting end to start, over consecutive intervals, joined into one (C0 at the joins).
BSplineCurve joined(const std::vector<BSplineCurve>& curves);

// Least-squares fit of a clamped cubic curve with nCtrl control points to points at
// parameters in [0, 1], through the first and last point exactly, with a small bending
// penalty on the free control points so that spans without samples stay well defined.
BSplineCurve fitCurve(const std::vector<Vec3d>& points, const std::vector<double>& params, int nCtrl);

} // namespace vdbsurf::reeb
