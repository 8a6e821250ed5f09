#include "vdbsurf/dmc/lattice_surface.h"

#include "vdbsurf/core/cancel.h"
#include "vdbsurf/core/prefault.h"
#include "vdbsurf/core/progress.h"
#include "vdbsurf/dmc/cube_table.h"
#include "vdbsurf/dmc/lattice_deformation.h"
#include "vdbsurf/dmc/leaf_nodes.h"
#include "vdbsurf/dmc/node_gradients.h"
#include "vdbsurf/dmc/node_weld.h"

#include <openvdb/tree/LeafManager.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_group.h>

#include <algorithm>
#include <array>
#include <bitset>
#include <chrono>
#include <stdexcept>

namespace vdbsurf {

using openvdb::Coord;
using openvdb::CoordBBox;

namespace {

using MaskLeaf = CellTree::LeafNodeType;

// A crossing this close to a node (in cells) is that node's, as if the node held the iso value:
// far below any detail a lattice of this spacing shows (node offsets keep 10^-5 cells inside
// their Ω likewise), and far above the rounding of a level set's stored values.
constexpr double kOnNode = 1e-5;

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
    std::vector<Vec3f> normals;
    // With normals: the surface cells through which a sharp feature may pass, as
    // (offset << 16) | rank, by rank (the sharp pass visits these alone).
    bool candidatesKnown = false;
    std::vector<std::uint32_t> sharpCells;
    // Vertices that sit exactly on a node whose value is the iso value: (local vertex, node).
    std::vector<std::pair<std::uint32_t, Coord>> nodeVertices;
    // Of those, the ones put there because they rounded to the node (ascending).
    std::vector<std::uint32_t> roundedVertices;
    std::uint32_t faceCount = 0, indexCount = 0;
    std::uint32_t vertexBase = 0, faceBase = 0, indexBase = 0;
    std::uint64_t cellsWithSurface = 0;
    bool unresolved = false; // its sharp candidates were dropped (unresolvedForFeatures)
};

// A sharp edge is a curve: of the cells a resolved surface crosses in one leaf (64 and more for a
// sheet across its 8^3 cells) its own are few — an edge crosses 8 to 16, and on the cube file no
// leaf has more than 41 % of its surface cells where the normals may turn past the edge
// threshold. Where nearly all of a leaf's surface cells do, the surface is not resolved at this
// spacing (fog and smoke at their voxel size: 77 k of smoke_fog's 81.5 k surface cells were
// candidates) and what the sharp pass would find there is noise: 8 in 10 of its edges went
// unconfirmed, and the ones placed took the mesh farther from the surface (F at H/4 0.9693
// against marching cubes' 0.9700, and 3 more pieces) at 1.5 times the cost of the rest of the
// mesher. Such a leaf holds no candidates. The default share, 95 %, is high enough for
// hard-surface detail a few voxels wide (random boxes on a slab, as level sets): boxes 3-6 and
// 4-8 voxels wide keep every edge node, 6-12 voxels 713 of 744, 2-4 voxels 437 of 525, and the
// boxes' corners lie as close to the mesh as before (at 80 % a third of the 6-12 voxel boxes'
// edge nodes went, and their corners moved 0.03 H farther at the median). Judged on node
// gradients only (a grid at its own voxel size): elsewhere every cell is a candidate, and the
// field is what it says; nor where the edge cosine is 1 (every cell a candidate, asked for).
// Leaves with few surface cells (a corner's tip clipping a leaf) are not judged. The share is
// SurfaceOptions::unresolvedShare (--sharp-noise).
constexpr std::uint64_t kUnresolvedMinCells = 32;

bool unresolvedForFeatures(const LeafWork& w, double share) {
    if (w.cellsWithSurface < kUnresolvedMinCells) return false;
    return double(w.sharpCells.size()) >= share * double(w.cellsWithSurface);
}

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

std::uint32_t loopFaces(std::uint32_t k, bool triangulate, bool whole) { return k == 4 ? (triangulate ? 2 : 1) : whole ? 1 : k - 2; }
std::uint32_t loopIndices(std::uint32_t k, bool triangulate, bool whole) { return k == 4 ? (triangulate ? 6 : 4) : whole ? k : 3 * (k - 2); }

struct VertexRef {
    std::uint32_t leaf, local;
};

// Origin of the d-th (0..7) leaf-sized block that holds nodes of the leaf at `origin`: its own and
// those of its +x, +y, +z neighbours, whose first layer closes the leaf's 9^3 node block.
inline Coord nodeBlock(const Coord& origin, int d) { return origin.offsetBy(8 * (d & 1), 8 * ((d >> 1) & 1), 8 * ((d >> 2) & 1)); }

// Is a node of the leaf at `origin` active in the tree behind `acc`? One probe per leaf of that
// tree the 9^3 nodes touch (a missing leaf under an inactive tile holds none) instead of one per
// node; the tree's leaves may be smaller than the lattice's (OffsetTree).
template <typename Accessor>
bool anyActiveNode(Accessor& acc, const Coord& origin) {
    constexpr int kStep = int(Accessor::TreeType::LeafNodeType::DIM);
    static_assert(8 % kStep == 0, "leaves of the node trees tile the lattice's 8^3 blocks");
    for (int z = 0; z <= 8; z += kStep)
        for (int y = 0; y <= 8; y += kStep)
            for (int x = 0; x <= 8; x += kStep) {
                const Coord lo = origin.offsetBy(x, y, z);
                if (acc.probeConstLeaf(lo) || acc.isValueOn(lo)) return true;
            }
    return false;
}

// Marks, in `cells` (word x, bit 8 y + z), the leaf's cells that have node (x, y, z) of the leaf's
// 9^3 block as a corner.
inline void markCellsAround(int x, int y, int z, std::array<std::uint64_t, 8>& cells) {
    for (int cx = std::max(x - 1, 0); cx <= std::min(x, 7); ++cx)
        for (int cy = std::max(y - 1, 0); cy <= std::min(y, 7); ++cy)
            for (int cz = std::max(z - 1, 0); cz <= std::min(z, 7); ++cz) cells[std::size_t(cx)] |= std::uint64_t(1) << (8 * cy + cz);
}

// The nodes of the leaf at `origin` (its 9^3 block, by leafNodeIndex) that are active in a
// node-mask tree, and the leaf's cells that have one as a corner; false if none is. One probe per
// 8^3 block of the tree and its few active bits, instead of a tree probe per node asked about.
template <typename Accessor>
bool activeLeafNodes(Accessor& acc, const Coord& origin, std::bitset<kLeafNodeCount>& on, std::array<std::uint64_t, 8>& cells) {
    on.reset();
    cells.fill(0);
    bool any = false;
    for (int d = 0; d < 8; ++d) {
        const Coord lo = nodeBlock(origin, d);
        // Of the tree's 8^3 block at lo, the leaf's block holds all of it (d = 0) or only its first
        // layer along each axis d steps onto.
        const int nx = (d & 1) ? 1 : 8, ny = (d & 2) ? 1 : 8, nz = (d & 4) ? 1 : 8;
        const int rx = (d & 1) * 8, ry = ((d >> 1) & 1) * 8, rz = ((d >> 2) & 1) * 8;
        if (const auto* leaf = acc.probeConstLeaf(lo)) {
            for (auto it = leaf->getValueMask().beginOn(); it; ++it) {
                const int pos = int(it.pos()), x = pos >> 6, y = (pos >> 3) & 7, z = pos & 7;
                if (x >= nx || y >= ny || z >= nz) continue;
                on.set(std::size_t(leafNodeIndex(rx + x, ry + y, rz + z)));
                markCellsAround(rx + x, ry + y, rz + z, cells);
                any = true;
            }
        } else if (acc.isValueOn(lo)) {
            for (int z = 0; z < nz; ++z)
                for (int y = 0; y < ny; ++y)
                    for (int x = 0; x < nx; ++x) {
                        on.set(std::size_t(leafNodeIndex(rx + x, ry + y, rz + z)));
                        markCellsAround(rx + x, ry + y, rz + z, cells);
                    }
            any = true;
        }
    }
    return any;
}

} // namespace

