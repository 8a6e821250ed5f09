#include "vdbsurf/dmc/node_weld.h"

#include "vdbsurf/core/fixed_chunks.h"
#include "vdbsurf/core/parallel_buckets.h"
#include "vdbsurf/core/prefault.h"
#include "vdbsurf/mesh/mesh_folds.h"
#include "vdbsurf/mesh/separate_points.h"
#include "vdbsurf/mesh/vertex_fans.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <cstring>
#include <stdexcept>
#include <tuple>

namespace vdbsurf {

namespace {

constexpr std::uint32_t kNone = ~0u;
// Work is split into chunks of this many items whatever the thread count, and chunk results are
// joined in chunk order: the output is the same with any number of threads.
constexpr std::size_t kChunk = 2048;

std::size_t chunkCount(std::size_t n) { return fixedChunkCount(n, kChunk); }

template <typename Body>
void forEachChunk(std::size_t n, Body&& body) {
    forEachFixedChunk(n, kChunk, body);
}

// Exclusive prefix sums of `counts`, with the total appended.
template <typename T>
std::vector<std::size_t> prefixSums(const std::vector<T>& counts) {
    std::vector<std::size_t> base(counts.size() + 1, 0);
    for (std::size_t i = 0; i < counts.size(); ++i) base[i + 1] = base[i] + counts[i];
    return base;
}

struct Loops {
    std::vector<std::uint32_t> offsets{0}, indices;
    std::size_t count() const { return offsets.size() - 1; }
    std::uint32_t size(std::size_t l) const { return offsets[l + 1] - offsets[l]; }
    const std::uint32_t* loop(std::size_t l) const { return indices.data() + offsets[l]; }
};

// Chunks of loops joined in order into one list.
Loops joinLoops(const std::vector<Loops>& parts) {
    std::vector<std::size_t> loopCount, indexCount;
    for (const Loops& p : parts) loopCount.push_back(p.count()), indexCount.push_back(p.indices.size());
    const std::vector<std::size_t> loopBase = prefixSums(loopCount), indexBase = prefixSums(indexCount);
    Loops all;
    all.offsets.assign(loopBase.back() + 1, 0);
    all.indices.resize(indexBase.back());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, parts.size(), 1), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t c = r.begin(); c < r.end(); ++c) {
            const Loops& p = parts[c];
            std::copy(p.indices.begin(), p.indices.end(), all.indices.begin() + std::ptrdiff_t(indexBase[c]));
            for (std::size_t l = 1; l <= p.count(); ++l) all.offsets[loopBase[c] + l] = std::uint32_t(p.offsets[l] + indexBase[c]);
        }
    });
    return all;
}

// A polygon after welding: runs of one vertex merged, and split into simple loops where a vertex
// comes back (a pinched polygon); loops under three vertices have collapsed.
class LoopCleaner {
public:
    std::uint64_t collapsed = 0;
    void emit(const std::vector<std::uint32_t>& loop, Loops& out) {
        clean.clear();
        for (std::uint32_t v : loop)
            if (clean.empty() || clean.back() != v) clean.push_back(v);
        while (clean.size() > 1 && clean.front() == clean.back()) clean.pop_back();
        if (clean.size() < 3) {
            ++collapsed;
            return;
        }
        for (std::size_t i = 0; i < clean.size(); ++i)
            for (std::size_t j = i + 1; j < clean.size(); ++j)
                if (clean[i] == clean[j]) {
                    const std::vector<std::uint32_t> a(clean.begin() + std::ptrdiff_t(i), clean.begin() + std::ptrdiff_t(j));
                    std::vector<std::uint32_t> b(clean.begin(), clean.begin() + std::ptrdiff_t(i));
                    b.insert(b.end(), clean.begin() + std::ptrdiff_t(j), clean.end());
                    emit(a, out);
                    emit(b, out);
                    return;
                }
        out.indices.insert(out.indices.end(), clean.begin(), clean.end());
        out.offsets.push_back(std::uint32_t(out.indices.size()));
    }

private:
    std::vector<std::uint32_t> clean; // reused: most loops need no split, so no allocation
};

