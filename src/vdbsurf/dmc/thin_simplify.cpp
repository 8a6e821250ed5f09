#include "vdbsurf/dmc/thin_simplify.h"

#include "vdbsurf/core/cancel.h"
#include "vdbsurf/field/field.h"
#include "vdbsurf/mesh/mesh_distance.h"
#include "vdbsurf/mesh/mesh_folds.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <memory>
#include <queue>
#include <stdexcept>
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
// apart, in ThinSimplifier::mOptions): the collapses are tried in the order of one queue of every
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

    // Set before run() (collapseRegion: from the triangles, none, none; a block or a later run:
    // carried from the runs before): per vertex its quadric, per triangle the removed vertices it
    // answers for, per vertex whether it was removed.
    std::vector<Quadric> quadric;
    std::vector<std::vector<std::uint32_t>> removed;
    std::vector<std::uint8_t> dead;
    // Per vertex, after run(): whether a collapse changed its neighbourhood (it was tried again).
    std::vector<std::uint8_t> touched;

    // Garland and Heckbert's quadrics of the triangles as they are (alive), each plane weighted by
    // its triangle's area.
    std::vector<Quadric> quadricsOfTriangles() const {
        std::vector<Quadric> q(pos.size());
        for (const Triangle& t : triangles) {
            if (!t.alive) continue;
            const Vec3d c = cross(pos[t.v[1]] - pos[t.v[0]], pos[t.v[2]] - pos[t.v[0]]);
            const double len = length(c);
            if (!(len > 0)) continue;
            const Vec3d nrm = c / len;
            for (std::uint32_t v : t.v) q[v].addPlane(nrm, -dot(nrm, pos[t.v[0]]), 0.5 * len);
        }
        return q;
    }

    // Collapses until none passes, cheapest first. Vertices that `settled` marks are not tried
    // until a collapse changes their neighbourhood (an earlier run tried them all as they are).
    // After it, `locked` holds the borders and pinches too, and `fan`-less vertices are dead or
    // outside the region.
    std::uint64_t run(const CancelToken* cancel, const std::vector<std::uint8_t>* settled = nullptr) {
        const std::size_t n = pos.size();
        fan.assign(n, {});
        for (std::uint32_t t = 0; t < triangles.size(); ++t)
            if (triangles[t].alive)
                for (std::uint32_t v : triangles[t].v) fan[v].push_back(t);
        if (quadric.size() != n || dead.size() != n || removed.size() != triangles.size())
            throw std::logic_error("thin simplification: a run's quadrics, removed vertices or dead marks are not set");
        lockBordersAndPinches();
        touched.assign(n, 0);
        mStamp.assign(n, 0);
        mOptions.assign(n, {});
        mTried.assign(n, 0);
        for (std::uint32_t u = 0; u < n; ++u)
            if (!settled || !(*settled)[u]) pushAround(u);
        std::uint64_t collapses = 0, pops = 0;
        while (!mQueue.empty()) {
            const Candidate c = mQueue.top();
            mQueue.pop();
            if (cancel && (++pops & 4095) == 0) cancel->check();
            if (dead[c.u] || c.stamp != mStamp[c.u]) continue;
            const std::uint32_t v = mOptions[c.u][mTried[c.u]++].v;
            if (!dead[v] && collapse(c.u, v)) {
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
    std::vector<std::uint32_t> mStamp;
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
            if (t.alive)
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
        if (locked[u] || dead[u]) return;
        neighbours(u, mScratch);
        std::vector<Option>& options = mOptions[u];
        options.clear();
        mTried[u] = 0;
        for (std::uint32_t v : mScratch) {
            if (fan[v].empty()) continue; // (outside the region: not a target)
            Quadric q = quadric[u];
            q += quadric[v];
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
            for (std::uint32_t r : removed[t])
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
            moving.insert(moving.end(), removed[t].begin(), removed[t].end());
            removed[t].clear();
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
            removed[best].push_back(r);
        }
        fan[u].clear();
        dead[u] = 1;
        quadric[v] += quadric[u];
        // Every vertex whose fan changed gets its candidates again.
        neighbours(v, mNv);
        const std::vector<std::uint32_t>& around = mNv; // (pushAround leaves mNv alone)
        ++mStamp[v];
        pushAround(v);
        touched[v] = 1;
        for (std::uint32_t w : around) {
            ++mStamp[w];
            pushAround(w);
            touched[w] = 1;
        }
        return true;
    }
};

// One grid of blocks (its corner at `offset` cells from the frame's origin) over the region as
// it is. `settled`: vertices tried as they are, which no run needs to try again (updated).
std::uint64_t collapseInBlocks(ThinSimplifier& whole, const Field& field, const ThinSimplifyOptions& options, const LatticeFrame& frame,
                               double offset, std::vector<std::uint8_t>& settled) {
    const std::size_t n = whole.pos.size();
    const double side = options.blockCells * frame.h;
    const Vec3d corner = frame.origin + Vec3d(offset, offset, offset) * frame.h;
    std::vector<std::uint64_t> blockOf(n);
    for (std::size_t v = 0; v < n; ++v) {
        const Vec3d c = (whole.pos[v] - corner) / side;
        blockOf[v] = cellKey(std::int64_t(std::floor(c.x)), std::int64_t(std::floor(c.y)), std::int64_t(std::floor(c.z)));
    }
    // The live triangles by block (those with corners in two blocks in none), and the fans.
    std::vector<std::pair<std::uint64_t, std::uint32_t>> inBlock; // (block, triangle), by block, then triangle
    std::vector<std::vector<std::uint32_t>> fanOf(n);
    for (std::uint32_t t = 0; t < whole.triangles.size(); ++t) {
        if (!whole.triangles[t].alive) continue;
        const auto& v = whole.triangles[t].v;
        for (std::uint32_t x : v) fanOf[x].push_back(t);
        if (blockOf[v[0]] == blockOf[v[1]] && blockOf[v[0]] == blockOf[v[2]]) inBlock.emplace_back(blockOf[v[0]], t);
    }
    std::sort(inBlock.begin(), inBlock.end());
    std::vector<std::size_t> firstOfBlock;
    for (std::size_t i = 0; i < inBlock.size(); ++i)
        if (i == 0 || inBlock[i].first != inBlock[i - 1].first) firstOfBlock.push_back(i);
    firstOfBlock.push_back(inBlock.size());
    auto interior = [&](std::uint32_t t, std::uint64_t block) {
        const auto& v = whole.triangles[t].v;
        return blockOf[v[0]] == block && blockOf[v[1]] == block && blockOf[v[2]] == block;
    };

    // What each block's run leaves, written back once all are done (a block reads the vertices
    // beside it from the whole region meanwhile).
    struct Result {
        std::vector<std::uint32_t> globalOf; // local vertex -> region vertex (the block's own first)
        std::size_t own = 0;
        std::vector<std::uint32_t> triangleOf; // local triangle -> region triangle
        std::unique_ptr<ThinSimplifier> sub;
        std::uint64_t collapses = 0;
    };
    const std::size_t blocks = firstOfBlock.size() - 1;
    std::vector<Result> results(blocks);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, blocks, 1), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t b = r.begin(); b < r.end(); ++b) {
            const std::uint64_t block = inBlock[firstOfBlock[b]].first;
            Result& res = results[b];
            res.sub = std::make_unique<ThinSimplifier>(field, options, frame.h);
            ThinSimplifier& sub = *res.sub;
            // The block's own vertices (ascending: ties fall as in the region's numbering), then
            // the others of their triangles and fixed edges.
            std::vector<std::uint32_t>& globalOf = res.globalOf;
            for (std::size_t i = firstOfBlock[b]; i < firstOfBlock[b + 1]; ++i)
                for (std::uint32_t x : whole.triangles[inBlock[i].second].v) globalOf.push_back(x);
            std::sort(globalOf.begin(), globalOf.end());
            globalOf.erase(std::unique(globalOf.begin(), globalOf.end()), globalOf.end());
            res.own = globalOf.size();
            auto isOwn = [&](std::uint32_t x) { return std::binary_search(globalOf.begin(), globalOf.begin() + std::ptrdiff_t(res.own), x); };
            // Each own vertex's fixed edges (its fixed neighbours, then the other corners of its
            // triangles beyond the block), in region numbers: numbered locally once all are known.
            std::vector<std::uint32_t> fixedGlobal, fixedStart{0};
            for (std::size_t i = 0; i < res.own; ++i) {
                const std::uint32_t g = globalOf[i];
                fixedGlobal.insert(fixedGlobal.end(), whole.fixedNeighbours[g].begin(), whole.fixedNeighbours[g].end());
                for (std::uint32_t t : fanOf[g])
                    if (!interior(t, block))
                        for (std::uint32_t x : whole.triangles[t].v)
                            if (x != g) fixedGlobal.push_back(x);
                fixedStart.push_back(std::uint32_t(fixedGlobal.size()));
            }
            std::vector<std::uint32_t> beside;
            for (std::uint32_t x : fixedGlobal)
                if (!isOwn(x)) beside.push_back(x);
            // And the vertices removed earlier that the block's triangles answer for (dead).
            for (std::size_t i = firstOfBlock[b]; i < firstOfBlock[b + 1]; ++i)
                for (std::uint32_t x : whole.removed[inBlock[i].second]) beside.push_back(x);
            std::sort(beside.begin(), beside.end());
            beside.erase(std::unique(beside.begin(), beside.end()), beside.end());
            globalOf.insert(globalOf.end(), beside.begin(), beside.end());
            const auto ownEnd = globalOf.begin() + std::ptrdiff_t(res.own);
            auto localOf = [&](std::uint32_t g) {
                auto it = std::lower_bound(globalOf.begin(), ownEnd, g);
                if (it == ownEnd || *it != g) it = std::lower_bound(ownEnd, globalOf.end(), g);
                if (it == globalOf.end() || *it != g) throw std::logic_error("thin simplification: a block lacks a vertex it reads");
                return std::uint32_t(it - globalOf.begin());
            };
            const std::size_t m = globalOf.size();
            sub.pos.resize(m);
            sub.locked.assign(m, 1); // (the vertices beside the block)
            sub.fixedNeighbours.assign(m, {});
            sub.quadric.assign(m, Quadric());
            sub.dead.assign(m, 0);
            std::vector<std::uint8_t> settledHere(m, 1);
            for (std::size_t i = 0; i < m; ++i) {
                sub.pos[i] = whole.pos[globalOf[i]];
                sub.dead[i] = whole.dead[globalOf[i]];
            }
            for (std::size_t i = 0; i < res.own; ++i) {
                const std::uint32_t g = globalOf[i];
                sub.locked[i] = whole.locked[g];
                sub.quadric[i] = whole.quadric[g];
                settledHere[i] = settled[g];
                for (std::uint32_t k = fixedStart[i]; k < fixedStart[i + 1]; ++k) sub.fixedNeighbours[i].push_back(localOf(fixedGlobal[k]));
            }
            for (std::size_t i = firstOfBlock[b]; i < firstOfBlock[b + 1]; ++i) {
                const std::uint32_t t = inBlock[i].second;
                res.triangleOf.push_back(t);
                Triangle local;
                local.changed = whole.triangles[t].changed;
                for (std::size_t k = 0; k < 3; ++k) local.v[k] = localOf(whole.triangles[t].v[k]);
                sub.triangles.push_back(local);
                std::vector<std::uint32_t> answered;
                for (std::uint32_t x : whole.removed[t]) answered.push_back(localOf(x));
                sub.removed.push_back(std::move(answered));
            }
            res.collapses = sub.run(options.cancel, &settledHere);
        }
    });
    if (options.cancel) options.cancel->check();

    std::uint64_t collapses = 0;
    for (const Result& res : results) {
        const ThinSimplifier& sub = *res.sub;
        collapses += res.collapses;
        for (std::size_t i = 0; i < res.own; ++i) {
            const std::uint32_t g = res.globalOf[i];
            whole.quadric[g] = sub.quadric[i];
            whole.dead[g] = sub.dead[i];
            // Tried in this run as it now is: free here. Else as settled as before, unless a
            // collapse here changed its neighbourhood.
            settled[g] = !sub.locked[i] || (settled[g] && !sub.touched[i]);
        }
        for (std::size_t i = 0; i < res.triangleOf.size(); ++i) {
            Triangle& t = whole.triangles[res.triangleOf[i]];
            const Triangle& local = sub.triangles[i];
            t.alive = local.alive;
            t.changed = local.changed;
            for (std::size_t k = 0; k < 3; ++k) t.v[k] = res.globalOf[local.v[k]];
            auto& answered = whole.removed[res.triangleOf[i]];
            answered.clear();
            for (std::uint32_t x : sub.removed[i]) answered.push_back(res.globalOf[x]);
        }
    }
    return collapses;
}

