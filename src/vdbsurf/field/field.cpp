#include "vdbsurf/field/field.h"

#include "vdbsurf/core/error.h"

#include <algorithm>
#include <cmath>
#include <vector>

namespace vdbsurf {

void Field::sampleNodes(const LatticeFrame& frame, const Vec3i& first, const Vec3i& dims,
                        const std::uint8_t* needed, double* out) const {
    // The needed nodes together, through values(): a field that evaluates many points at once
    // (a formula, a density scene) does so for lattice blocks too. A lone node is one value():
    // the searches ask for single nodes often, and a batch of one costs more than the point.
    if (dims.x * dims.y * dims.z == 1) {
        if (!needed || needed[0]) out[0] = value(frame.nodeWorld(first.x, first.y, first.z));
        return;
    }
    // (Per thread, reused: values() never asks for nodes itself.)
    thread_local std::vector<Vec3d> points;
    thread_local std::vector<std::size_t> at;
    thread_local std::vector<double> sampled;
    points.clear();
    at.clear();
    Box3 box{Vec3d(INFINITY, INFINITY, INFINITY), Vec3d(-INFINITY, -INFINITY, -INFINITY)};
    std::size_t n = 0;
    for (int k = 0; k < dims.z; ++k)
        for (int j = 0; j < dims.y; ++j)
            for (int i = 0; i < dims.x; ++i, ++n) {
                if (needed && !needed[n]) continue;
                const Vec3d p = frame.nodeWorld(first.x + i, first.y + j, first.z + k);
                box = {vmin(box.min, p), vmax(box.max, p)};
                points.push_back(p);
                at.push_back(n);
            }
    if (points.empty()) return;
    sampled.resize(points.size());
    values(box, points.data(), points.size(), sampled.data());
    for (std::size_t m = 0; m < at.size(); ++m) out[at[m]] = sampled[m];
}

std::string valueRangeText(const Field& field) {
    const Interval r = field.bounds(field.domain());
    return "values lie within " + messageNumber(r.lo) + " .. " + messageNumber(r.hi);
}

void Field::values(const Box3&, const Vec3d* points, std::size_t n, double* out) const {
    for (std::size_t i = 0; i < n; ++i) out[i] = value(points[i]);
}

double Field::edgeCrossing(const Vec3d& a, const Vec3d& b, double va, double vb, double iso) const {
    return refineCrossing(*this, a, b, va, vb, iso);
}

double refineCrossing(const Field& field, const Vec3d& a, const Vec3d& b, double va, double vb, double iso,
                      int maxSteps) {
    double t0 = 0.0, t1 = 1.0;
    double f0 = va - iso, f1 = vb - iso;
    if (f0 == 0.0) return 0.0;
    if (f1 == 0.0) return 1.0;
    const double scale = std::max(std::fabs(f0), std::fabs(f1));
    // Illinois: halve the weight of an end point that is retained twice, which keeps regula falsi
    // superlinear on convex pieces; bisect while an end is infinite (1/r-style formulas).
    int side = 0;
    double t = 0.5;
    for (int step = 0; step < maxSteps; ++step) {
        if (std::isfinite(f0) && std::isfinite(f1)) t = t0 + (t1 - t0) * (f0 / (f0 - f1));
        else t = 0.5 * (t0 + t1);
        if (!(t > t0 && t < t1)) t = 0.5 * (t0 + t1);
        const double ft = field.value(a + (b - a) * t) - iso;
        if (!std::isfinite(scale) ? ft == 0.0 : std::fabs(ft) <= 1e-12 * scale) return t;
        if (std::isnan(ft)) break;
        if ((ft < 0) == (f0 < 0)) {
            t0 = t; f0 = ft;
            if (side == -1 && std::isfinite(f1)) f1 *= 0.5;
            side = -1;
        } else {
            t1 = t; f1 = ft;
            if (side == 1 && std::isfinite(f0)) f0 *= 0.5;
            side = 1;
        }
        if (t1 - t0 < 1e-9) break;
    }
    if (std::isfinite(f0) && std::isfinite(f1)) return t0 + (t1 - t0) * (f0 / (f0 - f1));
    return 0.5 * (t0 + t1);
}

} // namespace vdbsurf