struct LatticeSurface::Impl {
    const Field& field;
    const Lattice& lattice;
    const LatticeDeformation* deformation;
    SurfaceOptions options;
    bool linear;
    openvdb::tree::LeafManager<const CellTree> leafManager;
    std::vector<LeafWork> work;
    SurfaceStats stats;
    std::chrono::steady_clock::time_point start;
    bool meshTaken = false;

    Impl(const Field& f, const Lattice& l, const LatticeDeformation* d, const SurfaceOptions& o)
        : field(f), lattice(l), deformation(d && !d->empty() ? d : nullptr), options(o),
          linear(f.edgesAreLinear(l.frame)), leafManager(*l.cells), start(std::chrono::steady_clock::now()) {}

    // Leaf pointer -> index in leafManager order, for each leaf's neighbour table: (pointer,
    // index) sorted by pointer. (A hash map of them was built serially, a node allocated per
    // leaf, at every first pass and rebuild: about 0.4 ms each on the armadillo.)
    std::vector<std::pair<const MaskLeaf*, std::int32_t>> leafIndex;

    void indexLeaves() {
        const std::size_t leafCount = leafManager.leafCount();
        leafIndex.resize(leafCount);
        for (std::size_t i = 0; i < leafCount; ++i) leafIndex[i] = {&leafManager.leaf(i), std::int32_t(i)};
        std::sort(leafIndex.begin(), leafIndex.end());
    }
    std::int32_t indexOf(const MaskLeaf* leaf) const {
        const auto it = std::lower_bound(leafIndex.begin(), leafIndex.end(), std::make_pair(leaf, std::int32_t(-1)));
        if (it == leafIndex.end() || it->first != leaf) throw std::logic_error("lattice surface: a leaf missing from the leaf index");
        return it->second;
    }

    // The indices of the leaves beside w's (w.neighbor), from the leaf index.
    void linkNeighbours(LeafWork& w, openvdb::tree::ValueAccessor<const CellTree, false>& cells) const {
        for (int d = 0; d < 8; ++d) {
            const MaskLeaf* nb = cells.probeConstLeaf(nodeBlock(w.origin, d));
            w.neighbor[std::size_t(d)] = nb ? indexOf(nb) : -1;
        }
    }

    // All leaves, or only those listed (their work is recomputed from scratch).
    void firstPass(const std::vector<std::size_t>* only = nullptr);
    VertexRef vertexOf(const LeafWork& w, const Coord& cell, int e) const;
    // vertexOf for edge e of the cell at local offset `offset` of leaf li (w = work[li]), with the
    // common case answered from that leaf alone: a cell off the lattice's max faces owns the
    // edges at its min corner, so the owner of an edge is the cell at the edge's min corner,
    // most often in the same leaf.
    VertexRef vertexOfCell(std::size_t li, const LeafWork& w, openvdb::Index offset, const Coord& cell, bool onMax, int e) const {
        if (!onMax) {
            const Vec3i eo = cubeEdgeOrigin(e);
            const int x = int(offset >> 6) + eo.x, y = int((offset >> 3) & 7) + eo.y, z = int(offset & 7) + eo.z;
            if (x < 8 && y < 8 && z < 8) {
                const openvdb::Index o = openvdb::Index((x << 6) | (y << 3) | z);
                const MaskLeaf& leaf = leafManager.leaf(li);
                if (!leaf.isValueOn(o)) throw std::logic_error("lattice surface: the owner cell of an edge is inactive");
                const std::uint32_t rank = cellRank(leaf, w, o);
                const std::uint16_t m = w.ownedEdges[rank];
                const int oe = cubeEdgeAxis(e) * 4; // the edge along the same axis at the owner's min corner
                if (!(m & (1u << oe))) throw std::logic_error("lattice surface: an edge crossing has no vertex");
                return {std::uint32_t(li), std::uint32_t(w.vertexPrefix[rank]) + std::uint32_t(__builtin_popcount(m & ((1u << oe) - 1u)))};
            }
        }
        return vertexOf(w, cell, e);
    }
};

