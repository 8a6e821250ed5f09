#include "vdbsurf/dmc/sharp_features.h"

#include "vdbsurf/core/cancel.h"
#include "vdbsurf/core/error.h"
#include "vdbsurf/core/planes.h"
#include "vdbsurf/core/prefault.h"
#include "vdbsurf/dmc/cube_table.h"
#include "vdbsurf/dmc/edge_runs.h"
#include "vdbsurf/dmc/inside_topology.h"
#include "vdbsurf/dmc/lattice_deformation.h"
#include "vdbsurf/dmc/lattice_surface.h"
#include "vdbsurf/dmc/rest_sides.h"
#include "vdbsurf/dmc/sampled_planes.h"
#include "vdbsurf/dmc/thin_search.h"
#include "vdbsurf/lattice/lattice.h"

#include <tbb/concurrent_vector.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <optional>
#include <tuple>
#include <unordered_map>

namespace vdbsurf {

using openvdb::Coord;

namespace {

// Normals closer to opposite than this (|n_a × n_b| below it) belong to two sheets of a thin
// part rather than to the two faces of an edge.
constexpr double kMinSine = 0.25;
// How deep (in cells) the solid behind an edge or corner must reach for it to be a feature. One
// cell is not enough: on a round rod about a cell across, two tangent planes meet a little
// outside the surface, a probe one cell in lands just short of the far side, and the node
// placed there carries the rod's whole cross-section (welded to a point, the rod comes apart:
// 5 of 10 random rods of diameter H did; at 1.5 cells, about 1 in 40 rods 1.5 H across). Two
// cells keep rods up to 2 H whole; the cube file loses no feature node, the armadillo 2 of 3970.
constexpr double kMinThickness = 2.0;
// Two crossing normals of one cell closer to opposite than this (cosine) are the two sides of a
// thin part (a rod, a plate) inside the cell.
constexpr double kOppositeSheets = 0.9;
// A feature point farther than this from the surface (in cells, estimated as |f - iso| / |∇f|)
// is an artefact of curvature or of sampling, not a feature.
constexpr double kMaxSurfaceDistance = 0.2;
// A true edge or corner joins faces that are flat at the scale of a cell: the segment from the
// feature point to each crossing that defined it lies on that crossing's tangent plane and on the
// surface. Where the surface is merely curved (noisy fog, a rounded blob) the tangent planes meet
// off the surface and the segment's midpoint strays from it by more than this (in cells).
constexpr double kMaxFaceBend = 0.1;
// A node placed on a feature takes the crossings of its edges with it: each must lie on a face
// through the feature's point, its tangent plane within this share of a cell (or of its distance
// to the point, if farther) of the point. Curved faces stray ~0.1-0.2 (a cylinder's rim 4 cells
// around); a notch's far wall strays by the notch's depth.
constexpr double kCollapseBend = 0.3;
// On flat faces every crossing's normal is one of the faces' normals; on a curved surface the
// normals fan out between them. A crossing whose normal is farther than this (cosine) from every
// plane that defined the feature means curvature, not a feature.
constexpr double kFaceNormalAgreement = 0.95;

// A cell whose crossings lie on more planes than this holds no pair of features.
constexpr int kMaxPlanes = 4;
// A feature point another cell proposed (first round) or placed (second round) confirms an edge's
// line when it lies this close to it (in cells): the lines of one straight edge seen from two
// cells agree far closer than this. (A looser distance for curved edges confirmed the tangent
// lines of a smooth tube as readily as those of a crease: curved edges have a test of their own.)
constexpr double kOnConfirmedLine = 0.1;
// First round: an edge's point confirms another's line only this far along it (in cells).
constexpr double kConfirmAlong = 0.3;
// First round, curved edges (a cylinder's rim, a crease where two blobs meet): the tangent lines
// of two cells meet (within kOnConfirmedLine) at an angle below this (cosine) and within this
// distance (in cells) of both cells' points. A rim 4 cells around lay 0.048 H from the mesh at the
// median with straight lines alone, 0.013 with this (0.015 unconfirmed); a smooth tube 2 cells
// thick, curving 7 cells around, gains false edges by it (mean distance 0.036 -> 0.039 H).
constexpr double kCurvedEdgeCosine = 0.85;
constexpr double kCurvedEdgeReach = 2.0;
// A third face that meets the edge of the other two at a shallow angle (φ below --sharp-corner,
// down to this share of it) makes a corner too where it is a plane of its own (its normal agrees
// with neither), where the surface around the point lies on the three planes — at least two of
// the lines where they meet on it a cell out (within kShallowEdgeBend cells), and each face
// between two such lines kShallowFaceReach cells out (within kShallowFaceBend) — and where
// another cell's edge runs through the point. The paper's φ test alone turns such corners into
// edges, cut off by up to 0.6 H: a chamfered box's (φ 0.58), a pyramid's base corners below a
// height of its half base (φ = h / √(h² + a²)), an octagonal or finer prism's rim (sin 2π/m).
// Where faces merely curve (noisy fog, a blob curving about a cell), tangent planes meet at such
// angles in many cells: with the confirmation alone, smoke_fog at a voxel of 1 had 2.5 times its
// corners (46 -> 116), with the lines probed a cell out (within 0.1 cells) but not the faces 93,
// with both as below 47.
constexpr double kShallowCornerShare = 0.45;
constexpr double kShallowEdgeBend = 0.05, kShallowFaceReach = 1.5, kShallowFaceBend = 0.1;

struct Proposal {
    Coord node;
    int kind = 0; // 0 corner, 1 edge: corners win
    bool needsEdge = false; // a shallow corner (kShallowCornerShare): kept where another cell's edge runs through it
    double distance = 0;
    Coord cell;
    Vec3d point;
    Vec3d direction; // an edge's line
    Vec3d onLine;    // the point of the line the cell found (its other nodes' Ω are met from it)
    Vec3d outward;   // its faces' summed normals (second round)
    unsigned config = 0; // the cell's case: the side of each of its corners
    bool inside = false; // the node's side before it moves
    bool operator<(const Proposal& o) const {
        // The point last: one cell may propose one node twice (two features), and the order of
        // equal keys must not depend on the threads that found them.
        return std::tie(node, kind, distance, cell, point.x, point.y, point.z) <
               std::tie(o.node, o.kind, o.distance, o.cell, o.point.x, o.point.y, o.point.z);
    }
};

// The field checks of a proposal, kept for later where a cell's proposal is decided alone: a
// feature point near the surface, on flat faces towards each defining crossing, with solid behind.
struct FieldCheck {
    Vec3d faces[3];
    int faceCount = 0;
    Vec3d behind; // the faces' summed outward normals
};

// A proposal as the cells record it: its field checks, kept where they wait for a confirmation,
// and their status (below).
struct Recorded {
    Proposal proposal;
    FieldCheck check;
    std::uint8_t status;
};

// A proposal's field checks: not yet made, passed, failed. Made at most once each, on demand by
// any task; a pure function of the proposal, so a race writes the same value.
enum : std::uint8_t { kUnchecked = 0, kPassed = 1, kFailed = 2 };

// Into how many groups the nodes on side `side` fall among the 26 around a node, joined within
// its 3^3 block (bit k of `insideAround`: node k of the block is inside; the centre, k = 13, is
// left out) by `adjacency`: 6 across faces, 18 across face diagonals too, 26 across any corner.
int groupsAround(std::uint32_t insideAround, bool side, int adjacency) {
    // reach[a][k]: the nodes of the block joined to node k by adjacency 6, 18, 26 (a = 0, 1, 2).
    static const auto reach = [] {
        std::array<std::array<std::uint32_t, 27>, 3> r{};
        for (int k = 0; k < 27; ++k)
            for (int j = 0; j < 27; ++j) {
                const int away = std::abs(k % 3 - j % 3) + std::abs((k / 3) % 3 - (j / 3) % 3) + std::abs(k / 9 - j / 9);
                const bool near = std::abs(k % 3 - j % 3) <= 1 && std::abs((k / 3) % 3 - (j / 3) % 3) <= 1 && std::abs(k / 9 - j / 9) <= 1;
                if (!near || away == 0) continue;
                for (int a = 0; a < 3; ++a)
                    if (away <= a + 1) r[std::size_t(a)][std::size_t(k)] |= 1u << j;
            }
        return r;
    }();
    const auto& joined = reach[std::size_t(adjacency == 6 ? 0 : adjacency == 18 ? 1 : 2)];
    std::uint32_t left = (side ? insideAround : ~insideAround) & ((1u << 27) - 1) & ~(1u << 13);
    int groups = 0;
    while (left) {
        std::uint32_t group = left & (~left + 1), grown = 0;
        while (grown != group) {
            const std::uint32_t fresh = group & ~grown;
            grown = group;
            for (std::uint32_t g = fresh; g; g &= g - 1) group |= joined[std::size_t(__builtin_ctz(g))] & left;
        }
        left &= ~group;
        ++groups;
    }
    return groups;
}

Coord nearestNode(const LatticeFrame& frame, const Vec3d& p) {
    const Vec3d q = (p - frame.origin) / frame.h;
    return Coord(int(std::floor(q.x + 0.5)), int(std::floor(q.y + 0.5)), int(std::floor(q.z + 0.5)));
}

// The point of the line (p + t·dir, dir a unit vector) closest to `rest` among those in rest's
// cell Ω (taken a hair inside, as offsets must be), if the line crosses Ω.
bool closestOnLineInOmega(const Vec3d& p, const Vec3d& dir, const Vec3d& rest, double h, Vec3d& out) {
    const double inner = 0.5 * h * (1 - 1e-5);
    double lo = -INFINITY, hi = INFINITY;
    for (std::size_t i = 0; i < 3; ++i) {
        const double o = p[i] - rest[i], d = dir[i];
        if (std::fabs(d) < 1e-12) {
            if (std::fabs(o) > inner) return false;
            continue;
        }
        double t0 = (-inner - o) / d, t1 = (inner - o) / d;
        if (t0 > t1) std::swap(t0, t1);
        lo = std::max(lo, t0);
        hi = std::min(hi, t1);
    }
    if (!(lo <= hi)) return false;
    out = p + dir * std::clamp(dot(dir, rest - p), lo, hi);
    return true;
}

// Distance from q to the line through p along unit dir.
double distanceToLine(const Vec3d& q, const Vec3d& p, const Vec3d& dir) {
    const Vec3d d = q - p;
    return length(d - dir * dot(d, dir));
}

// The edge proposals another cell among the 26 around confirms: a feature point proposed there
// lies on the edge's line (an edge's point at least kConfirmAlong from this one along it; a corner
// anywhere, as the edge may end there), or an edge's line there meets this one nearby at a small
// angle (two tangents of a curved edge). A true edge spans cells and every cell it crosses finds
// the same line, or the next tangent; on a noisy or merely curved surface each cell's tangent
// planes meet on a line of their own (fog at its voxel size: more than eight in ten "edges" go
// unconfirmed, and the mesh comes closer to the surface without them). Cells side by side across
// a line share the face crossings that made it, so a point beside this one is no second view.
// Corners stand without confirmation: three faces seen at once in one cell are rare on curved
// surfaces (39 of 81,570 cells of the smoke file), and a short notch's corner may have no
// neighbour that sees its edges. A shallow corner (needsEdge) is not rare there: it stands where
// another cell's edge line passes through it, from at least kConfirmAlong away (one of its edges
// seen again), and confirms no edge itself. Only proposals whose field checks pass (passes(i)) count, on
// either side; the checks are asked for only where the geometry confirms, so most proposals of a
// noisy surface never need them. Order kept; decided in parallel, the result does not depend on
// the threads.
template <typename ProposalAt, typename Passes>
std::vector<Proposal> confirmedByNeighbours(std::size_t count, const ProposalAt& at, double h, const Passes& passes) {
    struct Seen { // what a confirming proposal needs, packed and ordered by cell
        Coord cell;
        int kind;
        bool needsEdge;
        Vec3d point, direction;
        std::size_t index;
    };
    // (Fresh memory, ~70 bytes a proposal: mapped, filled and sorted in parallel. The order of
    // proposals of one cell does not matter: each is decided by all the others.)
    std::vector<Seen> seen;
    resizePrefaulted(seen, count);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, 1024), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i < r.end(); ++i) {
            const Proposal& p = at(i);
            seen[i] = {p.cell, p.kind, p.needsEdge, p.point, p.direction, i};
        }
    });
    tbb::parallel_sort(seen.begin(), seen.end(), [](const Seen& x, const Seen& y) { return x.cell < y.cell; });
    const double tolerance = kOnConfirmedLine * h;
    auto confirms = [&](const Seen& q, const Seen& p) {
        if (p.kind == 0) // a shallow corner, by an edge through it
            return q.kind == 1 && distanceToLine(p.point, q.point, q.direction) <= tolerance &&
                   std::fabs(dot(p.point - q.point, q.direction)) >= kConfirmAlong * h;
        if (q.kind == 0) return !q.needsEdge && distanceToLine(q.point, p.point, p.direction) <= tolerance; // the edge may end there
        const Vec3d d = q.point - p.point;
        if (std::fabs(dot(d, p.direction)) < kConfirmAlong * h) return false;
        if (distanceToLine(q.point, p.point, p.direction) <= tolerance) return true; // one straight edge
        // Two tangents of one curved edge: lines at a small angle that meet near both points.
        if (std::fabs(dot(p.direction, q.direction)) < kCurvedEdgeCosine) return false;
        const Vec3d n = cross(p.direction, q.direction);
        const double n2 = dot(n, n);
        if (n2 < 1e-12 || std::fabs(dot(d, n)) > tolerance * std::sqrt(n2)) return false;
        const double t = dot(cross(d, q.direction), n) / n2, u = dot(cross(d, p.direction), n) / n2; // where they meet
        return std::fabs(t) <= kCurvedEdgeReach * h && std::fabs(u) <= kCurvedEdgeReach * h;
    };
    std::vector<std::uint8_t> keep(count, 0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, seen.size(), 256), [&](const tbb::blocked_range<std::size_t>& r) {
        // Cells are ordered x, y, z: the three cells of one (x, y) column are adjacent, and the
        // first of each of the nine columns around a cell moves forward as the cell does, so
        // one cursor a column walks the range once.
        using It = typename std::vector<Seen>::const_iterator;
        It cursor[9];
        for (int k = 0; k < 9; ++k)
            cursor[k] = std::lower_bound(seen.cbegin(), seen.cend(), seen[r.begin()].cell.offsetBy(k % 3 - 1, k / 3 - 1, -1),
                                         [](const Seen& q, const Coord& c) { return q.cell < c; });
        for (std::size_t s = r.begin(); s < r.end(); ++s) {
            const Seen& p = seen[s];
            const std::size_t i = p.index;
            if (p.kind == 0 && !p.needsEdge) {
                keep[i] = passes(i);
                continue;
            }
            bool decided = false;
            for (int k = 0; k < 9; ++k) {
                const Coord first = p.cell.offsetBy(k % 3 - 1, k / 3 - 1, -1), last = first.offsetBy(0, 0, 2);
                It& it = cursor[k];
                while (it != seen.cend() && it->cell < first) ++it;
                for (It q = it; !decided && q != seen.cend() && !(last < q->cell); ++q) {
                    if (q->cell == p.cell || !confirms(*q, p)) continue;
                    if (!passes(i)) decided = true;
                    else if (passes(q->index)) keep[i] = 1, decided = true;
                }
            }
        }
    });
    std::vector<Proposal> kept;
    for (std::size_t i = 0; i < count; ++i)
        if (keep[i]) kept.push_back(at(i));
    return kept;
}

