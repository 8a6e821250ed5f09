#include "vdbsurf/quality/surface_quality.h"

#include "vdbsurf/core/cancel.h"
#include "vdbsurf/dmc/mesher.h"
#include "vdbsurf/mesh/mesh_distance.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

namespace vdbsurf {

namespace {

// Bisection of f(a + t d) - iso on [t0, t1], whose ends lie on opposite sides.
double bisect(const Field& field, double iso, const Vec3d& a, const Vec3d& d, double t0, double t1, double v0) {
    for (int i = 0; i < 24; ++i) { // bracket / 2^24: far below any tolerance measured
        const double tm = 0.5 * (t0 + t1);
        const double vm = field.value(a + d * tm) - iso;
        if ((vm < 0) == (v0 < 0)) {
            t0 = tm;
            v0 = vm;
        } else {
            t1 = tm;
        }
    }
    return 0.5 * (t0 + t1);
}

// Every vertex, and for each fanned triangle its centroid plus, on triangles longer than h, the
// interior points of a barycentric pattern at spacing about h: flat interiors are where a mesh
// strays from a curved surface, and large triangles must weigh more than small ones.
std::vector<Vec3d> meshSamples(const Mesh& mesh, double h) {
    std::vector<Vec3d> out;
    out.reserve(mesh.points.size() + 2 * mesh.polygonCount());
    for (const Vec3f& v : mesh.points) out.push_back(Vec3d(v));
    for (std::size_t f = 0; f < mesh.polygonCount(); ++f) {
        const std::uint32_t b = mesh.offsets[f], e = mesh.offsets[f + 1];
        for (std::uint32_t i = b + 1; i + 1 < e; ++i) {
            const Vec3d A(mesh.points[mesh.indices[b]]), B(mesh.points[mesh.indices[i]]), C(mesh.points[mesh.indices[i + 1]]);
            const double longest = std::max({length(B - A), length(C - B), length(A - C)});
            const int n = int(std::ceil(longest / h));
            if (n < 3) {
                out.push_back((A + B + C) / 3.0);
                continue;
            }
            for (int u = 1; u < n; ++u)
                for (int v = 1; u + v < n; ++v) out.push_back(A + (B - A) * (double(u) / n) + (C - A) * (double(v) / n));
        }
    }
    return out;
}

} // namespace

double distanceToIsoSurface(const Field& field, double iso, const Vec3d& p, double maxDistance) {
    const double v = field.value(p) - iso;
    if (v == 0) return 0;
    double best = maxDistance;

    // Newton steps towards the surface; the point reached is on it when the sign flipped (then
    // bisect between the last two points) — its distance from p bounds the true distance.
    Vec3d q = p;
    double vq = v;
    for (int i = 0; i < 12; ++i) {
        const Vec3d g = field.gradient(q);
        const double gg = dot(g, g);
        if (!(gg > 0) || !std::isfinite(gg)) break;
        const Vec3d next = q - g * (vq / gg);
        if (length(next - p) > 2 * maxDistance) break;
        const double vn = field.value(next) - iso;
        if (vn == 0) {
            best = std::min(best, length(next - p));
            break;
        }
        if ((vn < 0) != (v < 0)) {
            const Vec3d d = next - q;
            const double t = bisect(field, iso, q, d, 0, 1, vq);
            best = std::min(best, length(q + d * t - p));
            break;
        }
        q = next;
        vq = vn;
    }

    // Where Newton failed, a march along the gradient line both ways, nearest sign change first:
    // robust where Newton overshoots (fog edges, kinks of a trilinear field).
    if (best < maxDistance) return best;
    Vec3d n = field.gradient(p);
    const double len = length(n);
    if (len > 0 && std::isfinite(len)) {
        n = n / len;
        const int steps = 32;
        const double dt = best / steps;
        double prevPlus = v, prevMinus = v;
        for (int s = 1; s <= steps; ++s) {
            const double t = s * dt;
            const double vp = field.value(p + n * t) - iso;
            if ((vp < 0) != (v < 0) || vp == 0) {
                best = std::min(best, bisect(field, iso, p, n, t - dt, t, prevPlus));
                break;
            }
            const double vm = field.value(p - n * t) - iso;
            if ((vm < 0) != (v < 0) || vm == 0) {
                best = std::min(best, bisect(field, iso, p, n * -1.0, t - dt, t, prevMinus));
                break;
            }
            prevPlus = vp;
            prevMinus = vm;
        }
    }
    return best;
}

std::vector<Vec3d> isoSurfaceSamples(const Field& field, double iso, double h, const CancelToken* cancel) {
    MeshRequest req;
    req.cancel = cancel;
    req.iso = iso;
    req.voxelSize = h;
    req.method = MeshMethod::MarchingCubes;
    req.allowEmpty = true; // no surface: no samples, for the caller to judge
    MeshReport rep;
    const Mesh m = meshField(field, req, rep);
    std::vector<Vec3d> out;
    out.reserve(m.points.size());
    for (const Vec3f& p : m.points) out.push_back(Vec3d(p));
    return out;
}

SurfaceQuality measureSurfaceQuality(const Mesh& mesh, const Field& field, double iso,
                                     const std::vector<Vec3d>& surfaceSamples, double h, const CancelToken* cancel) {
    SurfaceQuality q;
    q.h = h;
    const double cap = 2 * h;

    const std::vector<Vec3d> samples = meshSamples(mesh, h);
    std::vector<double> toSurface(samples.size());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, samples.size(), 256), [&](const auto& r) {
        if (cancel) cancel->check();
        for (std::size_t i = r.begin(); i != r.end(); ++i) toSurface[i] = distanceToIsoSurface(field, iso, samples[i], cap);
    });

    const MeshDistance meshDistance(mesh, h);
    std::vector<double> toMesh(surfaceSamples.size());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, surfaceSamples.size(), 256), [&](const auto& r) {
        if (cancel) cancel->check();
        for (std::size_t i = r.begin(); i != r.end(); ++i) toMesh[i] = meshDistance.distance(surfaceSamples[i], h * 1.000001);
    });

    q.meshSamples = samples.size();
    q.surfaceSamples = surfaceSamples.size();
    if (!samples.empty()) {
        double sum = 0; // summed in index order: the same result whatever the thread count
        std::size_t within = 0;
        for (double d : toSurface) {
            sum += d;
            within += d <= 0.25 * h;
        }
        q.meanDistance = sum / double(samples.size());
        q.accuracyQuarter = double(within) / double(samples.size());
        std::vector<double> sorted = toSurface;
        const std::size_t k = std::min(sorted.size() - 1, std::size_t(std::ceil(0.95 * double(sorted.size()))) - 1);
        std::nth_element(sorted.begin(), sorted.begin() + std::ptrdiff_t(k), sorted.end());
        q.p95Distance = sorted[k];
        q.maxDistance = *std::max_element(toSurface.begin(), toSurface.end());
    }
    if (!surfaceSamples.empty()) {
        std::size_t quarter = 0, one = 0;
        for (double d : toMesh) {
            quarter += d <= 0.25 * h;
            one += d <= h;
        }
        q.coverageQuarter = double(quarter) / double(surfaceSamples.size());
        q.coverageOne = double(one) / double(surfaceSamples.size());
    }
    const double pr = q.accuracyQuarter + q.coverageQuarter;
    q.fScoreQuarter = pr > 0 ? 2 * q.accuracyQuarter * q.coverageQuarter / pr : 0;
    return q;
}

} // namespace vdbsurf
