#include "vdbsurf/reeb/reeb_graph.h"
#include "vdbsurf/mesh/mesh.h"

#include "vdbsurf/core/union_find.h"

#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <stdexcept>

namespace vdbsurf::reeb {

const char* criticalTypeName(CriticalType t) {
    switch (t) {
    case CriticalType::Minimum: return "minimum";
    case CriticalType::Maximum: return "maximum";
    case CriticalType::Saddle: return "saddle";
    default: return "regular";
    }
}

double Lobe::length() const {
    double l = 0;
    for (std::size_t i = 1; i < points.size(); ++i) l += vdbsurf::length(points[i] - points[i - 1]);
    return l;
}

std::vector<ReebNode> criticalPoints(const ClosedSurface& s, const HeightFunction& f) {
    const std::size_t n = s.points.size();
    std::vector<CriticalType> type(n, CriticalType::Regular);
    std::vector<int> multiplicity(n, 1);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 4096), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t v = r.begin(); v != r.end(); ++v) {
            const std::uint32_t first = s.vertexCorner[v];
            std::uint32_t c = first, degree = 0, upper = 0, changes = 0;
            bool firstUp = false, lastUp = false;
            do {
                const bool up = f.rank[s.vertex[ClosedSurface::next(c)]] > f.rank[v];
                if (degree == 0) firstUp = up;
                else if (up != lastUp) ++changes;
                lastUp = up;
                upper += up;
                ++degree;
                c = s.around(c);
            } while (c != first);
            if (lastUp != firstUp) ++changes;
            if (upper == 0) type[v] = CriticalType::Maximum;
            else if (upper == degree) type[v] = CriticalType::Minimum;
            else if (changes > 2) {
                type[v] = CriticalType::Saddle;
                multiplicity[v] = int(changes / 2) - 1;
            }
        }
    });
    std::vector<ReebNode> nodes;
    long index = 0;
    for (std::uint32_t v : f.byRank) {
        if (type[v] == CriticalType::Regular) continue;
        ReebNode node;
        node.type = type[v];
        node.multiplicity = multiplicity[v];
        node.vertex = v;
        node.rank = f.rank[v];
        node.height = f.height[v];
        node.position = s.points[v];
        index += node.type == CriticalType::Saddle ? -node.multiplicity : 1;
        nodes.push_back(node);
    }
    if (index != s.eulerCharacteristic())
        throw std::logic_error("critical points: minima - saddles + maxima = " + std::to_string(index) +
                               " but the Euler characteristic is " + std::to_string(s.eulerCharacteristic()));
    return nodes;
}

