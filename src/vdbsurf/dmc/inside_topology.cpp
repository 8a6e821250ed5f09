#include "vdbsurf/dmc/inside_topology.h"

#include "vdbsurf/dmc/cube_table.h"

#include <algorithm>
#include <array>
#include <cstdint>
#include <cstdlib>
#include <vector>

namespace vdbsurf {

namespace {

struct Offset {
    int x, y, z;
};

// Offsets of the points of a 3x3x3 block from its centre.
Offset blockOffset(int i) { return {i % 3 - 1, (i / 3) % 3 - 1, i / 9 - 1}; }

// Steps from the centre to point i: 1 across a face, 2 across an edge, 3 across a corner.
int stepsFromCentre(int i) {
    const Offset o = blockOffset(i);
    return std::abs(o.x) + std::abs(o.y) + std::abs(o.z);
}

// Are points i and j of the block adjacent across a face?
bool adjacent(int i, int j) {
    const Offset a = blockOffset(i), b = blockOffset(j);
    return std::abs(a.x - b.x) + std::abs(a.y - b.y) + std::abs(a.z - b.z) == 1;
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
        const int s = k % 2 ? 1 : -1;
        euler -= at(0, 0, 0) || at(k / 2 == 0 ? s : 0, k / 2 == 1 ? s : 0, k / 2 == 2 ? s : 0);
    }
    for (int a = 0; a < 3; ++a)
        for (int b = a + 1; b < 3; ++b)
            for (int sa = -1; sa <= 1; sa += 2)
                for (int sb = -1; sb <= 1; sb += 2) {
                    int ea[3] = {0, 0, 0}, eb[3] = {0, 0, 0};
                    ea[a] = sa;
                    eb[b] = sb;
                    const unsigned corners = unsigned(at(0, 0, 0)) | unsigned(at(ea[0], ea[1], ea[2])) << 1 |
                                             unsigned(at(eb[0], eb[1], eb[2])) << 2 |
                                             unsigned(at(ea[0] + eb[0], ea[1] + eb[1], ea[2] + eb[2])) << 3;
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

int blockIndex(const Vec3i& p) { return p.x + 3 * p.y + 9 * p.z; }

// The crossing on the block's lattice edge along `axis` from point (x, y, z) (0 .. 2 each).
constexpr int kCrossings = 27 * 3;
int crossingId(int x, int y, int z, int axis) { return (x + 3 * y + 9 * z) * 3 + axis; }

// The vertex the centre's six edges' crossings are welded into.
constexpr int kCentre = -1;

Vec3i cubeAxisStep(int axis) { return {axis == 0, axis == 1, axis == 2}; }

// The root of item i's set (a union-find over a handful of items, halving paths).
int findRoot(int* parent, int i) {
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return i;
}

// Polygons as loops of vertex ids (0 or more) in one flat list, without allocating: the weld
// check runs for most nodes placed on features, each block of sides a new one.
struct Loops27 {
    static constexpr int kMaxIds = 256, kMaxLoops = 96;
    int ids[kMaxIds];
    int start[kMaxLoops + 1] = {0};
    int count = 0;
    void add(const int* first, int size) {
        for (int i = 0; i < size; ++i) ids[start[count] + i] = first[i];
        start[count + 1] = start[count] + size;
        ++count;
    }
    int size(int l) const { return start[l + 1] - start[l]; }
    const int* loop(int l) const { return ids + start[l]; }
};

// Vertex ids stay below this: crossings, then one per fan.
constexpr int kMaxVertexIds = kCrossings + Loops27::kMaxLoops;

// The pieces and the Euler characteristic of a patch of polygons.
PatchTopology countPatch(const Loops27& polygons) {
    int parent[kMaxVertexIds];
    std::fill(parent, parent + kMaxVertexIds, -1);
    auto root = [&](int v) { return findRoot(parent, v); };
    std::uint32_t edges[Loops27::kMaxIds];
    int edgeCount = 0;
    for (int l = 0; l < polygons.count; ++l) {
        const int* p = polygons.loop(l);
        const int n = polygons.size(l);
        for (int i = 0; i < n; ++i) {
            const int a = p[i], b = p[(i + 1) % n];
            edges[edgeCount++] = std::uint32_t(std::min(a, b)) << 16 | std::uint32_t(std::max(a, b));
            if (parent[a] < 0) parent[a] = a;
            if (parent[b] < 0) parent[b] = b;
            const int ra = root(a), rb = root(b);
            parent[std::max(ra, rb)] = std::min(ra, rb);
        }
    }
    std::sort(edges, edges + edgeCount);
    const int distinctEdges = int(std::unique(edges, edges + edgeCount) - edges);
    PatchTopology out;
    int vertices = 0;
    for (int v = 0; v < kMaxVertexIds; ++v) {
        if (parent[v] < 0) continue;
        ++vertices;
        out.pieces += root(v) == v;
    }
    out.euler = vertices - distinctEdges + polygons.count;
    return out;
}

} // namespace

CentreWeld weldAtCentre(const bool inside[27]) {
    // The polygons with a crossing at the centre as marching cubes makes them, and once welded:
    // each a run of crossings from the centre round to it again (a polygon where the centre comes
    // back gives one run for each time; a run of fewer than three vertices has collapsed).
    Loops27 polygons, runs;
    for (int cell = 0; cell < 8; ++cell) {
        const int cx = cell & 1, cy = (cell >> 1) & 1, cz = (cell >> 2) & 1; // min corner in the block
        unsigned config = 0;
        for (int c = 0; c < 8; ++c)
            if (inside[(cx + (c & 1)) + 3 * (cy + ((c >> 1) & 1)) + 9 * (cz + ((c >> 2) & 1))]) config |= 1u << c;
        const CubeCase& cc = cubeCase(config);
        int first = 0;
        for (int l = 0; l < cc.loopCount; first += cc.loopSize[l], ++l) {
            int polygon[12], loop[13], size = 0;
            for (int i = 0; i < cc.loopSize[l]; ++i) {
                const int e = cc.edges[first + i];
                const Vec3i from = Vec3i(cx, cy, cz) + cubeEdgeOrigin(e), to = from + cubeAxisStep(cubeEdgeAxis(e));
                polygon[i] = crossingId(from.x, from.y, from.z, cubeEdgeAxis(e));
                const int id = blockIndex(from) == 13 || blockIndex(to) == 13 ? kCentre : polygon[i];
                if (size == 0 || loop[size - 1] != id) loop[size++] = id;
            }
            while (size > 1 && loop[0] == loop[size - 1]) --size;
            const int at = int(std::find(loop, loop + size, kCentre) - loop);
            if (at == size) continue;
            polygons.add(polygon, cc.loopSize[l]);
            std::rotate(loop, loop + at, loop + size);
            loop[size++] = kCentre;
            for (int i = 0; i + 1 < size;) {
                int j = i + 1;
                while (loop[j] != kCentre) ++j;
                if (j - i >= 3) runs.add(loop + i, j - i);
                i = j;
            }
        }
    }
    // A pair of runs that are each other reversed folds onto itself (a pillow of no volume): the
    // weld drops both.
    bool dropped[Loops27::kMaxLoops] = {};
    for (int a = 0; a < runs.count; ++a)
        for (int b = a + 1; b < runs.count && !dropped[a]; ++b) {
            if (dropped[b] || runs.size(a) != runs.size(b)) continue;
            const int n = runs.size(a);
            bool reversed = true;
            for (int k = 1; k < n && reversed; ++k) reversed = runs.loop(a)[k] == runs.loop(b)[n - k];
            if (reversed) dropped[a] = dropped[b] = true;
        }
    // Runs sharing an edge at the centre (the crossing next to it on either side) are one fan,
    // and each fan gets a vertex of its own, as the weld splits them.
    int parent[Loops27::kMaxLoops];
    for (int i = 0; i < runs.count; ++i) parent[i] = i;
    auto root = [&](int i) { return findRoot(parent, i); };
    for (int a = 0; a < runs.count; ++a)
        for (int b = a + 1; b < runs.count; ++b) {
            if (dropped[a] || dropped[b]) continue;
            const int a0 = runs.loop(a)[1], a1 = runs.loop(a)[runs.size(a) - 1], b0 = runs.loop(b)[1], b1 = runs.loop(b)[runs.size(b) - 1];
            if (a0 == b0 || a0 == b1 || a1 == b0 || a1 == b1) parent[root(a)] = root(b);
        }
    Loops27 welded;
    for (int i = 0; i < runs.count; ++i) {
        if (dropped[i]) continue;
        welded.add(runs.loop(i), runs.size(i));
        welded.ids[welded.start[welded.count - 1]] = kCrossings + root(i);
    }
    return {countPatch(polygons), countPatch(welded)};
}

int insideEulerAround(const std::vector<Vec3i>& nodes, const std::function<bool(const Vec3i&)>& inside) {
    // Each element once, by its min corner and (edges, faces) an axis: along the edge, across the
    // face.
    std::vector<std::array<int, 4>> vertices, edges, faces, cells;
    for (const Vec3i& n : nodes) {
        vertices.push_back({n.x, n.y, n.z, 0});
        for (int a = 0; a < 3; ++a) {
            const Vec3i step = cubeAxisStep(a);
            for (const Vec3i& from : {n, n - step}) edges.push_back({from.x, from.y, from.z, a});
            const Vec3i u = cubeAxisStep((a + 1) % 3), v = cubeAxisStep((a + 2) % 3);
            for (int k = 0; k < 4; ++k) {
                const Vec3i from = n - (k & 1 ? u : Vec3i(0, 0, 0)) - (k & 2 ? v : Vec3i(0, 0, 0));
                faces.push_back({from.x, from.y, from.z, a});
            }
        }
        for (int k = 0; k < 8; ++k) cells.push_back({n.x - (k & 1), n.y - ((k >> 1) & 1), n.z - ((k >> 2) & 1), 0});
    }
    for (auto* list : {&vertices, &edges, &faces, &cells}) {
        std::sort(list->begin(), list->end());
        list->erase(std::unique(list->begin(), list->end()), list->end());
    }
    auto at = [&](const std::array<int, 4>& e, const Vec3i& offset) { return inside(Vec3i(e[0], e[1], e[2]) + offset); };
    int euler = 0;
    for (const auto& n : vertices) euler += at(n, Vec3i(0, 0, 0));
    for (const auto& e : edges) euler -= at(e, Vec3i(0, 0, 0)) || at(e, cubeAxisStep(e[3]));
    for (const auto& f : faces) {
        const Vec3i u = cubeAxisStep((f[3] + 1) % 3), v = cubeAxisStep((f[3] + 2) % 3);
        unsigned corners = 0;
        for (int k = 0; k < 4; ++k) corners |= unsigned(at(f, (k & 1 ? u : Vec3i(0, 0, 0)) + (k & 2 ? v : Vec3i(0, 0, 0)))) << k;
        euler += cornerComponents(corners, 2);
    }
    for (const auto& c : cells) {
        unsigned corners = 0;
        for (int k = 0; k < 8; ++k) corners |= unsigned(at(c, Vec3i(k & 1, (k >> 1) & 1, (k >> 2) & 1))) << k;
        euler -= cornerComponents(corners, 3);
    }
    return euler;
}

int piecesInBox(const Vec3i& lo, const Vec3i& hi, bool side, const std::function<bool(const Vec3i&)>& inside) {
    const Vec3i dims = hi - lo + Vec3i(1, 1, 1);
    if (dims.x <= 0 || dims.y <= 0 || dims.z <= 0) return 0;
    auto index = [&](const Vec3i& n) { return std::size_t((n.x - lo.x) + dims.x * ((n.y - lo.y) + dims.y * (n.z - lo.z))); };
    std::vector<std::int8_t> state(std::size_t(dims.x) * std::size_t(dims.y) * std::size_t(dims.z), -1); // -1: not yet read
    auto onSide = [&](const Vec3i& n) {
        std::int8_t& s = state[index(n)];
        if (s < 0) s = inside(n) == side ? 1 : 0;
        return s == 1;
    };
    std::vector<std::uint8_t> seen(state.size(), 0);
    std::vector<Vec3i> stack;
    int pieces = 0;
    for (int z = lo.z; z <= hi.z; ++z)
        for (int y = lo.y; y <= hi.y; ++y)
            for (int x = lo.x; x <= hi.x; ++x) {
                const Vec3i start(x, y, z);
                if (seen[index(start)] || !onSide(start)) continue;
                ++pieces;
                seen[index(start)] = 1;
                stack.push_back(start);
                while (!stack.empty()) {
                    const Vec3i n = stack.back();
                    stack.pop_back();
                    for (int dz = -1; dz <= 1; ++dz)
                        for (int dy = -1; dy <= 1; ++dy)
                            for (int dx = -1; dx <= 1; ++dx) {
                                const int steps = std::abs(dx) + std::abs(dy) + std::abs(dz);
                                if (steps == 0 || steps > (side ? 1 : 2)) continue;
                                const Vec3i m = n + Vec3i(dx, dy, dz);
                                if (m.x < lo.x || m.y < lo.y || m.z < lo.z || m.x > hi.x || m.y > hi.y || m.z > hi.z) continue;
                                if (seen[index(m)] || !onSide(m)) continue;
                                seen[index(m)] = 1;
                                stack.push_back(m);
                            }
                }
            }
    return pieces;
}

std::vector<std::vector<Vec3i>> groupsAcrossCorners(std::vector<Vec3i> nodes) {
    std::sort(nodes.begin(), nodes.end(), lessXYZ);
    nodes.erase(std::unique(nodes.begin(), nodes.end()), nodes.end());
    std::vector<int> parent(nodes.size());
    for (std::size_t i = 0; i < nodes.size(); ++i) parent[i] = int(i);
    for (std::size_t i = 0; i < nodes.size(); ++i)
        for (int z = -1; z <= 1; ++z)
            for (int y = -1; y <= 1; ++y)
                for (int x = -1; x <= 1; ++x) {
                    const Vec3i n = nodes[i] + Vec3i(x, y, z);
                    const auto it = std::lower_bound(nodes.begin(), nodes.end(), n, lessXYZ);
                    if (it == nodes.end() || !(*it == n)) continue;
                    parent[std::size_t(findRoot(parent.data(), int(it - nodes.begin())))] = findRoot(parent.data(), int(i));
                }
    std::vector<std::vector<Vec3i>> groups;
    std::vector<int> groupOf(nodes.size(), -1);
    for (std::size_t i = 0; i < nodes.size(); ++i) {
        int& g = groupOf[std::size_t(findRoot(parent.data(), int(i)))];
        if (g < 0) {
            g = int(groups.size());
            groups.emplace_back();
        }
        groups[std::size_t(g)].push_back(nodes[i]);
    }
    return groups;
}

int insidePiecesAtCentre(const bool inside[27], int leaveOut) {
    std::uint32_t rest = 0, faces = 0;
    for (int i = 0; i < 27; ++i) {
        if (i == 13 || i == leaveOut || !inside[i]) continue;
        rest |= 1u << i;
        if (stepsFromCentre(i) == 1) faces |= 1u << i;
    }
    int pieces = 0;
    while (faces) {
        ++pieces;
        std::uint32_t piece = faces & (~faces + 1);
        for (std::uint32_t next = grow(piece, rest); next != piece; next = grow(piece, rest)) piece = next;
        faces &= ~piece;
    }
    return pieces;
}

int insideEulerChange(const bool inside[27]) {
    bool state[27];
    std::copy(inside, inside + 27, state);
    state[13] = false;
    const int before = starEuler(state);
    state[13] = true;
    return before - starEuler(state);
}

} // namespace vdbsurf
