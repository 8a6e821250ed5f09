#include "vdbsurf/dmc/lone_nodes.h"

#include "vdbsurf/core/cancel.h"
#include "vdbsurf/dmc/edge_runs.h"
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

// Are points i and j of the block adjacent across a face?
bool adjacent(int i, int j) {
    const Coord d = blockOffset(i) - blockOffset(j);
    return std::abs(d.x()) + std::abs(d.y()) + std::abs(d.z()) == 1;
}

// Steps from the centre to point i: 1 across a face, 2 across an edge, 3 across a corner.
int stepsFromCentre(int i) {
    const Coord o = blockOffset(i);
    return std::abs(o.x()) + std::abs(o.y()) + std::abs(o.z());
}

// The points of `from` (bit i) and those of `within` adjacent to one of them across a face.
std::uint32_t grow(std::uint32_t from, std::uint32_t within) {
    std::uint32_t out = from;
    for (std::uint32_t left = within & ~from; left; left &= left - 1) {
        const int j = __builtin_ctz(left);
        for (std::uint32_t f = from; f; f &= f - 1)
            if (adjacent(__builtin_ctz(f), j)) {
                out |= 1u << j;
                break;
            }
    }
    return out;
}

// Segment sampling at steps shorter than a search step (h/k), as the thin search's.
int stepsAlong(const Vec3d& a, const Vec3d& b, double h, int searchSteps) {
    return std::max(2, int(std::ceil(length(b - a) / h * (searchSteps + 1))));
}

// Inside components of a lattice face or cell with these corners inside (bit i: corner i, its
// bits the offsets along the face's or cell's axes), as marching cubes' table makes them: corners
// joined along edges only.
int cornerComponents(unsigned inside, int dims) {
    const int corners = 1 << dims;
    int count = 0;
    for (unsigned left = inside; left;) {
        ++count;
        unsigned component = left & (~left + 1);
        for (bool grew = true; grew;) {
            grew = false;
            for (int i = 0; i < corners; ++i)
                if ((component >> i & 1u) == 0 && (left >> i & 1u))
                    for (int k = 0; k < dims; ++k)
                        if (component >> (i ^ (1 << k)) & 1u) {
                            component |= 1u << i;
                            grew = true;
                            break;
                        }
        }
        left &= ~component;
    }
    return count;
}

// The compactly supported Euler characteristic of the open inside, over the cells that have the
// block's centre as a corner: the centre, its 6 edges (an interval where either end is inside),
// 12 faces and 8 cells (their components). The inside's own Euler characteristic is its negative.
int starEuler(const bool inside[27]) {
    auto at = [&](int x, int y, int z) { return inside[(x + 1) + 3 * (y + 1) + 9 * (z + 1)]; };
    int euler = at(0, 0, 0);
    for (int k = 0; k < 6; ++k) {
        const Coord e = axisStep(k / 2, k % 2 ? 1 : -1);
        euler -= at(0, 0, 0) || at(e.x(), e.y(), e.z());
    }
    for (int a = 0; a < 3; ++a)
        for (int b = a + 1; b < 3; ++b)
            for (int sa = -1; sa <= 1; sa += 2)
                for (int sb = -1; sb <= 1; sb += 2) {
                    const Coord ea = axisStep(a, sa), eb = axisStep(b, sb), d = ea + eb;
                    const unsigned corners = unsigned(at(0, 0, 0)) | unsigned(at(ea.x(), ea.y(), ea.z())) << 1 |
                                             unsigned(at(eb.x(), eb.y(), eb.z())) << 2 | unsigned(at(d.x(), d.y(), d.z())) << 3;
                    euler += cornerComponents(corners, 2);
                }
    for (int sz = -1; sz <= 1; sz += 2)
        for (int sy = -1; sy <= 1; sy += 2)
            for (int sx = -1; sx <= 1; sx += 2) {
                unsigned corners = 0;
                for (int i = 0; i < 8; ++i) corners |= unsigned(at(i & 1 ? sx : 0, i & 2 ? sy : 0, i & 4 ? sz : 0)) << i;
                euler -= cornerComponents(corners, 3);
            }
    return euler;
}

