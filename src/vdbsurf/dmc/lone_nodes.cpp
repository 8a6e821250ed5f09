#include "vdbsurf/dmc/lone_nodes.h"

#include "vdbsurf/core/cancel.h"
#include "vdbsurf/dmc/edge_runs.h"
#include "vdbsurf/dmc/inside_topology.h"
#include "vdbsurf/dmc/lattice_deformation.h"
#include "vdbsurf/dmc/thin_search.h"
#include "vdbsurf/lattice/lattice.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <climits>
#include <cmath>
#include <optional>

namespace vdbsurf {

using openvdb::Coord;

namespace {

// Offsets of the points of a 3x3x3 block from its centre.
Coord blockOffset(int i) { return Coord(i % 3 - 1, (i / 3) % 3 - 1, i / 9 - 1); }

// Segment sampling at steps shorter than a search step (h/k), as the thin search's.
int stepsAlong(const Vec3d& a, const Vec3d& b, double h, int searchSteps) {
    return std::max(2, int(std::ceil(length(b - a) / h * (searchSteps + 1))));
}

struct Join {
    Coord corner;
    Vec3f offset;
};

// A face of a lone node with an inside node across its diagonal: its two outside corners, and the
// value and place of the field's bilinear saddle on it (face coordinates u towards ea, v towards
// eb, the lone node at (0, 0)). Values g are below zero inside.
struct SaddleFace {
    double value, u, v;
    Coord ea, eb;
};

// The face's saddle, from the values at the lone node, its corners ea and eb, and the node across.
SaddleFace saddleOf(double gn, double ga, double gb, double gd, const Coord& ea, const Coord& eb) {
    const double den = gn - ga - gb + gd; // < 0: n and d inside, a and b not
    return {(gn * gd - ga * gb) / den, (gn - gb) / den, (gn - ga) / den, ea, eb};
}

// The points of the quarter [u0, u0 + 1/2] x [v0, v0 + 1/2] of face f (one outside corner's Ω) to
// try, nearest the saddle first: the quarter's point nearest it, then an m x m grid of points.
std::vector<std::pair<double, double>> quarterPoints(const SaddleFace& f, double u0, double v0, int m) {
    std::vector<std::pair<double, std::pair<double, double>>> byDistance;
    for (int i = 0; i < m; ++i)
        for (int j = 0; j < m; ++j) {
            const double u = u0 + 0.5 * (i + 0.5) / m, v = v0 + 0.5 * (j + 0.5) / m;
            byDistance.push_back({(u - f.u) * (u - f.u) + (v - f.v) * (v - f.v), {u, v}});
        }
    std::stable_sort(byDistance.begin(), byDistance.end(), [](const auto& x, const auto& y) { return x.first < y.first; });
    std::vector<std::pair<double, double>> points{{std::clamp(f.u, u0, u0 + 0.5), std::clamp(f.v, v0, v0 + 0.5)}};
    for (const auto& p : byDistance) points.push_back(p.second);
    return points;
}

class LoneJoiner {
public:
    LoneJoiner(const Field& field, const Lattice& lattice, const ThinSearchOptions& options)
        : mField(field), mFrame(lattice.frame), mIso(options.iso), mSide(field.inside()), mSteps(options.steps),
          mEdgeRuns(field, lattice, options.iso, options.steps) {}