void LatticeSurface::Impl::firstPass(const std::vector<std::size_t>* only) {
    const double iso = options.iso;
    const Inside side = field.inside();
    const LatticeFrame& frame = lattice.frame;
    const CoordBBox& range = lattice.cellRange;
    const bool tri = options.triangulate;
    const bool nodeGradients = options.normals && linear;
    const double outward = side == Inside::Below ? 1.0 : -1.0;
    const SharpEdgeLimit edgeLimit(options.sharpEdgeCosine);

    const std::size_t leafCount = leafManager.leafCount();
    if (!only) {
        // (~300 bytes a leaf of fresh memory; room for a few more, which a rebuild may add.)
        reservePrefaulted(work, leafCount + leafCount / 16 + 8);
        resizePrefaulted(work, leafCount);
        indexLeaves();
    }
    const std::size_t tasks = only ? only->size() : leafCount;

    Progress progress("surface crossings", tasks, options.cancel);
    struct Crossings {
        std::vector<Vec3f> vertices, normals;
        std::vector<std::uint32_t> sharpCells;
    };
    tbb::enumerable_thread_specific<Crossings> scratchCrossings;

    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, tasks, 8), [&](const tbb::blocked_range<std::size_t>& r) {
        openvdb::tree::ValueAccessor<const CellTree, false> acc(*lattice.cells);
        std::unique_ptr<openvdb::tree::ValueAccessor<const OffsetTree, false>> offsetAcc;
        std::unique_ptr<openvdb::tree::ValueAccessor<const NodeMaskTree, false>> surfaceAcc, insideAcc;
        if (deformation) {
            insideAcc = std::make_unique<openvdb::tree::ValueAccessor<const NodeMaskTree, false>>(*deformation->insideOnSurface);
            offsetAcc = std::make_unique<openvdb::tree::ValueAccessor<const OffsetTree, false>>(*deformation->offsets);
            surfaceAcc = std::make_unique<openvdb::tree::ValueAccessor<const NodeMaskTree, false>>(*deformation->onSurface);
        }
        std::array<double, kLeafNodeCount> vals{}; // (zeroed once: the side loop below reads every entry)
        std::array<std::uint8_t, kLeafNodeCount> needed;
        // 0: in place, 1: moved, 2: on a sharp feature (value = iso) counted outside, 3: the same counted inside
        std::array<std::uint8_t, kLeafNodeCount> moved;
        std::array<std::uint8_t, kLeafNodeCount> inside; // 1: the node counts inside (of the needed ones)
        std::array<Vec3f, kLeafNodeCount> offsets;
        NodeGradients gradients;
        // A leaf's crossings are gathered here and then copied at their exact count: grown in
        // place, each leaf's arrays would hold up to twice what they need, all of it fresh
        // memory the process pays a page fault for (a tenth of the armadillo's DMC faults).
        Crossings& scratch = scratchCrossings.local();
        std::vector<Vec3f>& vertices = scratch.vertices;
        std::vector<Vec3f>& normals = scratch.normals;
        std::vector<std::uint32_t>& sharpCells = scratch.sharpCells;
        for (std::size_t task = r.begin(); task < r.end(); ++task) {
            const std::size_t li = only ? (*only)[task] : task;
            const MaskLeaf& leaf = leafManager.leaf(li);
            LeafWork& w = work[li];
            if (only) w = LeafWork();
            w.origin = leaf.origin();
            const auto& mask = leaf.getValueMask();
            std::uint16_t running = 0;
            for (int word = 0; word < 8; ++word) {
                w.wordRank[std::size_t(word)] = running;
                running = std::uint16_t(running + __builtin_popcountll(mask.template getWord<std::uint64_t>(openvdb::Index(word))));
            }
            linkNeighbours(w, acc);
            const std::size_t cells = running;
            w.config.resize(cells);
            w.ownedEdges.resize(cells);
            w.vertexPrefix.resize(cells);
            w.candidatesKnown = options.normals;
            sharpCells.clear();

            if (nodeGradients) {
                // The gradients' sample holds the leaf's node values too.
                markLeafNodes(leaf, needed);
                gradients.sample(field, frame, w.origin, needed);
                gradients.leafValues(vals);
            } else {
                sampleLeafNodes(field, frame, leaf, needed, vals);
            }
            moved.fill(0);
            vertices.clear();
            normals.clear();
            bool apronSampled = false; // without node gradients: gradients.sampleValues, once needed
            int aroundMoved = -1;      // do the leaf's nodes or those beside them move? (once needed)
            // Most leaves hold no moved node: then the three probes per node below are skipped.
            const bool leafMoved = deformation && (anyActiveNode(*offsetAcc, w.origin) || anyActiveNode(*surfaceAcc, w.origin));
            if (leafMoved) {
                for (int z = 0; z < kLeafNodesPerSide; ++z)
                    for (int y = 0; y < kLeafNodesPerSide; ++y)
                        for (int x = 0; x < kLeafNodesPerSide; ++x) {
                            const std::size_t i = std::size_t(leafNodeIndex(x, y, z));
                            if (!needed[i]) continue;
                            const Coord n = w.origin.offsetBy(x, y, z);
                            openvdb::Vec3f off;
                            const bool isMoved = offsetAcc->probeValue(n, off);
                            if (surfaceAcc->isValueOn(n)) {
                                moved[i] = insideAcc->isValueOn(n) ? 3 : 2;
                                vals[i] = iso;
                            } else if (isMoved) {
                                moved[i] = 1;
                            }
                            if (isMoved) {
                                offsets[i] = Vec3f(off.x(), off.y(), off.z());
                                if (moved[i] == 1) vals[i] = field.value(frame.nodeWorld(Vec3i(n.x(), n.y(), n.z())) + Vec3d(offsets[i]));
                            } else {
                                offsets[i] = Vec3f();
                            }
                        }
            }
            // A crossing on an undeformed edge of a linear field at least this far (as a share of
            // the edge) from both ends can neither round to a node in float nor lie within kOnNode
            // of one, so the tests for that are skipped for it: the float rounding reaches at most
            // 2^-22 of the largest coordinate of the leaf's nodes (taken twice over).
            double clear = 1.0;
            if (linear) {
                const Vec3d lo = frame.nodeWorld(Vec3i(w.origin.x(), w.origin.y(), w.origin.z()));
                const Vec3d hi = frame.nodeWorld(Vec3i(w.origin.x() + kLeafNodesPerSide - 1, w.origin.y() + kLeafNodesPerSide - 1,
                                                       w.origin.z() + kLeafNodesPerSide - 1));
                double largest = 0;
                for (std::size_t a = 0; a < 3; ++a) largest = std::max({largest, std::fabs(lo[a]), std::fabs(hi[a])});
                clear = std::max(kOnNode, largest / frame.h * 0x1p-21) + 1e-6;
            }
            auto nodePos = [&](const Vec3i& local) {
                Vec3d p = frame.nodeWorld(Vec3i(w.origin.x() + local.x, w.origin.y() + local.y, w.origin.z() + local.z));
                const std::size_t i = std::size_t(leafNodeIndex(local.x, local.y, local.z));
                if (moved[i]) p += Vec3d(offsets[i]);
                return p;
            };

            // Each node's side once (a node is a corner of up to eight cells); without a branch a
            // node where none moved (most leaves).
            if (leafMoved) {
                for (std::size_t i = 0; i < std::size_t(kLeafNodeCount); ++i)
                    inside[i] = needed[i] && (moved[i] >= 2 ? moved[i] == 3 : isInside(vals[i], iso, side));
            } else if (side == Inside::Below) { // (the side fixed in each loop: one vector compare)
                for (std::size_t i = 0; i < std::size_t(kLeafNodeCount); ++i)
                    inside[i] = std::uint8_t((needed[i] != 0) & isInside(vals[i], iso, Inside::Below));
            } else {
                for (std::size_t i = 0; i < std::size_t(kLeafNodeCount); ++i)
                    inside[i] = std::uint8_t((needed[i] != 0) & isInside(vals[i], iso, Inside::Above));
            }
            std::size_t rank = 0;
            for (auto it = mask.beginOn(); it; ++it, ++rank) {
                const int off = int(it.pos()), x = off >> 6, y = (off >> 3) & 7, z = off & 7;
                const std::uint8_t* corner = &inside[std::size_t(leafNodeIndex(x, y, z))];
                constexpr int kY = kLeafNodesPerSide, kZ = kLeafNodesPerSide * kLeafNodesPerSide;
                const unsigned config = unsigned(corner[0]) | unsigned(corner[1]) << 1 | unsigned(corner[kY]) << 2 |
                                        unsigned(corner[kY + 1]) << 3 | unsigned(corner[kZ]) << 4 | unsigned(corner[kZ + 1]) << 5 |
                                        unsigned(corner[kZ + kY]) << 6 | unsigned(corner[kZ + kY + 1]) << 7;
                w.config[rank] = std::uint8_t(config);
                w.vertexPrefix[rank] = std::uint16_t(vertices.size());
                if (config == 0 || config == 255) continue;
                ++w.cellsWithSurface;
                const CubeCase& cc = cubeCase(config);
                const Coord cell = w.origin.offsetBy(x, y, z);
                const bool boundary = onMaxFace(cell, range);
                std::uint16_t owned = 0;
                for (unsigned edges = cc.edgeMask; edges; edges &= edges - 1) {
                    const int e = __builtin_ctz(edges);
                    const int axis = cubeEdgeAxis(e);
                    const Vec3i eo = cubeEdgeOrigin(e);
                    if (eo != Vec3i()) {
                        if (!boundary) continue;
                        if (edgeOwner(cell.offsetBy(eo.x, eo.y, eo.z), axis, range) != cell) continue;
                    }
                    owned |= std::uint16_t(1u << e);
                    // (Built from scalars, not by indexing a copy: that left them in memory,
                    // written in parts and read whole, a store-forwarding stall per edge.)
                    const Vec3i la(x + eo.x, y + eo.y, z + eo.z);
                    const Vec3i lb(la.x + (axis == 0), la.y + (axis == 1), la.z + (axis == 2));
                    const std::size_t ia = std::size_t(leafNodeIndex(la.x, la.y, la.z));
                    const std::size_t ib = std::size_t(leafNodeIndex(lb.x, lb.y, lb.z));
                    const double va = vals[ia], vb = vals[ib];
                    const Vec3d pa = nodePos(la), pb = nodePos(lb);
                    // A node exactly at the iso value carries the crossing of each of its edges:
                    // those vertices coincide and are welded into one after the second pass. So
                    // does a crossing within kOnNode of a node or that rounds to its point in the
                    // mesh's float coordinates (a node within rounding of the iso value: a level
                    // set's voxels on a box's face are stored so): else the node's crossings would
                    // be distinct vertices at one point, and the polygons between them would have
                    // no area (a box's corner cap; nodes bridged onto a face at the lattice's half
                    // cells).
                    const std::uint32_t local = std::uint32_t(vertices.size());
                    Vec3d p;
                    double t;
                    int atEnd = va == iso ? 0 : (vb == iso ? 1 : -1);
                    bool weld = true; // list the vertex for welding at its node
                    const bool straight = linear && !moved[ia] && !moved[ib];
                    if (atEnd < 0) {
                        t = straight ? (iso - va) / (vb - va) : field.edgeCrossing(pa, pb, va, vb, iso);
                        p = pa + (pb - pa) * t;
                    }
                    if (atEnd < 0 && !(straight && t > clear && t < 1 - clear)) {
                        const Vec3f rounded(p);
                        const double near = kOnNode * kOnNode * frame.h * frame.h;
                        atEnd = rounded == Vec3f(pa) || dot(p - pa, p - pa) <= near ? 0
                                : rounded == Vec3f(pb) || dot(p - pb, p - pb) <= near ? 1 : -1;
                        if (atEnd >= 0) {
                            // Where one of the node's neighbours alone lies across, this is the
                            // node's only crossing: nothing to weld (a box's faces on node planes
                            // put every crossing there on a node). (Not where nodes moved: their
                            // sides are not the values'.)
                            const Vec3i ln = atEnd == 0 ? la : lb;
                            int across = -1;
                            if (aroundMoved < 0) {
                                const Coord below = w.origin.offsetBy(-8, -8, -8);
                                aroundMoved = leafMoved || (deformation && (anyActiveNode(*offsetAcc, below) || anyActiveNode(*surfaceAcc, below)));
                            }
                            if (!aroundMoved) {
                                if (!nodeGradients && !apronSampled) gradients.sampleValues(field, frame, w.origin), apronSampled = true;
                                const bool in = isInside(gradients.value(ln.x, ln.y, ln.z), iso, side);
                                across = 0;
                                for (int k = 0; k < 6; ++k) {
                                    Vec3i nb = ln;
                                    nb[std::size_t(k / 2)] += k % 2 ? 1 : -1;
                                    across += isInside(gradients.value(nb.x, nb.y, nb.z), iso, side) != in;
                                }
                            }
                            weld = across != 1;
                            if (weld) w.roundedVertices.push_back(local);
                        }
                    }
                    if (atEnd >= 0) {
                        t = atEnd;
                        p = atEnd == 0 ? pa : pb;
                        const Vec3i ln = atEnd == 0 ? la : lb;
                        if (weld) w.nodeVertices.emplace_back(local, w.origin.offsetBy(ln.x, ln.y, ln.z));
                    }
                    vertices.push_back(Vec3f(p));
                    if (options.normals) {
                        // On a grid at its own voxel size the gradient along an undeformed edge is
                        // that of the nodes' central differences, interpolated; else the field's.
                        const bool fromNodes = nodeGradients && !moved[ia] && !moved[ib];
                        Vec3d g = fromNodes ? gradients.at(la) * (1 - t) + gradients.at(lb) * t : field.gradient(p);
                        const double len = std::sqrt(dot(g, g));
                        normals.push_back(len > 0 && std::isfinite(len) ? Vec3f(g * (outward / len)) : Vec3f());
                    }
                }
                w.ownedEdges[rank] = owned;
                if (options.normals) {
                    bool candidate = true;
                    if (nodeGradients) {
                        bool anyMoved = false; // (none where the leaf's nodes all stand at rest)
                        for (int c = 0; c < 8 && leafMoved && !anyMoved; ++c) anyMoved = moved[std::size_t(leafCornerIndex(it.pos(), c))] != 0;
                        if (!anyMoved) candidate = gradients.mayHoldSharpEdge(x, y, z, edgeLimit);
                    }
                    if (candidate) sharpCells.push_back(std::uint32_t(off) << 16 | std::uint32_t(rank));
                }
                for (int l = 0; l < cc.loopCount; ++l) {
                    w.faceCount += loopFaces(cc.loopSize[l], tri, options.keepLoops);
                    w.indexCount += loopIndices(cc.loopSize[l], tri, options.keepLoops);
                }
            }
            w.vertices.assign(vertices.begin(), vertices.end());
            w.normals.assign(normals.begin(), normals.end());
            w.sharpCells.assign(sharpCells.begin(), sharpCells.end());
            if (nodeGradients && options.sharpEdgeCosine < 1 && unresolvedForFeatures(w, options.unresolvedShare)) {
                w.sharpCells.clear();
                w.unresolved = true;
            }
            progress.advance();
        }
    });
    if (options.cancel) options.cancel->check();
    stats.leaves = leafCount;
    stats.cellsWithSurface = 0;
    stats.unresolvedLeaves = 0;
    for (const LeafWork& w : work) {
        stats.cellsWithSurface += w.cellsWithSurface;
        stats.unresolvedLeaves += w.unresolved;
    }
}

