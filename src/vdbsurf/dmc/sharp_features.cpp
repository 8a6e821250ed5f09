#include "vdbsurf/dmc/sharp_features.h"

#include "vdbsurf/core/cancel.h"
#include "vdbsurf/core/error.h"
#include "vdbsurf/dmc/cube_table.h"
#include "vdbsurf/dmc/lattice_deformation.h"
#include "vdbsurf/dmc/lattice_surface.h"
#include "vdbsurf/dmc/thin_search.h"
#include "vdbsurf/lattice/lattice.h"

#include <Eigen/Dense>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <tuple>

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
// On flat faces every crossing's normal is one of the faces' normals; on a curved surface the
// normals fan out between them. A crossing whose normal is farther than this (cosine) from every
// plane that defined the feature means curvature, not a feature.
constexpr double kFaceNormalAgreement = 0.95;

struct Proposal {
    Coord node;
    int kind = 0; // 0 corner, 1 edge: corners win
    double distance = 0;
    Coord cell;
    Vec3d point;
    bool inside = false; // the node's side before it moves
    bool operator<(const Proposal& o) const {
        return std::tie(node, kind, distance, cell) < std::tie(o.node, o.kind, o.distance, o.cell);
    }
};

inline Vec3d toVec(const Eigen::Vector3d& v) { return {v[0], v[1], v[2]}; }
inline Eigen::Vector3d toEigen(const Vec3d& v) { return {v.x, v.y, v.z}; }

// The point where the three planes (c_i, n_i) meet, if the system is well conditioned.
bool intersectPlanes(const Vec3d n[3], const double rhs[3], Vec3d& out) {
    Eigen::Matrix3d A;
    for (int i = 0; i < 3; ++i) A.row(i) = toEigen(n[i]).transpose();
    Eigen::FullPivLU<Eigen::Matrix3d> lu(A);
    // Unit normals: the determinant is the volume they span; below this the point runs off.
    if (std::fabs(A.determinant()) < 1e-3) return false;
    out = toVec(lu.solve(Eigen::Vector3d(rhs[0], rhs[1], rhs[2])));
    return std::isfinite(out.x) && std::isfinite(out.y) && std::isfinite(out.z);
}

Coord nearestNode(const LatticeFrame& frame, const Vec3d& p) {
    const Vec3d q = (p - frame.origin) / frame.h;
    return Coord(int(std::floor(q.x + 0.5)), int(std::floor(q.y + 0.5)), int(std::floor(q.z + 0.5)));
}