// The region's collapses, most of them in parallel: each block of blockCells^3 lattice cells on
// its own, then each block of a grid shifted by half a block (what lay along the first blocks'
// faces lies inside these), then the whole region once more for what is left (where the two
// grids' faces cross). A block's run holds the triangles whose corners all lie in the block; a
// vertex with a triangle beyond the block is locked there (an open border of the block's
// triangles), and such triangles are its neighbours' fixed edges. Every triangle a block's run
// reads or changes then has a corner in the block, and none another block's run changes: a
// triangle that one changes has a vertex collapsing there, all of whose triangles lie in that
// block. So the blocks' runs are independent, and each is the serial greedy on its part. Later runs
// take the quadrics and removed vertices with them, and try the vertices no run has tried as they
// now are (the blocks' borders, and those around a collapse since), cheapest first. The blocks
// are fixed by the lattice, not by the threads: the output does not depend on their number.
std::uint64_t collapseRegion(ThinSimplifier& whole, const Field& field, const ThinSimplifyOptions& options, const LatticeFrame& frame) {
    const std::size_t n = whole.pos.size();
    whole.quadric = whole.quadricsOfTriangles();
    whole.removed.assign(whole.triangles.size(), {});
    whole.dead.assign(n, 0);
    if (!(options.blockCells > 0)) return whole.run(options.cancel);
    std::vector<std::uint8_t> settled(n, 0);
    std::uint64_t collapses = collapseInBlocks(whole, field, options, frame, 0.0, settled);
    collapses += collapseInBlocks(whole, field, options, frame, 0.5 * options.blockCells, settled);
    return collapses + whole.run(options.cancel, &settled);
}

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
    st.collapses = collapseRegion(simplifier, field, options, frame);
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