VertexRef LatticeSurface::Impl::vertexOf(const LeafWork& w, const Coord& cell, int e) const {
    const int axis = cubeEdgeAxis(e);
    const Vec3i eo = cubeEdgeOrigin(e);
    const Coord a = cell.offsetBy(eo.x, eo.y, eo.z);
    const Coord owner = edgeOwner(a, axis, lattice.cellRange);
    const Coord d = (owner & ~7) - w.origin;
    const std::int32_t ni = w.neighbor[std::size_t((d.x() >> 3) | ((d.y() >> 3) << 1) | ((d.z() >> 3) << 2))];
    if (ni < 0) throw std::logic_error("lattice surface: the owner of an edge is not in the lattice");
    const LeafWork& ow = work[std::size_t(ni)];
    const MaskLeaf& ol = leafManager.leaf(std::size_t(ni));
    const openvdb::Index off = MaskLeaf::coordToOffset(owner);
    if (!ol.isValueOn(off)) throw std::logic_error("lattice surface: the owner cell of an edge is inactive");
    const std::uint32_t rank = cellRank(ol, ow, off);
    const Coord rel = a - owner;
    const int oe = cubeEdgeIndex(axis, {rel.x(), rel.y(), rel.z()});
    const std::uint16_t m = ow.ownedEdges[rank];
    if (!(m & (1u << oe))) throw std::logic_error("lattice surface: an edge crossing has no vertex");
    return {std::uint32_t(ni), std::uint32_t(ow.vertexPrefix[rank]) + std::uint32_t(__builtin_popcount(m & ((1u << oe) - 1u)))};
}