namespace {

struct Crossing {
    std::uint32_t edge, level; // level: rank of the saddle
    Vec3d position;
};

// The pieces of the cut surface: polygons over global point ids (surface vertices, then
// crossings), each inside one triangle.
struct Pieces {
    std::vector<std::uint32_t> offsets{0}, indices, triangle;
    std::size_t count() const { return triangle.size(); }
};

// A unit's end at a saddle is one loop through the saddle, once per lobe: the contour just
// beside the saddle's level, which follows each lobe and, at the saddle, turns into the lobe
// that starts across the sector of the unit's side next to where the lobe ended. Around the
// saddle (in `around` order, the link running a, b, ... for triangle (s, a, b)) the lobes' ends
// alternate: a start where the link falls from above to below, an end where it climbs back; so
// the sector after a lobe's end lies above and leads to the start after it, the sector before
// the end lies below and leads to the start before it. With two lobes either order is that loop;
// with three or more (a saddle of multiplicity 2 or more) the lobes taken in index order could
// pair a lobe's end with the wrong start on one side, and the patches of the units above and
// below then met at the saddle in separate fans (a non-manifold preview vertex on a gyroid).
// Orders each unit's bottomLobes and topLobes so; a saddle whose ends do not alternate keeps
// the index order.
void orderLobesAlongContours(const ClosedSurface& s, ReebGraph& g, const std::vector<std::uint32_t>& startTriangle,
                             const std::vector<std::uint32_t>& endTriangle) {
    const std::uint32_t none = ~0u;
    std::vector<std::uint32_t> nextAbove(g.lobes.size(), none), nextBelow(g.lobes.size(), none);
    std::vector<std::uint32_t> lobesAt(g.nodes.size(), 0);
    for (const Lobe& lobe : g.lobes) ++lobesAt[lobe.node];
    // Lobes of each saddle by start and end triangle.
    std::vector<std::pair<std::uint32_t, std::uint32_t>> starts, ends; // (triangle, lobe)
    for (std::uint32_t li = 0; li < g.lobes.size(); ++li) {
        starts.push_back({startTriangle[li], li});
        ends.push_back({endTriangle[li], li});
    }
    std::sort(starts.begin(), starts.end());
    std::sort(ends.begin(), ends.end());
    auto lobeIn = [](const std::vector<std::pair<std::uint32_t, std::uint32_t>>& byTriangle, std::uint32_t t, std::uint32_t node,
                     const ReebGraph& graph) {
        for (auto it = std::lower_bound(byTriangle.begin(), byTriangle.end(), std::make_pair(t, 0u)); it != byTriangle.end() && it->first == t; ++it)
            if (graph.lobes[it->second].node == node) return it->second;
        return ~0u;
    };
    for (std::uint32_t ni = 0; ni < g.nodes.size(); ++ni) {
        if (lobesAt[ni] < 3) continue;
        // The lobes' starts (+1 + lobe) and ends (-1 - lobe) round the saddle, in order.
        std::vector<std::int64_t> events;
        const std::uint32_t first = s.vertexCorner[g.nodes[ni].vertex];
        std::uint32_t c = first;
        do {
            const std::uint32_t t = c / 3;
            if (const std::uint32_t l = lobeIn(starts, t, ni, g); l != none) events.push_back(std::int64_t(l) + 1);
            if (const std::uint32_t l = lobeIn(ends, t, ni, g); l != none) events.push_back(-std::int64_t(l) - 1);
            c = s.around(c);
        } while (c != first);
        const std::size_t n = events.size();
        bool alternate = n == 2 * std::size_t(lobesAt[ni]);
        for (std::size_t i = 0; i < n && alternate; ++i) alternate = (events[i] > 0) != (events[(i + 1) % n] > 0);
        if (!alternate) continue;
        for (std::size_t i = 0; i < n; ++i) {
            if (events[i] > 0) continue;
            const std::uint32_t ended = std::uint32_t(-events[i] - 1);
            nextAbove[ended] = std::uint32_t(events[(i + 1) % n] - 1);
            nextBelow[ended] = std::uint32_t(events[(i + n - 1) % n] - 1);
        }
    }
    // Each end list as the loop the successors make, from its first lobe; unchanged unless they
    // make one loop through all of it.
    auto order = [&](std::vector<std::uint32_t>& lobes, const std::vector<std::uint32_t>& next) {
        if (lobes.size() < 3) return;
        std::vector<std::uint32_t> loop{lobes.front()};
        while (loop.size() <= lobes.size()) {
            const std::uint32_t l = next[loop.back()];
            if (l == none || l == loop.front()) break;
            loop.push_back(l);
        }
        if (loop.size() != lobes.size() || next[loop.back()] != loop.front()) return;
        std::vector<std::uint32_t> sortedLoop(loop), sortedLobes(lobes);
        std::sort(sortedLoop.begin(), sortedLoop.end());
        std::sort(sortedLobes.begin(), sortedLobes.end());
        if (sortedLoop == sortedLobes) lobes = std::move(loop);
    };
    for (Unit& unit : g.units) {
        order(unit.bottomLobes, nextAbove);
        order(unit.topLobes, nextBelow);
    }
}

} // namespace

