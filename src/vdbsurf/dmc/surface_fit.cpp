#include "vdbsurf/dmc/surface_fit.h"

#include "vdbsurf/core/cancel.h"
#include "vdbsurf/core/planes.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <utility>
#include <vector>

namespace vdbsurf {

namespace {

// A projection that moves a point farther than this (in cells) has found another part of the
// surface than the one the chord stands for.
constexpr double kMaxProjection = 0.75;
// The straight path from a point to its projection is sampled at steps this long (in cells): a
// change of side before the end means the projection passed through a thin part or a gap to a
// sheet beyond it.
constexpr double kPathStep = 0.05;
// Newton steps onto the surface: at most this many, done when a step is below kConverged cells,
// accepted when the value lies within kOnSurface cells (|f - iso| / |grad f|) of the iso value.
constexpr int kNewtonSteps = 8;
constexpr double kConverged = 1e-6, kOnSurface = 1e-4;
// On a smooth surface the point between two others has a normal halfway between theirs (an
// angle of about θ/2 to each, θ being theirs); at a crease it has one face's normal (θ to the
// other). A split point must keep within this share of θ of both ends.
constexpr double kBetweenShare = 0.75;
// Samples of the surface round a polygon lie on one plane when their normals agree this well
// (cosine) and each lies within kOnPlane cells of the other's plane; a feature point must lie
// that close to every plane the samples show.
constexpr double kSamePlane = 0.995, kOnPlane = 0.02;
// Normals closer to opposite than this (|n_a × n_b| below it) are the two sheets of a thin part,
// not the faces of an edge (as in the sharp pass).
constexpr double kMinSine = 0.25;
// A polygon cutting a corner off may stray little at its middle (several polygons share the cut,
// and a corner 0.3 H away leaves a triangle's middle 0.1 H off): beside a feature node it is
// tried for a feature point from this share of the tolerance on (0.01 H at the default; the
// feature's own checks decide, its planes first, which rule out a curved surface from its
// corners' gradients alone), and the fan's checks hold it to the whole tolerance.
constexpr double kFeatureShare = 0.05;
// How far (in cells) a feature point may lie from the middle of the polygon fanned round it.
constexpr double kMaxFeatureReach = 1.25;
// A corner of the polygon this close (in cells) to the feature point already stands for it (the
// sharp pass's bar for a kept corner).
constexpr double kFeatureOnMesh = 0.1;

using EdgeKey = std::uint64_t;

// The least cosine a point's normal may make with the normals of the ends (or corners) whose
// widest angle has cosine `widest` (see kBetweenShare).
double betweenCosine(double widest) { return std::cos(kBetweenShare * std::acos(std::clamp(widest, -1.0, 1.0))); }

struct SplitEdge {
    EdgeKey key;
    Vec3f point;
};

class Fitter {
public:
    Fitter(const Field& field, const SurfaceFitOptions& o) : mField(field), mIso(o.iso), mH(o.h), mTolerance(o.tolerance) {}

    // Is p farther from the surface than the tolerance (first-order distance |f - iso| / |grad f|)?
    // (`share`: of the tolerance.)
    bool strays(const Vec3d& p, double share = 1) const {
        Vec3d g;
        const double v = mField.valueAndGradient(p, g);
        const double len = length(g);
        if (!(len > 0) || !std::isfinite(len) || !std::isfinite(v)) return false;
        return std::fabs(v - mIso) > share * mTolerance * mH * len;
    }

