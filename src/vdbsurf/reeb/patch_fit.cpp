#include "vdbsurf/reeb/patch_fit.h"

#include "vdbsurf/core/cancel.h"
#include "vdbsurf/core/progress.h"
#include "vdbsurf/reeb/least_squares.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

namespace vdbsurf::reeb {

namespace {

// A unit end's contour as one closed curve over u in [0, 1], starting `seam` (a fraction of its
// length) along it, made of stretches of the lobe curves in the unit's order.
BSplineCurve endCurve(const ReebGraph& g, const PatchSet& set, const std::vector<std::uint32_t>& lobes, double seam, bool top,
                      std::vector<BoundaryPiece>& pieces) {
    std::vector<double> lengths;
    double total = 0;
    for (std::uint32_t li : lobes) {
        lengths.push_back(g.lobes[li].length());
        total += lengths.back();
    }
    // The lobe holding the seam, and where in it (lobe parameter: fraction of its length).
    std::size_t k = 0;
    double at = seam * total, before = 0;
    while (k + 1 < lobes.size() && before + lengths[k] <= at) before += lengths[k++];
    double tau = lengths[k] > 0 ? std::clamp((at - before) / lengths[k], 0.0, 1.0) : 0.0;
    if (tau < 1e-6 || tau > 1 - 1e-6) tau = tau < 0.5 ? 0.0 : 1.0; // no sliver of a lobe at the seam
    std::vector<BoundaryPiece> stretch;
    auto add = [&](std::size_t i, double t0, double t1) {
        if (t1 > t0) stretch.push_back({lobes[i], t0, t1, 0, 0, top});
    };
    add(k, tau, 1.0);
    for (std::size_t j = 1; j < lobes.size(); ++j) add((k + j) % lobes.size(), 0.0, 1.0);
    add(k, 0.0, tau);
    // Each stretch gets a share of u by its length, but never a vanishing one (a lobe of a
    // degenerate contour can have no length), so its knots stay apart.
    std::vector<double> share;
    double shares = 0;
    for (const BoundaryPiece& p : stretch) {
        const std::size_t idx = std::size_t(std::find(lobes.begin(), lobes.end(), p.lobe) - lobes.begin());
        share.push_back(std::max((p.t1 - p.t0) * lengths[idx] / std::max(total, 1e-300), 1e-3 / double(stretch.size())));
        shares += share.back();
    }
    std::vector<BSplineCurve> curves;
    double u = 0;
    for (std::size_t i = 0; i < stretch.size(); ++i) {
        BoundaryPiece& p = stretch[i];
        p.u0 = u;
        p.u1 = i + 1 == stretch.size() ? 1.0 : u + share[i] / shares;
        u = p.u1;
        curves.push_back(reparameterized(subCurve(set.lobeCurves[p.lobe], p.t0, p.t1), p.u0, p.u1));
        pieces.push_back(p);
    }
    return joined(curves);
}

UnitPatch fitUnit(const ReebGraph& g, const PatchSet& set, const Unit& unit, RingGrid grid) {
    UnitPatch patch;
    patch.bottomPole = unit.bottomLobes.empty();
    patch.topPole = unit.topLobes.empty();
    const int U = grid.U, V = grid.V;
    BSplineCurve bottom, top;
    if (!patch.bottomPole) bottom = endCurve(g, set, unit.bottomLobes, grid.bottomSeam, false, patch.boundary);
    if (!patch.topPole) top = endCurve(g, set, unit.topLobes, grid.topSeam, true, patch.boundary);
    std::vector<double> knotsU;
    if (!patch.bottomPole && !patch.topPole) knotsU = mergeKnots(bottom.knots, top.knots);
    else if (!patch.bottomPole) knotsU = bottom.knots;
    else if (!patch.topPole) knotsU = top.knots;
    else knotsU = clampedUniformKnots(std::max(4, U / 2 + 3), 0.0, 1.0);
    const int nu = int(knotsU.size()) - 4;
    const int nv = std::max(4, (V - 1) / 2 + 3);
    BSplinePatch& S = patch.surface;
    S.knotsU = knotsU;
    S.knotsV = clampedUniformKnots(nv, 0.0, 1.0);
    S.nu = nu;
    S.nv = nv;
    S.ctrl.assign(std::size_t(nu) * std::size_t(nv), Vec3d());
    const ReebNode& low = g.nodes[unit.lower];
    const ReebNode& high = g.nodes[unit.upper];
    for (int i = 0; i < nu; ++i) {
        S.ctrl[std::size_t(i)] = patch.bottomPole ? low.position : Vec3d();
        S.ctrl[std::size_t(nv - 1) * std::size_t(nu) + std::size_t(i)] = patch.topPole ? high.position : Vec3d();
    }
    if (!patch.bottomPole) {
        const BSplineCurve r = refineTo(bottom, knotsU);
        std::copy(r.ctrl.begin(), r.ctrl.end(), S.ctrl.begin());
    }
    if (!patch.topPole) {
        const BSplineCurve r = refineTo(top, knotsU);
        std::copy(r.ctrl.begin(), r.ctrl.end(), S.ctrl.begin() + std::ptrdiff_t(std::size_t(nv - 1) * std::size_t(nu)));
    }
    // Inner rows: least squares over the grid, separably (the tensor-product basis is the
    // Kronecker product of the two), the last column tied to the first so the patch closes.
    std::vector<double> us(static_cast<std::size_t>(U)), vs(static_cast<std::size_t>(V));
    for (int i = 0; i < U; ++i) us[std::size_t(i)] = double(i) / U;
    for (int j = 0; j < V; ++j) vs[std::size_t(j)] = double(j) / (V - 1);
    const Eigen::MatrixXd Bu = basisMatrix(knotsU, nu, us);
    const Eigen::MatrixXd Bv = basisMatrix(S.knotsV, nv, vs);
    Eigen::MatrixXd Bf = Bu.leftCols(nu - 1);
    Bf.col(0) += Bu.col(nu - 1);
    const Eigen::MatrixXd Bvi = Bv.middleCols(1, nv - 2);
    for (int d = 0; d < 3; ++d) {
        Eigen::MatrixXd R(U, V); // grid minus what the fixed rows contribute
        Eigen::VectorXd c0(nu), cN(nu);
        for (int i = 0; i < nu; ++i) {
            c0(i) = S.ctrl[std::size_t(i)][std::size_t(d)];
            cN(i) = S.ctrl[std::size_t(nv - 1) * std::size_t(nu) + std::size_t(i)][std::size_t(d)];
        }
        for (int j = 0; j < V; ++j)
            for (int i = 0; i < U; ++i) R(i, j) = grid.at(i, j)[std::size_t(d)];
        R -= (Bu * c0) * Bv.col(0).transpose() + (Bu * cN) * Bv.col(nv - 1).transpose();
        const Eigen::MatrixXd Y = penalizedLeastSquares(Bf, R, true);                          // (nu-1) x V
        const Eigen::MatrixXd X = penalizedLeastSquares(Bvi, Y.transpose(), false).transpose(); // (nu-1) x (nv-2)
        for (int j = 1; j + 1 < nv; ++j)
            for (int i = 0; i < nu; ++i)
                S.ctrl[std::size_t(j) * std::size_t(nu) + std::size_t(i)][std::size_t(d)] = X(i % (nu - 1), j - 1);
    }
    patch.grid = std::move(grid);
    return patch;
}

} // namespace

std::vector<RingGrid> ringGrids(const ReebGraph& g, const PatchOptions& options) {
    std::vector<RingGrid> grids(g.units.size());
    Progress progress("ring grids", ringGridProgressUnits(options.gridV) * grids.size(), options.cancel);
    tbb::parallel_for(std::size_t(0), grids.size(), [&](std::size_t u) {
        grids[u] = ringGrid(g, g.units[u], options.gridU, options.gridV, options.cancel, &progress);
    });
    return grids;
}

PatchSet fitPatches(const ReebGraph& g, std::vector<RingGrid> grids, const CancelToken* cancel) {
    PatchSet set;
    const std::size_t n = g.units.size();
    // Lobe curves with about one span per two grid points of the finer neighbouring unit.
    set.lobeCurves.resize(g.lobes.size());
    tbb::parallel_for(std::size_t(0), g.lobes.size(), [&](std::size_t li) {
        const Lobe& lobe = g.lobes[li];
        double spacing = INFINITY;
        for (std::uint32_t u : {lobe.unitBelow, lobe.unitAbove}) {
            const RingGrid& grid = grids[u];
            double rowLength = 0;
            for (int v = 0; v < grid.V; ++v)
                for (int i = 0; i < grid.U; ++i) rowLength += length(grid.at((i + 1) % grid.U, v) - grid.at(i, v));
            spacing = std::min(spacing, rowLength / grid.V / grid.U);
        }
        const double len = lobe.length();
        const int spans = std::clamp(int(std::lround(len / (2.0 * std::max(spacing, 1e-30)))), 1, 200);
        std::vector<double> params(lobe.points.size(), 0.0);
        for (std::size_t i = 1; i < lobe.points.size(); ++i) params[i] = params[i - 1] + length(lobe.points[i] - lobe.points[i - 1]);
        for (double& t : params) t = len > 0 ? t / len : 0.0;
        params.back() = 1.0;
        set.lobeCurves[li] = fitCurve(lobe.points, params, spans + 3);
    });
    set.patches.resize(n);
    Progress progress("patch fit", n, cancel);
    tbb::parallel_for(std::size_t(0), n, [&](std::size_t u) {
        if (cancel) cancel->check();
        set.patches[u] = fitUnit(g, set, g.units[u], std::move(grids[u]));
        progress.advance();
    });
    for (const UnitPatch& p : set.patches) {
        set.sectionsWithSeveralLoops += p.grid.sectionsWithSeveralLoops;
        set.sectionsBlended += p.grid.sectionsBlended;
    }
    return set;
}

double maxJoinGap(const PatchSet& set, int samples) {
    double gap = 0;
    for (const UnitPatch& p : set.patches)
        for (const BoundaryPiece& b : p.boundary)
            for (int k = 0; k <= samples; ++k) {
                const double s = double(k) / samples;
                const Vec3d onLobe = set.lobeCurves[b.lobe].eval(b.t0 + (b.t1 - b.t0) * s);
                const Vec3d onPatch = p.surface.eval(b.u0 + (b.u1 - b.u0) * s, b.top ? 1.0 : 0.0);
                gap = std::max(gap, length(onLobe - onPatch));
            }
    return gap;
}

} // namespace vdbsurf::reeb
