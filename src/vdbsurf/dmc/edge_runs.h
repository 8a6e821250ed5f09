// What the segments between lattice nodes hide, and what moving one node changes about that:
// shared by the hidden-edge phase (which moves a node onto a part an edge hides) and bridging
// (which moves a node into a part two others share), so that neither move makes another edge
// hide what it showed. A segment is sampled at steps shorter than h/k, so a part at least h/k
// wide along it holds a sample, as in the thin search's Ω.
#pragma once

#include "vdbsurf/dmc/lattice_deformation.h"
#include "vdbsurf/field/field.h"

#include <openvdb/openvdb.h>

#include <array>
#include <cstdint>
#include <cstdlib>
#include <vector>

namespace vdbsurf {

struct Lattice;

using OffsetAccessor = openvdb::tree::ValueAccessor<const OffsetTree, false>;

// Where the nodes are now and on which side, read from a deformation by one thread: a node moved
// by the thin search changed side, a node placed on a sharp feature has the side recorded for it.
struct NodeStates {
    explicit NodeStates(const LatticeDeformation& deformation);
    bool inside(const openvdb::Coord& c, bool restInside) {
        if (onSurface.isValueOn(c)) return insideOnSurface.isValueOn(c);
        return offsets.isValueOn(c) != restInside;
    }
    OffsetAccessor offsets;
    openvdb::tree::ValueAccessor<const NodeMaskTree, false> onSurface, insideOnSurface;
};

// One lattice step along `axis` (0-2), towards `sign` (-1 or 1; 2 or -2 for two steps).
inline openvdb::Coord axisStep(int axis, int sign) {
    return openvdb::Coord(axis == 0 ? sign : 0, axis == 1 ? sign : 0, axis == 2 ? sign : 0);
}

// The six axis steps, then the twelve face diagonals: a node's neighbours along edges, and those
// marching cubes also joins to an outside node across faces.
inline const std::array<openvdb::Coord, 18>& faceNeighbourSteps() {
    static const std::array<openvdb::Coord, 18> steps = [] {
        std::array<openvdb::Coord, 18> a;
        std::size_t n = 0;
        for (int j = 0; j < 6; ++j) a[n++] = axisStep(j / 2, j % 2 ? 1 : -1);
        for (int u = 0; u < 3; ++u)
            for (int v = u + 1; v < 3; ++v)
                for (int su = -1; su <= 1; su += 2)
                    for (int sv = -1; sv <= 1; sv += 2) a[n++] = axisStep(u, su) + axisStep(v, sv);
        return a;
    }();
    return steps;
}

// Does the lattice join the nodes at offsets `from` and `to` from a centre through nodes that
// `onSide` accepts (asked by offset), stepping along edges or, with `faceDiagonals`, across faces'
// diagonals too (as marching cubes joins the outside), within `box` steps of the centre along
// each axis, by a path of at most `length` steps? (A template: bridging asks it for many nodes,
// and `onSide` is called for every node the search reaches.)
template <typename OnSide>
bool latticePathNear(const openvdb::Coord& from, const openvdb::Coord& to, int box, int length, bool faceDiagonals, const OnSide& onSide) {
    const int width = 2 * box + 1;
    auto index = [&](const openvdb::Coord& d) { return std::size_t((d.x() + box) + width * ((d.y() + box) + width * (d.z() + box))); };
    std::vector<std::uint8_t> seen(std::size_t(width) * std::size_t(width) * std::size_t(width), 0);
    std::vector<openvdb::Coord> queue{from};
    std::vector<int> steps{0};
    seen[index(from)] = 1;
    const int reach = faceDiagonals ? 18 : 6;
    for (std::size_t head = 0; head < queue.size(); ++head) {
        if (queue[head] == to) return true;
        if (steps[head] == length) continue;
        for (int k = 0; k < reach; ++k) {
            const openvdb::Coord e = queue[head] + faceNeighbourSteps()[std::size_t(k)];
            if (std::abs(e.x()) > box || std::abs(e.y()) > box || std::abs(e.z()) > box || seen[index(e)]) continue;
            seen[index(e)] = 1;
            if (!onSide(e)) continue;
            queue.push_back(e);
            steps.push_back(steps[head] + 1);
        }
    }
    return false;
}

// Does `moved` hold a node whose move can change what moving c does (EdgeRuns::moveEffect): one
// of the 26 around c, or two steps from it along an axis?
template <typename Moved> bool movedNear(const openvdb::Coord& c, const Moved& moved) {
    for (int z = -1; z <= 1; ++z)
        for (int y = -1; y <= 1; ++y)
            for (int x = -1; x <= 1; ++x)
                if ((x || y || z) && moved(c.offsetBy(x, y, z))) return true;
    for (int k = 0; k < 6; ++k)
        if (moved(c + axisStep(k / 2, k % 2 ? 2 : -2))) return true;
    return false;
}

class EdgeRuns {
public:
    EdgeRuns(const Field& field, const Lattice& lattice, double iso, int steps);

    struct Run {
        bool inside;
        int first, last;
    };

    // Runs of samples on one side from a to b (ends on the given sides), at n steps. A value at
    // iso stays in the run before it. Ends on one side whose bounds rule out the iso value give
    // one run without sampling (`examined` counts the segments sampled).
    std::vector<Run> runsAlong(const Vec3d& a, const Vec3d& b, bool insideA, bool insideB, int& n, std::uint64_t& examined,
                               std::uint64_t& evaluated) const;

