#include "vdbsurf/dmc/thin_simplify.h"

#include "vdbsurf/core/cancel.h"
#include "vdbsurf/field/field.h"
#include "vdbsurf/mesh/mesh_distance.h"
#include "vdbsurf/mesh/mesh_folds.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <queue>
#include <unordered_map>
#include <unordered_set>

namespace vdbsurf {

namespace {

// A hash key for a cell: 21 bits a coordinate, wrapping (cells that share a key only share a
// list of nodes, each of which is then measured).
std::uint64_t cellKey(std::int64_t x, std::int64_t y, std::int64_t z) {
    constexpr std::uint64_t kMask = 0x1fffff;
    return ((std::uint64_t(x) & kMask) << 42) | ((std::uint64_t(y) & kMask) << 21) | (std::uint64_t(z) & kMask);
}

// Garland and Heckbert's error quadric: the sum of squared distances to a set of planes.
struct Quadric {
    // xx xy xz xw yy yz yw zz zw ww
    std::array<double, 10> a{};

    void addPlane(const Vec3d& n, double d, double weight) {
        const double p[4] = {n.x, n.y, n.z, d};
        int k = 0;
        for (int i = 0; i < 4; ++i)
            for (int j = i; j < 4; ++j) a[std::size_t(k++)] += weight * p[i] * p[j];
    }
    Quadric& operator+=(const Quadric& o) {
        for (std::size_t i = 0; i < a.size(); ++i) a[i] += o.a[i];
        return *this;
    }
    double at(const Vec3d& p) const {
        const double x = p.x, y = p.y, z = p.z;
        return a[0] * x * x + 2 * a[1] * x * y + 2 * a[2] * x * z + 2 * a[3] * x + a[4] * y * y + 2 * a[5] * y * z +
               2 * a[6] * y + a[7] * z * z + 2 * a[8] * z + a[9];
    }
};

struct Triangle { // (the polygon it was cut from: firstTriangle in simplifyThinParts)
    std::array<std::uint32_t, 3> v; // local vertices
    bool alive = true, changed = false;
};

// A collapse of some vertex u onto its neighbour v, and its cost.
struct Option {
    double cost;
    std::uint32_t v;
    bool operator<(const Option& o) const { return cost != o.cost ? cost < o.cost : v < o.v; }
};

// The queue holds each vertex once, by its cheapest option not yet tried (its options sorted
// apart, in Vertex::options): the collapses are tried in the order of one queue of every
// option — by cost, then u, then v — with a sixth of its entries (a vertex has about six
// neighbours, and every collapse renews the options of a dozen vertices; the queue of options
// was most of the simplification's time). Valid while u's stamp is unchanged.
struct Candidate {
    double cost;
    std::uint32_t u, stamp;
    bool operator<(const Candidate& o) const { // (the queue pops the greatest: the cheapest first)
        if (cost != o.cost) return cost > o.cost;
        return u > o.u;
    }
};

class ThinSimplifier {
public:
    ThinSimplifier(const Field& field, const ThinSimplifyOptions& options, double h)
        : mField(field), mIso(options.iso), mTolerance(options.tolerance * h), mTinyArea(1e-10 * h * h) {}

    std::vector<Triangle> triangles;
    std::vector<Vec3d> pos;               // per local vertex (vertices never move)
    std::vector<std::uint8_t> locked;     // per local vertex: may not be removed (run() adds more)
    // Per local vertex: its neighbours along the edges of polygons outside the region (which
    // stay), so that the link condition sees every edge a collapse could double.
    std::vector<std::vector<std::uint32_t>> fixedNeighbours;