// For each entry of atNode, the first vertex listed for its node, and (listed) how many entries its node has.
std::vector<std::uint32_t> representatives(const std::vector<std::pair<std::uint32_t, Vec3i>>& atNode, std::vector<std::uint32_t>& listed) {
    // Sorted by node, then by entry: the first entry of each run is its node's. Nodes packed into
    // one integer sort several times faster than triples (every crossing on a box's face lies on
    // a node when the faces lie on node planes); triples where the nodes span too much for that.
    std::vector<std::uint32_t> repOf(atNode.size());
    listed.assign(atNode.size(), 0);
    auto assign = [&](std::size_t n, auto&& sameNode, auto&& entry) {
        for (std::size_t i = 0; i < n;) {
            std::size_t j = i + 1;
            while (j < n && sameNode(i, j)) ++j;
            for (std::size_t t = i; t < j; ++t) repOf[entry(t)] = atNode[entry(i)].first, listed[entry(t)] = std::uint32_t(j - i);
            i = j;
        }
    };
    Vec3i lo = atNode.front().second, hi = lo;
    for (const auto& [v, n] : atNode)
        for (std::size_t a = 0; a < 3; ++a) lo[a] = std::min(lo[a], n[a]), hi[a] = std::max(hi[a], n[a]);
    constexpr std::int64_t kSpan = std::int64_t(1) << 21;
    if (std::int64_t(hi.x) - lo.x < kSpan && std::int64_t(hi.y) - lo.y < kSpan && std::int64_t(hi.z) - lo.z < kSpan) {
        std::vector<std::pair<std::uint64_t, std::uint32_t>> keys(atNode.size());
        for (std::size_t k = 0; k < atNode.size(); ++k) {
            const Vec3i& n = atNode[k].second;
            keys[k] = {std::uint64_t(std::int64_t(n.x) - lo.x) << 42 | std::uint64_t(std::int64_t(n.y) - lo.y) << 21 |
                           std::uint64_t(std::int64_t(n.z) - lo.z),
                       std::uint32_t(k)};
        }
        tbb::parallel_sort(keys.begin(), keys.end());
        assign(keys.size(), [&](std::size_t i, std::size_t j) { return keys[i].first == keys[j].first; },
               [&](std::size_t t) { return keys[t].second; });
        return repOf;
    }
    struct Key {
        int x, y, z;
        std::uint32_t k;
        bool operator<(const Key& o) const { return std::tie(x, y, z, k) < std::tie(o.x, o.y, o.z, o.k); }
    };
    std::vector<Key> keys(atNode.size());
    for (std::size_t k = 0; k < atNode.size(); ++k) keys[k] = {atNode[k].second.x, atNode[k].second.y, atNode[k].second.z, std::uint32_t(k)};
    tbb::parallel_sort(keys.begin(), keys.end());
    assign(keys.size(), [&](std::size_t i, std::size_t j) { return std::tie(keys[i].x, keys[i].y, keys[i].z) == std::tie(keys[j].x, keys[j].y, keys[j].z); },
           [&](std::size_t t) { return keys[t].k; });
    return repOf;
}

// One attempt's weld, read through the node numbering (`slot`: a vertex on a node -> its node,
// kNone elsewhere) rather than through two more arrays of a number per vertex: filling those cost
// more than the attempts where a mesh has few vertices on nodes (bench_mesh's 3 M-voxel sphere:
// 32 of its 750 k).
// Which nodes are welded is fixed when the attempt starts, though `apart` grows during it.
struct Welding {
    const std::vector<std::uint32_t>& slot;
    const std::vector<std::uint32_t>& repOfSlot; // each node's representative
    std::vector<std::uint8_t> welded;            // per node: its vertices become its representative

    // Where vertex v goes.
    std::uint32_t target(std::uint32_t v) const {
        const std::uint32_t s = slot[v];
        return s != kNone && welded[s] ? repOfSlot[s] : v;
    }
    // Is v the vertex a welded node's vertices became?
    bool isRep(std::uint32_t v) const {
        const std::uint32_t s = slot[v];
        return s != kNone && welded[s] && repOfSlot[s] == v;
    }
};

// Welded vertices where the mesh would stop being edge-manifold: two loop edges leaving v for
// one vertex w, or two arriving from one, mean the edge {v, w} has more than two polygons or two
// running the same way (with at most one each way it is fine). Only edges at a welded vertex
// can have changed, and every loop through one is listed, so looking at the corners of the
// welded vertices finds every such edge. Marks welded vertices to keep apart in `apart` (by slot,
// the numbering of the possible representatives): where both ends of a bad edge are welded and
// `oneEnd` is set, only one of them — the one fewer polygons hold twice (`selfPolygons`), so
// that keeping it apart leaves its vertices coincident but no polygon without area (two nodes
// placed side by side on a sharp edge pinch it when both are welded; kept apart together, the
// polygons among one's vertices are slivers of no area); else both. Returns whether any was found.
bool markNonManifoldWelds(const Loops& loops, const Welding& weld, const std::vector<std::uint32_t>& slot, std::size_t slots,
                          const std::vector<std::uint32_t>& selfPolygons, bool oneEnd,
                          std::vector<std::uint8_t>& apart) {
    // The corners at each welded vertex: (next vertex, previous vertex), grouped in parallel
    // (their order within a vertex does not matter: the ends are sorted below).
    std::vector<std::uint32_t> first;
    std::vector<std::pair<std::uint32_t, std::uint32_t>> corners;
    fillBuckets(slots, [&](auto&& put) {
        forEachChunk(loops.count(), [&](std::size_t, std::size_t b, std::size_t e) {
            for (std::size_t l = b; l < e; ++l) {
                const std::uint32_t* p = loops.loop(l);
                const std::uint32_t n = loops.size(l);
                for (std::uint32_t i = 0; i < n; ++i)
                    if (weld.isRep(p[i])) put(slot[p[i]], [&] { return std::make_pair(p[i + 1 < n ? i + 1 : 0], p[i > 0 ? i - 1 : n - 1]); });
            }
        });
    }, first, corners);
    std::vector<std::vector<std::pair<std::uint32_t, std::uint32_t>>> badEdges(chunkCount(slots)); // (slot of v, w)
    forEachChunk(slots, [&](std::size_t c, std::size_t b, std::size_t e) {
        std::vector<std::uint32_t> ends;
        for (std::size_t s = b; s < e; ++s) {
            for (int way = 0; way < 2; ++way) {
                ends.clear();
                for (std::uint32_t i = first[s]; i < first[s + 1]; ++i) ends.push_back(way ? corners[i].second : corners[i].first);
                std::sort(ends.begin(), ends.end());
                for (std::size_t i = 1; i < ends.size(); ++i)
                    if (ends[i] == ends[i - 1]) badEdges[c].emplace_back(std::uint32_t(s), ends[i]);
            }
        }
    });
    bool any = false;
    for (const auto& edges : badEdges)
        for (const auto& [s, w] : edges) {
            any = true;
            if (!weld.isRep(w)) {
                apart[s] = 1;
                continue;
            }
            // (Seen from both ends: the choice depends on the pair alone.)
            const std::uint32_t t = slot[w];
            if (!oneEnd) {
                apart[s] = apart[t] = 1;
                continue;
            }
            const bool sApart = selfPolygons[s] != selfPolygons[t] ? selfPolygons[s] < selfPolygons[t] : s > t;
            apart[sApart ? s : t] = 1;
        }
    return any;
}