bool isCornerOf(const Coord& node, const Coord& cell) {
    const Coord d = node - cell;
    return d.x() >= 0 && d.x() <= 1 && d.y() >= 0 && d.y() <= 1 && d.z() >= 0 && d.z() <= 1;
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

    struct Local {
        std::vector<Proposal> proposals;
        std::uint64_t edgeCells = 0, cornerCells = 0, rejected = 0;
        Vec3d c[12], n[12]; // one cell's crossings and normals (here: not cleared for every cell)
    };
    tbb::enumerable_thread_specific<Local> locals;
    auto within = [&](const Vec3d& p, double cells) {
        Vec3d g;
        const double v = field.valueAndGradient(p, g);
        const double len = length(g);
        if (!(len > 0) || !std::isfinite(len)) return false;
        return std::fabs(v - iso) <= cells * h * len;
    };
    auto nearSurface = [&](const Vec3d& p) { return within(p, kMaxSurfaceDistance); };
    auto facesFlat = [&](const Vec3d& feature, std::initializer_list<Vec3d> crossings) {
        for (const Vec3d& c : crossings)
            if (!within(0.5 * (feature + c), kMaxFaceBend)) return false;
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
        int a = -1, b = -1;
        double theta = options.edgeThreshold;
        bool twoSheets = false;
        for (int i = 0; i < count; ++i)
            for (int j = i + 1; j < count; ++j) {
                const double d = dot(n[i], n[j]);
                if (d < theta) {
                    const Vec3d x = cross(n[i], n[j]);
                    if (dot(x, x) >= kMinSine * kMinSine) theta = d, a = i, b = j;
                }
                twoSheets = twoSheets || d <= -kOppositeSheets;
            }
        if (a < 0) return;
        // Two sheets facing away from each other within one cell: a thin part (rod, plate)
        // passes here, and what its curvature makes of the normals is no feature. A node placed
        // on it would pinch the part (a thin rod into beads touching at points). (Nodes the thin
        // search moved are not a sign: it also moves nodes next to a convex corner's tip.)
        if (twoSheets) {
            ++local.rejected;
            return;
        }
        const Vec3d edgeDir = normalized(cross(n[a], n[b]));
        int third = -1;
        double phi = options.cornerThreshold;
        for (int i = 0; i < count; ++i) {
            if (i == a || i == b) continue;
            const double d = std::fabs(dot(n[i], edgeDir));
            if (d > phi) phi = d, third = i;
        }
        auto normalsCluster = [&](std::initializer_list<int> planes) {
            for (int i = 0; i < count; ++i) {
                bool agrees = false;
                for (int k : planes) agrees = agrees || dot(n[i], n[k]) >= kFaceNormalAgreement;
                if (!agrees) return false;
            }
            return true;
        };
        if (!(third >= 0 ? normalsCluster({a, b, third}) : normalsCluster({a, b}))) {
            ++local.rejected;
            return;
        }
        Proposal p;
        p.cell = cc.cell;
        if (third >= 0) {
            ++local.cornerCells;
            const Vec3d planes[3] = {n[a], n[b], n[third]};
            const double rhs[3] = {dot(n[a], c[a]), dot(n[b], c[b]), dot(n[third], c[third])};
            Vec3d corner;
            if (!intersectPlanes(planes, rhs, corner) || !isCornerOf(nearestNode(frame, corner), cc.cell) || !nearSurface(corner) ||
                !facesFlat(corner, {c[a], c[b], c[third]}) || !solidBehind(corner, n[a] + n[b] + n[third])) {
                ++local.rejected;
                return;
            }
            p.kind = 0;
            p.node = nearestNode(frame, corner);
            p.point = corner;
            p.distance = length(corner - frame.nodeWorld(Vec3i(p.node.x(), p.node.y(), p.node.z())));
        } else {
            ++local.edgeCells;
            Vec3d mean;
            for (int i = 0; i < count; ++i) mean += c[i];
            mean = mean / double(count);
            const Vec3d planes[3] = {n[a], n[b], edgeDir};
            const double rhs[3] = {dot(n[a], c[a]), dot(n[b], c[b]), dot(edgeDir, mean)};
            Vec3d onLine;
            if (!intersectPlanes(planes, rhs, onLine)) {
                ++local.rejected;
                return;
            }
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
            if (!(best < INFINITY) || !nearSurface(p.point) || !facesFlat(p.point, {c[a], c[b]}) || !solidBehind(p.point, n[a] + n[b])) {
                ++local.rejected;
                return;
            }
            p.kind = 1;
        }
        const Coord d = p.node - cc.cell;
        p.inside = (cc.config >> (d.x() + 2 * d.y() + 4 * d.z())) & 1u;
        local.proposals.push_back(p);
    }, /*onlySharpCandidates=*/true);

    SharpStats out;
    std::vector<Proposal> all;
    for (Local& l : locals) {
        all.insert(all.end(), l.proposals.begin(), l.proposals.end());
        out.edgeCells += l.edgeCells;
        out.cornerCells += l.cornerCells;
        out.rejected += l.rejected;
    }
    std::sort(all.begin(), all.end());
    // One proposal a node (the best), then corners before edges, so that an edge node never
    // takes the crossing a corner node needs.
    all.erase(std::unique(all.begin(), all.end(), [](const Proposal& x, const Proposal& y) { return x.node == y.node; }), all.end());
    std::stable_sort(all.begin(), all.end(), [](const Proposal& x, const Proposal& y) { return x.kind < y.kind; });

    openvdb::tree::ValueAccessor<openvdb::Vec3STree> offsets(*deformation.offsets);
    openvdb::tree::ValueAccessor<openvdb::MaskTree> onSurface(*deformation.onSurface);
    openvdb::tree::ValueAccessor<openvdb::MaskTree> insideOnSurface(*deformation.insideOnSurface);
    // The field's side at each proposal's six neighbours does not depend on the order below:
    // sampled first, in parallel (bit k: neighbour k of kNeighbours is inside).
    constexpr int kNeighbours[6] = {4, 10, 12, 14, 16, 22}; // in the 3^3 block around the node
    std::vector<std::uint8_t> insideNeighbours(all.size(), 0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, all.size(), 64), [&](const tbb::blocked_range<std::size_t>& r) {
        double around[27];
        for (std::size_t i = r.begin(); i < r.end(); ++i) {
            const Coord& n = all[i].node;
            field.sampleNodes(frame, Vec3i(n.x() - 1, n.y() - 1, n.z() - 1), {3, 3, 3}, nullptr, around);
            for (int j = 0; j < 6; ++j)
                if (isInside(around[kNeighbours[j]], iso, side)) insideNeighbours[i] |= std::uint8_t(1u << j);
        }
    });
    if (options.cancel) options.cancel->check();
    std::vector<Vec3i> flipped;
    for (std::size_t i = 0; i < all.size(); ++i) {
        const Proposal& p = all[i];
        int otherSide = 0;
        bool sharesCrossing = false; // with a node already on a feature: the edge's one vertex can't be at both
        for (int j = 0; j < 6; ++j) {
            const int k = kNeighbours[j];
            const Coord nb = p.node.offsetBy(k % 3 - 1, (k / 3) % 3 - 1, k / 9 - 1);
            bool inside = (insideNeighbours[i] >> j) & 1u;
            if (onSurface.isValueOn(nb)) {
                inside = insideOnSurface.isValueOn(nb);
                sharesCrossing = sharesCrossing || inside != p.inside;
            } else if (offsets.isValueOn(nb)) {
                inside = !inside; // moved into a thin part
            }
            otherSide += inside != p.inside;
        }
        if (otherSide == 6 || sharesCrossing) {
            ++out.rejected;
            continue;
        }
        // A node with no edge to the other side carries no crossing: placed on the feature as it
        // is, it would change nothing. It changes side instead (the feature's tip is a thin part
        // of the other side) and is joined to that side by bridging below.
        const bool flip = otherSide == 0;
        const bool inside = flip ? !p.inside : p.inside;
        const Vec3d rest = frame.nodeWorld(Vec3i(p.node.x(), p.node.y(), p.node.z()));
        const Vec3f off(p.point - rest);
        offsets.setValue(p.node, openvdb::Vec3f(off.x, off.y, off.z));
        onSurface.setValueOn(p.node);
        if (inside) insideOnSurface.setValueOn(p.node);
        if (flip) flipped.emplace_back(p.node.x(), p.node.y(), p.node.z());
        (p.kind == 0 ? out.nodesOnCorners : out.nodesOnEdges) += 1;
    }
    if (!flipped.empty()) {
        ThinSearchOptions to;
        to.iso = iso;
        to.steps = options.searchSteps;
        to.cancel = options.cancel;
        out.changedNodes = flipped;
        out.bridged = bridgeThinParts(field, lattice, to, deformation, flipped, nullptr, &out.changedNodes);
        std::sort(out.changedNodes.begin(), out.changedNodes.end(), [](const Vec3i& x, const Vec3i& y) {
            return std::tie(x.x, x.y, x.z) < std::tie(y.x, y.y, y.z);
        });
        out.changedNodes.erase(std::unique(out.changedNodes.begin(), out.changedNodes.end()), out.changedNodes.end());
    }
    out.flipped = flipped.size();
    out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (stats) *stats = out;
}

} // namespace vdbsurf