    // The join for lone node n with the nodes where `nodes` puts them, if any.
    std::optional<Join> propose(const Coord& n, NodeStates& nodes, std::uint64_t& evaluated) const {
        std::array<double, 125> rest;
        mField.sampleNodes(mFrame, Vec3i(n.x() - 2, n.y() - 2, n.z() - 2), {5, 5, 5}, nullptr, rest.data());
        evaluated += rest.size();
        auto at = [&](const Coord& o) { return std::size_t((o.x() + 2) + 5 * (o.y() + 2) + 25 * (o.z() + 2)); };
        auto moved = [&](const Coord& o) { return nodes.offsets.isValueOn(n + o) || nodes.onSurface.isValueOn(n + o); };
        auto insideNow = [&](const Coord& o) { return nodes.inside(n + o, isInside(rest[at(o)], mIso, mSide)); };
        // Below zero inside, whichever side the field calls inside.
        const double sign = mSide == Inside::Below ? 1.0 : -1.0;
        auto g = [&](double v) { return sign * (v - mIso); };
        const Coord origin(0, 0, 0);
        if (moved(origin) || !insideNow(origin)) return std::nullopt;
        for (int k = 0; k < 6; ++k)
            if (insideNow(axisStep(k / 2, k % 2 ? 1 : -1))) return std::nullopt;

        std::vector<SaddleFace> faces;
        for (int a = 0; a < 3; ++a)
            for (int b = a + 1; b < 3; ++b)
                for (int sa = -1; sa <= 1; sa += 2)
                    for (int sb = -1; sb <= 1; sb += 2) {
                        const Coord ea = axisStep(a, sa), eb = axisStep(b, sb), d = ea + eb;
                        if (!insideNow(d) || moved(d) || moved(ea) || moved(eb)) continue;
                        const SaddleFace f = saddleOf(g(rest[at(origin)]), g(rest[at(ea)]), g(rest[at(eb)]), g(rest[at(d)]), ea, eb);
                        if (f.value < 0) faces.push_back(f);
                    }
        // Deepest saddle first; ties in the order above.
        std::stable_sort(faces.begin(), faces.end(), [](const SaddleFace& x, const SaddleFace& y) { return x.value < y.value; });

        const Vec3d nWorld = mFrame.nodeWorld(Vec3i(n.x(), n.y(), n.z()));
        const double h = mFrame.h;
        auto world = [&](const Coord& o) { return nWorld + Vec3d(o.x(), o.y(), o.z()) * h; };
        auto insideAlong = [&](const Vec3d& p, const Vec3d& q) {
            const int steps = stepsAlong(p, q, h, mSteps);
            for (int s = 1; s < steps; ++s) {
                ++evaluated;
                if (!isInside(mField.value(p + (q - p) * (double(s) / steps)), mIso, mSide)) return false;
            }
            return true;
        };
        for (const SaddleFace& f : faces) {
            const Coord d = f.ea + f.eb;
            // Each outside corner may move within its quarter of the face (its Ω): the corner
            // whose quarter holds the saddle, or lies nearer it, first.
            struct Corner {
                Coord offset;
                double u0, v0; // its quarter: [u0, u0 + 1/2] x [v0, v0 + 1/2]
                double distance;
            };
            auto quarterDistance = [&](double u0, double v0) {
                const double du = std::max({u0 - f.u, 0.0, f.u - (u0 + 0.5)}), dv = std::max({v0 - f.v, 0.0, f.v - (v0 + 0.5)});
                return du * du + dv * dv;
            };
            std::array<Corner, 2> corners{Corner{f.ea, 0.5, 0.0, quarterDistance(0.5, 0.0)}, Corner{f.eb, 0.0, 0.5, quarterDistance(0.0, 0.5)}};
            if (corners[1].distance < corners[0].distance) std::swap(corners[0], corners[1]);
            for (const Corner& c : corners) {
                if (!joinsWithoutOtherChange(c.offset, insideNow)) continue;
                const Vec3d cornerWorld = world(c.offset);
                const Vec3d ea(f.ea.x(), f.ea.y(), f.ea.z()), eb(f.eb.x(), f.eb.y(), f.eb.z());
                for (const auto& [u, v] : quarterPoints(f, c.u0, c.v0, mSteps)) {
                    const Vec3d target = nWorld + (ea * u + eb * v) * h;
                    const std::optional<Vec3f> offset = offsetInOmega(target - cornerWorld, h);
                    if (!offset) continue;
                    const Vec3d to = cornerWorld + Vec3d(*offset);
                    ++evaluated;
                    if (!isInside(mField.value(to), mIso, mSide) || !insideAlong(nWorld, to) || !insideAlong(to, world(d))) continue;
                    std::uint64_t examined = 0;
                    if (!mEdgeRuns.moveEffect(n + c.offset, false, to, nodes, examined, evaluated).keeps) continue;
                    return Join{n + c.offset, *offset};
                }
            }
        }
        return std::nullopt;
    }

private:
    // Does putting the outside node at offset c (a neighbour of the lone node at the origin)
    // inside join the node's bubble to the rest and change nothing else (joinsBubbleOnly)?
    template <typename InsideNow> static bool joinsWithoutOtherChange(const Coord& c, const InsideNow& insideNow) {
        bool around[27];
        int lone = -1;
        for (int i = 0; i < 27; ++i) {
            const Coord o = c + blockOffset(i);
            around[i] = insideNow(o);
            if (o == Coord(0, 0, 0)) lone = i;
        }
        return joinsBubbleOnly(around, lone);
    }