    std::uint64_t run(const CancelToken* cancel) {
        const std::size_t n = pos.size();
        fan.assign(n, {});
        for (std::uint32_t t = 0; t < triangles.size(); ++t)
            for (std::uint32_t v : triangles[t].v) fan[v].push_back(t);
        lockBordersAndPinches();
        mDead.assign(n, 0);
        mStamp.assign(n, 0);
        mOptions.assign(n, {});
        mTried.assign(n, 0);
        mRemoved.assign(triangles.size(), {});
        mQuadric.assign(n, Quadric());
        for (const Triangle& t : triangles) {
            const Vec3d c = cross(pos[t.v[1]] - pos[t.v[0]], pos[t.v[2]] - pos[t.v[0]]);
            const double len = length(c);
            if (!(len > 0)) continue;
            const Vec3d nrm = c / len;
            for (std::uint32_t v : t.v) mQuadric[v].addPlane(nrm, -dot(nrm, pos[t.v[0]]), 0.5 * len);
        }
        for (std::uint32_t u = 0; u < n; ++u) pushAround(u);
        std::uint64_t collapses = 0, pops = 0;
        while (!mQueue.empty()) {
            const Candidate c = mQueue.top();
            mQueue.pop();
            if (cancel && (++pops & 4095) == 0) cancel->check();
            if (mDead[c.u] || c.stamp != mStamp[c.u]) continue;
            const std::uint32_t v = mOptions[c.u][mTried[c.u]++].v;
            if (!mDead[v] && collapse(c.u, v)) {
                ++collapses;
                continue;
            }
            if (mTried[c.u] < mOptions[c.u].size()) mQueue.push({mOptions[c.u][mTried[c.u]].cost, c.u, c.stamp});
        }
        return collapses;
    }

private:
    std::vector<std::vector<std::uint32_t>> fan; // per local vertex: its live triangles
    const Field& mField;
    const double mIso, mTolerance, mTinyArea;
    std::vector<std::uint8_t> mDead;
    std::vector<std::uint32_t> mStamp;
    std::vector<std::vector<std::uint32_t>> mRemoved; // per triangle: removed vertices it answers for
    std::vector<Quadric> mQuadric;
    std::priority_queue<Candidate> mQueue;
    std::vector<std::vector<Option>> mOptions; // per vertex: its collapses, cheapest first
    std::vector<std::uint32_t> mTried;         // per vertex: how many of them were tried
    std::vector<std::uint32_t> mNu, mNv, mScratch, mMoving, mKept;

    // x's neighbours, ascending. (Each is met about twice, and there are about six: kept sorted as
    // they come, which costs a third of sorting them all after.)
    void neighbours(std::uint32_t x, std::vector<std::uint32_t>& out) const {
        out.clear();
        auto add = [&](std::uint32_t w) {
            auto it = out.end();
            while (it != out.begin() && *(it - 1) > w) --it;
            if (it == out.begin() || *(it - 1) != w) out.insert(it, w);
        };
        for (std::uint32_t t : fan[x])
            for (std::uint32_t w : triangles[t].v)
                if (w != x) add(w);
        for (std::uint32_t w : fixedNeighbours[x]) add(w);
    }

    // A vertex on an edge that is not shared by exactly two region triangles (an open border,
    // or a non-manifold edge), or whose triangles do not close one disk around it, stays.
    void lockBordersAndPinches() {
        std::vector<std::uint64_t> edges;
        edges.reserve(triangles.size() * 3);
        for (const Triangle& t : triangles)
            for (int k = 0; k < 3; ++k) edges.push_back(undirectedEdgeKey(t.v[std::size_t(k)], t.v[std::size_t((k + 1) % 3)]));
        std::sort(edges.begin(), edges.end());
        for (std::size_t i = 0; i < edges.size();) {
            std::size_t j = i;
            while (j < edges.size() && edges[j] == edges[i]) ++j;
            if (j - i != 2) {
                locked[edges[i] >> 32] = 1;
                locked[edges[i] & 0xffffffffu] = 1;
            }
            i = j;
        }
        for (std::uint32_t v = 0; v < pos.size(); ++v) {
            if (locked[v]) continue;
            neighbours(v, mScratch);
            // A closed disk of k triangles has k neighbours; two disks at one vertex have more.
            if (mScratch.size() != fan[v].size()) locked[v] = 1;
        }
    }

    void pushAround(std::uint32_t u) {
        if (locked[u] || mDead[u]) return;
        neighbours(u, mScratch);
        std::vector<Option>& options = mOptions[u];
        options.clear();
        mTried[u] = 0;
        for (std::uint32_t v : mScratch) {
            if (fan[v].empty()) continue; // (outside the region: not a target)
            Quadric q = mQuadric[u];
            q += mQuadric[v];
            options.push_back({std::max(0.0, q.at(pos[v])), v});
        }
        if (options.empty()) return;
        std::sort(options.begin(), options.end());
        mQueue.push({options.front().cost, u, mStamp[u]});
    }

