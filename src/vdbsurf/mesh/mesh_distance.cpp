#include "vdbsurf/mesh/mesh_distance.h"

#include <algorithm>
#include <cmath>

namespace vdbsurf {

double pointTriangleDistance(const Vec3d& p, const Vec3d& a, const Vec3d& b, const Vec3d& c) {
    // Closest point by Voronoi regions of the triangle (vertices, edges, face).
    const Vec3d ab = b - a, ac = c - a, ap = p - a;
    const double d1 = dot(ab, ap), d2 = dot(ac, ap);
    if (d1 <= 0 && d2 <= 0) return length(p - a);
    const Vec3d bp = p - b;
    const double d3 = dot(ab, bp), d4 = dot(ac, bp);
    if (d3 >= 0 && d4 <= d3) return length(p - b);
    const double vc = d1 * d4 - d3 * d2;
    if (vc <= 0 && d1 >= 0 && d3 <= 0) {
        const double den = d1 - d3;
        return length(p - (a + ab * (den > 0 ? d1 / den : 0.0)));
    }
    const Vec3d cp = p - c;
    const double d5 = dot(ab, cp), d6 = dot(ac, cp);
    if (d6 >= 0 && d5 <= d6) return length(p - c);
    const double vb = d5 * d2 - d1 * d6;
    if (vb <= 0 && d2 >= 0 && d6 <= 0) {
        const double den = d2 - d6;
        return length(p - (a + ac * (den > 0 ? d2 / den : 0.0)));
    }
    const double va = d3 * d6 - d5 * d4;
    if (va <= 0 && d4 - d3 >= 0 && d5 - d6 >= 0) {
        const double den = (d4 - d3) + (d5 - d6);
        return length(p - (b + (c - b) * (den > 0 ? (d4 - d3) / den : 0.0)));
    }
    const double sum = va + vb + vc;
    if (!(sum > 0)) return std::min({length(p - a), length(p - b), length(p - c)}); // degenerate
    return length(p - (a + ab * (vb / sum) + ac * (vc / sum)));
}

namespace {

constexpr double kGrowth = 4;       // one level's cells over the level below's
constexpr double kMaxAcross = 4;    // cells a triangle may span along an axis of its level
constexpr int kMaxLevels = 64;
constexpr double kMaxIndex = 1e15;  // cell indices beyond this do not fit floor() into 64 bits

bool finite(const Vec3d& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }
double largest(const Vec3d& v) { return std::max({v.x, v.y, v.z}); }
Vec3d magnitude(const Vec3d& v) { return {std::abs(v.x), std::abs(v.y), std::abs(v.z)}; }

} // namespace

std::int64_t MeshDistance::key(std::int64_t i, std::int64_t j, std::int64_t k) {
    // Indices wrap at 2^21: cells that share a key share a bucket, which costs distances, not answers.
    return (i & 0x1fffff) | ((j & 0x1fffff) << 21) | ((k & 0x1fffff) << 42);
}

MeshDistance::MeshDistance(const Mesh& mesh, double cell) {
    for (std::size_t f = 0; f < mesh.polygonCount(); ++f) {
        const std::uint32_t b = mesh.offsets[f], e = mesh.offsets[f + 1];
        for (std::uint32_t i = b + 1; i + 1 < e; ++i)
            mTris.push_back({Vec3d(mesh.points[mesh.indices[b]]), Vec3d(mesh.points[mesh.indices[i]]), Vec3d(mesh.points[mesh.indices[i + 1]])});
    }
    const double base = cell > 0 && std::isfinite(cell) ? cell : 1.0;
    for (std::uint32_t t = 0; t < mTris.size(); ++t) {
        const Tri& tr = mTris[t];
        // A triangle with a point that is not finite is at no distance from anything.
        if (!finite(tr.a) || !finite(tr.b) || !finite(tr.c)) continue;
        const Vec3d lo = vmin(tr.a, vmin(tr.b, tr.c)), hi = vmax(tr.a, vmax(tr.b, tr.c));
        const double width = largest(hi - lo), reach = std::max(largest(magnitude(lo)), largest(magnitude(hi)));
        int level = 0;
        double c = base;
        while (level < kMaxLevels && (width > kMaxAcross * c || reach > kMaxIndex * c)) c *= kGrowth, ++level;
        if (level == kMaxLevels) {
            mLoose.push_back(t);
            continue;
        }
        if (mLevels.size() <= std::size_t(level)) mLevels.resize(std::size_t(level) + 1);
        Level& l = mLevels[std::size_t(level)];
        l.cell = c;
        l.tris.push_back(t);
        for (auto k = std::int64_t(std::floor(lo.z / c)); k <= std::int64_t(std::floor(hi.z / c)); ++k)
            for (auto j = std::int64_t(std::floor(lo.y / c)); j <= std::int64_t(std::floor(hi.y / c)); ++j)
                for (auto i = std::int64_t(std::floor(lo.x / c)); i <= std::int64_t(std::floor(hi.x / c)); ++i)
                    l.cells[key(i, j, k)].push_back(t);
    }
}

double MeshDistance::nearest(const std::vector<std::uint32_t>& tris, const Vec3d& p, double best) const {
    for (std::uint32_t t : tris) best = std::min(best, pointTriangleDistance(p, mTris[t].a, mTris[t].b, mTris[t].c));
    return best;
}

double MeshDistance::distance(const Vec3d& p, double maxRadius) const {
    if (!finite(p)) return maxRadius;
    double best = nearest(mLoose, p, maxRadius);
    for (const Level& l : mLevels) {
        if (l.tris.empty()) continue;
        // A query box of more cells than the level has triangles (or beyond its indices) reads
        // the triangles one by one.
        const double across = 2 * maxRadius / l.cell + 2;
        if (!(across * across * across <= double(l.tris.size())) || largest(magnitude(p)) > kMaxIndex * l.cell) {
            best = nearest(l.tris, p, best);
            continue;
        }
        const auto lo = [&](double v) { return std::int64_t(std::floor((v - maxRadius) / l.cell)); };
        const auto hi = [&](double v) { return std::int64_t(std::floor((v + maxRadius) / l.cell)); };
        for (std::int64_t k = lo(p.z); k <= hi(p.z); ++k)
            for (std::int64_t j = lo(p.y); j <= hi(p.y); ++j)
                for (std::int64_t i = lo(p.x); i <= hi(p.x); ++i) {
                    const auto it = l.cells.find(key(i, j, k));
                    if (it != l.cells.end()) best = nearest(it->second, p, best);
                }
    }
    return best;
}

} // namespace vdbsurf