    const Field& mField;
    const LatticeFrame& mFrame;
    double mIso;
    Inside mSide;
    int mSteps;
    EdgeRuns mEdgeRuns;
};

// Could a join moved at corner `m` change what propose decides for lone node n? It reads the
// nodes within two steps of n, and the corner's move checks reach three steps from the corner.
constexpr int kNear = 4;
bool near(const Coord& n, const Coord& m) {
    const Coord d = n - m;
    return std::max({std::abs(d.x()), std::abs(d.y()), std::abs(d.z())}) <= kNear;
}

} // namespace

bool joinsBubbleOnly(const bool inside[27], int lone) {
    if (lone < 0 || lone >= 27 || lone == 13 || !inside[lone]) return false;
    const Coord o = blockOffset(lone);
    if (std::abs(o.x()) + std::abs(o.y()) + std::abs(o.z()) != 1) return false;
    // The centre's other inside neighbours across faces must lie in one piece of the block: the
    // centre then joins that piece and the node's, not two ends of one piece (a handle); and the
    // inside's Euler characteristic drops by the bubble's 1, unless the centre also closes a
    // handle or fills a cavity.
    return insidePiecesAtCentre(inside, lone) == 1 && insideEulerChange(inside) == -1;
}

std::vector<Vec3i> joinLoneNodes(const Field& field, const Lattice& lattice, const ThinSearchOptions& options,
                                 LatticeDeformation& deformation, std::uint64_t* samples) {
    const std::vector<Coord>& lone = lattice.loneInsideNodes;
    std::vector<Vec3i> joined;
    if (lone.empty()) return joined;
    const LoneJoiner joiner(field, lattice, options);
    std::vector<std::optional<Join>> proposals(lone.size());
    tbb::enumerable_thread_specific<std::uint64_t> evaluated(0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, lone.size(), 16), [&](const tbb::blocked_range<std::size_t>& r) {
        NodeStates nodes(deformation);
        std::uint64_t& count = evaluated.local();
        for (std::size_t i = r.begin(); i < r.end(); ++i) proposals[i] = joiner.propose(lone[i], nodes, count);
    });
    std::uint64_t total = 0;
    for (std::uint64_t e : evaluated) total += e;
    openvdb::tree::ValueAccessor<OffsetTree> acc(*deformation.offsets);
    std::vector<std::uint8_t> stale(lone.size(), 0); // near a join applied before it
    for (std::size_t i = 0; i < lone.size(); ++i) {
        if (options.cancel) options.cancel->check();
        std::optional<Join>& join = proposals[i];
        if (stale[i]) {
            NodeStates nodes(deformation);
            join = joiner.propose(lone[i], nodes, total);
        }
        if (!join) continue;
        const Coord m = join->corner;
        acc.setValue(m, openvdb::Vec3f(join->offset.x, join->offset.y, join->offset.z));
        joined.emplace_back(m.x(), m.y(), m.z());
        // (Lone nodes are in node order: those that may be near lie in a slab of x.)
        const auto first = std::lower_bound(lone.begin() + std::ptrdiff_t(i) + 1, lone.end(), Coord(m.x() - kNear, INT_MIN, INT_MIN));
        const auto last = std::upper_bound(first, lone.end(), Coord(m.x() + kNear, INT_MAX, INT_MAX));
        for (auto it = first; it != last; ++it)
            if (near(*it, m)) stale[std::size_t(it - lone.begin())] = 1;
    }
    if (samples) *samples += total;
    return joined;
}

} // namespace vdbsurf