// For each node (by slot): how many of the candidate polygons hold two or more of its vertices.
std::vector<std::uint32_t> countSelfPolygons(const Mesh& mesh, const std::vector<std::uint32_t>& candidates,
                                             const std::vector<std::uint32_t>& slot, std::size_t slots) {
    std::vector<std::vector<std::uint32_t>> parts(chunkCount(candidates.size()));
    forEachChunk(candidates.size(), [&](std::size_t c, std::size_t b, std::size_t e) {
        std::vector<std::uint32_t> seen;
        for (std::size_t k = b; k < e; ++k) {
            const std::uint32_t f = candidates[k];
            seen.clear();
            for (std::uint32_t i = mesh.offsets[f]; i < mesh.offsets[f + 1]; ++i)
                if (slot[mesh.indices[i]] != kNone) seen.push_back(slot[mesh.indices[i]]);
            std::sort(seen.begin(), seen.end());
            for (std::size_t i = 1; i < seen.size(); ++i)
                if (seen[i] == seen[i - 1] && (i == 1 || seen[i - 2] != seen[i])) parts[c].push_back(seen[i]);
        }
    });
    std::vector<std::uint32_t> count(slots, 0);
    for (const auto& p : parts)
        for (std::uint32_t s : p) ++count[s];
    return count;
}

bool reversedLoops(const Loops& loops, std::size_t x, std::size_t y) {
    const std::uint32_t n = loops.size(x);
    if (loops.size(y) != n) return false;
    const std::uint32_t *a = loops.loop(x), *b = loops.loop(y);
    const std::uint32_t* at = std::find(b, b + n, a[0]);
    if (at == b + n) return false;
    const std::uint32_t s = std::uint32_t(at - b);
    for (std::uint32_t i = 1; i < n; ++i)
        if (a[i] != b[(s + n - i) % n]) return false;
    return true;
}

std::uint64_t mixBits(std::uint64_t v) {
    v ^= v >> 33;
    v *= 0xff51afd7ed558ccdull;
    v ^= v >> 33;
    v *= 0xc4ceb9fe1a85ec53ull;
    return v ^ (v >> 33);
}

// Marks both loops of every reversed pair (pillow[l] = 1) among the loops through a welded
// vertex: on an edge-manifold surface their edges belong to them alone, so dropping them leaves
// nothing open, and a loop has at most one reversed twin. Twins share an order-free hash of
// their vertices; only loops with equal hashes are compared. Returns the number marked.
std::uint64_t markReversedPairs(const Loops& loops, const Welding& weld, std::vector<std::uint8_t>& pillow) {
    pillow.assign(loops.count(), 0);
    std::vector<std::vector<std::pair<std::uint64_t, std::uint32_t>>> parts(chunkCount(loops.count()));
    forEachChunk(loops.count(), [&](std::size_t c, std::size_t b, std::size_t e) {
        for (std::size_t l = b; l < e; ++l) {
            const std::uint32_t* p = loops.loop(l);
            const std::uint32_t n = loops.size(l);
            if (std::none_of(p, p + n, [&](std::uint32_t v) { return weld.isRep(v); })) continue;
            std::uint64_t h = mixBits(n);
            for (std::uint32_t i = 0; i < n; ++i) h += mixBits(p[i] + 1);
            parts[c].emplace_back(h, std::uint32_t(l));
        }
    });
    std::vector<std::pair<std::uint64_t, std::uint32_t>> keyed;
    for (const auto& p : parts) keyed.insert(keyed.end(), p.begin(), p.end());
    tbb::parallel_sort(keyed.begin(), keyed.end());
    std::uint64_t marked = 0;
    for (std::size_t i = 0; i < keyed.size();) {
        std::size_t j = i;
        while (j < keyed.size() && keyed[j].first == keyed[i].first) ++j;
        for (std::size_t x = i; x < j; ++x) {
            if (pillow[keyed[x].second]) continue;
            for (std::size_t y = x + 1; y < j; ++y)
                if (!pillow[keyed[y].second] && reversedLoops(loops, keyed[x].second, keyed[y].second)) {
                    pillow[keyed[x].second] = pillow[keyed[y].second] = 1;
                    marked += 2;
                    break;
                }
        }
        i = j;
    }
    return marked;
}

