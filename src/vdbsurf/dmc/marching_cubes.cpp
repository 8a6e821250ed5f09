#include "vdbsurf/dmc/marching_cubes.h"

#include "vdbsurf/core/cancel.h"
#include "vdbsurf/core/progress.h"
#include "vdbsurf/dmc/cube_table.h"

#include <openvdb/tree/LeafManager.h>
#include <tbb/parallel_for.h>

#include <array>
#include <chrono>
#include <stdexcept>
#include <unordered_map>

namespace vdbsurf {

using openvdb::Coord;
using openvdb::CoordBBox;

namespace {

using MaskLeaf = openvdb::MaskTree::LeafNodeType;
constexpr int kN = 9; // nodes per block side
constexpr int kNodeCount = kN * kN * kN;

inline int nodeIndex(int x, int y, int z) { return x + kN * y + kN * kN * z; }
inline Coord toCoord(const Vec3i& v) { return Coord(v.x, v.y, v.z); }

// Per-leaf results of the first pass: the vertices this leaf owns and what the second pass
// needs to find them again (cell rank -> first vertex, owned-edge mask).
struct LeafWork {
    Coord origin;
    std::array<std::uint16_t, 8> wordRank{};
    std::array<std::int32_t, 8> neighbor{}; // leaf index at origin + 8 * (dx, dy, dz), -1 if none
    std::vector<std::uint8_t> config;
    std::vector<std::uint16_t> ownedEdges;
    std::vector<std::uint16_t> vertexPrefix;
    std::vector<Vec3f> vertices;
    std::uint32_t centreCount = 0; // vertices added at loop centres, numbered after the edge vertices
    std::uint32_t faceCount = 0, indexCount = 0;
    std::uint32_t vertexBase = 0, faceBase = 0, indexBase = 0;
    std::uint64_t cellsWithSurface = 0;
};

inline std::uint32_t cellRank(const MaskLeaf& leaf, const LeafWork& w, openvdb::Index offset) {
    const auto word = leaf.getValueMask().template getWord<std::uint64_t>(offset >> 6);
    const std::uint64_t below = word & ((std::uint64_t(1) << (offset & 63)) - 1);
    return w.wordRank[offset >> 6] + std::uint32_t(__builtin_popcountll(below));
}

// The cell that holds the vertex of the edge from node `a` along `axis`: the cell whose min
// corner is `a`, or, where that cell lies beyond the lattice's max faces, the neighbour inside.
inline Coord edgeOwner(const Coord& a, int axis, const CoordBBox& range) {
    Coord o = a;
    for (int k = 1; k <= 2; ++k) {
        const int ax = (axis + k) % 3;
        if (o[ax] > range.max()[ax]) o[ax] -= 1;
    }
    return o;
}

inline bool onMaxFace(const Coord& c, const CoordBBox& range) {
    return c.x() == range.max().x() || c.y() == range.max().y() || c.z() == range.max().z();
}

std::uint32_t loopFaces(std::uint32_t k, bool triangulate) { return k == 4 ? (triangulate ? 2 : 1) : k - 2; }
std::uint32_t loopIndices(std::uint32_t k, bool triangulate) { return k == 4 ? (triangulate ? 6 : 4) : 3 * (k - 2); }

} // namespace

Mesh marchingCubes(const Field& field, const Lattice& lattice, const MarchingCubesOptions& options, MarchingCubesStats* stats) {
    const auto start = std::chrono::steady_clock::now();
    const double iso = options.iso;
    const Inside side = field.inside();
    const LatticeFrame& frame = lattice.frame;
    const CoordBBox& range = lattice.cellRange;
    const bool linear = field.edgesAreLinear(frame);
    const bool tri = options.triangulate;

    openvdb::tree::LeafManager<const openvdb::MaskTree> leafManager(*lattice.cells);
    const std::size_t leafCount = leafManager.leafCount();
    std::vector<LeafWork> work(leafCount);
    std::unordered_map<const MaskLeaf*, std::int32_t> indexOf;
    indexOf.reserve(leafCount * 2);
    for (std::size_t i = 0; i < leafCount; ++i) indexOf.emplace(&leafManager.leaf(i), std::int32_t(i));

    Progress progress("marching cubes", 2 * leafCount, options.cancel);

    // Pass 1: per leaf, cell cases and the vertices of the edges its cells own.
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, leafCount, 8), [&](const tbb::blocked_range<std::size_t>& r) {
        openvdb::tree::ValueAccessor<const openvdb::MaskTree, false> acc(*lattice.cells);
        std::array<double, kNodeCount> vals;
        std::array<std::uint8_t, kNodeCount> needed;
        for (std::size_t li = r.begin(); li < r.end(); ++li) {
            const MaskLeaf& leaf = leafManager.leaf(li);
            LeafWork& w = work[li];
            w.origin = leaf.origin();
            const auto& mask = leaf.getValueMask();
            std::uint16_t running = 0;
            for (int word = 0; word < 8; ++word) {
                w.wordRank[std::size_t(word)] = running;
                running = std::uint16_t(running + __builtin_popcountll(mask.template getWord<std::uint64_t>(openvdb::Index(word))));
            }
            for (int d = 0; d < 8; ++d) {
                const MaskLeaf* nb = acc.probeConstLeaf(w.origin.offsetBy(8 * (d & 1), 8 * ((d >> 1) & 1), 8 * ((d >> 2) & 1)));
                w.neighbor[std::size_t(d)] = nb ? indexOf.at(nb) : -1;
            }
            const std::size_t cells = running;
            w.config.resize(cells);
            w.ownedEdges.resize(cells);
            w.vertexPrefix.resize(cells);

            needed.fill(0);
            for (auto it = mask.beginOn(); it; ++it) {
                const int off = int(it.pos()), x = off >> 6, y = (off >> 3) & 7, z = off & 7;
                for (int c = 0; c < 8; ++c) needed[std::size_t(nodeIndex(x + (c & 1), y + ((c >> 1) & 1), z + ((c >> 2) & 1)))] = 1;
            }
            field.sampleNodes(frame, {w.origin.x(), w.origin.y(), w.origin.z()}, {kN, kN, kN}, needed.data(), vals.data());

            std::size_t rank = 0;
            for (auto it = mask.beginOn(); it; ++it, ++rank) {
                const int off = int(it.pos()), x = off >> 6, y = (off >> 3) & 7, z = off & 7;
                unsigned config = 0;
                for (int c = 0; c < 8; ++c) {
                    const double v = vals[std::size_t(nodeIndex(x + (c & 1), y + ((c >> 1) & 1), z + ((c >> 2) & 1)))];
                    if (isInside(v, iso, side)) config |= 1u << c;
                }
                w.config[rank] = std::uint8_t(config);
                w.vertexPrefix[rank] = std::uint16_t(w.vertices.size());
                if (config == 0 || config == 255) continue;
                ++w.cellsWithSurface;
                const CubeCase& cc = cubeCase(config);
                const Coord cell = w.origin.offsetBy(x, y, z);
                const bool boundary = onMaxFace(cell, range);
                std::uint16_t owned = 0;
                for (int e = 0; e < 12; ++e) {
                    if (!(cc.edgeMask & (1u << e))) continue;
                    const int axis = cubeEdgeAxis(e);
                    const Vec3i eo = cubeEdgeOrigin(e);
                    if (eo != Vec3i()) {
                        if (!boundary) continue;
                        if (edgeOwner(cell.offsetBy(eo.x, eo.y, eo.z), axis, range) != cell) continue;
                    }
                    owned |= std::uint16_t(1u << e);
                    const Vec3i la(x + eo.x, y + eo.y, z + eo.z);
                    Vec3i lb = la;
                    lb[std::size_t(axis)] += 1;
                    const double va = vals[std::size_t(nodeIndex(la.x, la.y, la.z))];
                    const double vb = vals[std::size_t(nodeIndex(lb.x, lb.y, lb.z))];
                    const Vec3i ga(w.origin.x() + la.x, w.origin.y() + la.y, w.origin.z() + la.z);
                    const Vec3i gb(w.origin.x() + lb.x, w.origin.y() + lb.y, w.origin.z() + lb.z);
                    const Vec3d pa = frame.nodeWorld(ga), pb = frame.nodeWorld(gb);
                    const double t = linear ? (iso - va) / (vb - va) : field.edgeCrossing(pa, pb, va, vb, iso);
                    w.vertices.push_back(Vec3f(pa + (pb - pa) * t));
                }
                w.ownedEdges[rank] = owned;
                for (int l = 0; l < cc.loopCount; ++l) {
                    if (cc.needsCentre & (1u << l)) {
                        ++w.centreCount;
                        w.faceCount += cc.loopSize[l];
                        w.indexCount += 3u * cc.loopSize[l];
                        continue;
                    }
                    w.faceCount += loopFaces(cc.loopSize[l], tri);
                    w.indexCount += loopIndices(cc.loopSize[l], tri);
                }
            }
            progress.advance();
        }
    });
    if (options.cancel) options.cancel->check();

    // Prefix sums, in leaf order: this fixes every vertex and polygon number.
    std::uint32_t vtotal = 0, ftotal = 0, itotal = 0;
    std::uint64_t withSurface = 0;
    for (LeafWork& w : work) {
        w.vertexBase = vtotal;
        w.faceBase = ftotal;
        w.indexBase = itotal;
        const std::uint64_t nv = std::uint64_t(vtotal) + w.vertices.size() + w.centreCount;
        const std::uint64_t ni = std::uint64_t(itotal) + w.indexCount;
        if (nv > 0xffffffffull || ni > 0xffffffffull) throw std::runtime_error("mesh too large for 32-bit indices");
        vtotal = std::uint32_t(nv);
        ftotal += w.faceCount;
        itotal = std::uint32_t(ni);
        withSurface += w.cellsWithSurface;
    }

    Mesh mesh;
    mesh.points.resize(vtotal);
    mesh.offsets.assign(std::size_t(ftotal) + 1, 0);
    mesh.indices.resize(itotal);

    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, leafCount, 64), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t li = r.begin(); li < r.end(); ++li)
            std::copy(work[li].vertices.begin(), work[li].vertices.end(), mesh.points.begin() + work[li].vertexBase);
    });

    // Pass 2: polygons with global vertex numbers (all vertices are in place: quads may be split
    // along their shorter diagonal).
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, leafCount, 8), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t li = r.begin(); li < r.end(); ++li) {
            const MaskLeaf& leaf = leafManager.leaf(li);
            const LeafWork& w = work[li];
            std::uint32_t f = w.faceBase, idx = w.indexBase;
            std::uint32_t nextCentre = w.vertexBase + std::uint32_t(w.vertices.size());
            auto vertexOf = [&](const Coord& cell, int e) -> std::uint32_t {
                const int axis = cubeEdgeAxis(e);
                const Vec3i eo = cubeEdgeOrigin(e);
                const Coord a = cell.offsetBy(eo.x, eo.y, eo.z);
                const Coord owner = edgeOwner(a, axis, range);
                const Coord d = (owner & ~7) - w.origin;
                const std::int32_t ni = w.neighbor[std::size_t((d.x() >> 3) | ((d.y() >> 3) << 1) | ((d.z() >> 3) << 2))];
                if (ni < 0) throw std::logic_error("marching cubes: the owner of an edge is not in the lattice");
                const LeafWork& ow = work[std::size_t(ni)];
                const MaskLeaf& ol = leafManager.leaf(std::size_t(ni));
                const openvdb::Index off = MaskLeaf::coordToOffset(owner);
                if (!ol.isValueOn(off)) throw std::logic_error("marching cubes: the owner cell of an edge is inactive");
                const std::uint32_t rank = cellRank(ol, ow, off);
                const Coord rel = a - owner;
                const int oe = cubeEdgeIndex(axis, {rel.x(), rel.y(), rel.z()});
                const std::uint16_t m = ow.ownedEdges[rank];
                if (!(m & (1u << oe))) throw std::logic_error("marching cubes: an edge crossing has no vertex");
                return ow.vertexBase + ow.vertexPrefix[rank] + std::uint32_t(__builtin_popcount(m & ((1u << oe) - 1u)));
            };
            std::size_t rank = 0;
            for (auto it = leaf.getValueMask().beginOn(); it; ++it, ++rank) {
                const unsigned config = w.config[rank];
                if (config == 0 || config == 255) continue;
                const int off = int(it.pos());
                const Coord cell = w.origin.offsetBy(off >> 6, (off >> 3) & 7, off & 7);
                const CubeCase& cc = cubeCase(config);
                std::array<std::uint32_t, 12> ids;
                for (int l = 0, k0 = 0; l < cc.loopCount; k0 += cc.loopSize[l], ++l) {
                    const std::uint32_t k = cc.loopSize[l];
                    for (std::uint32_t i = 0; i < k; ++i) ids[i] = vertexOf(cell, cc.edges[k0 + int(i)]);
                    auto emit = [&](std::initializer_list<std::uint32_t> vs) {
                        for (std::uint32_t v : vs) mesh.indices[idx++] = v;
                        mesh.offsets[++f] = idx;
                    };
                    if (cc.needsCentre & (1u << l)) {
                        // Only this leaf writes its centre vertices; the loop's edge vertices are all in place.
                        Vec3d c;
                        for (std::uint32_t i = 0; i < k; ++i) c += Vec3d(mesh.points[ids[i]]);
                        const std::uint32_t centre = nextCentre++;
                        mesh.points[centre] = Vec3f(c / double(k));
                        for (std::uint32_t i = 0; i < k; ++i) emit({ids[i], ids[(i + 1) % k], centre});
                    } else if (k == 3) emit({ids[0], ids[1], ids[2]});
                    else if (k == 4 && !tri) emit({ids[0], ids[1], ids[2], ids[3]});
                    else if (k == 4) {
                        const auto& P = mesh.points;
                        const double d02 = dot(Vec3d(P[ids[0]] - P[ids[2]]), Vec3d(P[ids[0]] - P[ids[2]]));
                        const double d13 = dot(Vec3d(P[ids[1]] - P[ids[3]]), Vec3d(P[ids[1]] - P[ids[3]]));
                        if (d02 <= d13) { emit({ids[0], ids[1], ids[2]}); emit({ids[0], ids[2], ids[3]}); }
                        else { emit({ids[0], ids[1], ids[3]}); emit({ids[1], ids[2], ids[3]}); }
                    } else {
                        for (std::uint32_t i = 1; i + 1 < k; ++i) emit({ids[0], ids[i], ids[i + 1]});
                    }
                }
            }
            progress.advance();
        }
    });
    if (options.cancel) options.cancel->check();

    if (stats) {
        stats->cellsWithSurface = withSurface;
        stats->leaves = leafCount;
        stats->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    }
    return mesh;
}

} // namespace vdbsurf