struct Join {
    Coord corner;
    Vec3f offset;
};

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

        struct Face {
            double saddleValue, u, v; // the bilinear saddle's value and place (u towards ea, v towards eb)
            Coord ea, eb;
        };
        std::vector<Face> faces;
        for (int a = 0; a < 3; ++a)
            for (int b = a + 1; b < 3; ++b)
                for (int sa = -1; sa <= 1; sa += 2)
                    for (int sb = -1; sb <= 1; sb += 2) {
                        const Coord ea = axisStep(a, sa), eb = axisStep(b, sb), d = ea + eb;
                        if (!insideNow(d) || moved(d) || moved(ea) || moved(eb)) continue;
                        const double gn = g(rest[at(origin)]), ga = g(rest[at(ea)]), gb = g(rest[at(eb)]), gd = g(rest[at(d)]);
                        const double den = gn - ga - gb + gd; // < 0: n and d inside, a and b not
                        const double saddle = (gn * gd - ga * gb) / den;
                        if (!(den < 0) || !(saddle < 0)) continue;
                        faces.push_back({saddle, (gn - gb) / den, (gn - ga) / den, ea, eb});
                    }
        // Deepest saddle first; ties in the order above.
        std::stable_sort(faces.begin(), faces.end(), [](const Face& x, const Face& y) { return x.saddleValue < y.saddleValue; });

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
        for (const Face& f : faces) {
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
                // Points of the quarter, the one nearest the saddle first, then a grid of them.
                std::vector<std::pair<double, std::pair<double, double>>> points;
                const double cu = std::clamp(f.u, c.u0, c.u0 + 0.5), cv = std::clamp(f.v, c.v0, c.v0 + 0.5);
                points.push_back({0.0, {cu, cv}});
                for (int i = 0; i < mSteps; ++i)
                    for (int j = 0; j < mSteps; ++j) {
                        const double u = c.u0 + 0.5 * (i + 0.5) / mSteps, v = c.v0 + 0.5 * (j + 0.5) / mSteps;
                        points.push_back({(u - f.u) * (u - f.u) + (v - f.v) * (v - f.v), {u, v}});
                    }
                std::stable_sort(points.begin() + 1, points.end(), [](const auto& x, const auto& y) { return x.first < y.first; });
                const Vec3d cornerWorld = world(c.offset);
                const Vec3d ea(f.ea.x(), f.ea.y(), f.ea.z()), eb(f.eb.x(), f.eb.y(), f.eb.z());
                for (const auto& point : points) {
                    const Vec3d target = nWorld + (ea * point.second.first + eb * point.second.second) * h;
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
    bool state[27];
    std::copy(inside, inside + 27, state);
    if (lone < 0 || lone >= 27 || stepsFromCentre(lone) != 1 || !state[lone]) return false;
    // The centre's other inside neighbours across faces must lie in one piece of the block
    // (joined along edges, around neither the centre nor the node): the centre then joins that
    // piece and the node's, no two ends of one piece (a handle).
    std::uint32_t rest = 0, faces = 0;
    for (int i = 0; i < 27; ++i) {
        if (i == 13 || i == lone || !state[i]) continue;
        rest |= 1u << i;
        if (stepsFromCentre(i) == 1) faces |= 1u << i;
    }
    if (!faces) return false;
    std::uint32_t piece = faces & (~faces + 1);
    for (std::uint32_t next = grow(piece, rest); next != piece; next = grow(piece, rest)) piece = next;
    if ((faces & ~piece) != 0) return false;
    // Two pieces become one: the inside's Euler characteristic drops by the bubble's 1, unless
    // the centre also closes a handle or a cavity of the piece.
    state[13] = false;
    const int before = starEuler(state);
    state[13] = true;
    return starEuler(state) - before == 1;
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