// Which candidates (positions in the ascending list) lie among the polygons [b, e).
std::pair<std::size_t, std::size_t> candidatesIn(const std::vector<std::uint32_t>& candidates, std::size_t b, std::size_t e) {
    const auto lo = std::lower_bound(candidates.begin(), candidates.end(), std::uint32_t(b));
    const auto hi = std::lower_bound(lo, candidates.end(), std::uint32_t(e));
    return {std::size_t(lo - candidates.begin()), std::size_t(hi - candidates.begin())};
}

// body(chunk, first, last) for the index range [first, last) of each run of polygons between
// candidates, over fixed chunks of the polygons.
template <typename Body>
void forEachRunBetween(const Mesh& mesh, const std::vector<std::uint32_t>& candidates, Body&& body) {
    forEachChunk(mesh.polygonCount(), [&](std::size_t c, std::size_t b, std::size_t e) {
        const auto [k0, k1] = candidatesIn(candidates, b, e);
        std::size_t f = b;
        for (std::size_t k = k0; k <= k1; ++k) {
            const std::size_t until = k < k1 ? std::size_t(candidates[k]) : e;
            body(c, mesh.offsets[f], mesh.offsets[until]);
            f = until + 1;
        }
    });
}

// A per-point flag that several tasks may set at once (polygons of different chunks share
// points): GCC's relaxed atomic store on the plain array, as each pass stores one value.
void setFlag(std::vector<std::uint8_t>& flags, std::uint32_t v, std::uint8_t value) { __atomic_store_n(&flags[v], value, __ATOMIC_RELAXED); }

// The points of every kept loop flagged 1, in parallel.
void markKeptLoops(const Loops& loops, const std::vector<std::uint8_t>& pillow, std::vector<std::uint8_t>& flags) {
    forEachChunk(loops.count(), [&](std::size_t, std::size_t b, std::size_t e) {
        for (std::size_t l = b; l < e; ++l)
            if (!pillow[l])
                for (std::uint32_t i = 0; i < loops.size(l); ++i) setFlag(flags, loops.loop(l)[i], 1);
    });
}

// Which points a polygon uses once the candidates are replaced by their kept loops (1), found
// by marking the points of every polygon between candidates and of every kept loop.
std::vector<std::uint8_t> pointsUsedAfter(const Mesh& mesh, const std::vector<std::uint32_t>& candidates, const Loops& loops,
                                          const std::vector<std::uint8_t>& pillow) {
    std::vector<std::uint8_t> used = prefaultedVector<std::uint8_t>(mesh.points.size(), 0);
    forEachRunBetween(mesh, candidates, [&](std::size_t, std::uint32_t first, std::uint32_t last) {
        for (std::uint32_t i = first; i < last; ++i) setFlag(used, mesh.indices[i], 1);
    });
    markKeptLoops(loops, pillow, used);
    return used;
}

// pointsUsedAfter where every point lies on a polygon, from the candidates alone (the marking
// pass over every polygon was most of the weld's time on meshes with few vertices on nodes):
// only a point of a candidate can go, when no kept loop holds it and no polygon between the
// candidates does. A vertex on a welded node lies on candidates alone; another point of a
// candidate that no kept loop holds (rare: its polygons there all collapsed) is looked for
// among the rest.
std::vector<std::uint8_t> pointsLeftByCandidates(const Mesh& mesh, const std::vector<std::uint32_t>& candidates, const Loops& loops,
                                                 const std::vector<std::uint8_t>& pillow, const std::vector<std::uint32_t>& onNode) {
    constexpr std::uint8_t kUnsure = 2;
    std::vector<std::uint8_t> used = prefaultedVector<std::uint8_t>(mesh.points.size(), 1);
    // Three passes in parallel (each a scattered read of the candidates: most of the time is
    // waiting for memory), each storing one value (setFlag), so the outcome is the serial one's.
    // A point may enter `unsure` twice: harmless.
    auto forEachCandidatePoint = [&](auto&& body) { // body(chunk, point)
        forEachChunk(candidates.size(), [&](std::size_t c, std::size_t b, std::size_t e) {
            for (std::size_t k = b; k < e; ++k)
                for (std::uint32_t i = mesh.offsets[candidates[k]]; i < mesh.offsets[candidates[k] + 1]; ++i) body(c, mesh.indices[i]);
        });
    };
    forEachCandidatePoint([&](std::size_t, std::uint32_t v) { setFlag(used, v, 0); });
    markKeptLoops(loops, pillow, used);
    std::vector<std::vector<std::uint32_t>> unsureIn(chunkCount(candidates.size()));
    forEachCandidatePoint([&](std::size_t c, std::uint32_t v) {
        if (__atomic_load_n(&used[v], __ATOMIC_RELAXED) == 0 && onNode[v] == kNone) setFlag(used, v, kUnsure), unsureIn[c].push_back(v);
    });
    std::vector<std::uint32_t> unsure;
    for (const auto& u : unsureIn) unsure.insert(unsure.end(), u.begin(), u.end());
    if (!unsure.empty()) {
        std::vector<std::vector<std::uint32_t>> found(chunkCount(mesh.polygonCount()));
        forEachRunBetween(mesh, candidates, [&](std::size_t c, std::uint32_t first, std::uint32_t last) {
            for (std::uint32_t i = first; i < last; ++i)
                if (used[mesh.indices[i]] == kUnsure) found[c].push_back(mesh.indices[i]);
        });
        for (const auto& vs : found)
            for (const std::uint32_t v : vs) used[v] = 1;
        for (const std::uint32_t v : unsure)
            if (used[v] == kUnsure) used[v] = 0;
    }
    return used;
}

