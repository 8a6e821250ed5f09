#include "vdbsurf/dmc/crossed_moves.h"

#include "vdbsurf/core/lattice_frame.h"
#include "vdbsurf/dmc/inside_topology.h"
#include "vdbsurf/dmc/lattice_deformation.h"
#include "vdbsurf/dmc/rest_sides.h"

#include <algorithm>
#include <array>
#include <cmath>

namespace vdbsurf {

namespace {

// On the face with corners a, u, b, v in turn (a bilinear patch between the nodes where they
// stand; a and b outside, u and v inside), does the inside join u and v, edge to edge between
// samples n per side?
bool insideJoinsAcrossFace(const Field& field, double iso, int n, const Vec3d& a, const Vec3d& u, const Vec3d& b, const Vec3d& v) {
    const std::size_t count = std::size_t(n) * std::size_t(n);
    std::vector<Vec3d> points(count);
    std::vector<double> values(count);
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
            const double s = double(i) / (n - 1), t = double(j) / (n - 1);
            points[std::size_t(i + n * j)] = a * ((1 - s) * (1 - t)) + u * (s * (1 - t)) + b * (s * t) + v * ((1 - s) * t);
        }
    const Vec3d lo = vmin(vmin(a, u), vmin(b, v)), hi = vmax(vmax(a, u), vmax(b, v));
    const double hair = 1e-9 * (1 + std::max({std::fabs(lo.x), std::fabs(lo.y), std::fabs(lo.z), std::fabs(hi.x), std::fabs(hi.y), std::fabs(hi.z)}));
    field.values(Box3{lo - Vec3d(hair, hair, hair), hi + Vec3d(hair, hair, hair)}, points.data(), count, values.data());
    const Inside side = field.inside();
    std::vector<std::uint8_t> inside(count), reached(count, 0);
    for (std::size_t i = 0; i < count; ++i) inside[i] = isInside(values[i], iso, side);
    // The corners on the sides the lattice gives them: u at (n-1, 0), v at (0, n-1).
    const std::size_t from = std::size_t(n - 1), to = std::size_t(n) * std::size_t(n - 1);
    inside[0] = inside[count - 1] = 0;
    inside[from] = inside[to] = 1;
    std::vector<std::size_t> stack{from};
    reached[from] = 1;
    while (!stack.empty()) {
        const std::size_t at = stack.back();
        stack.pop_back();
        if (at == to) return true;
        const int i = int(at % std::size_t(n)), j = int(at / std::size_t(n));
        const int next[4][2] = {{i - 1, j}, {i + 1, j}, {i, j - 1}, {i, j + 1}};
        for (const auto& q : next) {
            if (q[0] < 0 || q[1] < 0 || q[0] >= n || q[1] >= n) continue;
            const std::size_t k = std::size_t(q[0] + n * q[1]);
            if (inside[k] && !reached[k]) {
                reached[k] = 1;
                stack.push_back(k);
            }
        }
    }
    return false;
}

} // namespace

std::vector<Vec3i> undoCrossedMoves(const Field& field, const LatticeFrame& frame, double iso, LatticeDeformation& deformation,
                                    const std::vector<Vec3i>& keep) {
    std::vector<Vec3i> moved;
    for (auto it = deformation.offsets->cbeginValueOn(); it; ++it) {
        const openvdb::Coord c = it.getCoord();
        if (!deformation.onSurface->isValueOn(c)) moved.emplace_back(c.x(), c.y(), c.z());
    }
    RestSides rest(field, frame, iso);
    auto atRest = [&](const Vec3i& n) { return rest.inside(n); };
    std::vector<Vec3i> undone;
    for (const std::vector<Vec3i>& group : groupsAcrossCorners(moved)) {
        // (Every node of the group is moved: its side now is the other one.)
        std::vector<Vec3i> wentIn, wentOut;
        for (const Vec3i& n : group)
            if (!std::binary_search(keep.begin(), keep.end(), n, lessXYZ)) (atRest(n) ? wentOut : wentIn).push_back(n);
        if (wentIn.empty() || wentOut.empty()) continue;
        auto inGroup = [&](const Vec3i& n) { return std::binary_search(group.begin(), group.end(), n, lessXYZ); };
        // The group's count with the moves of `part` undone (none: all moves as made).
        auto eulerWithout = [&](const std::vector<Vec3i>* part) {
            return insideEulerAround(group, [&](const Vec3i& n) {
                const bool undo = part && std::binary_search(part->begin(), part->end(), n, lessXYZ);
                return inGroup(n) && !undo ? !atRest(n) : atRest(n);
            });
        };
        const int atRestEuler = insideEulerAround(group, atRest);
        // Only where each side's moves alone keep the topology and together change it: a thin part
        // of either side changes the lattice's topology on its own, and that is kept.
        if (eulerWithout(nullptr) == atRestEuler || eulerWithout(&wentIn) != atRestEuler || eulerWithout(&wentOut) != atRestEuler) continue;
        // And only a handle (or its loss): where the pieces of either side around the group
        // change, the moves together join or part what one side's thin part alone could not
        // (between a fracture's pieces, a wedge tip of one joined to it across a gap), and stay.
        Vec3i lo = group.front(), hi = group.front();
        for (const Vec3i& n : group) {
            lo = Vec3i(std::min(lo.x, n.x), std::min(lo.y, n.y), std::min(lo.z, n.z));
            hi = Vec3i(std::max(hi.x, n.x), std::max(hi.y, n.y), std::max(hi.z, n.z));
        }
        lo = lo - Vec3i(2, 2, 2);
        hi = hi + Vec3i(2, 2, 2);
        auto now = [&](const Vec3i& n) { return inGroup(n) != atRest(n); };
        if (piecesInBox(lo, hi, true, now) != piecesInBox(lo, hi, true, atRest) ||
            piecesInBox(lo, hi, false, now) != piecesInBox(lo, hi, false, atRest))
            continue;
        const std::vector<Vec3i>& fewer = wentIn.size() <= wentOut.size() ? wentIn : wentOut;
        for (const Vec3i& n : fewer) deformation.offsets->setValueOff(openvdb::Coord(n.x, n.y, n.z), openvdb::Vec3f(0.0f));
        undone.insert(undone.end(), fewer.begin(), fewer.end());
    }
    std::sort(undone.begin(), undone.end(), lessXYZ);
    return undone;
}