    // Runs beyond what the ends' sides explain.
    std::size_t hiddenRuns(const Vec3d& a, const Vec3d& b, bool insideA, bool insideB, std::uint64_t& examined,
                           std::uint64_t& evaluated) const;

    // How far joinedNearby looks: the box around both ends grown by `margin` cells, and the samples
    // per search step (`budget`) it may take before it gives up.
    struct JoinReach {
        double margin;
        int budget;
    };
    // Outside, half a cell and 20: where a crack reaches a surface within a cell of a node, its
    // outside and the outside beyond that surface meet around the rim, which bent paths miss.
    // The outside around a crack is mostly wide, and a larger search spends its whole budget
    // there: with the inside's reach, the thin search on noisy fog resampled to 2 voxels a cell
    // took 10-25 % longer, and though 7 more of 30 pairs of crossing cracks came out right, 2 of
    // 80 random blob scenes got a handle or a piece that they do not have.
    static constexpr JoinReach kRimReach{0.5, 20};
    // Inside, a cell and 100: thin parts that cross (rods, plates) meet in a junction up to a cell
    // beyond nodes that stand in different parts, and the path round it turns away from b. With
    // the outside's reach, random pairs of crossing rods 0.2-0.5 H thick came out in pieces 33
    // times in 120, pairs of crossing plates 0.3-0.7 H thick got holes or handles 13 times in 30;
    // with this, 8 and 5 times (a budget of 50 left more, 200 no fewer).
    static constexpr JoinReach kJunctionReach{1.0, 100};

    // What moving node c (on side `inside`, not moved) to `to` (onto the other side) does to its
    // six edges, the other nodes where `nodes` puts them. `outsideReach`: how far the outside is
    // searched for a path that makes harmless what the move joins across a part of the inside (an
    // edge whose ends it puts both outside, a face it turns ambiguous).
    struct MoveEffect {
        bool keeps = true;      // no edge hides a part it showed, no face turns ambiguous across a part,
                                // no feature node loses its last edge to the other side, c is not on
                                // the lattice's outer faces
        std::size_t before = 0; // hidden runs on the six edges before the move
        std::size_t after = 0;  // and after (bulges that bent paths go around count as before)
        bool alone = true;      // no neighbour on c's side: c stands for a thin part itself
    };
    MoveEffect moveEffect(const openvdb::Coord& c, bool inside, const Vec3d& to, NodeStates& nodes, std::uint64_t& examined,
                          std::uint64_t& evaluated, const JoinReach& outsideReach = kRimReach) const;

    // Would moving node c (on side `inside`) to the other side part nodes of its side that the
    // lattice joins, within three steps of c, only through c (outside: by no path of four steps
    // but through c), where the field joins them by a path bowing less than a cell from the
    // segment between them (bentPathJoins)? `nodes` as they stand. Inside, the two neighbours
    // across c along an axis: the hidden-edge phase moves a node into the outside that an edge
    // hides; where a ball's surface grazed an edge beside a spike's root, the root node so moved
    // cut the spike off the ball (its other nodes had each other for company). Outside, any two
    // of its neighbours along edges and face diagonals: bridging moved the one node in a hole
    // about a cell wide through a plate two cells thick into the plate, to join two of the
    // plate's nodes across a face beside the hole, and closed the hole. A crack's halves, the two
    // sides of a sheet, are not joined across it.
    bool partsJoined(const openvdb::Coord& c, bool inside, NodeStates& nodes, std::uint64_t& evaluated) const;

    bool validNode(const openvdb::Coord& c) const {
        return c.x() >= mNodeLo.x() && c.y() >= mNodeLo.y() && c.z() >= mNodeLo.z() && c.x() <= mNodeHi.x() &&
               c.y() <= mNodeHi.y() && c.z() <= mNodeHi.z();
    }
    Vec3d world(const openvdb::Coord& c) const { return mFrame.nodeWorld(Vec3i(c.x(), c.y(), c.z())); }

    // Is there a path from a to b on side `inside` that bows away from the segment by less than a
    // cell? Then the ends lie in one piece of their side here, and a run of the other side on the
    // segment between them is the other side's surface curving across it, not a part between
    // them (a crack between them crosses every such path).
    bool bentPathJoins(const Vec3d& a, const Vec3d& b, bool inside, std::uint64_t& evaluated) const;

    // Do a and b lie in one piece of side `inside` within `reach` (by default, the side's)? A
    // search over samples at h/(2k) (26-connected: a crack at least h/k wide holds a connected
    // layer of them, and a sheet at least h/k wide leaves no diagonal gap between its two sides),
    // best first towards b, that gives up (no) after reach.budget·k samples. With `path`, a path
    // found is put there: the samples from a to b, each on side `inside`, a and b included.
    bool joinedNearby(const Vec3d& a, const Vec3d& b, bool inside, std::uint64_t& evaluated) const {
        return joinedNearby(a, b, inside, evaluated, inside ? kJunctionReach : kRimReach);
    }
    bool joinedNearby(const Vec3d& a, const Vec3d& b, bool inside, std::uint64_t& evaluated, const JoinReach& reach,
                      std::vector<Vec3d>* path = nullptr) const;

private:
    const Field& mField;
    const LatticeFrame& mFrame;
    double mIso;
    Inside mSide;
    int mSteps;
    openvdb::Coord mNodeLo, mNodeHi;
};

} // namespace vdbsurf