// The mesh's polygons with each candidate replaced by its loops (pillows left out), and the
// points no polygon then uses dropped (the order of the rest kept); the new numbers of the
// polygons that came from candidates (ascending) go to fromCandidates. Returns old -> new point
// numbers (kNone for dropped points). Rewritten in place, front to back within each of a few
// segments (in parallel): a candidate's loops hold no more vertices than it did, and points only
// move down, so nothing is written before it is read; the polygon count can grow where a pinched
// polygon splits, and then the offsets alone go to a new array. (A rewrite into new arrays touched 6 MB of fresh memory on the armadillo, a
// page fault per 4 KB: the weld's largest cost.) Polygons between candidates move as runs: they
// are nearly all of them, and only their vertex numbers change. `onNode`: the vertices on nodes
// the weld may merge (not kNone), all of whose polygons are candidates; `everyPointUsed`: every
// point lies on a polygon (see weldNodeVertices).
std::vector<std::uint32_t> replaceCandidates(Mesh& mesh, const std::vector<std::uint32_t>& candidates, const std::vector<std::uint32_t>& firstLoop,
                                             const Loops& loops, const std::vector<std::uint8_t>& pillow,
                                             const std::vector<std::uint32_t>& onNode, bool everyPointUsed,
                                             std::vector<std::uint32_t>& fromCandidates) {
    const std::size_t polygons = mesh.polygonCount(), points = mesh.points.size();
    const std::vector<std::uint8_t> used = everyPointUsed ? pointsLeftByCandidates(mesh, candidates, loops, pillow, onNode)
                                                          : pointsUsedAfter(mesh, candidates, loops, pillow);
    std::vector<std::uint32_t> kept(chunkCount(points), 0);
    forEachChunk(points, [&](std::size_t c, std::size_t b, std::size_t e) {
        for (std::size_t v = b; v < e; ++v) kept[c] += used[v];
    });
    const std::vector<std::size_t> pointBase = prefixSums(kept);
    std::vector<std::uint32_t> newId = prefaultedVector(points, kNone);
    forEachChunk(points, [&](std::size_t c, std::size_t b, std::size_t e) {
        std::size_t next = pointBase[c];
        for (std::size_t v = b; v < e; ++v)
            if (used[v]) newId[v] = std::uint32_t(next++);
    });

    // Per candidate, as sums over those before it: its indices, its kept loops and their indices.
    // Can the offsets be rewritten in place: is the output, after each candidate, no more
    // polygons than the input up to it? (Between candidates the difference stays.)
    const std::size_t K = candidates.size();
    std::vector<std::uint64_t> candidateIndicesBefore(K + 1, 0), loopsBefore(K + 1, 0), loopIndicesBefore(K + 1, 0);
    bool offsetsInPlace = true;
    for (std::size_t k = 0; k < K; ++k) {
        std::uint64_t mine = 0, mineIndices = 0;
        for (std::uint32_t l = firstLoop[k]; l < firstLoop[k + 1]; ++l)
            if (!pillow[l]) ++mine, mineIndices += loops.size(l);
        const std::size_t c = candidates[k];
        candidateIndicesBefore[k + 1] = candidateIndicesBefore[k] + (mesh.offsets[c + 1] - mesh.offsets[c]);
        loopsBefore[k + 1] = loopsBefore[k] + mine;
        loopIndicesBefore[k + 1] = loopIndicesBefore[k] + mineIndices;
        offsetsInPlace = offsetsInPlace && c - k + loopsBefore[k + 1] <= c + 1;
    }
    const std::size_t keptPolygons = polygons - K + loopsBefore[K];
    const std::size_t keptIndices = mesh.indices.size() - candidateIndicesBefore[K] + loopIndicesBefore[K];
    std::vector<std::uint32_t> grown;
    if (!offsetsInPlace) grown.resize(keptPolygons + 1, 0);
    std::uint32_t* offsets = offsetsInPlace ? mesh.offsets.data() : grown.data();
    std::uint32_t* indices = mesh.indices.data();

    // The polygons are rewritten in segments, in parallel, each front to back as one serial pass
    // would (vertex numbers renumbered as they move). Nothing lands after where it was read, so
    // a segment's writes stay within what it reads itself, except its first outputs, which land
    // below its input, where the segment before may not have read yet: those are kept aside
    // and put in place when all are done. (Moved serially, these were the weld's largest step
    // on meshes with few candidates.)
    struct Segment {
        std::size_t first = 0, kFirst = 0;           // input: first polygon, first candidate
        std::size_t outPolygons = 0, outIndices = 0; // output written before the segment
        std::uint32_t inIndex = 0;                   // mesh.offsets[first]
        std::size_t endPolygons = 0, endIndices = 0; // output written after it
        std::vector<std::uint32_t> heldOffsets, heldIndices, fromCandidates;
    };
    const std::size_t segmentCount = std::clamp<std::size_t>(polygons / 8192, 1, 64);
    std::vector<Segment> segments(segmentCount);
    for (std::size_t s = 0; s < segmentCount; ++s) {
        Segment& seg = segments[s];
        seg.first = polygons * s / segmentCount;
        seg.kFirst = std::size_t(std::lower_bound(candidates.begin(), candidates.end(), std::uint32_t(seg.first)) - candidates.begin());
        seg.outPolygons = seg.first - seg.kFirst + loopsBefore[seg.kFirst];
        seg.inIndex = mesh.offsets[seg.first];
        seg.outIndices = seg.inIndex - candidateIndicesBefore[seg.kFirst] + loopIndicesBefore[seg.kFirst];
    }
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, segmentCount, 1), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t s = r.begin(); s < r.end(); ++s) {
            Segment& seg = segments[s];
            const std::size_t end = s + 1 < segmentCount ? segments[s + 1].first : polygons;
            // Offsets at or below `first` and indices below inIndex may not have been read yet.
            const std::size_t offsetsFrom = offsetsInPlace ? seg.first + 1 : 0, indicesFrom = seg.inIndex;
            std::size_t f = seg.outPolygons, i = seg.outIndices; // output: polygons and indices written
            std::uint32_t runStart = seg.inIndex;                // input: the first index of the polygon read next
            auto putOffset = [&](std::size_t at, std::uint32_t value) {
                if (at < offsetsFrom) seg.heldOffsets.push_back(value);
                else offsets[at] = value;
            };
            auto copyRun = [&](std::size_t f0, std::size_t f1) { // input polygons [f0, f1)
                if (f1 <= f0) return;
                const std::uint32_t runEnd = mesh.offsets[f1]; // (read before offsets[f + 1] <= it is written)
                const std::uint32_t shift = std::uint32_t(i) - runStart; // (mod 2^32: i <= runStart)
                const std::size_t n = runEnd - runStart, held = i < indicesFrom ? std::min(n, indicesFrom - i) : 0;
                for (std::size_t j = 0; j < held; ++j) seg.heldIndices.push_back(newId[indices[runStart + j]]);
                for (std::size_t j = held; j < n; ++j) indices[i + j] = newId[indices[runStart + j]];
                i += n;
                runStart = runEnd;
                for (std::size_t g = f0; g < f1; ++g) putOffset(++f, mesh.offsets[g + 1] + shift); // (f + 1 <= g + 1)
            };
            std::size_t next = seg.first;
            for (std::size_t k = seg.kFirst; k < K && candidates[k] < end; ++k) {
                copyRun(next, candidates[k]);
                const std::uint32_t candidateEnd = mesh.offsets[std::size_t(candidates[k]) + 1]; // (before its loops' offsets are written)
                for (std::uint32_t l = firstLoop[k]; l < firstLoop[k + 1]; ++l) {
                    if (pillow[l]) continue;
                    seg.fromCandidates.push_back(std::uint32_t(f));
                    const std::uint32_t* p = loops.loop(l);
                    for (std::uint32_t j = 0; j < loops.size(l); ++j, ++i) {
                        if (i < indicesFrom) seg.heldIndices.push_back(newId[p[j]]);
                        else indices[i] = newId[p[j]];
                    }
                    putOffset(++f, std::uint32_t(i));
                }
                runStart = candidateEnd;
                next = std::size_t(candidates[k]) + 1;
            }
            copyRun(next, end);
            seg.endPolygons = f, seg.endIndices = i;
        }
    });
    fromCandidates.clear();
    for (std::size_t s = 0; s < segmentCount; ++s) {
        const Segment& seg = segments[s];
        const bool last = s + 1 == segmentCount;
        if (seg.endPolygons != (last ? keptPolygons : segments[s + 1].outPolygons) ||
            seg.endIndices != (last ? keptIndices : segments[s + 1].outIndices))
            throw std::logic_error("lattice surface: the weld's segments do not join");
        std::copy(seg.heldOffsets.begin(), seg.heldOffsets.end(), offsets + seg.outPolygons + 1);
        std::copy(seg.heldIndices.begin(), seg.heldIndices.end(), indices + seg.outIndices);
        fromCandidates.insert(fromCandidates.end(), seg.fromCandidates.begin(), seg.fromCandidates.end());
    }
    if (offsetsInPlace) mesh.offsets.resize(keptPolygons + 1);
    else mesh.offsets = std::move(grown);
    mesh.indices.resize(keptIndices);
    // Points move down, chunk by chunk in parallel as they were numbered (each lands at or before
    // where it was read; those that land below their chunk are kept aside, as above).
    std::vector<std::vector<Vec3f>> heldPoints(chunkCount(points));
    forEachChunk(points, [&](std::size_t c, std::size_t b, std::size_t e) {
        for (std::size_t v = b; v < e; ++v) {
            const std::uint32_t to = newId[v];
            if (to == kNone) continue;
            if (to < b) heldPoints[c].push_back(mesh.points[v]);
            else if (to != v) mesh.points[to] = mesh.points[v];
        }
    });
    for (std::size_t c = 0; c < heldPoints.size(); ++c)
        std::copy(heldPoints[c].begin(), heldPoints[c].end(), mesh.points.begin() + std::ptrdiff_t(pointBase[c]));
    mesh.points.resize(pointBase.back());
    return newId;
}