// The axis neighbours of `nodes` that stand on another side than at rest (moved by the thin search
// into a thin part, or placed on a feature on the other side), sorted.
std::vector<Vec3i> crossedNeighbours(const Field& field, const LatticeFrame& frame, double iso, const std::vector<Vec3i>& nodes,
                                     const LatticeDeformation& deformation) {
    NodeStates states(deformation);
    std::vector<Coord> around;
    for (const Vec3i& n : nodes)
        for (int k = 0; k < 6; ++k) around.push_back(Coord(n.x, n.y, n.z) + axisStep(k / 2, k % 2 ? 1 : -1));
    std::sort(around.begin(), around.end());
    around.erase(std::unique(around.begin(), around.end()), around.end());
    std::vector<Vec3i> crossed;
    for (const Coord& c : around) {
        if (!states.offsets.isValueOn(c)) continue;
        double rest = 0;
        field.sampleNodes(frame, Vec3i(c.x(), c.y(), c.z()), {1, 1, 1}, nullptr, &rest);
        const bool restInside = isInside(rest, iso, field.inside());
        if (states.inside(c, restInside) != restInside) crossed.emplace_back(c.x(), c.y(), c.z());
    }
    return crossed;
}

// Does the surface around node x (moved across, off the surface) meet the rest of the mesh only at
// points? Crossings on the edges of a node placed on a feature sit on that node, so where every
// loop through x's crossings in its eight cells holds nothing but them and such points (and the
// segments between two such points lie on faces of x's cells), x's part of the surface is closed
// on its own: a bubble touching the rest at feature nodes (a node moved into a step's edge between
// two nodes placed on its faces: 8 triangles apart). `inside(o)` and `placed(o)` tell the side of
// the node at offset o from x and whether it stands on a feature.
template <typename Side, typename Placed> bool meetsOnlyAtFeatureNodes(const Side& inside, const Placed& placed) {
    for (int cell = 0; cell < 8; ++cell) {
        const Coord origin(-(cell & 1), -((cell >> 1) & 1), -((cell >> 2) & 1)); // of the cell, from x
        unsigned config = 0;
        for (int k = 0; k < 8; ++k)
            if (inside(origin.offsetBy(k & 1, (k >> 1) & 1, (k >> 2) & 1))) config |= 1u << k;
        const CubeCase& cube = cubeCase(config);
        // What an edge's crossing is: 0 x's own, 1 + k on the feature node at corner k, 9 another.
        auto vertexOf = [&](int e) {
            const Vec3i o = cubeEdgeOrigin(e);
            const Coord a = origin.offsetBy(o.x, o.y, o.z), b = a + axisStep(cubeEdgeAxis(e), 1);
            if (a == Coord(0, 0, 0) || b == Coord(0, 0, 0)) return 0;
            for (const Coord& n : {a, b})
                if (placed(n)) {
                    const Coord k = n - origin;
                    return 1 + k.x() + 2 * k.y() + 4 * k.z();
                }
            return 9;
        };
        int start = 0;
        for (int l = 0; l < cube.loopCount; start += cube.loopSize[l++]) {
            const std::uint8_t* loop = cube.edges + start;
            const int size = cube.loopSize[l];
            int vertex[12];
            bool throughX = false;
            for (int i = 0; i < size; ++i) {
                vertex[i] = vertexOf(loop[i]);
                throughX = throughX || vertex[i] == 0;
            }
            if (!throughX) continue;
            for (int i = 0; i < size; ++i) {
                if (vertex[i] == 9) return false;
                const int j = (i + 1) % size;
                if (vertex[i] == 0 || vertex[j] == 0 || vertex[i] == vertex[j]) continue;
                // Two feature points: their segment lies on the face the two edges share, which
                // the cell across shares too; unless x is a corner of that face, that cell is not
                // one of x's, and its surface goes on from there.
                const Vec3i oi = cubeEdgeOrigin(loop[i]), oj = cubeEdgeOrigin(loop[j]);
                const int ai = cubeEdgeAxis(loop[i]), aj = cubeEdgeAxis(loop[j]);
                if (ai == aj) return false; // (parallel edges of one loop: not on one face)
                const int normal = 3 - ai - aj; // the face's axis
                const int side = oi[std::size_t(normal)];
                if (oj[std::size_t(normal)] != side) return false;
                if (-origin[normal] != side) return false; // x is not on that face
            }
        }
    }
    return true;
}

