#include "vdbsurf/reeb/bspline.h"

#include "vdbsurf/reeb/least_squares.h"

#include <algorithm>
#include <stdexcept>

namespace vdbsurf::reeb {

int findSpan(const std::vector<double>& U, int n, double t) {
    if (t >= U[std::size_t(n)]) return n - 1;
    if (t <= U[kDegree]) return kDegree;
    const auto it = std::upper_bound(U.begin() + kDegree, U.begin() + n + 1, t);
    return int(it - U.begin()) - 1;
}

void basisFunctions(const std::vector<double>& U, int k, double t, double N[4]) {
    double left[4], right[4];
    N[0] = 1.0;
    for (int j = 1; j <= kDegree; ++j) {
        left[j] = t - U[std::size_t(k + 1 - j)];
        right[j] = U[std::size_t(k + j)] - t;
        double saved = 0.0;
        for (int r = 0; r < j; ++r) {
            const double denom = right[r + 1] + left[j - r];
            const double temp = denom != 0 ? N[r] / denom : 0.0;
            N[r] = saved + right[r + 1] * temp;
            saved = left[j - r] * temp;
        }
        N[j] = saved;
    }
}

Vec3d BSplineCurve::eval(double t) const {
    const int n = int(ctrl.size());
    const int k = findSpan(knots, n, t);
    double N[4];
    basisFunctions(knots, k, t, N);
    Vec3d p;
    for (int i = 0; i < 4; ++i) p += ctrl[std::size_t(k - 3 + i)] * N[i];
    return p;
}

Vec3d BSplinePatch::eval(double u, double v) const {
    const int ku = findSpan(knotsU, nu, u), kv = findSpan(knotsV, nv, v);
    double Nu[4], Nv[4];
    basisFunctions(knotsU, ku, u, Nu);
    basisFunctions(knotsV, kv, v, Nv);
    Vec3d p;
    for (int j = 0; j < 4; ++j) {
        Vec3d row;
        for (int i = 0; i < 4; ++i) row += ctrl[std::size_t(kv - 3 + j) * std::size_t(nu) + std::size_t(ku - 3 + i)] * Nu[i];
        p += row * Nv[j];
    }
    return p;
}

std::vector<double> clampedUniformKnots(int n, double a, double b) {
    std::vector<double> U(std::size_t(n + 4));
    const int spans = n - 3;
    for (int i = 0; i < n + 4; ++i) {
        const int j = std::clamp(i - 3, 0, spans);
        U[std::size_t(i)] = j == spans ? b : a + (b - a) * j / spans;
    }
    return U;
}

std::vector<double> mergeKnots(const std::vector<double>& a, const std::vector<double>& b) {
    std::vector<double> out;
    std::size_t i = 0, j = 0;
    while (i < a.size() || j < b.size()) {
        if (j == b.size() || (i < a.size() && a[i] < b[j])) out.push_back(a[i++]);
        else if (i == a.size() || b[j] < a[i]) out.push_back(b[j++]);
        else {
            out.push_back(a[i++]);
            ++j;
        }
    }
    return out;
}

namespace {

// Boehm's algorithm: one more knot at t (inside the curve's interval).
void insertKnot(BSplineCurve& c, double t) {
    const int n = int(c.ctrl.size());
    const int k = findSpan(c.knots, n, t);
    std::vector<Vec3d> q(std::size_t(n + 1));
    for (int i = 0; i <= n; ++i) {
        if (i <= k - kDegree) q[std::size_t(i)] = c.ctrl[std::size_t(i)];
        else if (i > k) q[std::size_t(i)] = c.ctrl[std::size_t(i - 1)];
        else {
            const double denom = c.knots[std::size_t(i + kDegree)] - c.knots[std::size_t(i)];
            const double alpha = denom > 0 ? (t - c.knots[std::size_t(i)]) / denom : 0.0;
            q[std::size_t(i)] = c.ctrl[std::size_t(i)] * alpha + c.ctrl[std::size_t(i - 1)] * (1 - alpha);
        }
    }
    c.ctrl = std::move(q);
    c.knots.insert(c.knots.begin() + k + 1, t);
}

int multiplicity(const std::vector<double>& U, double t) { return int(std::count(U.begin(), U.end(), t)); }

// A cut a hair from a knot (a seam found as a fraction of a length lands on a knot but for the
// last bits) would leave a span of that hair, which a change of parameter can round to nothing:
// a knot repeated past the degree, or equal to an end. Such a cut is made at the knot itself.
double snappedToKnot(const std::vector<double>& knots, double t) {
    const double tolerance = 1e-9 * (knots.back() - knots.front());
    const auto above = std::lower_bound(knots.begin(), knots.end(), t);
    if (above != knots.end() && *above - t <= tolerance) return *above;
    if (above != knots.begin() && t - *(above - 1) <= tolerance) return *(above - 1);
    return t;
}

} // namespace

BSplineCurve refineTo(const BSplineCurve& curve, const std::vector<double>& target) {
    BSplineCurve c = curve;
    for (std::size_t i = 0; i < target.size();) {
        std::size_t j = i;
        while (j < target.size() && target[j] == target[i]) ++j;
        const double t = target[i];
        if (t > c.begin() && t < c.end())
            for (int m = multiplicity(c.knots, t); m < int(j - i); ++m) insertKnot(c, t);
        i = j;
    }
    if (c.knots.size() != target.size()) throw std::logic_error("bspline: target knots are not a superset of the curve's");
    return c;
}

BSplineCurve subCurve(const BSplineCurve& curve, double a, double b) {
    a = snappedToKnot(curve.knots, a);
    b = snappedToKnot(curve.knots, b);
    BSplineCurve c = curve;
    for (double t : {a, b})
        if (t > c.begin() && t < c.end())
            for (int m = multiplicity(c.knots, t); m < kDegree; ++m) insertKnot(c, t);
    // A knot of multiplicity 3 first at index j (or the clamped start, taken as j = 1) is where
    // the curve passes through control point j - 1; the part's control points run between the two.
    auto firstIndex = [&](double t) { return std::size_t(std::lower_bound(c.knots.begin(), c.knots.end(), t) - c.knots.begin()); };
    const std::size_t ja = a <= c.begin() ? 1 : firstIndex(a), jb = firstIndex(b);
    BSplineCurve out;
    out.ctrl.assign(c.ctrl.begin() + std::ptrdiff_t(ja - 1), c.ctrl.begin() + std::ptrdiff_t(jb));
    out.knots.assign(4, a);
    out.knots.insert(out.knots.end(), c.knots.begin() + std::ptrdiff_t(ja + 3), c.knots.begin() + std::ptrdiff_t(jb));
    out.knots.insert(out.knots.end(), 4, b);
    return out;
}

BSplineCurve reparameterized(const BSplineCurve& curve, double a, double b) {
    BSplineCurve c = curve;
    const double a0 = curve.begin(), b0 = curve.end();
    for (double& k : c.knots) k = k == b0 ? b : a + (k - a0) * (b - a) / (b0 - a0);
    return c;
}

BSplineCurve joined(const std::vector<BSplineCurve>& curves) {
    BSplineCurve out = curves.front();
    for (std::size_t i = 1; i < curves.size(); ++i) {
        const BSplineCurve& c = curves[i];
        out.knots.pop_back();
        out.knots.insert(out.knots.end(), c.knots.begin() + 4, c.knots.end());
        out.ctrl.insert(out.ctrl.end(), c.ctrl.begin() + 1, c.ctrl.end());
    }
    return out;
}

Eigen::MatrixXd basisMatrix(const std::vector<double>& knots, int n, const std::vector<double>& params) {
    Eigen::MatrixXd B = Eigen::MatrixXd::Zero(Eigen::Index(params.size()), n);
    for (std::size_t s = 0; s < params.size(); ++s) {
        const int k = findSpan(knots, n, params[s]);
        double N[4];
        basisFunctions(knots, k, params[s], N);
        for (int i = 0; i < 4; ++i) B(Eigen::Index(s), k - 3 + i) += N[i];
    }
    return B;
}

Eigen::MatrixXd penalizedLeastSquares(const Eigen::MatrixXd& B, const Eigen::MatrixXd& R, bool cyclic) {
    const Eigen::Index n = B.cols();
    Eigen::MatrixXd A = B.transpose() * B;
    const double scale = std::max(1e-12, A.diagonal().mean());
    const Eigen::Index rows = cyclic ? n : n - 2;
    for (Eigen::Index r = 0; r < rows; ++r) {
        const Eigen::Index idx[3] = {r, (r + 1) % n, (r + 2) % n};
        const double w[3] = {1, -2, 1};
        for (int a = 0; a < 3; ++a)
            for (int b = 0; b < 3; ++b) A(idx[a], idx[b]) += 1e-4 * scale * w[a] * w[b];
    }
    A.diagonal().array() += 1e-9 * scale;
    return A.ldlt().solve(B.transpose() * R);
}

BSplineCurve fitCurve(const std::vector<Vec3d>& points, const std::vector<double>& params, int n) {
    BSplineCurve c;
    c.knots = clampedUniformKnots(n, 0.0, 1.0);
    c.ctrl.assign(std::size_t(n), Vec3d());
    c.ctrl.front() = points.front();
    c.ctrl.back() = points.back();
    if (n <= 2) return c;
    // The free control points see the samples less what the two fixed ends contribute.
    const Eigen::MatrixXd B = basisMatrix(c.knots, n, params);
    Eigen::MatrixXd R(Eigen::Index(points.size()), 3);
    for (std::size_t s = 0; s < points.size(); ++s) {
        const Vec3d r = points[s] - c.ctrl.front() * B(Eigen::Index(s), 0) - c.ctrl.back() * B(Eigen::Index(s), n - 1);
        R.row(Eigen::Index(s)) << r.x, r.y, r.z;
    }
    const Eigen::MatrixXd X = penalizedLeastSquares(B.middleCols(1, n - 2), R, false);
    for (int i = 0; i + 2 < n; ++i) c.ctrl[std::size_t(i + 1)] = Vec3d(X(i, 0), X(i, 1), X(i, 2));
    return c;
}

} // namespace vdbsurf::reeb