// weldNodeVertices for nodes of two vertices or more; repOf as representatives() gives it.
// `suspects`: the vertices that may share a point with another when the weld is done (see
// weldNodeVertices), numbered as before it; they are separated before the folds are closed.
NodeWeldStats weldSeveral(Mesh& mesh, const std::vector<std::pair<std::uint32_t, Vec3i>>& atNode, const std::vector<std::uint32_t>& repOf,
                          const std::vector<std::uint8_t>& rounded, std::vector<std::uint32_t> suspects,
                          const std::vector<std::uint32_t>* polygonsToWeld) {
    NodeWeldStats stats;
    if (atNode.empty()) {
        stats.separatedVertices = separateCoincidentPoints(mesh, std::move(suspects));
        return stats;
    }

    // Only polygons through a vertex on a node can change: the attempts below redo just those.
    std::vector<std::uint32_t> candidates; // ascending
    if (polygonsToWeld) {
        candidates = *polygonsToWeld;
    } else {
        std::vector<std::uint8_t> onNode = prefaultedVector<std::uint8_t>(mesh.points.size(), 0);
        for (const auto& [v, node] : atNode) onNode[v] = 1;
        std::vector<std::vector<std::uint32_t>> parts(chunkCount(mesh.polygonCount()));
        forEachChunk(mesh.polygonCount(), [&](std::size_t c, std::size_t b, std::size_t e) {
            for (std::size_t f = b; f < e; ++f) {
                const std::uint32_t* p = mesh.polygon(f);
                if (std::any_of(p, p + mesh.polygonSize(f), [&](std::uint32_t v) { return onNode[v] != 0; }))
                    parts[c].push_back(std::uint32_t(f));
            }
        });
        for (const auto& p : parts) candidates.insert(candidates.end(), p.begin(), p.end());
    }

    // The representatives, numbered (for grouping corners by welded vertex); later also the other
    // vertices on a node, with their node's number.
    std::vector<std::uint32_t> slot = prefaultedVector(mesh.points.size(), kNone);
    std::size_t slots = 0;
    for (std::uint32_t rep : repOf)
        if (slot[rep] == kNone) slot[rep] = std::uint32_t(slots++);
    std::vector<std::uint32_t> repOfSlot(slots);
    for (std::uint32_t rep : repOf) repOfSlot[slot[rep]] = rep;
    std::vector<std::uint8_t> apart(slots, 0); // representatives kept apart, by slot
    for (std::size_t k = 0; k < atNode.size(); ++k) slot[atNode[k].first] = slot[repOf[k]]; // every vertex on a node: its node's
    const std::vector<std::uint32_t> selfPolygons = countSelfPolygons(mesh, candidates, slot, slots);
    std::vector<std::uint8_t> onlyRounded(slots, !rounded.empty()); // nodes whose vertices all rounded to them
    for (std::size_t k = 0; k < rounded.size(); ++k)
        if (!rounded[k]) onlyRounded[slot[repOf[k]]] = 0;
    std::vector<std::uint32_t> others(slots, 0); // per node: its vertices besides the representative
    for (std::size_t k = 0; k < atNode.size(); ++k) others[slot[repOf[k]]] += atNode[k].first != repOf[k];
    for (int attempt = 0;; ++attempt) {
        Welding weld{slot, repOfSlot, std::vector<std::uint8_t>(slots, 0)};
        std::uint64_t welded = 0;
        for (std::size_t s = 0; s < slots; ++s)
            if (!apart[s] && others[s] > 0) weld.welded[s] = 1, welded += others[s];
        if (welded == 0) {
            stats.separatedVertices = separateCoincidentPoints(mesh, std::move(suspects));
            return stats;
        }

        // The candidates' polygons after welding: candidate k becomes loops [firstLoop[k], firstLoop[k + 1]).
        std::vector<Loops> parts(chunkCount(candidates.size()));
        std::vector<std::uint32_t> loopsOf(candidates.size());
        std::vector<std::uint64_t> collapsedIn(parts.size(), 0);
        forEachChunk(candidates.size(), [&](std::size_t c, std::size_t b, std::size_t e) {
            LoopCleaner cleaner;
            std::vector<std::uint32_t> poly;
            for (std::size_t k = b; k < e; ++k) {
                const std::uint32_t f = candidates[k];
                poly.clear();
                for (std::uint32_t i = mesh.offsets[f]; i < mesh.offsets[f + 1]; ++i) poly.push_back(weld.target(mesh.indices[i]));
                const std::size_t before = parts[c].count();
                cleaner.emit(poly, parts[c]);
                loopsOf[k] = std::uint32_t(parts[c].count() - before);
            }
            collapsedIn[c] = cleaner.collapsed;
        });
        const Loops loops = joinLoops(parts);
        parts.clear();
        std::vector<std::uint32_t> firstLoop(candidates.size() + 1, 0);
        for (std::size_t k = 0; k < candidates.size(); ++k) firstLoop[k + 1] = firstLoop[k] + loopsOf[k];

        // A node whose vertices only rounded to it and whose polygons all collapse is a closed
        // piece of its own, shrunk to the node's point: a node inside by a rounding error, alone
        // on its side (a ball whose surface passes through it). Welded, the piece would vanish,
        // and with it the only sign of a part that the thin search, which skips the cells around
        // such a node, does not find; it keeps its vertices, as before rounding counted. (Pieces
        // that collapse onto feature nodes and data nodes at the iso value are bubbles: they go.)
        bool vanished = false;
        {
            std::vector<std::uint8_t> survives(slots, 0);
            for (std::uint32_t v : loops.indices)
                if (weld.isRep(v)) survives[slot[v]] = 1;
            for (std::uint32_t rep : repOf)
                if (weld.isRep(rep) && onlyRounded[slot[rep]] && !survives[slot[rep]]) apart[slot[rep]] = 1, vanished = true;
        }
        // One end of each bad edge first; from the fourth attempt on, both (as few attempts as
        // before where keeping one apart moves the problem to the next node).
        const bool bad = markNonManifoldWelds(loops, weld, slot, slots, selfPolygons, attempt < 4, apart) || vanished;
        if (bad && attempt < 12) continue;
        if (bad) throw std::logic_error("lattice surface: welding iso nodes left a non-manifold edge");

        // Edge-manifold now, so a reversed pair is a closed piece of its own.
        std::vector<std::uint8_t> pillow;
        std::uint64_t collapsed = markReversedPairs(loops, weld, pillow);
        for (std::uint64_t c : collapsedIn) collapsed += c;
        std::vector<std::uint32_t> fromCandidates;
        const std::vector<std::uint32_t> newId =
            replaceCandidates(mesh, candidates, firstLoop, loops, pillow, slot, polygonsToWeld != nullptr, fromCandidates);
        stats.weldedVertices = welded;
        stats.collapsedPolygons = collapsed;
        // A welded node where separate sheets touch (two blobs meeting exactly at an iso node, a
        // feature node between two fans) gets one vertex per fan: the mesh stays vertex-manifold.
        // Welded vertices lie on polygons that came from candidates alone.
        std::vector<std::uint32_t> welds;
        for (std::uint32_t rep : repOf)
            if (weld.isRep(rep) && newId[rep] != kNone) welds.push_back(newId[rep]);
        const std::size_t beforeSplit = mesh.points.size();
        for (const auto& [v, node] : atNode) slot[v] = kNone; // (every entry kNone now: the fans' scratch)
        stats.splitVertices = splitFansAt(mesh, welds, &fromCandidates, &slot);
        // What is left on a node's point: its vertices kept apart, the copies of a split one.
        for (std::uint32_t& v : suspects) v = newId[v]; // (kNone where gone: skipped)
        suspects.insert(suspects.end(), welds.begin(), welds.end());
        for (std::size_t v = beforeSplit; v < mesh.points.size(); ++v) suspects.push_back(std::uint32_t(v));
        stats.separatedVertices = separateCoincidentPoints(mesh, std::move(suspects));
        // Where the polygons between two others at a vertex collapsed, those two can close its
        // fan alone, folded onto each other; only polygons that came from candidates can.
        const FoldStats folds = closeFolds(mesh, std::move(fromCandidates), slot);
        stats.collapsedPolygons += folds.removedPolygons;
        stats.foldsClosed = folds.closed;
        return stats;
    }
}

} // namespace