    bool nearSurface(const Vec3d& p) const {
        Vec3d g;
        const double v = mField.valueAndGradient(p, g);
        const double len = length(g);
        return std::isfinite(v) && len > 0 && std::isfinite(len) && std::fabs(v - mIso) <= mTolerance * len;
    }

    static bool has(const Triangle& t, std::uint32_t x) { return t.v[0] == x || t.v[1] == x || t.v[2] == x; }

    bool collapse(std::uint32_t u, std::uint32_t v) {
        // The two triangles on the edge, and their third vertices.
        std::uint32_t shared[2], count = 0;
        for (std::uint32_t t : fan[u])
            if (has(triangles[t], v)) {
                if (count < 2) shared[count] = t;
                ++count;
            }
        if (count != 2) return false;
        auto third = [&](std::uint32_t t) {
            for (std::uint32_t w : triangles[t].v)
                if (w != u && w != v) return w;
            return u;
        };
        const std::uint32_t a = third(shared[0]), b = third(shared[1]);
        if (a == b) return false;
        // Link condition: u and v have no neighbour in common but a and b; and no vertex is left
        // with fewer than three neighbours (a tetrahedron would fold into a double triangle). On
        // a closed surface these also keep the edges' links apart: a triangle u x y beside a
        // triangle v x y makes x and y common neighbours, so {x, y} = {a, b}, a tetrahedron.
        neighbours(u, mNu);
        neighbours(v, mNv);
        std::size_t common = 0;
        for (std::size_t i = 0, j = 0; i < mNu.size() && j < mNv.size();) {
            if (mNu[i] < mNv[j]) ++i;
            else if (mNv[j] < mNu[i]) ++j;
            else ++common, ++i, ++j;
        }
        if (common != 2 || mNu.size() + mNv.size() < 7) return false;
        for (std::uint32_t w : {a, b}) {
            neighbours(w, mScratch);
            if (mScratch.size() < 4) return false;
        }
        // The triangles that stay, with v for u: none turns over or loses its area.
        const Vec3d pv = pos[v];
        auto moved = [&](std::uint32_t t) {
            std::array<Vec3d, 3> q;
            for (int k = 0; k < 3; ++k) {
                const std::uint32_t w = triangles[t].v[std::size_t(k)];
                q[std::size_t(k)] = w == u ? pv : pos[w];
            }
            return q;
        };
        for (std::uint32_t t : fan[u]) {
            if (t == shared[0] || t == shared[1]) continue;
            const std::array<Vec3d, 3> q = moved(t);
            const Vec3d& p0 = pos[triangles[t].v[0]];
            const Vec3d& p1 = pos[triangles[t].v[1]];
            const Vec3d& p2 = pos[triangles[t].v[2]];
            const Vec3d before = cross(p1 - p0, p2 - p0), after = cross(q[1] - q[0], q[2] - q[0]);
            if (!(length(after) > mTinyArea) || !(dot(before, after) > 0)) return false;
        }
        // Every vertex removed here or before, near the triangles that stay.
        auto near = [&](const Vec3d& x) {
            for (std::uint32_t t : fan[u]) {
                if (t == shared[0] || t == shared[1]) continue;
                const std::array<Vec3d, 3> q = moved(t);
                bool far = false; // (a cheap test first: x beyond the triangle's box grown by the tolerance)
                for (std::size_t i = 0; i < 3 && !far; ++i)
                    far = x[i] < std::min({q[0][i], q[1][i], q[2][i]}) - mTolerance ||
                          x[i] > std::max({q[0][i], q[1][i], q[2][i]}) + mTolerance;
                if (!far && pointTriangleDistance(x, q[0], q[1], q[2]) <= mTolerance) return true;
            }
            return false;
        };
        if (!near(pos[u])) return false;
        for (std::uint32_t t : fan[u])
            for (std::uint32_t r : mRemoved[t])
                if (!near(pos[r])) return false;
        // The new triangles near the surface at their centroids and at the middles of their new
        // edges (v to each of u's neighbours but a and b; the other edges were there before).
        for (std::uint32_t t : fan[u]) {
            if (t == shared[0] || t == shared[1]) continue;
            const std::array<Vec3d, 3> q = moved(t);
            if (!nearSurface((q[0] + q[1] + q[2]) / 3.0)) return false;
        }
        for (std::uint32_t x : mNu)
            if (x != v && x != a && x != b && !nearSurface((pv + pos[x]) * 0.5)) return false;
        // Collapse.
        std::vector<std::uint32_t>& moving = mMoving;
        moving.assign(1, u);
        for (std::uint32_t t : fan[u]) {
            moving.insert(moving.end(), mRemoved[t].begin(), mRemoved[t].end());
            mRemoved[t].clear();
        }
        for (std::uint32_t t : shared) {
            triangles[t].alive = false;
            for (std::uint32_t w : triangles[t].v) {
                if (w == u) continue;
                auto& f = fan[w];
                f.erase(std::remove(f.begin(), f.end(), t), f.end());
            }
        }
        std::vector<std::uint32_t>& kept = mKept; // u's triangles, now v's
        kept.clear();
        for (std::uint32_t t : fan[u]) {
            if (!triangles[t].alive) continue;
            for (std::uint32_t& w : triangles[t].v)
                if (w == u) w = v;
            triangles[t].changed = true;
            fan[v].push_back(t);
            kept.push_back(t);
        }
        std::sort(fan[v].begin(), fan[v].end());
        // Each removed vertex is answered for by the nearest of them (those the check above saw).
        for (std::uint32_t r : moving) {
            std::uint32_t best = kept.front();
            double bestDistance = INFINITY;
            for (std::uint32_t t : kept) {
                const Triangle& tr = triangles[t];
                const double d = pointTriangleDistance(pos[r], pos[tr.v[0]], pos[tr.v[1]], pos[tr.v[2]]);
                if (d < bestDistance) bestDistance = d, best = t;
            }
            mRemoved[best].push_back(r);
        }
        fan[u].clear();
        mDead[u] = 1;
        mQuadric[v] += mQuadric[u];
        // Every vertex whose fan changed gets its candidates again.
        neighbours(v, mNv);
        const std::vector<std::uint32_t>& around = mNv; // (pushAround leaves mNv alone)
        ++mStamp[v];
        pushAround(v);
        for (std::uint32_t w : around) {
            ++mStamp[w];
            pushAround(w);
        }
        return true;
    }
};

} // namespace

Mesh simplifyThinParts(const Field& field, const LatticeFrame& frame, const std::vector<Vec3d>& thinNodes, Mesh mesh,
                       const ThinSimplifyOptions& options, ThinSimplifyStats* stats) {
    const auto start = std::chrono::steady_clock::now();
    ThinSimplifyStats local;
    ThinSimplifyStats& st = stats ? *stats : local;
    st = ThinSimplifyStats();
    auto timed = [&](Mesh&& result) {
        st.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        return std::move(result);
    };
    if (thinNodes.empty() || mesh.empty()) return mesh;

    // A vertex is in a thin part when it lies within kReach cells (along every axis) of a node
    // the thin search moved, where the node is now: the crossings on a moved node's edges lie
    // about the part's half width from it. The nodes are hashed by the cells they reach.
    constexpr double kReach = 0.75;
    std::unordered_map<std::uint64_t, std::vector<Vec3d>> near;
    near.reserve(thinNodes.size() * 8);
    for (const Vec3d& w : thinNodes) {
        const Vec3d c = (w - frame.origin) / frame.h;
        const std::int64_t x0 = std::int64_t(std::floor(c.x - kReach)), x1 = std::int64_t(std::floor(c.x + kReach));
        const std::int64_t y0 = std::int64_t(std::floor(c.y - kReach)), y1 = std::int64_t(std::floor(c.y + kReach));
        const std::int64_t z0 = std::int64_t(std::floor(c.z - kReach)), z1 = std::int64_t(std::floor(c.z + kReach));
        for (std::int64_t z = z0; z <= z1; ++z)
            for (std::int64_t y = y0; y <= y1; ++y)
                for (std::int64_t x = x0; x <= x1; ++x)
                    near[cellKey(x, y, z)].push_back(c);
    }
    std::vector<std::uint8_t> thinVertex(mesh.points.size());
    for (std::size_t i = 0; i < mesh.points.size(); ++i) {
        const Vec3d c = (Vec3d(mesh.points[i]) - frame.origin) / frame.h;
        const auto it = near.find(cellKey(std::int64_t(std::floor(c.x)), std::int64_t(std::floor(c.y)), std::int64_t(std::floor(c.z))));
        if (it == near.end()) continue;
        for (const Vec3d& n : it->second)
            if (std::fabs(c.x - n.x) <= kReach && std::fabs(c.y - n.y) <= kReach && std::fabs(c.z - n.z) <= kReach) {
                thinVertex[i] = 1;
                break;
            }
    }

    // The region's polygons as triangles, on local vertex numbers.
    ThinSimplifier simplifier(field, options, frame.h);
    std::vector<std::uint32_t> localOf(mesh.points.size(), 0xffffffffu);
    std::vector<std::uint8_t> outside(mesh.points.size()); // used by a polygon outside the region
    std::vector<std::uint32_t> firstTriangle(mesh.polygonCount() + 1, 0);
    std::vector<std::uint8_t> inRegion(mesh.polygonCount());
    auto localVertex = [&](std::uint32_t g) {
        if (localOf[g] == 0xffffffffu) {
            localOf[g] = std::uint32_t(simplifier.pos.size());
            simplifier.pos.push_back(Vec3d(mesh.points[g]));
        }
        return localOf[g];
    };
    // A triangle's diagonal may not be an edge of another polygon (DMC's quads can have one):
    // the triangles would share it with that polygon, three to an edge.
    std::vector<std::uint64_t> thinEdges;
    for (std::size_t p = 0; p < mesh.polygonCount(); ++p) {
        const std::uint32_t* P = mesh.polygon(p);
        const std::uint32_t k = mesh.polygonSize(p);
        for (std::uint32_t i = 0; i < k; ++i)
            if (thinVertex[P[i]] && thinVertex[P[(i + 1) % k]]) thinEdges.push_back(undirectedEdgeKey(P[i], P[(i + 1) % k]));
    }
    std::sort(thinEdges.begin(), thinEdges.end());
    std::unordered_set<std::uint64_t> diagonals; // those chosen so far (two quads may share both ends of one)
    auto isEdge = [&](std::uint32_t a, std::uint32_t b) {
        const std::uint64_t key = undirectedEdgeKey(a, b);
        return std::binary_search(thinEdges.begin(), thinEdges.end(), key) || diagonals.count(key) != 0;
    };
    for (std::size_t p = 0; p < mesh.polygonCount(); ++p) {
        firstTriangle[p] = std::uint32_t(simplifier.triangles.size());
        const std::uint32_t* P = mesh.polygon(p);
        const std::uint32_t k = mesh.polygonSize(p);
        bool all = k >= 3;
        for (std::uint32_t i = 0; i < k && all; ++i) all = thinVertex[P[i]];
        // Fanned from which corner: a quad's shorter diagonal first, as the mesher splits it.
        int from = -1;
        if (all) {
            std::uint32_t first = 0;
            if (k == 4) {
                const Vec3d d02 = Vec3d(mesh.points[P[0]] - mesh.points[P[2]]), d13 = Vec3d(mesh.points[P[1]] - mesh.points[P[3]]);
                first = dot(d02, d02) <= dot(d13, d13) ? 0 : 1;
            }
            for (std::uint32_t j = 0; j < k && from < 0; ++j) {
                const std::uint32_t s = (first + j) % k;
                bool clear = true;
                for (std::uint32_t i = 2; i + 1 < k && clear; ++i) clear = !isEdge(P[s], P[(s + i) % k]);
                if (clear) from = int(s);
            }
        }
        inRegion[p] = from >= 0;
        if (from < 0) {
            for (std::uint32_t i = 0; i < k; ++i) outside[P[i]] = 1;
            continue;
        }
        const std::uint32_t s = std::uint32_t(from);
        for (std::uint32_t i = 2; i + 1 < k; ++i) diagonals.insert(undirectedEdgeKey(P[s], P[(s + i) % k]));
        for (std::uint32_t i = 1; i + 1 < k; ++i)
            simplifier.triangles.push_back(
                {{localVertex(P[s]), localVertex(P[(s + i) % k]), localVertex(P[(s + i + 1) % k])}});
    }
    firstTriangle[mesh.polygonCount()] = std::uint32_t(simplifier.triangles.size());
    st.regionTriangles = simplifier.triangles.size();
    if (simplifier.triangles.empty()) return timed(std::move(mesh));
    std::vector<std::pair<std::uint32_t, std::uint32_t>> fixedEdges;
    for (std::size_t p = 0; p < mesh.polygonCount(); ++p) {
        if (inRegion[p]) continue;
        const std::uint32_t* P = mesh.polygon(p);
        const std::uint32_t k = mesh.polygonSize(p);
        for (std::uint32_t i = 0; i < k; ++i) {
            const std::uint32_t a = P[i], b = P[(i + 1) % k];
            if (localOf[a] == 0xffffffffu && localOf[b] == 0xffffffffu) continue;
            fixedEdges.emplace_back(localVertex(a), localVertex(b));
        }
    }

    const std::size_t n = simplifier.pos.size();
    simplifier.fixedNeighbours.assign(n, {});
    for (const auto& [a, b] : fixedEdges) {
        simplifier.fixedNeighbours[a].push_back(b);
        simplifier.fixedNeighbours[b].push_back(a);
    }
    simplifier.locked.assign(n, 0);
    for (std::size_t g = 0; g < mesh.points.size(); ++g)
        if (localOf[g] != 0xffffffffu && outside[g]) simplifier.locked[localOf[g]] = 1;
    st.collapses = simplifier.run(options.cancel);
    if (st.collapses == 0) return timed(std::move(mesh));

    // The mesh again, in polygon order: untouched polygons as they were, the rest as the
    // triangles left of them.
    Mesh out;
    out.points = std::move(mesh.points);
    out.offsets.reserve(mesh.offsets.size());
    out.indices.reserve(mesh.indices.size());
    std::vector<std::uint32_t> globalOf(n);
    for (std::size_t g = 0; g < localOf.size(); ++g)
        if (localOf[g] != 0xffffffffu) globalOf[localOf[g]] = std::uint32_t(g);
    std::vector<std::uint32_t> fromRegion; // output polygons that came from the region
    for (std::size_t p = 0; p < mesh.polygonCount(); ++p) {
        bool asBefore = !inRegion[p];
        if (!asBefore) {
            asBefore = true;
            for (std::uint32_t t = firstTriangle[p]; t < firstTriangle[p + 1] && asBefore; ++t)
                asBefore = simplifier.triangles[t].alive && !simplifier.triangles[t].changed;
        }
        if (asBefore) {
            if (inRegion[p]) fromRegion.push_back(std::uint32_t(out.polygonCount()));
            out.addPolygon(mesh.polygon(p), mesh.polygonSize(p));
            continue;
        }
        for (std::uint32_t t = firstTriangle[p]; t < firstTriangle[p + 1]; ++t) {
            const Triangle& tr = simplifier.triangles[t];
            if (!tr.alive) continue;
            fromRegion.push_back(std::uint32_t(out.polygonCount()));
            out.addPolygon({globalOf[tr.v[0]], globalOf[tr.v[1]], globalOf[tr.v[2]]});
        }
    }
    // A region polygon whose triangles all stayed goes out whole, without the diagonals the
    // link condition counted: a vertex beside it can be left with two neighbours, its fan a
    // collapsed triangle's neighbour folded onto the polygon. Closed here (mesh/mesh_folds.h).
    out = keepPolygons(out, std::vector<std::uint8_t>(out.polygonCount(), 1));
    std::vector<std::uint32_t> scratch;
    st.foldsClosed = closeFolds(out, std::move(fromRegion), scratch).closed;
    return timed(std::move(out));
}

} // namespace vdbsurf