bool isCornerOf(const Coord& node, const Coord& cell) {
    const Coord d = node - cell;
    return d.x() >= 0 && d.x() <= 1 && d.y() >= 0 && d.y() <= 1 && d.z() >= 0 && d.z() <= 1;
}

// Is node a corner of the cell or of one of the 26 around it? An acute corner's tip reaches into
// a cell that sees only two of its faces (the third passes the tip by less than a cell); the three
// are seen together only a cell back, where the planes meet outside the cell.
bool nearCell(const Coord& node, const Coord& cell) {
    const Coord d = node - cell;
    return d.x() >= -1 && d.x() <= 2 && d.y() >= -1 && d.y() <= 2 && d.z() >= -1 && d.z() <= 2;
}

} // namespace

void placeSharpFeatures(const Field& field, const Lattice& lattice, const LatticeSurface& surface, const SharpOptions& options,
                        LatticeDeformation& deformation, SharpStats* stats) {
    const auto start = std::chrono::steady_clock::now();
    if (!(options.edgeThreshold >= -1 && options.edgeThreshold <= 1))
        throw Error("--sharp-edge", "must be a cosine between -1 and 1");
    if (!(options.cornerThreshold >= 0 && options.cornerThreshold <= 1))
        throw Error("--sharp-corner", "must be between 0 and 1");
    const LatticeFrame& frame = lattice.frame;
    const double h = frame.h, iso = options.iso;
    const Inside side = field.inside();

    // The proposals of all cells, in no particular order (every step after sorts what it keeps).
    // One growing list in segments: per-task lists merged after were three copies of the
    // proposals' memory (growth, merge), each page of it a fault on fresh memory, and on a noisy
    // surface (the armadillo) most proposals fail later.
    tbb::concurrent_vector<Recorded> recorded;
    struct Local {
        std::uint64_t edgeCells = 0, cornerCells = 0, rejected = 0;
        Vec3d c[12], n[12]; // one cell's crossings and normals (here: not cleared for every cell)
        SampledPlanes::Scratch planes;
    };
    tbb::enumerable_thread_specific<Local> locals;
    // On a grid meshed coarser than its voxels, crossings near a kink take their face's normal.
    std::optional<SampledPlanes> sampledPlanes;
    if (SampledPlanes::appliesTo(field, frame)) sampledPlanes.emplace(field, frame, iso);
    auto within = [&](const Vec3d& p, double cells) {
        Vec3d g;
        const double v = field.valueAndGradient(p, g);
        const double len = length(g);
        if (!(len > 0) || !std::isfinite(len)) return false;
        return std::fabs(v - iso) <= cells * h * len;
    };
    auto nearSurface = [&](const Vec3d& p) { return within(p, kMaxSurfaceDistance); };
    auto facesFlat = [&](const Vec3d& feature, const FieldCheck& check) {
        for (int i = 0; i < check.faceCount; ++i)
            if (!within(0.5 * (feature + check.faces[i]), kMaxFaceBend)) return false;
        return true;
    };

    // An edge or corner belongs to a solid thicker than two cells: that far in along the
    // mean of its faces' outward normals is still inside (convex and concave alike).
    // Across a rod or plate thinner than that the normals turn as fast as at an edge, the
    // feature tests above pass, and a node placed there would pinch the part.
    auto solidBehind = [&](const Vec3d& feature, const Vec3d& outward) {
        const double len = length(outward);
        if (!(len > 1e-9)) return false;
        return isInside(field.value(feature - outward * (kMinThickness * h / len)), iso, side);
    };
    // The field checks of a proposal's point (see FieldCheck).
    auto passesFieldChecks = [&](const Vec3d& point, const FieldCheck& check) {
        return nearSurface(point) && facesFlat(point, check) && solidBehind(point, check.behind);
    };

    // Cells whose corner gradients rule out an edge below the surface's sharpEdgeCosine (the
    // mesher sets it to options.edgeThreshold) are skipped without gathering their crossings.
    surface.forEachSurfaceCell([&](const CellCrossings& cc) {
        Local& local = locals.local();
        Vec3d* c = local.c;
        Vec3d* n = local.n;
        int count = 0;
        const CubeCase& cube = cubeCase(cc.config);
        for (int e = 0; e < 12; ++e) {
            if (!(cube.edgeMask & (1u << e))) continue;
            const Vec3d ne(cc.normal[e]);
            if (dot(ne, ne) < 0.5) continue; // no usable gradient there
            c[count] = Vec3d(cc.position[e]);
            n[count++] = ne;
        }
        // The two most different normals (an edge, if below the edge threshold), and whether two
        // are nearly opposite.
        int a = -1, b = -1;
        bool twoSheets = false;
        auto findEdge = [&] {
            a = b = -1;
            twoSheets = false;
            double theta = options.edgeThreshold;
            for (int i = 0; i < count; ++i)
                for (int j = i + 1; j < count; ++j) {
                    const double d = dot(n[i], n[j]);
                    if (d < theta) {
                        const Vec3d x = cross(n[i], n[j]);
                        if (dot(x, x) >= kMinSine * kMinSine) theta = d, a = i, b = j;
                    }
                    twoSheets = twoSheets || d <= -kOppositeSheets;
                }
        };
        findEdge();
        // (Sampling the faces around costs far more than the cell's own test: only where it shows
        // a feature.)
        if (a >= 0 && !twoSheets && sampledPlanes &&
            sampledPlanes->snap(Vec3i(cc.cell.x(), cc.cell.y(), cc.cell.z()), c, n, count, local.planes) > 0)
            findEdge();
        if (a < 0) return;
        // Two sheets facing away from each other within one cell: a thin part (rod, plate)
        // passes here, and what its curvature makes of the normals is no feature. A node placed
        // on it would pinch the part (a thin rod into beads touching at points). (Nodes the thin
        // search moved are not a sign: it also moves nodes next to a convex corner's tip.)
        if (twoSheets) {
            ++local.rejected;
            return;
        }
        auto insideAt = [&](const Coord& node) {
            const Coord d = node - cc.cell;
            return ((cc.config >> (d.x() + 2 * d.y() + 4 * d.z())) & 1u) != 0;
        };
        // Records a proposal whose geometry stands. Its field checks are made now (`defer` false:
        // the cell's further proposals depend on them), or when a neighbour confirms it.
        auto record = [&](const Proposal& p, const FieldCheck& check, bool defer) {
            if (!defer && !passesFieldChecks(p.point, check)) {
                ++local.rejected;
                return false;
            }
            recorded.push_back({p, defer ? check : FieldCheck(), defer ? kUnchecked : kPassed});
            return true;
        };
        // Does a shallow corner's neighbourhood lie on its three planes: the lines where two meet
        // on the surface a cell from it (to one side: the edge), and each face a cell and a half
        // out between its two edges? One line may miss: where the three faces are of a four-face
        // apex (a low pyramid's), two of them are opposite and meet at the point alone. Where
        // faces merely curve, the tangent planes and their lines leave the surface that far out.
        auto facesAround = [&](const Vec3d& corner, const int* face) {
            Vec3d e[3];
            bool edge[3];
            int edges = 0;
            for (int u = 0; u < 3; ++u) {
                e[u] = normalized(cross(n[face[u]], n[face[(u + 1) % 3]]));
                edge[u] = true;
                if (within(corner + e[u] * h, kShallowEdgeBend)) { ++edges; continue; }
                e[u] = -e[u];
                if (within(corner + e[u] * h, kShallowEdgeBend)) { ++edges; continue; }
                edge[u] = false;
            }
            if (edges < 2) return false;
            for (int u = 0; u < 3; ++u) { // face u lies between edges u and u + 2
                if (!edge[u] || !edge[(u + 2) % 3]) continue;
                const Vec3d between = e[u] + e[(u + 2) % 3];
                if (dot(between, between) < 1e-6) return false; // (edges in line: no face between)
                if (!within(corner + normalized(between) * (kShallowFaceReach * h), kShallowFaceBend)) return false;
            }
            return true;
        };
        // A corner where the planes of crossings i, j, k meet (and l's, if l >= 0: an apex of four
        // faces, as an octahedron's), for the cell corner nearest it.
        auto proposeCorner = [&](int i, int j, int k, bool defer, int l = -1, bool shallow = false) {
            ++local.cornerCells;
            int face[4] = {i, j, k, l};
            auto normalsBut = [&](int out, Vec3d* t) { // the normals of the four faces but face[out]
                for (int q = 0, m = 0; q < 4; ++q)
                    if (q != out) t[m++] = n[face[q]];
            };
            if (l >= 0) {
                // The three planes that meet at the steepest angles give the point; the fourth
                // must pass through it too, or the cell holds more than one feature.
                double best = -1;
                int left = 3;
                for (int out = 0; out < 4; ++out) {
                    Vec3d t[3];
                    normalsBut(out, t);
                    const double det = std::fabs(dot(t[0], cross(t[1], t[2])));
                    if (det > best) best = det, left = out;
                }
                std::swap(face[left], face[3]);
            }
            const Vec3d planes[3] = {n[face[0]], n[face[1]], n[face[2]]};
            const double rhs[3] = {dot(planes[0], c[face[0]]), dot(planes[1], c[face[1]]), dot(planes[2], c[face[2]])};
            Vec3d corner;
            if (!intersectPlanes(planes, rhs, corner) || !nearCell(nearestNode(frame, corner), cc.cell) ||
                (l >= 0 && std::fabs(dot(n[face[3]], corner - c[face[3]])) > kMaxFaceBend * h)) {
                ++local.rejected;
                return false;
            }
            if (shallow && !facesAround(corner, face)) {
                ++local.rejected;
                return false;
            }
            Proposal p;
            p.cell = cc.cell;
            p.config = cc.config;
            p.kind = 0;
            p.needsEdge = shallow;
            p.node = nearestNode(frame, corner);
            p.point = corner;
            p.distance = length(corner - frame.nodeWorld(Vec3i(p.node.x(), p.node.y(), p.node.z())));
            p.inside = isCornerOf(p.node, cc.cell) && insideAt(p.node); // (else: set below)
            // The solid behind a corner is probed at one angle to its faces (n · d = 1 for three:
            // d points out of the solid's cone, whatever the corner's shape). Their normals' sum
            // can point out of an acute corner: at a shallow pyramid's base corner, through the
            // base, and the corner was rejected. At four faces, of the four triples' directions
            // (and the sum) the one farthest from every face's plane.
            const double ones[3] = {1, 1, 1};
            Vec3d behind = planes[0] + planes[1] + planes[2];
            if (l < 0) {
                Vec3d d;
                if (intersectPlanes(planes, ones, d)) behind = d;
            } else {
                auto leastAngle = [&](const Vec3d& d) {
                    double m = INFINITY;
                    for (int f : face) m = std::min(m, dot(n[f], d));
                    return m / length(d);
                };
                behind += n[face[3]];
                double best = leastAngle(behind);
                for (int out = 0; out < 4; ++out) {
                    Vec3d triple[3], d;
                    normalsBut(out, triple);
                    if (!intersectPlanes(triple, ones, d)) continue;
                    const double a = leastAngle(d);
                    if (a > best) best = a, behind = d;
                }
            }
            return record(p, FieldCheck{{c[face[0]], c[face[1]], c[face[2]]}, 3, behind}, defer);
        };
        // The edge where the planes of crossings i and j meet, placed along the line at `along`
        // (a point whose projection fixes where on the line the cell is): the cell corner whose
        // projection onto the line stays in its Ω and is nearest. (The other corners whose Ω the
        // line crosses are the second round's.)
        auto proposeEdge = [&](int i, int j, const Vec3d& along, bool defer) {
            ++local.edgeCells;
            const Vec3d edgeDir = normalized(cross(n[i], n[j]));
            const Vec3d planes[3] = {n[i], n[j], edgeDir};
            const double rhs[3] = {dot(n[i], c[i]), dot(n[j], c[j]), dot(edgeDir, along)};
            Vec3d onLine;
            if (!intersectPlanes(planes, rhs, onLine)) {
                ++local.rejected;
                return false;
            }
            Proposal p;
            p.cell = cc.cell;
            p.config = cc.config;
            p.kind = 1;
            p.direction = edgeDir;
            p.onLine = onLine;
            p.outward = n[i] + n[j];
            double best = INFINITY;
            for (int k = 0; k < 8; ++k) {
                const Coord node = cc.cell.offsetBy(k & 1, (k >> 1) & 1, (k >> 2) & 1);
                const Vec3d rest = frame.nodeWorld(Vec3i(node.x(), node.y(), node.z()));
                const Vec3d q = onLine + edgeDir * dot(edgeDir, rest - onLine);
                const double dist = length(q - rest);
                if (nearestNode(frame, q) != node || dist >= best) continue;
                best = dist;
                p.node = node;
                p.point = q;
                p.distance = dist;
            }
            if (!(best < INFINITY)) {
                ++local.rejected;
                return false;
            }
            p.inside = insideAt(p.node);
            return record(p, FieldCheck{{c[i], c[j], Vec3d()}, 2, p.outward}, defer);
        };

        const Vec3d edgeDir = normalized(cross(n[a], n[b]));
        int third = -1;
        double phi = options.cornerThreshold;
        for (int i = 0; i < count; ++i) {
            if (i == a || i == b) continue;
            const double d = std::fabs(dot(n[i], edgeDir));
            if (d > phi) phi = d, third = i;
        }
        // Else a shallow corner: a third plane of its own (kShallowCornerShare).
        bool shallow = false;
        if (third < 0) {
            double least = kShallowCornerShare * options.cornerThreshold;
            for (int i = 0; i < count; ++i) {
                if (i == a || i == b || dot(n[i], n[a]) >= kFaceNormalAgreement || dot(n[i], n[b]) >= kFaceNormalAgreement) continue;
                const double d = std::fabs(dot(n[i], edgeDir));
                if (d >= least) least = d, third = i, shallow = true;
            }
        }
        // A fourth face through the corner (an apex of four faces: a pyramid's or an octahedron's)
        // shows as crossings whose normals agree with none of the three; the first of them stands
        // for it, and the corner is proposed from all four.
        int fourth = -1;
        if (third >= 0)
            for (int i = 0; i < count && fourth < 0; ++i)
                if (dot(n[i], n[a]) < kFaceNormalAgreement && dot(n[i], n[b]) < kFaceNormalAgreement &&
                    dot(n[i], n[third]) < kFaceNormalAgreement)
                    fourth = i;
        // Every crossing's normal must agree with a defining crossing's (else: curvature). Whether
        // it also lies on that plane (within kMaxFaceBend) tells what normals cannot: two parallel
        // faces less than a cell apart (a notch's floor and the face it is cut into), so two
        // features in the cell, of which the proposal below finds only one.
        auto liesOn = [&](int i, int k) { return std::fabs(dot(n[k], c[i] - c[k])) <= kMaxFaceBend * h; }; // i on k's plane
        bool normalsAgree = true, onPlanes = true;
        for (int i = 0; i < count; ++i) {
            bool agrees = false, on = false;
            for (int k : {a, b, third, fourth}) {
                if (k < 0 || dot(n[i], n[k]) < kFaceNormalAgreement) continue;
                agrees = true;
                on = on || liesOn(i, k);
            }
            normalsAgree = normalsAgree && agrees;
            onPlanes = onPlanes && on;
        }
        if (!normalsAgree) {
            ++local.rejected;
            return;
        }
        // Two features in one cell (a step or a notch less than a cell deep) show three or four
        // planes, one of them met by two crossings or more; more planes, or each crossing on a
        // plane of its own, is a curved or noisy surface, where the one proposal below stands.
        int plane[12], rep[12], planes = 0;
        if (!onPlanes) {
            for (int i = 0; i < count; ++i) {
                plane[i] = -1;
                for (int k = 0; k < planes && plane[i] < 0; ++k)
                    if (dot(n[i], n[rep[k]]) >= kFaceNormalAgreement && liesOn(i, rep[k]))
                        plane[i] = k;
                if (plane[i] < 0) rep[planes] = i, plane[i] = planes++;
            }
        }
        Vec3d mean;
        for (int i = 0; i < count; ++i) mean += c[i];
        // Most cells (all on a curved or noisy surface) stop at one proposal, whose field checks
        // wait until a neighbour confirms it; a cell that may hold two features needs them now.
        const bool alone = onPlanes || planes > kMaxPlanes || planes == count;
        // A shallow corner waits for its confirmation. (Without it the cell has no feature: its
        // third plane's normals agree with neither of the edge's.)
        if (shallow) {
            proposeCorner(a, b, third, true, fourth, true);
            return;
        }
        const bool proposed =
            third >= 0 ? proposeCorner(a, b, third, alone, fourth) : proposeEdge(a, b, mean / double(count), alone);
        if (!proposed || alone) return;
        // Then every other corner three of the planes make is proposed (or, if none, every edge
        // two make): where the proposal above passed, the cell holds a true feature and its
        // planes are worth the field checks.
        auto meets = [&](int i, int j) { // an edge's two faces
            const Vec3d x = cross(n[i], n[j]);
            return dot(n[i], n[j]) < options.edgeThreshold && dot(x, x) >= kMinSine * kMinSine;
        };
        bool anyCorner = false;
        for (int x = 0; x < planes; ++x)
            for (int y = x + 1; y < planes; ++y)
                for (int z = y + 1; z < planes; ++z) {
                    const int i = rep[x], j = rep[y], k = rep[z];
                    if (!meets(i, j) || !meets(i, k) || !meets(j, k)) continue;
                    if (std::fabs(dot(n[k], normalized(cross(n[i], n[j])))) <= options.cornerThreshold) continue;
                    anyCorner = proposeCorner(i, j, k, false) || anyCorner;
                }
        if (anyCorner) return;
        for (int x = 0; x < planes; ++x)
            for (int y = x + 1; y < planes; ++y) {
                const int i = rep[x], j = rep[y];
                if (!meets(i, j)) continue;
                Vec3d mean;
                int m = 0;
                for (int u = 0; u < count; ++u)
                    if (plane[u] == x || plane[u] == y) mean += c[u], ++m;
                proposeEdge(i, j, mean / double(m), false);
            }
    }, /*onlySharpCandidates=*/true);

    SharpStats out;
    for (Local& l : locals) {
        out.edgeCells += l.edgeCells;
        out.cornerCells += l.cornerCells;
        out.rejected += l.rejected;
    }
    std::vector<std::atomic<std::uint8_t>> status(recorded.size());
    for (std::size_t i = 0; i < recorded.size(); ++i) status[i].store(recorded[i].status, std::memory_order_relaxed);
    auto proposal = [&](std::size_t i) -> const Proposal& { return recorded[i].proposal; };
    auto passes = [&](std::size_t i) {
        std::uint8_t s = status[i].load(std::memory_order_relaxed);
        if (s == kUnchecked) {
            s = passesFieldChecks(recorded[i].proposal.point, recorded[i].check) ? kPassed : kFailed;
            status[i].store(s, std::memory_order_relaxed);
        }
        return s == kPassed;
    };
    std::vector<Proposal> all = confirmedByNeighbours(recorded.size(), proposal, h, passes);
    {
        // A corner whose node is not one of its cell's corners takes the node's side from the
        // lattice as the thin search left it (a cell's case tells only its own corners).
        NodeStates states(deformation);
        for (Proposal& p : all) {
            if (isCornerOf(p.node, p.cell)) continue;
            double rest = 0;
            field.sampleNodes(frame, Vec3i(p.node.x(), p.node.y(), p.node.z()), {1, 1, 1}, nullptr, &rest);
            p.inside = states.inside(p.node, isInside(rest, iso, side));
        }
    }
    // (Each proposal not kept was rejected once: by its field checks or for want of a second view.)
    out.rejected += recorded.size() - all.size();
    tbb::parallel_sort(all.begin(), all.end());
    // One proposal a node (the best), then corners before edges, so that an edge node never
    // takes the crossing a corner node needs.
    all.erase(std::unique(all.begin(), all.end(), [](const Proposal& x, const Proposal& y) { return x.node == y.node; }), all.end());
    std::stable_partition(all.begin(), all.end(), [](const Proposal& x) { return x.kind == 0; });

    constexpr int kNeighbours[6] = {4, 10, 12, 14, 16, 22}; // in the 3^3 block around the node
    // Placed on its feature, a node carries the crossings of its edges to the other side: they
    // move onto the feature's point, and the surface runs from the point to the crossings around.
    // That is the feature only where each of those crossings lies on a face through the point (its
    // tangent plane passes the point). A crossing on another face is a part of the shape the node
    // alone stands for: a notch about a cell deep whose one outside node reaches the notch's rim
    // (a corner there, or where a concave edge meets the face) took the notch's far walls with it
    // onto the rim, and the mesh ran flush over the notch. Decided on the lattice as the thin
    // search left it (`around`: the values at rest of the 27 nodes around the proposal's node).
    const bool linearEdges = field.edgesAreLinear(frame);
    auto crossingsOnFeatureFaces = [&](const Proposal& p, const double* around, const OffsetAccessor& moved) {
        // Node c (27-block index k) where it stands, and its value there.
        auto position = [&](const Coord& c, int k, double& value, bool& atRest) {
            openvdb::Vec3f o;
            const Vec3d rest = frame.nodeWorld(Vec3i(c.x(), c.y(), c.z()));
            atRest = !moved.probeValue(c, o);
            if (atRest) return value = around[k], rest;
            const Vec3d at = rest + Vec3d(o.x(), o.y(), o.z());
            value = field.value(at);
            return at;
        };
        double va = 0;
        bool aAtRest = true;
        const Vec3d a = position(p.node, 13, va, aAtRest);
        const bool aInside = isInside(va, iso, side);
        for (int j = 0; j < 6; ++j) {
            const int k = kNeighbours[j];
            double vb = 0;
            bool bAtRest = true;
            const Vec3d b = position(p.node.offsetBy(k % 3 - 1, (k / 3) % 3 - 1, k / 9 - 1), k, vb, bAtRest);
            if (isInside(vb, iso, side) == aInside) continue;
            // Along an undeformed edge of a grid at its voxel size the field is linear (the
            // surface finds its crossings there so).
            const double t = linearEdges && aAtRest && bAtRest ? (iso - va) / (vb - va) : field.edgeCrossing(a, b, va, vb, iso);
            const Vec3d c = a + (b - a) * t;
            const double reach = kCollapseBend * std::max(h, length(p.point - c));
            if (length(p.point - c) <= reach) continue; // no plane through c can miss the point by more
            const Vec3d g = field.gradient(c);
            const double len = length(g);
            if (!(len > 0) || !std::isfinite(len)) continue;
            if (std::fabs(dot(g, p.point - c)) / len > reach) return false;
        }
        return true;
    };
    // The field's side at rest at the 27 nodes around each proposal's node does not depend on the
    // order below: sampled first, in parallel (bit k: node k of the 3^3 block is inside). With
    // `keepsFaces`, whether the proposal passes crossingsOnFeatureFaces too.
    auto sampleNeighbours = [&](const std::vector<Proposal>& proposals, std::vector<std::uint8_t>* keepsFaces) {
        std::vector<std::uint32_t> bits(proposals.size(), 0);
        if (keepsFaces) keepsFaces->assign(proposals.size(), 1);
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, proposals.size(), 64), [&](const tbb::blocked_range<std::size_t>& r) {
            OffsetAccessor moved(*deformation.offsets);
            double around[27];
            for (std::size_t i = r.begin(); i < r.end(); ++i) {
                const Coord& n = proposals[i].node;
                field.sampleNodes(frame, Vec3i(n.x() - 1, n.y() - 1, n.z() - 1), {3, 3, 3}, nullptr, around);
                for (int k = 0; k < 27; ++k)
                    if (isInside(around[k], iso, side)) bits[i] |= 1u << k;
                if (keepsFaces) (*keepsFaces)[i] = crossingsOnFeatureFaces(proposals[i], around, moved);
            }
        });
        if (options.cancel) options.cancel->check();
        return bits;
    };
    // One set of accessors for the serial loops below (bridging writes the trees in between:
    // cleared after it).
    openvdb::tree::ValueAccessor<OffsetTree> offsets(*deformation.offsets);
    openvdb::tree::ValueAccessor<NodeMaskTree> onSurface(*deformation.onSurface);
    openvdb::tree::ValueAccessor<NodeMaskTree> insideOnSurface(*deformation.insideOnSurface);
    auto place = [&](const Proposal& p, bool inside) {
        const Vec3d rest = frame.nodeWorld(Vec3i(p.node.x(), p.node.y(), p.node.z()));
        const Vec3f off(p.point - rest);
        offsets.setValue(p.node, openvdb::Vec3f(off.x, off.y, off.z));
        onSurface.setValueOn(p.node);
        if (inside) insideOnSurface.setValueOn(p.node);
        (p.kind == 0 ? out.nodesOnCorners : out.nodesOnEdges) += 1;
    };
    // How many of p's six neighbours lie on the other side now (placed nodes by the side they
    // keep, moved nodes on the side they moved to), whether one of them already sits on a
    // feature across the edge between them (that edge's one vertex cannot be at both), and
    // whether one was taken across to p's side (by the thin search, or placed on that side: a
    // node the thin search moved into a rod and this pass then placed at the rod's root, where
    // an unmoved neighbour was flipped next, cut the rod off).
    auto neighbourSides = [&](const Proposal& p, std::uint32_t insideAround, bool& sharesCrossing, bool& takenAcross) {
        int otherSide = 0;
        sharesCrossing = takenAcross = false;
        for (int j = 0; j < 6; ++j) {
            const int k = kNeighbours[j];
            const Coord nb = p.node.offsetBy(k % 3 - 1, (k / 3) % 3 - 1, k / 9 - 1);
            bool inside = (insideAround >> k) & 1u;
            if (onSurface.isValueOn(nb)) {
                const bool atRest = inside;
                inside = insideOnSurface.isValueOn(nb);
                sharesCrossing = sharesCrossing || inside != p.inside;
                takenAcross = takenAcross || (inside == p.inside && inside != atRest);
            } else if (offsets.isValueOn(nb)) {
                inside = !inside; // moved into a thin part
                takenAcross = takenAcross || inside == p.inside;
            }
            otherSide += inside != p.inside;
        }
        return otherSide;
    };
    // The sides of the 27 nodes around `node` now (bit k: node k of its 3^3 block is inside),
    // from their sides at rest.
    auto sidesNow = [&](const Coord& node, std::uint32_t atRest) {
        std::uint32_t now = atRest;
        for (int k = 0; k < 27; ++k) {
            const Coord nb = node.offsetBy(k % 3 - 1, (k / 3) % 3 - 1, k / 9 - 1);
            bool inside = (atRest >> k) & 1u;
            if (onSurface.isValueOn(nb)) inside = insideOnSurface.isValueOn(nb);
            else if (offsets.isValueOn(nb)) inside = !inside;
            now = inside ? now | (1u << k) : now & ~(1u << k);
        }
        return now;
    };
    // Placed on its feature, a node is a vertex of the surface, where the crossings of all its
    // edges meet: the surface around it is one disc only where the nodes around it on each side
    // form one group. A node flipped where they form two (joined by the mesher's own rule: inside
    // nodes across cube faces, outside ones across face diagonals too) joined two parts of a side
    // through it: a tunnel under a thin fin's root (the outside on both sides of the fin; 15 of 60
    // random fins 0.2-0.6 H thick), a rod cut off at its root (the inside of the rod and of the
    // ball it stands on). A node that keeps its side needs one group of its own side only, and
    // counted loosely (inside across face diagonals, outside across any corner): around a tip or
    // a corner its side's nodes often meet across a diagonal (a tetrahedron's tips, a pyramid's
    // base corners, a notch's corner were lost counted strictly), but a node moved into a rod and
    // placed at its root, with the rod's nodes above it and the ball's below, cut the rod off.
    auto splitsLink = [&](const Proposal& p, bool flip, std::uint32_t now) {
        if (flip) return groupsAround(now, true, 6) > 1 || groupsAround(now, false, 18) > 1;
        return groupsAround(now, p.inside, p.inside ? 18 : 26) > 1;
    };
    // Counted loosely, a node's side can meet round it across a diagonal that marching cubes
    // never joins: a wedge's thin edge, a row of inside nodes beside the solid, joined to it
    // beyond the node only along the row, came off as a piece of its own (welded, the row's
    // tube met the node from both ends: two fans, split apart; 1 of 70 random wedges). So a node
    // that keeps its side must also leave the topology of the surface round it as it was once
    // its crossings are welded into it (weldAtCentre; a flipped node is joined by bridging after).
    // (A function of the 27 sides alone, asked for most nodes placed: a surface repeats few of
    // them, and the count allocates, so each is counted once. A node with one crossing has
    // nothing to weld.)
    std::unordered_map<std::uint32_t, bool> weldCuts;
    auto pinches = [&](const Proposal& p, int otherSide, std::uint32_t now) {
        if (otherSide < 2) return false;
        const std::uint32_t sides = p.inside ? now | (1u << 13) : now & ~(1u << 13);
        const auto known = weldCuts.find(sides);
        if (known != weldCuts.end()) return known->second;
        bool block[27];
        for (int k = 0; k < 27; ++k) block[k] = (sides >> k) & 1u;
        return weldCuts[sides] = !weldAtCentre(block).keepsTopology();
    };

    // The nodes as the thin search left them, for flips undone below.
    LatticeDeformation before;
    before.offsets = std::make_shared<OffsetTree>(*deformation.offsets);
    before.onSurface = std::make_shared<NodeMaskTree>(*deformation.onSurface);
    before.insideOnSurface = std::make_shared<NodeMaskTree>(*deformation.insideOnSurface);
    std::vector<std::uint8_t> keepsFaces;
    const std::vector<std::uint32_t> insideAround = sampleNeighbours(all, &keepsFaces);
    std::vector<Vec3i> flipped;
    // Where the thin search had put a flipped node (into a crack, off a thin part): a flip that is
    // undone goes back there, not to rest, where it is on the other side (at a crack's rim, a node
    // of one half alone beside the crack: a bubble of 6 vertices).
    std::vector<std::pair<Coord, openvdb::Vec3f>> movedBeforeFlip;
    std::vector<Proposal> placedFirst; // in node order
    for (std::size_t i = 0; i < all.size(); ++i) {
        const Proposal& p = all[i];
        bool sharesCrossing = false, takenAcross = false;
        const int otherSide = neighbourSides(p, insideAround[i], sharesCrossing, takenAcross);
        // A node with no edge to the other side carries no crossing: placed on the feature as it
        // is, it would change nothing. It changes side instead (the feature's tip is a thin part
        // of the other side) and is joined to that side by bridging below — unless it has no
        // such edge only because the thin search took its neighbours across: then what lies
        // between is a thin part of its own side (a crack's rim: the outside node beyond a ball
        // whose neighbours on the rim went into the crack, flipped onto the rim's edge, made a
        // tunnel under it in 11 of 120 random cracks 0.2-0.5 H wide, 3 of 60 at 0.5-1 H).
        const bool flip = otherSide == 0;
        if (otherSide == 6 || sharesCrossing || !keepsFaces[i] || (flip && takenAcross)) {
            ++out.rejected;
            continue;
        }
        const std::uint32_t now = sidesNow(p.node, insideAround[i]);
        if (splitsLink(p, flip, now) || (!flip && pinches(p, otherSide, now))) {
            ++out.rejected;
            continue;
        }
        openvdb::Vec3f before;
        if (flip && offsets.probeValue(p.node, before)) movedBeforeFlip.emplace_back(p.node, before);
        place(p, flip ? !p.inside : p.inside);
        placedFirst.push_back(p);
        if (flip) flipped.emplace_back(p.node.x(), p.node.y(), p.node.z());
    }
    if (!flipped.empty()) {
        ThinSearchOptions to;
        to.iso = iso;
        to.steps = options.searchSteps;
        to.cancel = options.cancel;
        to.keepFeatureNodes = options.edgeThreshold;
        out.changedNodes = flipped;
        out.bridged = bridgeThinParts(field, lattice, to, deformation, flipped, nullptr, &out.changedNodes);
        std::vector<Vec3i> bridged = out.changedNodes;
        std::sort(bridged.begin(), bridged.end(), lessXYZ);
        // A flipped node is a join too: a tip of the other side that bridging could not join to it
        // is a bubble (at a crack's rim: 4 or 8 triangles beside the crack). So is a node next to
        // a flipped or bridged one that had been taken across to its side (by the thin search, or
        // placed here on that side) and hung on it: the flip left it alone there (a notch's node
        // moved into the wedge between the notch's wall and the face it is cut into, held by the
        // node the notch's corner flipped: a bubble of 8 triangles on the wall).
        std::vector<Vec3i> joins = out.changedNodes;
        const std::vector<Vec3i> hanging = crossedNeighbours(field, frame, iso, out.changedNodes, deformation);
        joins.insert(joins.end(), hanging.begin(), hanging.end());
        std::vector<std::pair<Coord, openvdb::Vec3f>> backToThinSearch;
        for (const Vec3i& r : restoreLoneJoins(field, frame, iso, joins, deformation)) {
            const auto placed = std::find_if(placedFirst.begin(), placedFirst.end(), [&](const Proposal& p) {
                return p.node == Coord(r.x, r.y, r.z);
            });
            if (placed != placedFirst.end()) (placed->kind == 0 ? out.nodesOnCorners : out.nodesOnEdges) -= 1;
            const auto f = std::find(flipped.begin(), flipped.end(), r);
            if (f != flipped.end()) {
                for (const auto& m : movedBeforeFlip)
                    if (m.first == Coord(r.x, r.y, r.z)) backToThinSearch.push_back(m);
                flipped.erase(f);
            } else if (std::binary_search(bridged.begin(), bridged.end(), r, lessXYZ)) {
                --out.bridged;
            } else {
                ++out.unhung;
                out.changedNodes.push_back(r);
            }
        }
        offsets.clear();
        onSurface.clear();
        insideOnSurface.clear();
        for (const auto& m : backToThinSearch) offsets.setValue(m.first, m.second);
        // Each flip and its bridge make a tip of one side longer, which changes nothing about the
        // inside's topology. Where flips of both sides meet (a notch under two cells, where the
        // concave corner's node flips out and the rim's corners' flip in), their bridges can pass
        // round each other: a handle (9 of 200 random notched boxes). In each group of changed
        // nodes (joined across any corner) whose changes alter the inside's Euler characteristic,
        // the nodes that went to one side go back as they were before the flips — the side with
        // fewer, if that mends it, else the other, else all.
        std::vector<Vec3i> changed = out.changedNodes;
        changed.insert(changed.end(), flipped.begin(), flipped.end());
        RestSides rest(field, frame, iso);
        for (const std::vector<Vec3i>& group : groupsAcrossCorners(changed)) {
            NodeStates now(deformation), was(before);
            auto insideNow = [&](const Vec3i& n) { return now.inside(Coord(n.x, n.y, n.z), rest.inside(n)); };
            auto insideBefore = [&](const Vec3i& n) { return was.inside(Coord(n.x, n.y, n.z), rest.inside(n)); };
            const int prior = insideEulerAround(group, insideBefore);
            if (insideEulerAround(group, insideNow) == prior) continue;
            std::vector<Vec3i> wentIn, wentOut;
            for (const Vec3i& n : group)
                if (insideNow(n) != insideBefore(n)) (insideNow(n) ? wentIn : wentOut).push_back(n);
            if (wentOut.size() < wentIn.size()) std::swap(wentIn, wentOut);
            std::vector<Vec3i> undo = group;
            for (const std::vector<Vec3i>* part : {&wentIn, &wentOut}) {
                if (part->empty() || part->size() == group.size()) continue;
                auto mended = [&](const Vec3i& n) {
                    return std::binary_search(part->begin(), part->end(), n, lessXYZ) ? insideBefore(n) : insideNow(n);
                };
                if (insideEulerAround(group, mended) == prior) {
                    undo = *part;
                    break;
                }
            }
            for (const Vec3i& n : undo) {
                out.flipsUndone += insideNow(n) != insideBefore(n);
                const Coord c(n.x, n.y, n.z);
                const auto placed = std::find_if(placedFirst.begin(), placedFirst.end(), [&](const Proposal& p) { return p.node == c; });
                if (placed != placedFirst.end() && onSurface.isValueOn(c)) (placed->kind == 0 ? out.nodesOnCorners : out.nodesOnEdges) -= 1;
                const auto f = std::find(flipped.begin(), flipped.end(), n);
                if (f != flipped.end()) flipped.erase(f);
                else if (std::binary_search(bridged.begin(), bridged.end(), n, lessXYZ)) --out.bridged;
                openvdb::Vec3f offset;
                if (was.offsets.probeValue(c, offset)) offsets.setValue(c, offset);
                else offsets.setValueOff(c, openvdb::Vec3f(0.0f));
                onSurface.setValueOff(c);
                insideOnSurface.setValueOff(c);
            }
        }
    }

    // Second round, along edges. One node a cell leaves gaps where an edge runs between nodes
    // that no cell chose (a line through a row of cells picks the same few nodes from each), and
    // the mesh cuts across the edge there by up to half a cell — most on concave edges, where the
    // solid's 270° leaves fewer cells whose crossings show both faces. Every other node whose Ω
    // the edge's line crosses moves onto it now, if another cell confirms the line (a node placed
    // in the first round from another cell, next to this one, lies on it: on curved surfaces the
    // tangent planes of neighbouring cells meet on different lines, and following each one's
    // line off its cell would only add false edges), the node still stands where it did (not
    // placed, not moved), has an edge to the other side (it keeps its side: no case changes)
    // and shares no crossing with a node placed across it. Only the first round flips nodes.
    std::sort(placedFirst.begin(), placedFirst.end(), [](const Proposal& x, const Proposal& y) { return x.node < y.node; });
    // The candidates: the other nodes of an edge proposal's cell whose Ω its line crosses, from
    // every edge proposal that passes the field checks (confirmed or not: a placed node is the
    // second view here), where the node is free and a node placed in the first round from another
    // cell, next to it, lies on the line. Such a placed node lies in [C - 1, C + 2]^3 of the
    // proposal's cell C: they are gathered once a proposal (a few at most), and a proposal with
    // none on its line needs no field checks. First, the 4^3 blocks of cells with a placed node in
    // reach are marked (dilating the placed nodes in OpenVDB cost more than the whole round): one
    // probe skips most proposals of a noisy surface.
    auto block = [](const Coord& c) { return Coord(c.x() >> 2, c.y() >> 2, c.z() >> 2); };
    NodeMaskTree nearPlaced;
    {
        openvdb::tree::ValueAccessor<NodeMaskTree> mark(nearPlaced);
        for (const Proposal& p : placedFirst) {
            const Coord lo = block(p.node.offsetBy(-2)), hi = block(p.node.offsetBy(1));
            for (int z = lo.z(); z <= hi.z(); ++z)
                for (int y = lo.y(); y <= hi.y(); ++y)
                    for (int x = lo.x(); x <= hi.x(); ++x) mark.setValueOn(Coord(x, y, z));
        }
    }
    const double lineTolerance = kOnConfirmedLine * h;
    tbb::enumerable_thread_specific<std::vector<Proposal>> alongLocal;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, recorded.size(), 256), [&](const tbb::blocked_range<std::size_t>& r) {
        openvdb::tree::ValueAccessor<const OffsetTree> moved(*deformation.offsets);
        openvdb::tree::ValueAccessor<const NodeMaskTree> placed(*deformation.onSurface), near(nearPlaced);
        std::vector<Proposal>& mine = alongLocal.local();
        const Proposal* placedOnLine[64];
        for (std::size_t i = r.begin(); i < r.end(); ++i) {
            const Proposal& p = proposal(i);
            if (p.kind != 1 || !near.isValueOn(block(p.cell))) continue;
            // The candidates' points are other points of this line: a hair of slack for rounding
            // keeps every node the exact test below may accept.
            const double slack = 1e-9 * (h + std::max({std::fabs(p.onLine.x), std::fabs(p.onLine.y), std::fabs(p.onLine.z)}));
            // placedFirst is in node order (x, then y, then z): in each of the block's four planes
            // of x, its nodes lie in one run of the list, from a search for the block's first
            // column to the end of its last (rows of other z between: few, even on a box's face).
            int count = 0;
            const Coord lo = p.cell.offsetBy(-1, -1, -1), hi = p.cell.offsetBy(2, 2, 2);
            for (int x = lo.x(); x <= hi.x(); ++x)
                for (auto it = std::lower_bound(placedFirst.begin(), placedFirst.end(), Coord(x, lo.y(), lo.z()),
                                                [](const Proposal& q, const Coord& c) { return q.node < c; });
                     it != placedFirst.end() && !(Coord(x, hi.y(), hi.z()) < it->node); ++it) {
                    const Coord& n = it->node;
                    if (n.z() < lo.z() || n.z() > hi.z()) continue;
                    // (A node bridging took back is in the list but no longer placed.)
                    if (it->cell == p.cell || !placed.isValueOn(n)) continue;
                    if (distanceToLine(it->point, p.onLine, p.direction) <= lineTolerance + slack) placedOnLine[count++] = &*it;
                }
            if (count == 0 || !passes(i)) continue;
            for (int k = 0; k < 8; ++k) {
                const Coord node = p.cell.offsetBy(k & 1, (k >> 1) & 1, (k >> 2) & 1);
                if (node == p.node || moved.isValueOn(node) || placed.isValueOn(node)) continue;
                const Vec3d rest = frame.nodeWorld(Vec3i(node.x(), node.y(), node.z()));
                Vec3d q;
                if (!closestOnLineInOmega(p.onLine, p.direction, rest, h, q)) continue;
                bool confirmed = false;
                for (int j = 0; j < count && !confirmed; ++j) {
                    const Coord d = placedOnLine[j]->node - node;
                    confirmed = std::abs(d.x()) <= 1 && std::abs(d.y()) <= 1 && std::abs(d.z()) <= 1 &&
                                distanceToLine(placedOnLine[j]->point, q, p.direction) <= lineTolerance;
                }
                if (!confirmed) continue;
                Proposal e = p;
                e.node = node;
                e.point = q;
                e.distance = length(q - rest);
                e.inside = ((p.config >> k) & 1u) != 0;
                mine.push_back(e);
            }
        }
    });
    std::vector<Proposal> along;
    for (const std::vector<Proposal>& l : alongLocal) along.insert(along.end(), l.begin(), l.end());
    tbb::parallel_sort(along.begin(), along.end());
    along.erase(std::unique(along.begin(), along.end(), [](const Proposal& x, const Proposal& y) { return x.node == y.node; }), along.end());
    // The field checks of the first round, for the nearest confirmed line of each node only
    // (decided in parallel; the order stays).
    {
        std::vector<std::uint8_t> keep(along.size(), 0);
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, along.size(), 64), [&](const tbb::blocked_range<std::size_t>& r) {
            for (std::size_t i = r.begin(); i < r.end(); ++i) keep[i] = nearSurface(along[i].point) && solidBehind(along[i].point, along[i].outward);
        });
        std::size_t kept = 0;
        for (std::size_t i = 0; i < along.size(); ++i)
            if (keep[i]) along[kept++] = along[i];
        along.resize(kept);
    }
    const std::vector<std::uint32_t> alongAround = sampleNeighbours(along, nullptr);
    for (std::size_t i = 0; i < along.size(); ++i) {
        bool sharesCrossing = false, takenAcross = false;
        const int otherSide = neighbourSides(along[i], alongAround[i], sharesCrossing, takenAcross);
        if (otherSide == 0 || otherSide == 6 || sharesCrossing) continue;
        if (otherSide >= 2 && pinches(along[i], otherSide, sidesNow(along[i].node, alongAround[i]))) continue;
        place(along[i], along[i].inside);
        ++out.nodesAlongEdges;
    }
    // Last, nodes moved across whose surface the placed nodes around them have closed off
    // (meetsOnlyAtFeatureNodes) go back to rest; decided on one state, then applied.
    std::vector<Vec3i> closedOff;
    {
        std::vector<Coord> candidates;
        {
            // Moved nodes off the surface beside one on it, found from the moved side: those
            // are few (the placed nodes are moved too, and skipped with one probe each), where
            // six probes around each placed node were 0.3 ms of the armadillo's serial time.
            NodeStates states(deformation);
            for (auto it = deformation.offsets->cbeginValueOn(); it; ++it) {
                const Coord c = it.getCoord();
                if (states.onSurface.isValueOn(c)) continue;
                for (int k = 0; k < 6; ++k)
                    if (states.onSurface.isValueOn(c + axisStep(k / 2, k % 2 ? 1 : -1))) {
                        candidates.push_back(c);
                        break;
                    }
            }
        }
        std::sort(candidates.begin(), candidates.end()); // (the tree's order is not the coordinates')
        // Each test reads the one state and writes nothing: in parallel (27 field samples each).
        std::vector<std::uint8_t> closes(candidates.size(), 0);
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, candidates.size(), 32), [&](const tbb::blocked_range<std::size_t>& r) {
            NodeStates states(deformation);
            double around[27];
            for (std::size_t i = r.begin(); i < r.end(); ++i) {
                const Coord& x = candidates[i];
                field.sampleNodes(frame, Vec3i(x.x() - 1, x.y() - 1, x.z() - 1), {3, 3, 3}, nullptr, around);
                auto inside = [&](const Coord& o) {
                    return states.inside(x + o, isInside(around[(o.x() + 1) + 3 * (o.y() + 1) + 9 * (o.z() + 1)], iso, side));
                };
                const bool xInside = inside(Coord(0, 0, 0));
                if (xInside == isInside(around[13], iso, side)) continue; // not across
                bool anyOffSurface = false; // a neighbour on x's side off the surface joins x's surface to its own
                for (int k = 0; k < 6 && !anyOffSurface; ++k) {
                    const Coord o = axisStep(k / 2, k % 2 ? 1 : -1);
                    anyOffSurface = inside(o) == xInside && !states.onSurface.isValueOn(x + o);
                }
                if (anyOffSurface) continue;
                closes[i] = meetsOnlyAtFeatureNodes(inside, [&](const Coord& o) { return states.onSurface.isValueOn(x + o); });
            }
        });
        if (options.cancel) options.cancel->check();
        for (std::size_t i = 0; i < candidates.size(); ++i)
            if (closes[i]) closedOff.emplace_back(candidates[i].x(), candidates[i].y(), candidates[i].z());
    }
    if (!closedOff.empty()) {
        for (const Vec3i& c : closedOff) offsets.setValueOff(Coord(c.x, c.y, c.z), openvdb::Vec3f(0.0f));
        out.unhung += closedOff.size();
        out.changedNodes.insert(out.changedNodes.end(), closedOff.begin(), closedOff.end());
    }
    std::sort(out.changedNodes.begin(), out.changedNodes.end(), lessXYZ);
    out.changedNodes.erase(std::unique(out.changedNodes.begin(), out.changedNodes.end()), out.changedNodes.end());
    out.flipped = flipped.size();
    out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (stats) *stats = out;
}

} // namespace vdbsurf