NodeGroups groupByNode(const std::vector<std::pair<std::uint32_t, Vec3i>>& atNode) {
    NodeGroups groups;
    if (!atNode.empty()) groups.representative = representatives(atNode, groups.listed);
    return groups;
}

std::vector<std::uint32_t> verticesToWeld(const std::vector<std::pair<std::uint32_t, Vec3i>>& atNode, const NodeGroups& groups) {
    std::vector<std::uint32_t> out;
    for (std::size_t k = 0; k < atNode.size(); ++k)
        if (groups.listed[k] >= 2) out.push_back(atNode[k].first);
    std::sort(out.begin(), out.end());
    return out;
}

std::vector<std::uint32_t> verticesToWeld(const std::vector<std::pair<std::uint32_t, Vec3i>>& atNode) {
    return verticesToWeld(atNode, groupByNode(atNode));
}

NodeWeldStats weldNodeVertices(Mesh& mesh, const std::vector<std::pair<std::uint32_t, Vec3i>>& atNode,
                               const std::vector<std::uint8_t>& rounded, const std::vector<std::uint32_t>& alsoSuspect,
                               const std::vector<std::uint32_t>* polygonsToWeld, const NodeGroups* groups) {
    std::vector<std::uint32_t> suspects = alsoSuspect;
    for (const auto& [v, node] : atNode) suspects.push_back(v);
    if (atNode.empty()) {
        NodeWeldStats stats;
        stats.separatedVertices = separateCoincidentPoints(mesh, std::move(suspects));
        return stats;
    }
    const NodeGroups found = groups ? NodeGroups() : groupByNode(atNode);
    if (groups && (groups->representative.size() != atNode.size() || groups->listed.size() != atNode.size()))
        throw std::logic_error("weldNodeVertices: the node groups are not atNode's");
    const std::vector<std::uint32_t>& repOf = groups ? groups->representative : found.representative;
    const std::vector<std::uint32_t>& listed = groups ? groups->listed : found.listed;
    // A node with one vertex has nothing to weld: left out, the attempts touch only the polygons
    // around nodes with several (where a box's faces lie on node planes, every crossing on a face
    // rounds to a node, one a node but for the edges and corners).
    std::vector<std::pair<std::uint32_t, Vec3i>> several;
    std::vector<std::uint32_t> severalRep;
    std::vector<std::uint8_t> severalRounded;
    for (std::size_t k = 0; k < atNode.size(); ++k) {
        if (listed[k] < 2) continue;
        several.push_back(atNode[k]);
        severalRep.push_back(repOf[k]);
        if (!rounded.empty()) severalRounded.push_back(rounded[k]);
    }
    return weldSeveral(mesh, several, severalRep, severalRounded, std::move(suspects), polygonsToWeld);
}

} // namespace vdbsurf
