#include "vdbsurf/reeb/ring_grid.h"
#include "vdbsurf/core/cancel.h"
#include "vdbsurf/core/progress.h"
#include "vdbsurf/mesh/mesh.h"

#include <unsupported/Eigen/FFT>

#include <algorithm>
#include <array>
#include <cmath>
#include <complex>
#include <stdexcept>
#include <unordered_map>

namespace vdbsurf::reeb {

double loopLength(const std::vector<Vec3d>& loop) {
    double l = 0;
    for (std::size_t i = 1; i < loop.size(); ++i) l += length(loop[i] - loop[i - 1]);
    return l;
}

std::vector<Vec3d> resampleLoop(const std::vector<Vec3d>& loop, int n, double offset) {
    std::vector<double> cum(loop.size(), 0.0);
    for (std::size_t i = 1; i < loop.size(); ++i) cum[i] = cum[i - 1] + length(loop[i] - loop[i - 1]);
    const double total = cum.back();
    std::vector<Vec3d> out(std::size_t(std::max(n, 0)));
    if (!(total > 0)) {
        std::fill(out.begin(), out.end(), loop.front());
        return out;
    }
    for (int i = 0; i < n; ++i) {
        double s = (offset + double(i) / n) * total;
        s = std::fmod(s, total);
        if (s < 0) s += total;
        const std::size_t k = std::size_t(std::upper_bound(cum.begin(), cum.end(), s) - cum.begin());
        const std::size_t hi = std::min(k, loop.size() - 1), lo = hi - 1;
        const double seg = cum[hi] - cum[lo];
        const double t = seg > 0 ? (s - cum[lo]) / seg : 0.0;
        out[std::size_t(i)] = loop[lo] + (loop[hi] - loop[lo]) * t;
    }
    return out;
}

UnitEnd unitEnd(const ReebGraph& g, const Unit& unit, bool top) {
    UnitEnd end;
    const ReebNode& node = g.nodes[top ? unit.upper : unit.lower];
    end.height = node.height;
    end.point = node.position;
    const std::vector<std::uint32_t>& lobes = top ? unit.topLobes : unit.bottomLobes;
    end.pole = lobes.empty();
    for (std::uint32_t li : lobes) {
        const std::vector<Vec3d>& pts = g.lobes[li].points;
        end.loop.insert(end.loop.end(), end.loop.empty() ? pts.begin() : pts.begin() + 1, pts.end());
    }
    return end;
}

namespace {

// Contours of a unit mesh at a height: polygons sorted by their lowest point, so a section only
// looks at the polygons that reach below it.
class Sectioner {
public:
    Sectioner(const Unit& unit, const Vec3d& axis) : mUnit(unit) {
        mHeight.resize(unit.points.size());
        for (std::size_t i = 0; i < unit.points.size(); ++i) mHeight[i] = dot(unit.points[i], axis);
        const std::size_t n = unit.polygonCount();
        mOrder.resize(n);
        mLow.resize(n);
        mHigh.resize(n);
        for (std::size_t p = 0; p < n; ++p) {
            double lo = INFINITY, hi = -INFINITY;
            for (std::uint32_t k = unit.offsets[p]; k < unit.offsets[p + 1]; ++k) {
                lo = std::min(lo, mHeight[unit.indices[k]]);
                hi = std::max(hi, mHeight[unit.indices[k]]);
            }
            mLow[p] = lo;
            mHigh[p] = hi;
            mOrder[p] = std::uint32_t(p);
        }
        std::sort(mOrder.begin(), mOrder.end(), [&](std::uint32_t a, std::uint32_t b) { return mLow[a] != mLow[b] ? mLow[a] < mLow[b] : a < b; });
        mSortedLow.resize(n);
        for (std::size_t i = 0; i < n; ++i) mSortedLow[i] = mLow[mOrder[i]];
    }