    // p moved onto the surface along the gradient (Newton's method), if that converges nearby
    // without crossing the surface on the way.
    bool project(Vec3d& p) const {
        Vec3d q = p;
        for (int i = 0; i < kNewtonSteps; ++i) {
            Vec3d g;
            const double v = mField.valueAndGradient(q, g);
            const double gg = dot(g, g);
            if (!(gg > 0) || !std::isfinite(gg)) return false;
            const Vec3d step = g * ((v - mIso) / gg);
            q = q - step;
            if (length(step) < kConverged * mH) break;
        }
        Vec3d g;
        const double v = mField.valueAndGradient(q, g);
        if (!std::isfinite(v) || !(std::fabs(v - mIso) <= kOnSurface * mH * length(g))) return false;
        const double moved = length(q - p);
        if (!(moved <= kMaxProjection * mH)) return false;
        const bool above = mField.value(p) > mIso;
        const int steps = int(std::ceil(moved / (kPathStep * mH)));
        for (int i = 1; i < steps; ++i)
            if ((mField.value(p + (q - p) * (double(i) / steps)) > mIso) != above) return false;
        p = q;
        return true;
    }

    // Unit gradient at p, or zero where there is none.
    Vec3d normal(const Vec3d& p) const {
        const Vec3d g = mField.gradient(p);
        const double len = length(g);
        return len > 0 && std::isfinite(len) ? g / len : Vec3d();
    }

    // The point on the surface that splits the edge a-b, if its midpoint strays and the surface
    // between a and b is smooth (not a crease, where the projection would land on one face).
    bool splitPoint(const Vec3d& a, const Vec3d& b, Vec3d& out) const {
        Vec3d p = (a + b) * 0.5;
        if (!strays(p) || !project(p)) return false;
        const Vec3d na = normal(a), nb = normal(b), np = normal(p);
        if (dot(na, na) == 0 || dot(nb, nb) == 0 || dot(np, np) == 0) return false;
        if (std::min(dot(np, na), dot(np, nb)) < betweenCosine(dot(na, nb))) return false;
        out = p;
        return true;
    }

    // Does the fan of triangles (ring[j], ring[j + 1], c) fit the surface: c not on one face of a
    // crease the ring spans, and each triangle facing the way the surface does at its corners
    // (the ring's own orientation against the gradients deciding which way is out)?
    bool fanFits(const std::vector<Vec3d>& ring, const Vec3d& c) const {
        const std::size_t n = ring.size();
        std::vector<Vec3d> normals(n);
        Vec3d newell, sum;
        for (std::size_t j = 0; j < n; ++j) {
            normals[j] = normal(ring[j]);
            newell += cross(ring[j], ring[(j + 1) % n]);
            sum += normals[j];
        }
        const Vec3d nc = normal(c);
        // As for a split point: on a smooth surface the centre's normal lies among the corners'
        // (within kBetweenShare of their widest angle of each); at a crease it is one face's.
        double widest = 1;
        for (std::size_t i = 0; i < n; ++i)
            for (std::size_t j = i + 1; j < n; ++j) widest = std::min(widest, dot(normals[i], normals[j]));
        const double need = betweenCosine(widest);
        for (std::size_t j = 0; j < n; ++j)
            if (!(dot(nc, normals[j]) >= need)) return false;
        const double agree = dot(newell, sum);
        if (!(std::fabs(agree) > 0)) return false;
        const double out = agree > 0 ? 1.0 : -1.0;
        for (std::size_t j = 0; j < n; ++j) {
            const std::size_t k = (j + 1) % n;
            const Vec3d t = cross(ring[k] - ring[j], c - ring[j]);
            if (!(dot(t, (normals[j] + normals[k] + nc) * out) > 0)) return false;
        }
        return true;
    }