LatticeSurface::LatticeSurface(const Field& field, const Lattice& lattice, const LatticeDeformation* deformation,
                               const SurfaceOptions& options)
    : mImpl(std::make_unique<Impl>(field, lattice, deformation, options)) {
    mImpl->firstPass();
    mImpl->stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - mImpl->start).count();
}

LatticeSurface::~LatticeSurface() = default;

const SurfaceStats& LatticeSurface::stats() const { return mImpl->stats; }

void LatticeSurface::forEachSurfaceCell(const std::function<void(const CellCrossings&)>& fn, bool onlySharpCandidates) const {
    const Impl& im = *mImpl;
    if (im.meshTaken) throw std::logic_error("LatticeSurface: cells visited after the mesh was taken");
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, im.work.size(), 8), [&](const tbb::blocked_range<std::size_t>& r) {
        std::array<Vec3f, 12> pos, nrm;
        for (std::size_t li = r.begin(); li < r.end(); ++li) {
            const LeafWork& w = im.work[li];
            auto visit = [&](openvdb::Index offset, unsigned config) {
                const int off = int(offset);
                CellCrossings c;
                c.cell = w.origin.offsetBy(off >> 6, (off >> 3) & 7, off & 7);
                c.config = config;
                const CubeCase& cc = cubeCase(config);
                const bool onMax = onMaxFace(c.cell, im.lattice.cellRange);
                for (unsigned edges = cc.edgeMask; edges; edges &= edges - 1) {
                    const int e = __builtin_ctz(edges);
                    const VertexRef v = im.vertexOfCell(li, w, offset, c.cell, onMax, e);
                    pos[std::size_t(e)] = im.work[v.leaf].vertices[v.local];
                    if (im.options.normals) nrm[std::size_t(e)] = im.work[v.leaf].normals[v.local];
                }
                c.position = pos.data();
                c.normal = im.options.normals ? nrm.data() : nullptr;
                fn(c);
            };
            if (onlySharpCandidates && w.candidatesKnown) {
                for (const std::uint32_t cell : w.sharpCells) visit(openvdb::Index(cell >> 16), w.config[cell & 0xFFFFu]);
                continue;
            }
            std::size_t rank = 0;
            for (auto it = im.leafManager.leaf(li).getValueMask().beginOn(); it; ++it, ++rank) {
                const unsigned config = w.config[rank];
                if (config != 0 && config != 255) visit(it.pos(), config);
            }
        }
    });
    if (im.options.cancel) im.options.cancel->check();
}