    // The longest contour loop at height t, oriented like the lobes (first point repeated).
    std::vector<Vec3d> longestLoop(double t, std::size_t& loops) const {
        struct Segment {
            std::uint64_t in, out;
            Vec3d a;
        };
        std::vector<Segment> segs;
        const std::size_t end = std::size_t(std::lower_bound(mSortedLow.begin(), mSortedLow.end(), t) - mSortedLow.begin());
        for (std::size_t i = 0; i < end; ++i) {
            const std::uint32_t p = mOrder[i];
            if (mHigh[p] < t) continue;
            const std::uint32_t b = mUnit.offsets[p], n = mUnit.offsets[p + 1] - b;
            std::uint64_t in = ~0ull;
            Vec3d a;
            for (std::uint32_t k = 0; k < n; ++k) {
                const std::uint32_t u = mUnit.indices[b + k], w = mUnit.indices[b + (k + 1) % n];
                const bool uAbove = mHeight[u] >= t, wAbove = mHeight[w] >= t;
                if (uAbove == wAbove) continue;
                const std::uint64_t key = undirectedEdgeKey(u, w);
                if (!uAbove) { // climbing: the contour enters here
                    in = key;
                    const double s = (t - mHeight[u]) / (mHeight[w] - mHeight[u]);
                    a = mUnit.points[u] + (mUnit.points[w] - mUnit.points[u]) * s;
                } else if (in != ~0ull) {
                    segs.push_back({in, key, a});
                    in = ~0ull;
                } else { // the entry comes later in corner order: wrap around
                    for (std::uint32_t j = k + 1; j < k + n; ++j) {
                        const std::uint32_t u2 = mUnit.indices[b + j % n], w2 = mUnit.indices[b + (j + 1) % n];
                        if (mHeight[u2] < t && mHeight[w2] >= t) {
                            const double s = (t - mHeight[u2]) / (mHeight[w2] - mHeight[u2]);
                            segs.push_back({undirectedEdgeKey(u2, w2), key,
                                            mUnit.points[u2] + (mUnit.points[w2] - mUnit.points[u2]) * s});
                            break;
                        }
                    }
                }
            }
        }
        std::unordered_map<std::uint64_t, std::size_t> byEntry;
        byEntry.reserve(segs.size() * 2);
        for (std::size_t i = 0; i < segs.size(); ++i) byEntry.emplace(segs[i].in, i);
        std::vector<char> used(segs.size(), 0);
        std::vector<Vec3d> best;
        double bestLength = -1;
        loops = 0;
        for (std::size_t s0 = 0; s0 < segs.size(); ++s0) {
            if (used[s0]) continue;
            std::vector<Vec3d> loop;
            std::size_t s = s0;
            bool closed = false;
            while (!used[s]) {
                used[s] = 1;
                loop.push_back(segs[s].a);
                const auto it = byEntry.find(segs[s].out);
                if (it == byEntry.end()) break;
                s = it->second;
                closed = s == s0;
            }
            if (!closed || loop.size() < 2) continue;
            loop.push_back(loop.front());
            ++loops;
            const double l = loopLength(loop);
            if (l > bestLength) {
                bestLength = l;
                best = std::move(loop);
            }
        }
        return best;
    }

private:
    const Unit& mUnit;
    std::vector<double> mHeight, mLow, mHigh, mSortedLow;
    std::vector<std::uint32_t> mOrder;
};

// The two searches below find the shift k (of 4 U) minimising sum_i |samples[(k + 4 i) mod 4 U] -
// reference[i]|^2: the direct one in O(U^2) (a partial sum stops once it passes the best), the
// spectral one in O(U log U). Grids sized from their unit (U <= 128) take the direct one.
constexpr int kDirectShiftSearchMaxU = 128;

int bestShiftDirect(const std::vector<Vec3d>& samples, const std::vector<Vec3d>& reference) {
    const int U = int(reference.size()), fine = 4 * U;
    double bestCost = INFINITY;
    int best = 0;
    for (int k = 0; k < fine; ++k) {
        double cost = 0;
        std::size_t at = std::size_t(k); // (k + 4 i) mod fine, without a division a term
        for (int i = 0; i < U && cost < bestCost; ++i) {
            const Vec3d d = samples[at] - reference[std::size_t(i)];
            cost += dot(d, d);
            at += 4;
            if (at >= std::size_t(fine)) at -= std::size_t(fine);
        }
        if (cost < bestCost) {
            bestCost = cost;
            best = k;
        }
    }
    return best;
}

// For each of the four interleaved sample sets x_j = samples[c + 4 j], the cost of shift
// k = c + 4 m is sum |x|^2 + sum |reference|^2 - 2 sum_i x_((m + i) mod U) . reference_i, whose
// last term, a cyclic correlation, is the inverse FFT of X conj(R) summed over the three axes.
int bestShiftSpectral(const std::vector<Vec3d>& samples, const std::vector<Vec3d>& reference) {
    const std::size_t U = reference.size();
    Eigen::FFT<double> fft;
    std::vector<double> axis(U);
    std::array<std::vector<std::complex<double>>, 3> R;
    for (std::size_t a = 0; a < 3; ++a) {
        for (std::size_t i = 0; i < U; ++i) axis[i] = reference[i][a];
        fft.fwd(R[a], axis);
    }
    std::array<std::vector<double>, 4> cost;
    std::vector<std::complex<double>> X, sum(U);
    for (std::size_t c = 0; c < 4; ++c) {
        std::fill(sum.begin(), sum.end(), std::complex<double>(0.0));
        double norm = 0;
        for (std::size_t a = 0; a < 3; ++a) {
            for (std::size_t j = 0; j < U; ++j) {
                axis[j] = samples[c + 4 * j][a];
                norm += axis[j] * axis[j];
            }
            fft.fwd(X, axis);
            for (std::size_t f = 0; f < U; ++f) sum[f] += X[f] * std::conj(R[a][f]);
        }
        std::vector<double> correlation;
        fft.inv(correlation, sum);
        cost[c].resize(U);
        for (std::size_t m = 0; m < U; ++m) cost[c][m] = norm - 2 * correlation[m];
    }
    // (sum |reference|^2 is the same for every shift.) The first least cost in k's order, as the
    // direct search takes it.
    int best = 0;
    double bestCost = INFINITY;
    for (std::size_t k = 0; k < 4 * U; ++k)
        if (cost[k % 4][k / 4] < bestCost) bestCost = cost[k % 4][k / 4], best = int(k);
    return best;
}

// The offset (fraction of the loop) whose resampling lies closest to `reference`.
double bestOffset(const std::vector<Vec3d>& loop, const std::vector<Vec3d>& reference) {
    const int U = int(reference.size()), fine = 4 * U;
    const std::vector<Vec3d> samples = resampleLoop(loop, fine, 0.0);
    const int best = U > kDirectShiftSearchMaxU ? bestShiftSpectral(samples, reference) : bestShiftDirect(samples, reference);
    return double(best) / fine;
}

} // namespace

RingGrid ringGrid(const ReebGraph& g, const Unit& unit, int U, int V, const CancelToken* cancel, Progress* progress) {
    const std::uint64_t share = ringGridProgressUnits(V);
    std::uint64_t advanced = 0;
    const UnitEnd bottom = unitEnd(g, unit, false), top = unitEnd(g, unit, true);
    const Sectioner sectioner(unit, g.axis);
    const double h0 = bottom.height, h1 = top.height;
    std::size_t several = 0;
    // A section can find no contour where the unit is flat (a plateau) or where simplification
    // re-ordered vertices against their heights; such rows are blended from their neighbours.
    std::size_t missing = 0;
    auto section = [&](double t) {
        if (cancel) cancel->check();
        std::size_t loops = 0;
        std::vector<Vec3d> loop = sectioner.longestLoop(t, loops);
        several += loops > 1;
        missing += loop.empty();
        return loop;
    };
    if (U <= 0 || V <= 0) {
        // Loop lengths at a few heights give the unit's girth; its area over the girth its length.
        double girth = 0;
        int n = 0;
        for (int i = 1; i < 8; ++i) {
            const std::vector<Vec3d> loop = section(h0 + (h1 - h0) * i / 8.0);
            if (loop.empty()) continue;
            girth += loopLength(loop);
            ++n;
        }
        girth = n ? girth / n : std::sqrt(unit.area);
        const double spacing = std::sqrt(unit.area / std::max(1.0, double(unit.inputVertices) / 4.0));
        if (U <= 0) U = std::clamp(int(std::lround(girth / spacing)), 8, 128);
        if (V <= 0) V = std::clamp(int(std::lround(unit.area / std::max(girth, 1e-30) / spacing)) + 1, 4, kMaxAutoV);
    }
    RingGrid grid;
    grid.U = U;
    grid.V = V;
    grid.heights.resize(static_cast<std::size_t>(V));
    for (int v = 0; v < V; ++v) grid.heights[std::size_t(v)] = h0 + (h1 - h0) * v / double(V - 1);
    std::vector<std::vector<Vec3d>> rows{std::size_t(V)};
    // Sections at the current heights; the seam is carried outwards from an end with a saddle
    // (where u = 0 is the saddle), else from the middle section's extreme point across the axis.
    auto build = [&]() {
        std::vector<std::vector<Vec3d>> loopsAt{std::size_t(V)};
        for (std::vector<Vec3d>& r : rows) r.clear();
        if (bottom.pole) rows[0].assign(std::size_t(U), bottom.point);
        else loopsAt[0] = bottom.loop;
        if (top.pole) rows[std::size_t(V - 1)].assign(std::size_t(U), top.point);
        else loopsAt[std::size_t(V - 1)] = top.loop;
        for (int v = 1; v + 1 < V; ++v) loopsAt[std::size_t(v)] = section(grid.heights[std::size_t(v)]);
        int anchor = -1;
        double anchorOffset = 0;
        if (!bottom.pole) anchor = 0;
        else if (!top.pole) anchor = V - 1;
        else {
            for (int d = 0; d < V && anchor < 0; ++d)
                for (int v : {V / 2 - d, V / 2 + d})
                    if (anchor < 0 && v > 0 && v + 1 < V && !loopsAt[std::size_t(v)].empty()) anchor = v;
            if (anchor >= 0) {
                const Vec3d across = acrossAxis(g.axis);
                const std::vector<Vec3d> fine = resampleLoop(loopsAt[std::size_t(anchor)], 4 * U, 0.0);
                std::size_t best = 0;
                for (std::size_t i = 1; i < fine.size(); ++i)
                    if (dot(fine[i], across) > dot(fine[best], across)) best = i;
                anchorOffset = double(best) / double(fine.size());
            }
        }
        grid.bottomSeam = grid.topSeam = 0.0;
        if (anchor >= 0) {
            rows[std::size_t(anchor)] = resampleLoop(loopsAt[std::size_t(anchor)], U, anchorOffset);
            if (anchor == 0) grid.bottomSeam = anchorOffset;
            if (anchor == V - 1) grid.topSeam = anchorOffset;
            for (int dir : {-1, 1}) {
                int ref = anchor;
                for (int v = anchor + dir; v >= 0 && v < V; v += dir) {
                    const std::vector<Vec3d>& loop = loopsAt[std::size_t(v)];
                    if (loop.empty()) continue; // a pole (already set) or a missing section
                    if (cancel) cancel->check();
                    const double offset = bestOffset(loop, rows[std::size_t(ref)]);
                    rows[std::size_t(v)] = resampleLoop(loop, U, offset);
                    if (v == 0) grid.bottomSeam = offset;
                    if (v == V - 1) grid.topSeam = offset;
                    ref = v;
                }
            }
        }
        for (int v = 1; v + 1 < V; ++v) {
            if (!rows[std::size_t(v)].empty()) continue;
            int lo = v - 1, hi = v + 1;
            while (rows[std::size_t(hi)].empty()) ++hi;
            const double span = grid.heights[std::size_t(hi)] - grid.heights[std::size_t(lo)];
            const double w = span > 0 ? (grid.heights[std::size_t(v)] - grid.heights[std::size_t(lo)]) / span : double(v - lo) / (hi - lo);
            rows[std::size_t(v)].resize(std::size_t(U));
            for (int u = 0; u < U; ++u)
                rows[std::size_t(v)][std::size_t(u)] = rows[std::size_t(lo)][std::size_t(u)] * (1 - w) + rows[std::size_t(hi)][std::size_t(u)] * w;
        }
    };
    // Even out the spacing of the sections along the surface: heights re-spaced by the mean
    // distance between consecutive rows, a few times.
    for (int iteration = 0; iteration < kSectionPasses; ++iteration) {
        several = 0;
        missing = 0;
        build();
        if (progress) progress->advance(std::uint64_t(V)), advanced += std::uint64_t(V);
        if (iteration == kSectionPasses - 1 || V < 3) break;
        std::vector<double> along(std::size_t(V), 0.0);
        for (int v = 1; v < V; ++v) {
            double d = 0;
            for (int u = 0; u < U; ++u) d += length(rows[std::size_t(v)][std::size_t(u)] - rows[std::size_t(v - 1)][std::size_t(u)]);
            along[std::size_t(v)] = along[std::size_t(v - 1)] + d / U;
        }
        if (!(along.back() > 0)) break;
        std::vector<double> heights(grid.heights);
        for (int v = 1; v + 1 < V; ++v) {
            const double target = along.back() * v / double(V - 1);
            const std::size_t k = std::size_t(std::upper_bound(along.begin(), along.end(), target) - along.begin());
            const std::size_t hi = std::min<std::size_t>(k, std::size_t(V - 1)), lo = hi - 1;
            const double span = along[hi] - along[lo];
            const double s = span > 0 ? (target - along[lo]) / span : 0.0;
            heights[std::size_t(v)] = grid.heights[lo] + (grid.heights[hi] - grid.heights[lo]) * s;
        }
        // Keep the sections strictly inside the unit and in order.
        const double margin = (h1 - h0) * 1e-6;
        for (int v = 1; v + 1 < V; ++v)
            heights[std::size_t(v)] = std::clamp(heights[std::size_t(v)], std::max(heights[std::size_t(v - 1)], h0) + margin, h1 - margin);
        grid.heights = heights;
    }
    if (progress) progress->advance(share - advanced);
    grid.sectionsWithSeveralLoops = several;
    grid.sectionsBlended = missing;
    grid.points.reserve(std::size_t(U) * std::size_t(V));
    for (int v = 0; v < V; ++v) grid.points.insert(grid.points.end(), rows[std::size_t(v)].begin(), rows[std::size_t(v)].end());
    return grid;
}

} // namespace vdbsurf::reeb