    // The sharp edge or corner a polygon beside a feature node cuts across (the lattice had no
    // node that could reach it): where the planes of the surface meet, read from its corners and its sides' projected
    // midpoints as the sharp pass reads a cell's crossings — the widest pair of normals an edge,
    // a third across their line a corner, the point on the edge nearest the polygon's middle `c`
    // otherwise. Taken only where every plane the samples show passes through it (one feature,
    // not a curved surface), it lies near the polygon and on the surface, and the fan round it
    // fits: each triangle's middle and each new edge's midpoint on the surface, each triangle
    // facing the way the gradient at its middle does.
    bool featureCentre(const std::vector<Vec3d>& ring, const Vec3d& c, double edgeCosine, double cornerThreshold, Vec3d& out) const {
        const std::size_t n = ring.size();
        struct Plane {
            Vec3d n, p;
        };
        std::vector<Plane> planes;
        auto add = [&](const Vec3d& p, const Vec3d& nn) {
            if (dot(nn, nn) == 0) return;
            for (const Plane& q : planes)
                if (dot(nn, q.n) >= kSamePlane && std::fabs(dot(q.n, p - q.p)) <= kOnPlane * mH) return;
            planes.push_back({nn, p});
        };
        // The feature the planes show, and whether every plane passes through it.
        auto meet = [&](Vec3d& x) {
            int a = -1, b = -1;
            double widest = edgeCosine;
            for (std::size_t i = 0; i < planes.size(); ++i)
                for (std::size_t j = i + 1; j < planes.size(); ++j) {
                    const double d = dot(planes[i].n, planes[j].n);
                    const Vec3d cr = cross(planes[i].n, planes[j].n);
                    if (d < widest && dot(cr, cr) >= kMinSine * kMinSine) widest = d, a = int(i), b = int(j);
                }
            if (a < 0) return false;
            const Plane &pa = planes[std::size_t(a)], &pb = planes[std::size_t(b)];
            const Vec3d edge = normalized(cross(pa.n, pb.n));
            int third = -1;
            double phi = cornerThreshold;
            for (std::size_t k = 0; k < planes.size(); ++k) {
                const double d = std::fabs(dot(planes[k].n, edge));
                if (int(k) != a && int(k) != b && d > phi) phi = d, third = int(k);
            }
            const Vec3d normals[3] = {pa.n, pb.n, third >= 0 ? planes[std::size_t(third)].n : edge};
            const double rhs[3] = {dot(pa.n, pa.p), dot(pb.n, pb.p), third >= 0 ? dot(normals[2], planes[std::size_t(third)].p) : dot(edge, c)};
            if (!intersectPlanes(normals, rhs, x)) return false;
            for (const Plane& q : planes)
                if (!(std::fabs(dot(q.n, x - q.p)) <= kOnPlane * mH)) return false;
            return true;
        };
        Vec3d newell, sum;
        for (std::size_t j = 0; j < n; ++j) {
            const Vec3d nj = normal(ring[j]);
            add(ring[j], nj);
            sum += nj;
            newell += cross(ring[j], ring[(j + 1) % n]);
        }
        // The corners alone show the feature, or part of it (its corners lie on its faces, or on
        // it): a curved surface, whose planes meet nowhere, is known before any projection.
        Vec3d x;
        if (!meet(x)) return false;
        for (std::size_t j = 0; j < n; ++j) {
            Vec3d m = (ring[j] + ring[(j + 1) % n]) * 0.5;
            if (project(m)) add(m, normal(m));
        }
        if (!meet(x) || !(length(x - c) <= kMaxFeatureReach * mH) || strays(x)) return false;
        for (const Vec3d& r : ring) // the feature is on the mesh already
            if (length(r - x) < kFeatureOnMesh * mH) return false;
        const double agree = dot(newell, sum);
        if (!(std::fabs(agree) > 0)) return false;
        const double outward = agree > 0 ? 1.0 : -1.0;
        for (std::size_t j = 0; j < n; ++j) {
            const Vec3d &p0 = ring[j], &p1 = ring[(j + 1) % n];
            if (p0 == p1) continue; // two crossings at one node: the weld collapses this triangle
            const Vec3d middle = (p0 + p1 + x) / 3.0;
            if (strays(middle) || strays((p0 + x) * 0.5)) return false;
            if (!(dot(cross(p1 - p0, x - p0), normal(middle)) * outward > 0)) return false;
        }
        out = x;
        return true;
    }

private:
    const Field& mField;
    double mIso, mH, mTolerance;
};

// What becomes of a polygon: kept, fanned from a vertex of its ring, or fanned round a new
// centre vertex.
enum class Kind : std::uint8_t { Kept, Fan, Centre };

} // namespace

Mesh fitToSurface(const Field& field, Mesh mesh, const std::vector<std::uint32_t>& fixed, const SurfaceFitOptions& options,
                  SurfaceFitStats* stats) {
    const auto start = std::chrono::steady_clock::now();
    const Fitter fitter(field, options);
    const std::size_t polygons = mesh.polygonCount();
    auto point = [&](std::uint32_t v) { return Vec3d(mesh.points[v]); };
    auto checkCancel = [&] {
        if (options.cancel) options.cancel->check();
    };

    // Crossings at a node (one point, several vertices until the weld joins them) are left to the
    // weld as marching cubes made them: a fan's triangle holding two of them is one the weld must
    // collapse or keep as a sliver, and new edges from one of them are edges the weld does not
    // expect (joined, two polygons' fans could share one). So polygons with such a vertex gain no
    // vertex, and their edges are not split.
    std::vector<std::uint8_t> welded(mesh.points.size(), 0);
    for (std::uint32_t v : fixed) welded[v] = 1;
    std::vector<std::uint8_t> holdsWeld(polygons, 0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, polygons, 1024), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t p = r.begin(); p < r.end(); ++p) {
            const std::uint32_t* q = mesh.polygon(p);
            for (std::uint32_t j = 0; j < mesh.polygonSize(p) && !holdsWeld[p]; ++j) holdsWeld[p] = welded[q[j]];
        }
    });
    std::vector<std::uint8_t> besideWeld(mesh.points.size(), 0);
    for (std::size_t p = 0; p < polygons; ++p)
        if (holdsWeld[p])
            for (std::uint32_t j = 0; j < mesh.polygonSize(p); ++j) besideWeld[mesh.polygon(p)[j]] = 1;

    // Edges: each decided once, by a polygon that runs it from its lower to its higher vertex
    // (in a closed oriented mesh exactly one of its two polygons; an edge no polygon runs so is
    // on the mesh's border with its one polygon running it the other way, and is left whole).
    tbb::enumerable_thread_specific<std::vector<SplitEdge>> found;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, polygons, 256), [&](const tbb::blocked_range<std::size_t>& r) {
        checkCancel();
        std::vector<SplitEdge>& local = found.local();
        for (std::size_t p = r.begin(); p < r.end(); ++p) {
            const std::uint32_t* q = mesh.polygon(p);
            const std::uint32_t k = mesh.polygonSize(p);
            for (std::uint32_t j = 0; j < k; ++j) {
                const std::uint32_t a = q[j], b = q[(j + 1) % k];
                if (!(a < b) || besideWeld[a] || besideWeld[b]) continue;
                Vec3d s;
                if (fitter.splitPoint(point(a), point(b), s)) local.push_back({undirectedEdgeKey(a, b), Vec3f(s)});
            }
        }
    });
    std::vector<SplitEdge> splits;
    for (const auto& l : found) splits.insert(splits.end(), l.begin(), l.end());
    tbb::parallel_sort(splits.begin(), splits.end(), [](const SplitEdge& x, const SplitEdge& y) { return x.key < y.key; });
    // (Two polygons running one edge the same way decide it alike: the same key twice.)
    splits.erase(std::unique(splits.begin(), splits.end(), [](const SplitEdge& x, const SplitEdge& y) { return x.key == y.key; }),
                 splits.end());
    const std::uint32_t firstSplit = std::uint32_t(mesh.points.size());
    const std::uint32_t noSplit = ~std::uint32_t(0);
    auto splitVertex = [&](std::uint32_t a, std::uint32_t b) {
        if (splits.empty()) return noSplit;
        const EdgeKey key = undirectedEdgeKey(a, b);
        const auto it = std::lower_bound(splits.begin(), splits.end(), key, [](const SplitEdge& s, EdgeKey k) { return s.key < k; });
        return it != splits.end() && it->key == key ? firstSplit + std::uint32_t(it - splits.begin()) : noSplit;
    };
    // The polygon's corners with the split vertices of its edges between them.
    auto ringOf = [&](std::size_t p, std::vector<std::uint32_t>& ring) {
        const std::uint32_t* q = mesh.polygon(p);
        const std::uint32_t k = mesh.polygonSize(p);
        ring.clear();
        for (std::uint32_t j = 0; j < k; ++j) {
            ring.push_back(q[j]);
            const std::uint32_t s = splitVertex(q[j], q[(j + 1) % k]);
            if (s != noSplit) ring.push_back(s);
        }
    };
    auto ringPoint = [&](std::uint32_t v) { return v < firstSplit ? point(v) : Vec3d(splits[v - firstSplit].point); };

    // Polygons: a centre on the surface where the middle strays (or edges were split) and the
    // fan round it fits the surface; a triangle with one split edge, two triangles from the split
    // vertex; a loop of five or more corners otherwise fanned from its first corner, as marching
    // cubes fans it. A polygon with split edges and no centre that fits refuses its splits (a fan
    // from a split vertex may repeat the diagonals of the polygon across the edge, where two loops
    // share two segments of an ambiguous face); those edges stay whole and the polygons around
    // them are decided again, until every split edge is taken.
    std::vector<Kind> kind(polygons, Kind::Kept);
    std::vector<std::uint32_t> apex(polygons, 0), ringSize(polygons, 0);
    std::vector<Vec3f> centre(polygons);
    std::vector<std::uint8_t> feature(polygons, 0); // a centre on a sharp edge or corner
    // A fan round a new vertex adds edges from it alone. Where the weld will join two of the
    // ring's vertices (crossings at one node: one point) next to each other, their triangle
    // collapses to an edge of its neighbours; two apart, the fan would fold.
    auto twoAtOneNode = [&](std::size_t p) {
        const std::uint32_t* q = mesh.polygon(p);
        const std::uint32_t k = mesh.polygonSize(p);
        for (std::uint32_t i = 0; i < k; ++i)
            for (std::uint32_t j = i + 2; j < k && welded[q[i]]; ++j)
                if (welded[q[j]] && !(i == 0 && j == k - 1) && mesh.points[q[i]] == mesh.points[q[j]]) return true;
        return false;
    };
    for (;;) {
        tbb::enumerable_thread_specific<std::vector<EdgeKey>> refusedLocal;
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, polygons, 256), [&](const tbb::blocked_range<std::size_t>& r) {
            checkCancel();
            std::vector<std::uint32_t> ring;
            std::vector<Vec3d> at;
            for (std::size_t p = r.begin(); p < r.end(); ++p) {
                ringOf(p, ring);
                const std::uint32_t* q = mesh.polygon(p);
                const std::size_t k = mesh.polygonSize(p);
                const bool split = ring.size() > k;
                ringSize[p] = std::uint32_t(ring.size());
                kind[p] = Kind::Kept;
                if (k == 3 && ring.size() == 4) {
                    kind[p] = Kind::Fan;
                    apex[p] = 0;
                    while (ring[apex[p]] < firstSplit) ++apex[p];
                    continue;
                }
                // (Triangles only for features: where a smooth surface bends away from one, its
                // sides were split.)
                if (ring.size() <= 3 && !(options.features && holdsWeld[p])) continue;
                at.resize(ring.size());
                Vec3d c;
                for (std::size_t j = 0; j < ring.size(); ++j) c += (at[j] = ringPoint(ring[j]));
                c = c / double(ring.size());
                bool centred = false;
                const bool strays = split || fitter.strays(c, options.features && holdsWeld[p] ? kFeatureShare : 1);
                if (strays) {
                    Vec3d x = c;
                    // (Only polygons beside a feature node were held to the smaller share.)
                    if (ring.size() > 3 && !holdsWeld[p] && fitter.project(x) && fitter.fanFits(at, x)) {
                        centred = true;
                        feature[p] = 0;
                    } else if (options.features && holdsWeld[p] && !twoAtOneNode(p) &&
                               fitter.featureCentre(at, c, options.edgeCosine, options.cornerThreshold, x)) {
                        centred = true;
                        feature[p] = 1;
                    }
                    if (centred) {
                        kind[p] = Kind::Centre;
                        centre[p] = Vec3f(x);
                    }
                }
                if (centred || ring.size() <= 3) continue;
                if (split) {
                    for (std::size_t j = 0; j < k; ++j)
                        if (splitVertex(q[j], q[(j + 1) % k]) != noSplit) refusedLocal.local().push_back(undirectedEdgeKey(q[j], q[(j + 1) % k]));
                } else if (k > 4) {
                    kind[p] = Kind::Fan;
                    apex[p] = 0;
                }
            }
        });
        checkCancel();
        std::vector<EdgeKey> refused;
        for (const auto& l : refusedLocal) refused.insert(refused.end(), l.begin(), l.end());
        if (refused.empty()) break;
        std::sort(refused.begin(), refused.end());
        splits.erase(std::remove_if(splits.begin(), splits.end(),
                                    [&](const SplitEdge& e) { return std::binary_search(refused.begin(), refused.end(), e.key); }),
                     splits.end());
    }

    std::uint64_t centres = 0, featureCentres = 0;
    bool changed = !splits.empty();
    std::vector<std::uint32_t> firstPolygon(polygons + 1), firstIndex(polygons + 1), centreVertex(polygons, noSplit);
    for (std::size_t p = 0; p < polygons; ++p) {
        const std::uint32_t k = mesh.polygonSize(p), n = ringSize[p];
        std::uint32_t outPolygons = 1, outIndices = k;
        if (kind[p] == Kind::Fan) {
            outPolygons = n - 2, outIndices = 3 * (n - 2);
            changed = true;
        } else if (kind[p] == Kind::Centre) {
            outPolygons = n, outIndices = 3 * n;
            centreVertex[p] = firstSplit + std::uint32_t(splits.size() + centres++);
            featureCentres += feature[p];
        }
        firstPolygon[p + 1] = firstPolygon[p] + outPolygons;
        firstIndex[p + 1] = firstIndex[p] + outIndices;
    }
    if (stats) {
        stats->edgesSplit = splits.size();
        stats->centresAdded = centres;
        stats->featureCentres = featureCentres;
    }
    if (!changed && centres == 0) {
        if (stats) stats->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        return mesh;
    }

    Mesh out;
    out.points.reserve(mesh.points.size() + splits.size() + centres);
    out.points = mesh.points;
    for (const SplitEdge& s : splits) out.points.push_back(s.point);
    for (std::size_t p = 0; p < polygons; ++p)
        if (centreVertex[p] != noSplit) out.points.push_back(centre[p]);
    out.offsets.assign(firstPolygon[polygons] + 1, 0);
    out.indices.resize(firstIndex[polygons]);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, polygons, 256), [&](const tbb::blocked_range<std::size_t>& r) {
        std::vector<std::uint32_t> ring;
        for (std::size_t p = r.begin(); p < r.end(); ++p) {
            std::uint32_t poly = firstPolygon[p], index = firstIndex[p];
            auto emit = [&](std::initializer_list<std::uint32_t> vs) {
                for (std::uint32_t v : vs) out.indices[index++] = v;
                out.offsets[++poly] = index;
            };
            if (kind[p] == Kind::Kept) {
                const std::uint32_t* q = mesh.polygon(p);
                for (std::uint32_t j = 0; j < mesh.polygonSize(p); ++j) out.indices[index++] = q[j];
                out.offsets[++poly] = index;
                continue;
            }
            ringOf(p, ring);
            const std::size_t n = ring.size();
            if (kind[p] == Kind::Fan) {
                const std::size_t a = apex[p];
                for (std::size_t j = 1; j + 1 < n; ++j) emit({ring[a], ring[(a + j) % n], ring[(a + j + 1) % n]});
            } else {
                for (std::size_t j = 0; j < n; ++j) emit({ring[j], ring[(j + 1) % n], centreVertex[p]});
            }
        }
    });
    if (stats) stats->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return out;
}

} // namespace vdbsurf
