#include "vdbsurf/reeb/bspline.h"

#include <Eigen/Dense>

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

BSplineCurve fitCurve(const std::vector<Vec3d>& points, const std::vector<double>& params, int n) {
    BSplineCurve c;
    c.knots = clampedUniformKnots(n, 0.0, 1.0);
    c.ctrl.assign(std::size_t(n), Vec3d());
    c.ctrl.front() = points.front();
    c.ctrl.back() = points.back();
    const int free = n - 2;
    if (free <= 0) return c;
    Eigen::MatrixXd A = Eigen::MatrixXd::Zero(free, free);
    Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(free, 3);
    for (std::size_t s = 0; s < points.size(); ++s) {
        const int k = findSpan(c.knots, n, params[s]);
        double N[4];
        basisFunctions(c.knots, k, params[s], N);
        Vec3d r = points[s];
        for (int i = 0; i < 4; ++i) {
            const int j = k - 3 + i;
            if (j == 0) r -= c.ctrl.front() * N[i];
            if (j == n - 1) r -= c.ctrl.back() * N[i];
        }
        for (int i = 0; i < 4; ++i) {
            const int a = k - 3 + i - 1;
            if (a < 0 || a >= free) continue;
            for (int l = 0; l < 4; ++l) {
                const int b = k - 3 + l - 1;
                if (b >= 0 && b < free) A(a, b) += N[i] * N[l];
            }
            rhs(a, 0) += N[i] * r.x;
            rhs(a, 1) += N[i] * r.y;
            rhs(a, 2) += N[i] * r.z;
        }
    }
    // Bending penalty on second differences of all control points (the fixed ends included).
    const double lambda = 1e-4 * std::max(1e-12, A.diagonal().mean());
    for (int i = 0; i + 2 < n; ++i) {
        const int idx[3] = {i, i + 1, i + 2};
        const double w[3] = {1, -2, 1};
        for (int x = 0; x < 3; ++x) {
            const int a = idx[x] - 1;
            if (a < 0 || a >= free) continue;
            for (int y = 0; y < 3; ++y) {
                const int b = idx[y] - 1;
                const double v = lambda * w[x] * w[y];
                if (b >= 0 && b < free) A(a, b) += v;
                else {
                    const Vec3d& fixed = idx[y] == 0 ? c.ctrl.front() : c.ctrl.back();
                    rhs(a, 0) -= v * fixed.x;
                    rhs(a, 1) -= v * fixed.y;
                    rhs(a, 2) -= v * fixed.z;
                }
            }
        }
    }
    const Eigen::MatrixXd X = A.ldlt().solve(rhs);
    for (int i = 0; i < free; ++i) c.ctrl[std::size_t(i + 1)] = Vec3d(X(i, 0), X(i, 1), X(i, 2));
    return c;
}

} // namespace vdbsurf::reeb