void LatticeSurface::rebuildAround(const std::vector<Vec3i>& nodes, const LatticeDeformation& deformation) {
    Impl& im = *mImpl;
    if (im.meshTaken) throw std::logic_error("LatticeSurface: rebuilt after the mesh was taken");
    // The lattice may have gained cells around moved nodes, some in new leaves: carry the work
    // of every leaf that existed over to the new leaf order; new leaves start empty.
    // Cells are only ever added, so the old leaves are all still there, and in the same order
    // (the leaf manager lists leaves in the tree's order, a fixed order of their origins): one
    // walk back along both lists matches them, moving each old leaf's work to its new place (at
    // or after its old one) in the same array. (Hash maps of origins and a fresh array cost
    // 1.5 ms of the armadillo's sharp pass, serially.)
    im.leafManager.rebuild();
    const std::size_t leafCount = im.leafManager.leafCount(), oldCount = im.work.size();
    if (leafCount < oldCount) throw std::logic_error("lattice surface: a leaf of the lattice went missing before a rebuild");
    im.work.resize(leafCount);
    std::vector<std::uint8_t> isDirty(leafCount, 0);
    std::vector<std::int32_t> newIndex(oldCount); // old leaf index -> new
    std::vector<std::size_t> added;               // new leaves, descending
    std::size_t old = oldCount; // old leaves [0, old) not yet placed
    for (std::size_t li = leafCount; li-- > 0;) {
        const MaskLeaf& leaf = im.leafManager.leaf(li);
        LeafWork& w = im.work[li];
        if (old > 0 && im.work[old - 1].origin == leaf.origin()) {
            newIndex[--old] = std::int32_t(li);
            if (old != li) w = std::move(im.work[old]);
        } else {
            w = LeafWork();
            isDirty[li] = 1;
            added.push_back(li);
        }
        // A leaf that gained cells has new cell ranks.
        if (leaf.onVoxelCount() != w.config.size()) isDirty[li] = 1;
    }
    if (old != 0) throw std::logic_error("lattice surface: a leaf of the lattice went missing before a rebuild");
    im.indexLeaves();
    for (const Vec3i& n : nodes)
        for (int d = 0; d < 8; ++d) {
            const Coord cell(n.x - (d & 1), n.y - ((d >> 1) & 1), n.z - ((d >> 2) & 1));
            if (!im.lattice.cellRange.isInside(cell)) continue;
            if (const MaskLeaf* leaf = im.lattice.cells->probeConstLeaf(cell)) isDirty[std::size_t(im.indexOf(leaf))] = 1;
        }
    std::vector<std::size_t> dirty;
    for (std::size_t li = 0; li < leafCount; ++li)
        if (isDirty[li]) dirty.push_back(li);
    // Neighbour tables hold leaf indices, which moved where leaves were added: the clean leaves'
    // are renumbered here, and those beside an added leaf told of it; the dirty leaves' are made
    // anew by the first pass. (Probing every leaf's neighbours again cost 0.7 ms on the armadillo
    // for one added leaf.)
    if (!added.empty()) {
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, leafCount, 256), [&](const tbb::blocked_range<std::size_t>& r) {
            for (std::size_t li = r.begin(); li < r.end(); ++li) {
                if (isDirty[li]) continue;
                for (std::int32_t& nb : im.work[li].neighbor)
                    if (nb >= 0) nb = newIndex[std::size_t(nb)];
            }
        });
        for (const std::size_t li : added) {
            const Coord origin = im.leafManager.leaf(li).origin();
            for (int d = 0; d < 8; ++d) { // the leaf whose neighbour d this one is
                const Coord below = origin.offsetBy(-8 * (d & 1), -8 * ((d >> 1) & 1), -8 * ((d >> 2) & 1));
                const MaskLeaf* leaf = im.lattice.cells->probeConstLeaf(below);
                if (!leaf) continue;
                const std::size_t bi = std::size_t(im.indexOf(leaf));
                if (!isDirty[bi]) im.work[bi].neighbor[std::size_t(d)] = std::int32_t(li);
            }
        }
    }
    im.deformation = deformation.empty() ? nullptr : &deformation;
    im.options.normals = false; // the sharp pass, their only reader, is done
    im.firstPass(&dirty);
}

