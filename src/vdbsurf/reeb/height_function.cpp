#include "vdbsurf/reeb/height_function.h"

#include "vdbsurf/core/error.h"
#include "vdbsurf/core/union_find.h"

#include <tbb/parallel_sort.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <numeric>
#include <queue>
#include <sstream>

namespace vdbsurf::reeb {

namespace {

template <typename F>
void forEachNeighbour(const ClosedSurface& s, std::uint32_t v, F&& f) {
    const std::uint32_t first = s.vertexCorner[v];
    std::uint32_t c = first;
    do {
        f(s.vertex[ClosedSurface::next(c)]);
        c = s.around(c);
    } while (c != first);
}

void setOrder(HeightFunction& f, std::vector<std::uint32_t> byRank) {
    f.byRank = std::move(byRank);
    for (std::uint32_t r = 0; r < f.byRank.size(); ++r) f.rank[f.byRank[r]] = r;
}

// Minima (of the order `rank`) to keep: the oldest of each component of the sweep, and every
// one whose component lives at least `persistence` in height before merging into an older one.
std::vector<std::uint32_t> persistentMinima(const ClosedSurface& s, const std::vector<double>& h,
                                            const std::vector<std::uint32_t>& rank, const std::vector<std::uint32_t>& byRank,
                                            double persistence, std::size_t& removed) {
    const std::size_t n = byRank.size();
    UnionFind uf(n);
    std::vector<std::uint32_t> minOf(n, ~0u);
    std::vector<char> keep(n, 0), isMin(n, 0);
    for (std::uint32_t r = 0; r < n; ++r) {
        const std::uint32_t v = byRank[r];
        std::uint32_t oldest = ~0u;
        std::vector<std::uint32_t> roots;
        forEachNeighbour(s, v, [&](std::uint32_t w) {
            if (rank[w] < r) roots.push_back(uf.find(w));
        });
        if (roots.empty()) {
            minOf[v] = v;
            isMin[v] = 1;
            continue;
        }
        std::sort(roots.begin(), roots.end());
        roots.erase(std::unique(roots.begin(), roots.end()), roots.end());
        for (std::uint32_t root : roots)
            if (oldest == ~0u || rank[minOf[root]] < rank[oldest]) oldest = minOf[root];
        for (std::uint32_t root : roots) {
            const std::uint32_t m = minOf[root];
            if (m != oldest && h[v] - h[m] >= persistence) keep[m] = 1;
        }
        for (std::uint32_t root : roots) uf.unite(root, v);
        minOf[uf.find(v)] = oldest;
    }
    std::vector<std::uint32_t> seeds;
    removed = 0;
    for (std::uint32_t v = 0; v < n; ++v) {
        if (!isMin[v]) continue;
        if (minOf[uf.find(v)] == v) keep[v] = 1; // the oldest of its component never dies
        if (keep[v]) seeds.push_back(v);
        else ++removed;
    }
    return seeds;
}

// New order: a sweep from the seeds that always takes the frontier vertex earliest in the
// current order. Every vertex but a seed is reached from an earlier neighbour, so it is not a
// minimum.
std::vector<std::uint32_t> sweepFrom(const ClosedSurface& s, const std::vector<std::uint32_t>& rank,
                                     const std::vector<std::uint32_t>& seeds) {
    const std::size_t n = rank.size();
    std::vector<char> queued(n, 0);
    using Item = std::pair<std::uint32_t, std::uint32_t>; // (rank, vertex)
    std::priority_queue<Item, std::vector<Item>, std::greater<Item>> frontier;
    for (std::uint32_t v : seeds) {
        queued[v] = 1;
        frontier.push({rank[v], v});
    }
    std::vector<std::uint32_t> order;
    order.reserve(n);
    while (!frontier.empty()) {
        const std::uint32_t v = frontier.top().second;
        frontier.pop();
        order.push_back(v);
        forEachNeighbour(s, v, [&](std::uint32_t w) {
            if (!queued[w]) {
                queued[w] = 1;
                frontier.push({rank[w], w});
            }
        });
    }
    return order;
}

} // namespace

Vec3d acrossAxis(const Vec3d& axis) {
    // Tilted off the coordinate planes, so that tie-breaks do not tie again on meshes built on a lattice.
    const Vec3d generic = normalized(Vec3d(0.5257311, 0.3313243, 0.7837181));
    Vec3d across = generic - axis * dot(generic, axis);
    if (length(across) < 1e-3) across = cross(axis, Vec3d(0.2673, -0.5345, 0.8018));
    return normalized(across);
}

HeightFunction makeHeightFunction(const ClosedSurface& s, const Vec3d& axisIn) {
    // Scaled by its largest component first, so that a direction given in huge or tiny numbers
    // (1e300,1e300,0) does not overflow or underflow its length.
    const double largest = maxAbsComponent(axisIn);
    if (!(largest > 0) || !std::isfinite(axisIn.x) || !std::isfinite(axisIn.y) || !std::isfinite(axisIn.z))
        throw Error("--axis", "the height axis must be a non-zero direction");
    const Vec3d scaled = axisIn / largest;
    HeightFunction f;
    f.axis = scaled / length(scaled);
    const Vec3d e1 = acrossAxis(f.axis);
    const Vec3d e2 = cross(f.axis, e1);
    const std::size_t n = s.points.size();
    f.height.resize(n);
    f.tie1.resize(n);
    f.tie2.resize(n);
    for (std::size_t v = 0; v < n; ++v) {
        f.height[v] = dot(s.points[v], f.axis);
        f.tie1[v] = dot(s.points[v], e1);
        f.tie2[v] = dot(s.points[v], e2);
    }
    std::vector<std::uint32_t> order(n);
    std::iota(order.begin(), order.end(), 0u);
    tbb::parallel_sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) {
        if (f.height[a] != f.height[b]) return f.height[a] < f.height[b];
        if (f.tie1[a] != f.tie1[b]) return f.tie1[a] < f.tie1[b];
        if (f.tie2[a] != f.tie2[b]) return f.tie2[a] < f.tie2[b];
        return a < b;
    });
    f.rank.resize(n);
    setOrder(f, std::move(order));
    return f;
}