std::vector<Vec3i> undoTunnelJoins(const Field& field, const LatticeFrame& frame, double iso, int steps, LatticeDeformation& deformation,
                                   const std::vector<Vec3i>& keep) {
    std::vector<Vec3i> moved;
    for (auto it = deformation.offsets->cbeginValueOn(); it; ++it) {
        const openvdb::Coord c = it.getCoord();
        if (!deformation.onSurface->isValueOn(c)) moved.emplace_back(c.x(), c.y(), c.z());
    }
    std::sort(moved.begin(), moved.end(), lessXYZ);
    RestSides rest(field, frame, iso);
    auto isMoved = [&](const Vec3i& n) { return std::binary_search(moved.begin(), moved.end(), n, lessXYZ); };
    auto current = [&](const Vec3i& n) { return isMoved(n) != rest.inside(n); };
    auto position = [&](const Vec3i& n) {
        openvdb::Vec3f off(0.0f);
        deformation.offsets->probeValue(openvdb::Coord(n.x, n.y, n.z), off);
        return frame.nodeWorld(n) + Vec3d(off.x(), off.y(), off.z());
    };
    const int samples = 2 * steps + 1;
    // Has c a face across which marching cubes joins it to an outside node through the inside?
    auto joinsThroughInside = [&](const Vec3i& c) {
        for (int a = 0; a < 3; ++a)
            for (int b = a + 1; b < 3; ++b)
                for (const int sa : {-1, 1})
                    for (const int sb : {-1, 1}) {
                        const Vec3i du = Vec3i(a == 0, a == 1, a == 2) * sa, dv = Vec3i(b == 0, b == 1, b == 2) * sb;
                        if (!current(c + du) || !current(c + dv) || current(c + du + dv)) continue;
                        if (insideJoinsAcrossFace(field, iso, samples, position(c), position(c + du), position(c + du + dv), position(c + dv)))
                            return true;
                    }
        return false;
    };
    std::vector<Vec3i> candidates;
    for (const Vec3i& c : moved) {
        if (rest.inside(c) && !std::binary_search(keep.begin(), keep.end(), c, lessXYZ)) candidates.push_back(c);
    }
    std::vector<Vec3i> undone;
    for (const Vec3i& c : candidates) {
        if (!joinsThroughInside(c)) continue;
        auto backAtRest = [&](const Vec3i& n) { return n == c ? true : current(n); };
        const std::vector<Vec3i> one{c};
        // (The count is the negative of the inside's Euler characteristic, which a tunnel through
        // the inside lowers by one: back at rest must take one off the count.)
        if (insideEulerAround(one, backAtRest) >= insideEulerAround(one, current)) continue;
        const Vec3i lo = c - Vec3i(2, 2, 2), hi = c + Vec3i(2, 2, 2);
        if (piecesInBox(lo, hi, true, current) != piecesInBox(lo, hi, true, backAtRest) ||
            piecesInBox(lo, hi, false, current) != piecesInBox(lo, hi, false, backAtRest))
            continue;
        moved.erase(std::lower_bound(moved.begin(), moved.end(), c, lessXYZ));
        deformation.offsets->setValueOff(openvdb::Coord(c.x, c.y, c.z), openvdb::Vec3f(0.0f));
        undone.push_back(c);
    }
    return undone;
}

} // namespace vdbsurf