std::uint64_t LatticeSurface::moveCrossingsToFeatureNodes(const LatticeDeformation& deformation) {
    Impl& im = *mImpl;
    if (im.meshTaken) throw std::logic_error("LatticeSurface: crossings moved after the mesh was taken");
    if (deformation.onSurface->empty()) return 0;
    const LatticeFrame& frame = im.lattice.frame;
    std::vector<std::uint64_t> movedPerLeaf(im.work.size(), 0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, im.work.size(), 8), [&](const tbb::blocked_range<std::size_t>& r) {
        openvdb::tree::ValueAccessor<const NodeMaskTree, false> onSurface(*deformation.onSurface);
        openvdb::tree::ValueAccessor<const OffsetTree, false> offsets(*deformation.offsets);
        std::bitset<kLeafNodeCount> featureNode;
        std::array<std::uint64_t, 8> nearFeature; // cells with a feature node as a corner
        auto placed = [&](const Coord& n) {
            const openvdb::Vec3f o = offsets.getValue(n);
            return Vec3f(frame.nodeWorld(Vec3i(n.x(), n.y(), n.z())) + Vec3d(o.x(), o.y(), o.z()));
        };
        for (std::size_t li = r.begin(); li < r.end(); ++li) {
            LeafWork& w = im.work[li];
            if (w.vertices.empty()) continue;
            // Only nodes of this leaf's block (origin .. origin + 8) can be edge ends here.
            if (!activeLeafNodes(onSurface, w.origin, featureNode, nearFeature)) continue;
            auto onFeature = [&](const Coord& n) {
                const Coord d = n - w.origin;
                return featureNode.test(std::size_t(leafNodeIndex(d.x(), d.y(), d.z())));
            };
            // Vertices already on a node (a data node at the iso value): (vertex, node), by vertex.
            std::vector<std::pair<std::uint32_t, Coord>> atDataNode(w.nodeVertices.begin(), w.nodeVertices.end());
            std::sort(atDataNode.begin(), atDataNode.end(), [](const auto& x, const auto& y) { return x.first < y.first; });
            std::vector<std::pair<std::uint32_t, Coord>> toFirstEnd; // data-node vertices moved to the edge's first end
            // An edge's ends are corners of the cell that owns its crossing: only cells with a
            // feature node as a corner can hold one that moves (or a data-node vertex that
            // follows a node). Those, in the leaf's order.
            const MaskLeaf& leaf = im.leafManager.leaf(li);
            for (int word = 0; word < 8; ++word)
                for (std::uint64_t bits = nearFeature[std::size_t(word)] & leaf.getValueMask().template getWord<std::uint64_t>(openvdb::Index(word));
                     bits; bits &= bits - 1) {
                const openvdb::Index offset = openvdb::Index(64 * word + __builtin_ctzll(bits));
                const std::uint32_t rank = cellRank(leaf, w, offset);
                const std::uint16_t owned = w.ownedEdges[rank];
                if (!owned || w.config[rank] == 0 || w.config[rank] == 255) continue;
                const int off = int(offset);
                const Coord cell = w.origin.offsetBy(off >> 6, (off >> 3) & 7, off & 7);
                std::uint32_t local = w.vertexPrefix[rank];
                for (int e = 0; e < 12; ++e) {
                    if (!(owned & (1u << e))) continue;
                    const std::uint32_t v = local++;
                    const Vec3i eo = cubeEdgeOrigin(e);
                    const Coord a = cell.offsetBy(eo.x, eo.y, eo.z);
                    Coord b = a;
                    b[cubeEdgeAxis(e)] += 1;
                    const auto data = std::lower_bound(atDataNode.begin(), atDataNode.end(), v,
                                                       [](const auto& x, std::uint32_t u) { return x.first < u; });
                    if (data != atDataNode.end() && data->first == v) {
                        // At a data node: it stays there, but follows the node onto a feature; and
                        // where the edge's first end is on a feature, it goes there, as in a
                        // surface built on the deformed lattice (both ends hold the iso value
                        // then, and the first end carries the crossing).
                        if (onFeature(data->second)) {
                            w.vertices[v] = placed(data->second);
                            ++movedPerLeaf[li];
                        } else if (data->second == b && onFeature(a)) {
                            w.vertices[v] = placed(a);
                            toFirstEnd.emplace_back(v, a);
                            ++movedPerLeaf[li];
                        }
                        continue;
                    }
                    const Coord* n = onFeature(a) ? &a : (onFeature(b) ? &b : nullptr);
                    if (!n) continue;
                    w.vertices[v] = placed(*n);
                    w.nodeVertices.emplace_back(v, *n);
                    ++movedPerLeaf[li];
                }
            }
            if (!toFirstEnd.empty()) {
                std::sort(toFirstEnd.begin(), toFirstEnd.end(), [](const auto& x, const auto& y) { return x.first < y.first; });
                for (auto& nv : w.nodeVertices) {
                    const auto it = std::lower_bound(toFirstEnd.begin(), toFirstEnd.end(), nv.first,
                                                     [](const auto& x, std::uint32_t u) { return x.first < u; });
                    if (it != toFirstEnd.end() && it->first == nv.first) nv.second = it->second;
                }
            }
            std::sort(w.nodeVertices.begin(), w.nodeVertices.end(),
                      [](const auto& x, const auto& y) { return x.first < y.first; });
        }
    });
    std::uint64_t total = 0;
    for (std::uint64_t m : movedPerLeaf) total += m;
    return total;
}