namespace {
std::string written(const Vec3d& v) {
    std::ostringstream s;
    s << '(' << v.x << ", " << v.y << ", " << v.z << ')';
    return s.str();
}
} // namespace

void requirePiecesSpanHeights(const ClosedSurface& s, const HeightFunction& f, const std::string& inputName) {
    std::vector<double> low(s.points.size(), INFINITY), high(s.points.size(), -INFINITY);
    for (std::uint32_t v = 0; v < s.points.size(); ++v) {
        const std::uint32_t r = s.piece[v];
        low[r] = std::min(low[r], f.height[v]);
        high[r] = std::max(high[r], f.height[v]);
    }
    // Pieces by their first vertex, so the one named is the same whatever the union order.
    for (std::uint32_t v = 0; v < s.points.size(); ++v) {
        const std::uint32_t r = s.piece[v];
        if (low[r] != high[r]) continue;
        const Vec3d& p = s.points[v];
        std::uint32_t size = 0;
        bool onePoint = true;
        for (std::uint32_t w = 0; w < s.points.size(); ++w)
            if (s.piece[w] == r) ++size, onePoint = onePoint && s.points[w] == p;
        const std::string piece = "the piece of vertex " + std::to_string(s.inputVertex[v]) + " (" + std::to_string(size) + " vertices)";
        if (onePoint)
            throw Error(inputName, piece + " has every point at one position, " + written(p) + ": it has no shape to fit patches to");
        std::ostringstream height;
        height << low[r];
        throw Error(inputName, piece + " lies flat across the height axis " + written(f.axis) + ", every point at height " + height.str() +
                                   ": its levels hold no contours to follow; choose another --axis");
    }
}

SimplifyReport simplifyExtrema(const ClosedSurface& s, HeightFunction& f, double persistence) {
    SimplifyReport report;
    if (!(persistence > 0)) return report;
    const std::size_t n = f.rank.size();
    std::vector<double> negHeight(n);
    for (std::size_t v = 0; v < n; ++v) negHeight[v] = -f.height[v];
    for (int pass = 0; pass < 16; ++pass) {
        bool changed = false;
        std::size_t removed = 0;
        std::vector<std::uint32_t> seeds = persistentMinima(s, f.height, f.rank, f.byRank, persistence, removed);
        if (removed) {
            report.minimaRemoved += removed;
            setOrder(f, sweepFrom(s, f.rank, seeds));
            changed = true;
        }
        // Maxima are the minima of the reversed order.
        std::vector<std::uint32_t> reverseRank(n), reverseByRank(f.byRank.rbegin(), f.byRank.rend());
        for (std::size_t v = 0; v < n; ++v) reverseRank[v] = std::uint32_t(n - 1 - f.rank[v]);
        seeds = persistentMinima(s, negHeight, reverseRank, reverseByRank, persistence, removed);
        if (removed) {
            report.maximaRemoved += removed;
            std::vector<std::uint32_t> order = sweepFrom(s, reverseRank, seeds);
            std::reverse(order.begin(), order.end());
            setOrder(f, std::move(order));
            changed = true;
        }
        ++report.passes;
        if (!changed) break;
    }
    return report;
}

double levelParameter(const HeightFunction& f, std::uint32_t s, std::uint32_t a, std::uint32_t b) {
    const std::vector<double>* keys[3] = {&f.height, &f.tie1, &f.tie2};
    for (const std::vector<double>* k : keys) {
        const double ka = (*k)[a], kb = (*k)[b];
        if (ka != kb) return std::clamp(((*k)[s] - ka) / (kb - ka), 0.0, 1.0);
    }
    return 0.5;
}

} // namespace vdbsurf::reeb
