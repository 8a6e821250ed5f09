#include "vdbsurf/dmc/edge_runs.h"

#include "vdbsurf/dmc/lattice_deformation.h"
#include "vdbsurf/lattice/lattice.h"

#include <algorithm>
#include <cmath>
#include <queue>
#include <tuple>
#include <unordered_set>
#include <utility>
#include <vector>

namespace vdbsurf {

using openvdb::Coord;

NodeStates::NodeStates(const LatticeDeformation& deformation)
    : offsets(*deformation.offsets), onSurface(*deformation.onSurface), insideOnSurface(*deformation.insideOnSurface) {}

EdgeRuns::EdgeRuns(const Field& field, const Lattice& lattice, double iso, int steps)
    : mField(field), mFrame(lattice.frame), mIso(iso), mSide(field.inside()), mSteps(steps), mNodeLo(lattice.cellRange.min()),
      mNodeHi(lattice.cellRange.max().offsetBy(1)) {}

std::vector<EdgeRuns::Run> EdgeRuns::runsAlong(const Vec3d& pa, const Vec3d& pb, bool insideA, bool insideB, int& n,
                                               std::uint64_t& examined, std::uint64_t& evaluated) const {
    n = int(std::floor(length(pb - pa) * mSteps / mFrame.h)) + 1;
    std::vector<Run> runs{{insideA, 0, 0}};
    const Vec3d lo = vmin(pa, pb), hi = vmax(pa, pb);
    if (insideA == insideB && !mField.mayStraddle(Box3{lo, hi}, mIso)) {
        runs.back().last = n;
        return runs;
    }
    ++examined;
    // The samples at once (a formula runs over them together, a grid reads their voxels once):
    // value()'s bits. The box is widened by a hair for the rounding of the points on the segment.
    thread_local std::vector<Vec3d> points;
    thread_local std::vector<double> values;
    points.resize(std::size_t(std::max(n - 1, 0)));
    values.resize(points.size());
    for (int i = 1; i < n; ++i) points[std::size_t(i - 1)] = pa + (pb - pa) * (double(i) / n);
    const double hair = 1e-9 * (mFrame.h + std::max({std::fabs(lo.x), std::fabs(lo.y), std::fabs(lo.z), std::fabs(hi.x), std::fabs(hi.y), std::fabs(hi.z)}));
    mField.values(Box3{lo - Vec3d(hair, hair, hair), hi + Vec3d(hair, hair, hair)}, points.data(), points.size(), values.data());
    evaluated += points.size();
    for (int i = 1; i < n; ++i) {
        const double v = values[std::size_t(i - 1)];
        if (isOtherSide(runs.back().inside, v, mIso, mSide)) runs.push_back({!runs.back().inside, i, i});
        else runs.back().last = i;
    }
    if (runs.back().inside != insideB) runs.push_back({insideB, n, n});
    else runs.back().last = n;
    return runs;
}

std::size_t EdgeRuns::hiddenRuns(const Vec3d& pa, const Vec3d& pb, bool insideA, bool insideB, std::uint64_t& examined,
                                 std::uint64_t& evaluated) const {
    int n = 0;
    return runsAlong(pa, pb, insideA, insideB, n, examined, evaluated).size() - (insideA == insideB ? 1 : 2);
}

bool EdgeRuns::bentPathJoins(const Vec3d& a, const Vec3d& b, bool inside, std::uint64_t& evaluated) const {
    const Vec3d d = b - a;
    const double len = length(d);
    if (len == 0) return true;
    const Vec3d w = d / len;
    const Vec3d u = normalized(cross(w, std::fabs(w.x) < 0.6 ? Vec3d(1, 0, 0) : Vec3d(0, 1, 0)));
    const Vec3d v = cross(w, u);
    for (const double bow : {0.1, 0.2, 0.35, 0.5, 0.75}) {
        // Steps by the path's greatest speed (at its ends, |d| and the bow's 4·bow·h across), so
        // no step is h/k long anywhere: counted by its length instead, a 0.5 or 0.75 bow stepped
        // over a crack h/k wide next to an end and joined the two halves of a ball through it.
        const double speed = std::sqrt(len * len + 16 * bow * bow * mFrame.h * mFrame.h);
        const int n = int(std::ceil(speed * mSteps / mFrame.h)) + 1;
        for (int k = 0; k < 8; ++k) {
            const double angle = k * (M_PI / 4);
            const Vec3d dir = u * std::cos(angle) + v * std::sin(angle);
            bool joined = true;
            for (int i = 1; i < n && joined; ++i) {
                const double t = double(i) / n;
                ++evaluated;
                joined = isOtherSide(!inside, mField.value(a + d * t + dir * (4 * t * (1 - t) * bow * mFrame.h)), mIso, mSide);
            }
            if (joined) return true;
        }
    }
    return false;
}

bool EdgeRuns::joinedNearby(const Vec3d& a, const Vec3d& b, bool inside, std::uint64_t& evaluated, const JoinReach& reach,
                            std::vector<Vec3d>* path) const {
    // Where a and b are joined the search heads almost straight for b: those it confirms (crack
    // rims) take a few dozen samples; a search that has not arrived within the budget's samples
    // per step of the search (a cell is 2k samples across) is taken to have found no path (noisy
    // fog at 3 voxels a cell, with 20 outside: a tenth of the evaluations of a search without a
    // budget, the same cracks kept apart).
    const std::uint64_t kBudget = std::uint64_t(reach.budget) * std::uint64_t(mSteps);
    const std::uint64_t before = evaluated;
    const double step = mFrame.h / (2.0 * mSteps);
    const double margin = reach.margin * mFrame.h;
    // Samples a + step·(i + lo) for i within size: a is one of them; the box holds both ends and margin.
    int lo[3], size[3];
    for (int i = 0; i < 3; ++i) {
        lo[i] = int(std::floor((std::min(a[i], b[i]) - margin - a[i]) / step));
        size[i] = int(std::ceil((std::max(a[i], b[i]) + margin - a[i]) / step)) - lo[i] + 1;
    }
    auto point = [&](int x, int y, int z) { return a + Vec3d(x + lo[0], y + lo[1], z + lo[2]) * step; };
    auto index = [&](int x, int y, int z) { return std::size_t(x) + std::size_t(size[0]) * (std::size_t(y) + std::size_t(size[1]) * std::size_t(z)); };
    auto coordinates = [&](std::size_t i, int& x, int& y, int& z) {
        x = int(i % std::size_t(size[0]));
        y = int((i / std::size_t(size[0])) % std::size_t(size[1]));
        z = int(i / (std::size_t(size[0]) * std::size_t(size[1])));
    };
    // Samples are evaluated when taken from the queue, so a search that heads straight for b
    // evaluates little more than the path. What was queued: a flag a sample of the box (~14 k at
    // the default steps), or a set where the box is large (~50 M samples at --search-steps 64;
    // the budget bounds what is queued).
    const std::size_t boxSamples = std::size_t(size[0]) * std::size_t(size[1]) * std::size_t(size[2]);
    constexpr std::size_t kLargestFlagged = std::size_t(1) << 20;
    std::vector<std::uint8_t> flagged(boxSamples <= kLargestFlagged ? boxSamples : 0, 0);
    std::unordered_set<std::size_t> inSet;
    auto firstQueued = [&](std::size_t i) { // true the first time i is queued
        if (boxSamples > kLargestFlagged) return inSet.insert(i).second;
        if (flagged[i]) return false;
        flagged[i] = 1;
        return true;
    };
    using Entry = std::tuple<double, std::size_t, std::size_t>; // distance to b, index (ties go by it), the sample that queued it
    std::priority_queue<Entry, std::vector<Entry>, std::greater<Entry>> open;
    std::vector<std::pair<std::size_t, std::size_t>> cameFrom; // with `path`: each sample taken, and the one that queued it
    const std::size_t first = index(-lo[0], -lo[1], -lo[2]);
    firstQueued(first);
    open.push({length(b - a), first, first});
    bool atStart = true;
    while (!open.empty()) {
        const std::size_t at = std::get<1>(open.top()), queuedBy = std::get<2>(open.top());
        open.pop();
        if (path) cameFrom.emplace_back(at, queuedBy);
        int x = 0, y = 0, z = 0;
        coordinates(at, x, y, z);
        const Vec3d p = point(x, y, z);
        if (!atStart) {
            if (evaluated - before >= kBudget) return false;
            ++evaluated;
            if (isOtherSide(inside, mField.value(p), mIso, mSide)) continue;
        }
        atStart = false;
        // b within one sample step (every axis): the straight stretch to it, at a few points.
        if (std::fabs(p.x - b.x) <= step && std::fabs(p.y - b.y) <= step && std::fabs(p.z - b.z) <= step) {
            bool straight = true;
            for (int i = 1; i <= 2 && straight; ++i) {
                ++evaluated;
                straight = !isOtherSide(inside, mField.value(p + (b - p) * (i / 3.0)), mIso, mSide);
            }
            if (straight) {
                if (path) {
                    path->assign(1, b);
                    // Back from the last sample taken through the ones that queued each.
                    for (std::size_t i = at;;) {
                        int ix = 0, iy = 0, iz = 0;
                        coordinates(i, ix, iy, iz);
                        path->push_back(i == first ? a : point(ix, iy, iz));
                        if (i == first) break;
                        i = std::find_if(cameFrom.begin(), cameFrom.end(), [&](const auto& e) { return e.first == i; })->second;
                    }
                    std::reverse(path->begin(), path->end());
                }
                return true;
            }
        }
        for (int dz = -1; dz <= 1; ++dz)
            for (int dy = -1; dy <= 1; ++dy)
                for (int dx = -1; dx <= 1; ++dx) {
                    const int nx = x + dx, ny = y + dy, nz = z + dz;
                    if (nx < 0 || ny < 0 || nz < 0 || nx >= size[0] || ny >= size[1] || nz >= size[2]) continue;
                    const std::size_t ni = index(nx, ny, nz);
                    if (!firstQueued(ni)) continue;
                    open.push({length(b - point(nx, ny, nz)), ni, at});
                }
    }
    return false;
}

bool EdgeRuns::partsJoined(const Coord& c, bool inside, NodeStates& nodes, std::uint64_t& evaluated) const {
    // The nodes within three steps of c, c left out; the outside joins across face diagonals too,
    // as marching cubes joins it.
    constexpr int kReach = 3, kWidth = 2 * kReach + 1, kOutsidePath = 4;
    const int reach = inside ? 6 : 18;
    // c's 3x3x3 first; the wider window only when a path must leave it.
    std::array<double, 27> close;
    std::array<double, kWidth * kWidth * kWidth> values;
    bool wide = false;
    mField.sampleNodes(mFrame, {c.x() - 1, c.y() - 1, c.z() - 1}, {3, 3, 3}, nullptr, close.data());
    evaluated += close.size();
    auto index = [&](const Coord& d) { return std::size_t((d.x() + kReach) + kWidth * ((d.y() + kReach) + kWidth * (d.z() + kReach))); };
    auto onSide = [&](const Coord& d) {
        if (d == Coord(0, 0, 0) || !validNode(c + d)) return false;
        double v = 0;
        if (std::max({std::abs(d.x()), std::abs(d.y()), std::abs(d.z())}) <= 1) {
            v = close[std::size_t((d.x() + 1) + 3 * (d.y() + 1) + 9 * (d.z() + 1))];
        } else {
            if (!wide) {
                mField.sampleNodes(mFrame, {c.x() - kReach, c.y() - kReach, c.z() - kReach}, {kWidth, kWidth, kWidth}, nullptr, values.data());
                evaluated += values.size();
                wide = true;
            }
            v = values[index(d)];
        }
        return nodes.inside(c + d, isInside(v, mIso, mSide)) == inside;
    };
    auto position = [&](const Coord& d) {
        openvdb::Vec3f off(0.0f);
        nodes.offsets.probeValue(c + d, off);
        return world(c + d) + Vec3d(off.x(), off.y(), off.z());
    };
    // (c itself is on no side: paths do not pass through it.)
    auto latticeJoins = [&](const Coord& from, const Coord& to, int box, int length) {
        return latticePathNear(from, to, box, length, !inside, onSide);
    };
    // Inside, only the two neighbours across c along an axis: two across a face's diagonal that
    // c's move parts, bridging joins again through the face's other corner (a fractured solid
    // beside a gap's corner, where refusing such moves welded two pieces together).
    if (inside) {
        for (int a = 0; a < 3; ++a) {
            const Coord below = axisStep(a, -1), above = axisStep(a, 1);
            if (onSide(below) && onSide(above) && !latticeJoins(below, above, kReach, kWidth * kWidth * kWidth) &&
                bentPathJoins(position(below), position(above), true, evaluated))
                return true;
        }
        return false;
    }
    // Outside, any two of c's neighbours (along edges and face diagonals) that the lattice joins
    // only through c, or by paths longer than four steps, asked whether the field joins them.
    // (Round a thin plate's rim a cell away, the outside above and below it is joined within four
    // steps, and a bridge into the plate there parts nothing the lattice needs; round a plate
    // with a hole, it is not.)
    std::vector<Coord> near;
    for (int k = 0; k < reach; ++k)
        if (onSide(faceNeighbourSteps()[std::size_t(k)])) near.push_back(faceNeighbourSteps()[std::size_t(k)]);
    // Groups joined within c's 3x3x3 first (no further samples), then within the window.
    std::vector<int> group(near.size());
    for (std::size_t i = 0; i < near.size(); ++i) group[i] = int(i);
    auto merge = [&](int box, int length) {
        for (std::size_t i = 0; i < near.size(); ++i)
            for (std::size_t j = 0; j < i; ++j)
                if (group[i] != group[j] && latticeJoins(near[j], near[i], box, length)) {
                    const int from = group[i];
                    for (int& g : group)
                        if (g == from) g = group[j];
                }
    };
    merge(1, 26);
    if (std::all_of(group.begin(), group.end(), [&](int g) { return g == group[0]; })) return false;
    merge(kReach, kOutsidePath);
    // Pairs of nodes in different groups, nearest first (then in order), until the field joins
    // one. (The nearest pair alone missed a hole's mouth: its node, bridged into the box to join
    // two of the box's nodes across a face beside it, was asked about a pair the hole does not
    // join; 4 of 240 random boxes with a hole under a cell wide lost it so.)
    std::vector<std::pair<int, std::pair<std::size_t, std::size_t>>> pairs;
    for (std::size_t x = 0; x < near.size(); ++x)
        for (std::size_t y = x + 1; y < near.size(); ++y)
            if (group[x] != group[y]) pairs.push_back({(near[x] - near[y]).asVec3i().lengthSqr(), {x, y}});
    std::sort(pairs.begin(), pairs.end());
    for (const auto& [d2, xy] : pairs)
        if (bentPathJoins(position(near[xy.first]), position(near[xy.second]), false, evaluated)) return true;
    return false;
}

EdgeRuns::MoveEffect EdgeRuns::moveEffect(const Coord& c, bool inside, const Vec3d& to, NodeStates& nodes, std::uint64_t& examined,
                                          std::uint64_t& evaluated, const JoinReach& outsideReach) const {
    MoveEffect effect;
    // A node on the lattice's outer faces keeps its side: marching cubes would close the surface
    // around it in cells beyond the lattice, which are not meshed (a shape within a cell of the
    // domain's edge, a node there moved into it: the mesh was open along the edge).
    if (!validNode(c.offsetBy(-1)) || !validNode(c.offsetBy(1))) {
        effect.keeps = false;
        return effect;
    }
    double around[27];
    mField.sampleNodes(mFrame, {c.x() - 1, c.y() - 1, c.z() - 1}, {3, 3, 3}, nullptr, around);
    // Where the node at offset d from c is now, and on which side.
    auto at = [&](const Coord& d, bool& nbInside) {
        const Coord nb = c + d;
        openvdb::Vec3f off(0.0f);
        nodes.offsets.probeValue(nb, off);
        nbInside = nodes.inside(nb, isInside(around[(d.x() + 1) + 3 * (d.y() + 1) + 9 * (d.z() + 1)], mIso, mSide));
        return world(nb) + Vec3d(off.x(), off.y(), off.z());
    };
    for (int k = 0; k < 6; ++k) {
        const Coord d = axisStep(k / 2, k % 2 ? 1 : -1);
        if (!validNode(c + d)) continue;
        bool nbInside = false;
        const Vec3d p = at(d, nbInside);
        if (nbInside == inside) effect.alone = false;
        const std::size_t was = hiddenRuns(world(c), p, inside, nbInside, examined, evaluated);
        std::size_t now = hiddenRuns(to, p, !inside, nbInside, examined, evaluated);
        // No edge may lose what it showed, nor join its ends across a part of the other side
        // (a node moved from outside a cracked ball into one half, beside a node of the other
        // half: the edge then joins the halves through the crack although it hides no more runs
        // than before) — unless the runs are only the other side's surface bulging across the
        // edge where both ends lie in one piece of their side.
        const bool sameSideAfter = inside != nbInside;
        if (now > was || (sameSideAfter && now > 0)) {
            if (!sameSideAfter ||
                (!bentPathJoins(to, p, nbInside, evaluated) && !joinedNearby(to, p, nbInside, evaluated, nbInside ? kJunctionReach : outsideReach))) {
                effect.keeps = false;
                return effect;
            }
            now = std::min(now, was);
        }
        effect.before += was;
        effect.after += now;
    }
    // Nor may the move leave a neighbour of c's side with no neighbour of its own side: a node
    // standing alone for a thick part is a bubble (crack nodes bridged into the crack one by one
    // around a node of the half beside it cut it off). Nor may it take from a neighbour placed on
    // a sharp feature its last edge to the other side (six neighbours only): the feature's crossings sit on those
    // edges, and with none left it vanishes from the mesh (bridging moved the one outside node
    // beside a notch's concave corner into the solid: the mesh cut the corner off by a cell).
    // A neighbour that moved to its side is not such a node: it stands for a thin part or joins
    // two nodes of one, and where c's move leaves it alone, bridging joins it again or the lone
    // joins go back to rest (restoreLoneJoins). Refusing c for it kept a crack hidden at a rim:
    // a node bridged into one half's wedge beside the crack leaned on the one node that had to
    // move into the crack.
    auto sideAt = [&](const Coord& e) { // the side of the node at offset e from c
        bool eInside = false;
        if (std::abs(e.x()) <= 1 && std::abs(e.y()) <= 1 && std::abs(e.z()) <= 1) {
            at(e, eInside);
        } else {
            double v = 0;
            const Coord m = c + e;
            mField.sampleNodes(mFrame, {m.x(), m.y(), m.z()}, {1, 1, 1}, nullptr, &v);
            eInside = nodes.inside(m, isInside(v, mIso, mSide));
        }
        return eInside;
    };
    // Does the node at offset d have a neighbour on `side`, other than c and `besides`, for which
    // `also` holds? With `diagonals`, an outside node counts across a face diagonal too: marching
    // cubes joins two outside nodes across a face whose other corners are inside, so such a node
    // is no bubble (where three wires thinner than a cell cross, the outside node amid them has
    // only such neighbours once the wires' nodes have moved in, and the node that had to move
    // into one of the wires beside it was refused: the wire came off two cells from the junction;
    // random pairs of crossing plates 0.3-0.7 H thick with holes or handles 28 -> 16 of 120).
    auto neighbourWith = [&](const Coord& d, bool side, const Coord& besides, bool diagonals, const auto& also) {
        const int reach = side || !diagonals ? 6 : 18;
        for (int j = 0; j < reach; ++j) {
            const Coord e = d + faceNeighbourSteps()[std::size_t(j)];
            if (e == Coord(0, 0, 0) || e == besides || !validNode(c + e) || sideAt(e) != side) continue;
            if (also(e)) return true;
        }
        return false;
    };
    // Does c's neighbour d have one on `side` (not c) that has one of its own (not d or c)? Two
    // nodes that only have each other are cut off as surely as one alone (two nodes of a half
    // beside a crack at its rim, whose other links to their half had moved into the crack: a
    // 10-vertex bubble).
    auto neighbourOn = [&](const Coord& d, bool side, bool diagonals) {
        return neighbourWith(d, side, Coord(0, 0, 0), diagonals, [&](const Coord& e) {
            return neighbourWith(e, side, d, diagonals, [](const Coord&) { return true; });
        });
    };
    for (int k = 0; k < 6; ++k) {
        const Coord d = axisStep(k / 2, k % 2 ? 1 : -1);
        if (!validNode(c + d)) continue;
        bool nbInside = false;
        at(d, nbInside);
        const bool movedToSide = nodes.offsets.isValueOn(c + d) && !nodes.onSurface.isValueOn(c + d);
        const bool keepsCompany = nbInside == inside ? movedToSide || neighbourOn(d, nbInside, true)
                                                     : !nodes.onSurface.isValueOn(c + d) || neighbourOn(d, inside, false);
        if (!keepsCompany) {
            effect.keeps = false;
            return effect;
        }
    }
    // An inside node that moves out may make the faces around it ambiguous: marching cubes then
    // joins it to the outside corner across each such face, which must not hide a part (a move
    // out of one side of a thin shell must not join the shell's two sides), unless the two lie
    // in one piece of the outside here anyway.
    if (!inside) return effect;
    for (int u = 0; u < 3; ++u)
        for (int v = u + 1; v < 3; ++v)
            for (int su = -1; su <= 1; su += 2)
                for (int sv = -1; sv <= 1; sv += 2) {
                    const Coord du = axisStep(u, su), dv = axisStep(v, sv);
                    if (!validNode(c + du) || !validNode(c + dv) || !validNode(c + du + dv)) continue;
                    bool inU = false, inV = false, inFar = false;
                    at(du, inU);
                    at(dv, inV);
                    const Vec3d far = at(du + dv, inFar);
                    if (inU && inV && !inFar && hiddenRuns(to, far, false, false, examined, evaluated) > 0 &&
                        !bentPathJoins(to, far, false, evaluated) && !joinedNearby(to, far, false, evaluated, outsideReach)) {
                        effect.keeps = false;
                        return effect;
                    }
                }
    return effect;
}

} // namespace vdbsurf