Mesh LatticeSurface::mesh(const std::function<void(Mesh&, const std::vector<std::uint32_t>&)>& beforeWeld) {
    Impl& im = *mImpl;
    if (im.meshTaken) throw std::logic_error("LatticeSurface::mesh called twice");
    im.meshTaken = true;
    const auto start = std::chrono::steady_clock::now();
    const std::size_t leafCount = im.work.size();
    const bool tri = im.options.triangulate, whole = im.options.keepLoops;

    // Prefix sums, in leaf order: this fixes every vertex and polygon number.
    std::uint32_t vtotal = 0, ftotal = 0, itotal = 0;
    for (LeafWork& w : im.work) {
        w.vertexBase = vtotal;
        w.faceBase = ftotal;
        w.indexBase = itotal;
        const std::uint64_t nv = std::uint64_t(vtotal) + w.vertices.size();
        const std::uint64_t ni = std::uint64_t(itotal) + w.indexCount;
        if (nv > 0xffffffffull || ni > 0xffffffffull) throw std::runtime_error("mesh too large for 32-bit indices");
        vtotal = std::uint32_t(nv);
        ftotal += w.faceCount;
        itotal = std::uint32_t(ni);
    }

    Mesh mesh;
    // The weld gives a welded node one vertex per fan where several meet (rarely more than two):
    // room for those, so that adding them does not move the whole array (a node has two vertices
    // or more to be welded, so there are fewer such nodes than vertices on nodes).
    std::size_t onNodes = 0;
    for (const LeafWork& w : im.work) onNodes += w.nodeVertices.size();
    // (Mapped in parallel first: fresh memory, a page fault every 4 KB.)
    mesh.points.reserve(std::size_t(vtotal) + onNodes);
    resizePrefaulted(mesh.points, vtotal);
    resizePrefaulted(mesh.offsets, std::size_t(ftotal) + 1);
    resizePrefaulted(mesh.indices, itotal);

    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, leafCount, 64), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t li = r.begin(); li < r.end(); ++li)
            std::copy(im.work[li].vertices.begin(), im.work[li].vertices.end(), mesh.points.begin() + im.work[li].vertexBase);
    });

    std::vector<std::pair<std::uint32_t, Vec3i>> atNode; // (vertex, node), in leaf order
    std::vector<std::uint8_t> rounded;                    // per entry of atNode: put there by rounding
    for (const LeafWork& w : im.work) {
        // (Both lists ascend by vertex.)
        auto r = w.roundedVertices.begin();
        for (const auto& [local, node] : w.nodeVertices) {
            atNode.emplace_back(w.vertexBase + local, Vec3i(node.x(), node.y(), node.z()));
            while (r != w.roundedVertices.end() && *r < local) ++r;
            rounded.push_back(r != w.roundedVertices.end() && *r == local);
        }
    }
    // The polygons through a vertex the weld may merge, found as they are made (a scan of the
    // whole mesh for them was a tenth of the weld), unless the fit below changes the polygons.
    std::vector<std::uint8_t> mayWeld; // per vertex
    std::vector<std::vector<std::uint32_t>> weldPolygons; // per leaf, ascending
    NodeGroups groups; // (a sort of atNode by node: once, here and for the weld)
    if (!beforeWeld && !atNode.empty()) {
        mayWeld = prefaultedVector<std::uint8_t>(vtotal, 0);
        groups = groupByNode(atNode);
        for (const std::uint32_t v : verticesToWeld(atNode, groups)) mayWeld[v] = 1;
        weldPolygons.resize(leafCount);
    }
    Progress progress("surface polygons", leafCount, im.options.cancel);
    // Second pass: polygons with global vertex numbers (all vertices are in place: quads may be
    // split along their shorter diagonal).
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, leafCount, 8), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t li = r.begin(); li < r.end(); ++li) {
            const MaskLeaf& leaf = im.leafManager.leaf(li);
            const LeafWork& w = im.work[li];
            std::uint32_t f = w.faceBase, idx = w.indexBase;
            std::vector<std::uint32_t>* weldHere = weldPolygons.empty() ? nullptr : &weldPolygons[li];
            std::size_t rank = 0;
            for (auto it = leaf.getValueMask().beginOn(); it; ++it, ++rank) {
                const unsigned config = w.config[rank];
                if (config == 0 || config == 255) continue;
                const int off = int(it.pos());
                const Coord cell = w.origin.offsetBy(off >> 6, (off >> 3) & 7, off & 7);
                const CubeCase& cc = cubeCase(config);
                const bool onMax = onMaxFace(cell, im.lattice.cellRange);
                std::array<std::uint32_t, 12> ids;
                for (int l = 0, k0 = 0; l < cc.loopCount; k0 += cc.loopSize[l], ++l) {
                    const std::uint32_t k = cc.loopSize[l];
                    for (std::uint32_t i = 0; i < k; ++i) {
                        const VertexRef v = im.vertexOfCell(li, w, it.pos(), cell, onMax, cc.edges[k0 + int(i)]);
                        ids[i] = im.work[v.leaf].vertexBase + v.local;
                    }
                    auto emit = [&](std::initializer_list<std::uint32_t> vs) {
                        bool weld = false;
                        for (std::uint32_t v : vs) mesh.indices[idx++] = v, weld = weld || (weldHere && mayWeld[v]);
                        if (weld) weldHere->push_back(f);
                        mesh.offsets[++f] = idx;
                    };
                    if (whole && k > 4) {
                        bool weld = false;
                        for (std::uint32_t i = 0; i < k; ++i) mesh.indices[idx++] = ids[i], weld = weld || (weldHere && mayWeld[ids[i]]);
                        if (weld) weldHere->push_back(f);
                        mesh.offsets[++f] = idx;
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
    if (im.options.cancel) im.options.cancel->check();
    // The leaves' lists of polygons to weld, joined in leaf order.
    std::vector<std::uint32_t> polygonsToWeld;
    std::vector<std::size_t> weldBase(weldPolygons.size() + 1, 0);
    for (std::size_t li = 0; li < weldPolygons.size(); ++li) weldBase[li + 1] = weldBase[li] + weldPolygons[li].size();
    polygonsToWeld.resize(weldBase.back());
    if (!weldPolygons.empty())
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, leafCount, 64), [&](const tbb::blocked_range<std::size_t>& r) {
            for (std::size_t li = r.begin(); li < r.end(); ++li)
                std::copy(weldPolygons[li].begin(), weldPolygons[li].end(), polygonsToWeld.begin() + std::ptrdiff_t(weldBase[li]));
        });
    weldPolygons = {};
    // The leaves' own arrays (several a leaf) are done with: freed by a task of their own while
    // the weld runs (its short parallel loops leave the other threads idle at times; freed before
    // it, they were a serial tail of the mesher, then a contended one: each leaf's arrays came
    // from the heap of the thread that made them).
    tbb::task_group teardown;
    teardown.run([&] {
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, leafCount, 64), [&](const tbb::blocked_range<std::size_t>& r) {
            for (std::size_t li = r.begin(); li < r.end(); ++li) im.work[li] = LeafWork();
        });
    });
    std::vector<std::uint32_t> added; // by beforeWeld (the surface fit: vertices on feature points among them)
    if (beforeWeld) {
        std::vector<std::uint32_t> toWeld(atNode.size());
        for (std::size_t i = 0; i < atNode.size(); ++i) toWeld[i] = atNode[i].first;
        const std::size_t before = mesh.points.size();
        beforeWeld(mesh, toWeld);
        for (std::size_t v = before; v < mesh.points.size(); ++v) added.push_back(std::uint32_t(v));
    }
    const NodeWeldStats welding = weldNodeVertices(mesh, atNode, rounded, added, mayWeld.empty() ? nullptr : &polygonsToWeld,
                                                   groups.representative.empty() ? nullptr : &groups);
    teardown.wait();
    im.stats.weldedVertices = welding.weldedVertices;
    im.stats.collapsedPolygons = welding.collapsedPolygons;
    im.stats.splitVertices = welding.splitVertices;
    im.stats.foldsClosed = welding.foldsClosed;
    im.stats.separatedVertices = welding.separatedVertices;
    im.stats.seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return mesh;
}

Mesh marchingCubes(const Field& field, const Lattice& lattice, const SurfaceOptions& options, SurfaceStats* stats) {
    LatticeSurface surface(field, lattice, nullptr, options);
    Mesh mesh = surface.mesh();
    if (stats) *stats = surface.stats();
    return mesh;
}

} // namespace vdbsurf