ReebGraph buildReebGraph(const ClosedSurface& s, const HeightFunction& f) {
    ReebGraph g;
    g.axis = f.axis;
    g.eulerCharacteristic = s.eulerCharacteristic();
    g.components = s.components;
    g.nodes = criticalPoints(s, f);
    const std::uint32_t nV = std::uint32_t(s.points.size());
    std::vector<std::uint32_t> nodeOfVertex(nV, ~0u);
    for (std::uint32_t i = 0; i < g.nodes.size(); ++i) {
        nodeOfVertex[g.nodes[i].vertex] = i;
        const CriticalType t = g.nodes[i].type;
        if (t == CriticalType::Minimum) ++g.minima;
        else if (t == CriticalType::Maximum) ++g.maxima;
        else g.saddles += std::size_t(g.nodes[i].multiplicity);
    }

    // 1. Trace each saddle's critical contour, one lobe per outgoing branch. In a triangle the
    // contour runs from where the boundary (in corner order) climbs through the level to where it
    // falls through it; at the saddle s, a triangle (s, a, b) with a above and b below starts one.
    std::vector<Crossing> crossings;
    std::vector<std::uint32_t> lobeStartTriangle, lobeEndTriangle, lobeFirstCrossing;
    for (std::uint32_t ni = 0; ni < g.nodes.size(); ++ni) {
        if (g.nodes[ni].type != CriticalType::Saddle) continue;
        const std::uint32_t sv = g.nodes[ni].vertex, level = g.nodes[ni].rank;
        const std::uint32_t first = s.vertexCorner[sv];
        std::uint32_t c = first;
        do {
            const std::uint32_t a = s.vertex[ClosedSurface::next(c)], b = s.vertex[ClosedSurface::prev(c)];
            if (f.rank[a] > level && f.rank[b] < level) {
                Lobe lobe;
                lobe.node = ni;
                lobe.points.push_back(s.points[sv]);
                std::uint32_t cc = ClosedSurface::next(c); // a -> b, falling through the level
                lobeFirstCrossing.push_back(std::uint32_t(crossings.size()));
                for (std::size_t steps = 0;; ++steps) {
                    if (steps > s.vertex.size()) throw std::logic_error("reeb: a critical contour does not close");
                    const std::uint32_t va = s.vertex[cc], vb = s.vertex[ClosedSurface::next(cc)];
                    const double t = levelParameter(f, sv, va, vb);
                    const Vec3d p = s.points[va] + (s.points[vb] - s.points[va]) * t;
                    crossings.push_back({s.edgeOf[cc], level, p});
                    lobe.points.push_back(p);
                    const std::uint32_t o = s.opposite[cc]; // vb -> va: climbing in the next triangle
                    const std::uint32_t d = s.vertex[ClosedSurface::prev(o)];
                    if (d == sv) {
                        lobeEndTriangle.push_back(o / 3);
                        break;
                    }
                    cc = f.rank[d] > level ? ClosedSurface::prev(o) : ClosedSurface::next(o);
                }
                lobe.points.push_back(s.points[sv]);
                g.lobes.push_back(std::move(lobe));
                lobeStartTriangle.push_back(c / 3);
            }
            c = s.around(c);
        } while (c != first);
    }

    // 2. Crossings by edge, in level order: point id nV + index.
    std::vector<std::uint32_t> order(crossings.size());
    for (std::uint32_t i = 0; i < order.size(); ++i) order[i] = i;
    tbb::parallel_sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) {
        return crossings[a].edge != crossings[b].edge ? crossings[a].edge < crossings[b].edge : crossings[a].level < crossings[b].level;
    });
    std::vector<std::uint32_t> edgeStart(s.edgeCount + 1, 0);
    for (const Crossing& x : crossings) ++edgeStart[x.edge + 1];
    for (std::size_t e = 0; e < s.edgeCount; ++e) edgeStart[e + 1] += edgeStart[e];
    std::vector<Vec3d> points(s.points);
    std::vector<std::uint32_t> key(f.rank);
    points.reserve(nV + crossings.size());
    key.reserve(nV + crossings.size());
    for (std::uint32_t i : order) {
        points.push_back(crossings[i].position);
        key.push_back(crossings[i].level);
    }
    std::vector<std::uint32_t> crossingId(crossings.size());
    for (std::uint32_t k = 0; k < order.size(); ++k) crossingId[order[k]] = nV + k;

    // 3. Cut every triangle along the levels crossing its edges into strips.
    Pieces pieces;
    std::vector<std::uint32_t> trianglePieces(s.triangleCount() + 1, 0);
    std::vector<std::uint32_t> ring, levels;
    for (std::uint32_t t = 0; t < s.triangleCount(); ++t) {
        ring.clear();
        levels.clear();
        for (std::uint32_t k = 0; k < 3; ++k) {
            const std::uint32_t c = 3 * t + k;
            const std::uint32_t a = s.vertex[c], b = s.vertex[ClosedSurface::next(c)];
            ring.push_back(a);
            const std::uint32_t e = s.edgeOf[c], lo = edgeStart[e], hi = edgeStart[e + 1];
            if (f.rank[a] < f.rank[b])
                for (std::uint32_t x = lo; x < hi; ++x) ring.push_back(nV + x);
            else
                for (std::uint32_t x = hi; x-- > lo;) ring.push_back(nV + x);
            for (std::uint32_t x = lo; x < hi; ++x) levels.push_back(key[nV + x]);
        }
        if (levels.empty()) {
            pieces.indices.insert(pieces.indices.end(), ring.begin(), ring.end());
            pieces.offsets.push_back(std::uint32_t(pieces.indices.size()));
            pieces.triangle.push_back(t);
        } else {
            std::sort(levels.begin(), levels.end());
            levels.erase(std::unique(levels.begin(), levels.end()), levels.end());
            for (std::size_t i = 0; i <= levels.size(); ++i) {
                const std::int64_t lo = i == 0 ? -1 : std::int64_t(levels[i - 1]);
                const std::int64_t hi = i == levels.size() ? std::int64_t(key.size()) + 1 : std::int64_t(levels[i]);
                const std::size_t before = pieces.indices.size();
                for (std::uint32_t p : ring)
                    if (std::int64_t(key[p]) >= lo && std::int64_t(key[p]) <= hi) pieces.indices.push_back(p);
                if (pieces.indices.size() - before >= 3) {
                    pieces.offsets.push_back(std::uint32_t(pieces.indices.size()));
                    pieces.triangle.push_back(t);
                } else {
                    pieces.indices.resize(before);
                }
            }
        }
        trianglePieces[t + 1] = std::uint32_t(pieces.count());
    }

    // 4. Pieces sharing a stretch of an input edge belong to one unit; cut segments (both ends on
    // one level) separate units.
    std::vector<std::pair<std::uint64_t, std::uint32_t>> sides;
    sides.reserve(pieces.indices.size());
    for (std::uint32_t p = 0; p < pieces.count(); ++p)
        for (std::uint32_t k = pieces.offsets[p]; k < pieces.offsets[p + 1]; ++k) {
            const std::uint32_t a = pieces.indices[k], b = pieces.indices[k + 1 == pieces.offsets[p + 1] ? pieces.offsets[p] : k + 1];
            if (key[a] == key[b]) continue;
            sides.push_back({undirectedEdgeKey(a, b), p});
        }
    tbb::parallel_sort(sides.begin(), sides.end());
    UnionFind uf(pieces.count());
    for (std::size_t i = 1; i < sides.size(); ++i)
        if (sides[i].first == sides[i - 1].first) uf.unite(sides[i].second, sides[i - 1].second);
    std::vector<std::uint32_t> unitOfRoot(pieces.count(), ~0u), unitOf(pieces.count());
    std::uint32_t unitCount = 0;
    for (std::uint32_t p = 0; p < pieces.count(); ++p) {
        std::uint32_t& u = unitOfRoot[uf.find(p)];
        if (u == ~0u) u = unitCount++;
        unitOf[p] = u;
    }

    // 5. Each unit as its own mesh; its lowest and highest keys are its arc's ends.
    g.units.resize(unitCount);
    std::vector<std::vector<std::uint32_t>> piecesOf(unitCount);
    for (std::uint32_t p = 0; p < pieces.count(); ++p) piecesOf[unitOf[p]].push_back(p);
    std::vector<std::uint32_t> local(points.size(), ~0u);
    for (std::uint32_t u = 0; u < unitCount; ++u) {
        Unit& unit = g.units[u];
        std::uint32_t lowKey = ~0u, highKey = 0;
        std::vector<std::uint32_t> used;
        for (std::uint32_t p : piecesOf[u]) {
            const std::uint32_t b = pieces.offsets[p], e = pieces.offsets[p + 1];
            for (std::uint32_t k = b; k < e; ++k) {
                const std::uint32_t id = pieces.indices[k];
                if (local[id] == ~0u) {
                    local[id] = std::uint32_t(unit.points.size());
                    unit.points.push_back(points[id]);
                    used.push_back(id);
                    if (id < nV) ++unit.inputVertices;
                }
                unit.indices.push_back(local[id]);
                lowKey = std::min(lowKey, key[id]);
                highKey = std::max(highKey, key[id]);
            }
            unit.offsets.push_back(std::uint32_t(unit.indices.size()));
            const Vec3d& o = points[pieces.indices[b]];
            for (std::uint32_t k = b + 1; k + 1 < e; ++k)
                unit.area += 0.5 * vdbsurf::length(cross(points[pieces.indices[k]] - o, points[pieces.indices[k + 1]] - o));
            unit.inputPolygons.push_back(s.polygon[pieces.triangle[p]]);
        }
        for (std::uint32_t id : used) local[id] = ~0u;
        std::sort(unit.inputPolygons.begin(), unit.inputPolygons.end());
        unit.inputPolygons.erase(std::unique(unit.inputPolygons.begin(), unit.inputPolygons.end()), unit.inputPolygons.end());
        unit.lower = nodeOfVertex[f.byRank[lowKey]];
        unit.upper = nodeOfVertex[f.byRank[highKey]];
        if (unit.lower == ~0u || unit.upper == ~0u || g.nodes[unit.lower].type == CriticalType::Maximum ||
            g.nodes[unit.upper].type == CriticalType::Minimum)
            throw std::logic_error("reeb: a unit does not run from a critical point up to another");
    }

    // 6. The units on either side of each lobe, from the two pieces beside its first segment.
    for (std::uint32_t li = 0; li < g.lobes.size(); ++li) {
        Lobe& lobe = g.lobes[li];
        const std::uint32_t sv = g.nodes[lobe.node].vertex, level = g.nodes[lobe.node].rank;
        const std::uint32_t x1 = crossingId[lobeFirstCrossing[li]];
        const std::uint32_t t = lobeStartTriangle[li];
        for (std::uint32_t p = trianglePieces[t]; p < trianglePieces[t + 1]; ++p) {
            const auto b = pieces.indices.begin() + pieces.offsets[p], e = pieces.indices.begin() + pieces.offsets[p + 1];
            if (std::find(b, e, sv) == e || std::find(b, e, x1) == e) continue;
            const bool below = std::any_of(b, e, [&](std::uint32_t id) { return key[id] < level; });
            (below ? lobe.unitBelow : lobe.unitAbove) = unitOf[p];
        }
        if (lobe.unitBelow == ~0u || lobe.unitAbove == ~0u) throw std::logic_error("reeb: a lobe lacks a unit on one side");
        g.units[lobe.unitAbove].bottomLobes.push_back(li);
        g.units[lobe.unitBelow].topLobes.push_back(li);
    }
    orderLobesAlongContours(s, g, lobeStartTriangle, lobeEndTriangle);
    return g;
}

} // namespace vdbsurf::reeb
