#include "vdbsurf/dmc/crossed_moves.h"

#include "vdbsurf/core/lattice_frame.h"
#include "vdbsurf/dmc/inside_topology.h"
#include "vdbsurf/dmc/lattice_deformation.h"
#include "vdbsurf/dmc/rest_sides.h"

#include <algorithm>

namespace vdbsurf {

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

} // namespace vdbsurf
