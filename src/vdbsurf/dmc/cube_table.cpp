#include "vdbsurf/dmc/cube_table.h"

#include <algorithm>
#include <array>
#include <stdexcept>

namespace vdbsurf {

bool cubeEdgesShareFace(int a, int b) {
    // Edge e lies on the faces (u, origin[u]) and (v, origin[v]) of its two other axes.
    const int axA = cubeEdgeAxis(a), axB = cubeEdgeAxis(b);
    const Vec3i oa = cubeEdgeOrigin(a), ob = cubeEdgeOrigin(b);
    for (int i = 0; i < 3; ++i) {
        if (i == axA || i == axB) continue;
        if (oa[std::size_t(i)] == ob[std::size_t(i)]) return true;
    }
    return false;
}

namespace {

// Rotates loop[0..k) so that vertex 0 is a safe fan apex; returns false if there is none.
bool rotateToSafeApex(std::uint8_t* loop, int k) {
    for (int apex = 0; apex < k; ++apex) {
        bool safe = true;
        for (int j = 2; j <= k - 2 && safe; ++j) safe = !cubeEdgesShareFace(loop[apex], loop[(apex + j) % k]);
        if (!safe) continue;
        std::uint8_t tmp[12];
        for (int i = 0; i < k; ++i) tmp[i] = loop[(apex + i) % k];
        std::copy(tmp, tmp + k, loop);
        return true;
    }
    return false;
}

int cornerAt(const Vec3i& o) { return o.x | (o.y << 1) | (o.z << 2); }
Vec3i cornerOffset(int c) { return {c & 1, (c >> 1) & 1, (c >> 2) & 1}; }

int edgeBetween(int c0, int c1) {
    const int diff = c0 ^ c1;
    const int axis = diff == 1 ? 0 : diff == 2 ? 1 : 2;
    return cubeEdgeIndex(axis, cornerOffset(c0 & c1));
}

CubeCase makeCase(unsigned config) {
    auto inside = [&](int c) { return ((config >> c) & 1u) != 0; };
    std::array<int, 12> next;
    next.fill(-1);
    for (int axis = 0; axis < 3; ++axis) {
        const std::size_t u = std::size_t((axis + 1) % 3), v = std::size_t((axis + 2) % 3);
        for (int side = 0; side < 2; ++side) {
            // Corners counter-clockwise seen from outside the cube (u x v = axis).
            std::array<Vec3i, 4> ring;
            const int uv[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
            for (int i = 0; i < 4; ++i) {
                const int k = side == 1 ? i : (4 - i) % 4; // the -axis face is seen mirrored
                Vec3i o;
                o[std::size_t(axis)] = side;
                o[u] = uv[k][0];
                o[v] = uv[k][1];
                ring[std::size_t(i)] = o;
            }
            std::array<int, 4> c;
            for (int i = 0; i < 4; ++i) c[std::size_t(i)] = cornerAt(ring[std::size_t(i)]);
            for (int i = 0; i < 4; ++i) {
                const int a = c[std::size_t(i)], b = c[std::size_t((i + 1) % 4)];
                if (inside(a) || !inside(b)) continue; // start where the walk enters the inside
                for (int j = 1; j <= 4; ++j) {
                    const int p = c[std::size_t((i + j) % 4)], q = c[std::size_t((i + j + 1) % 4)];
                    if (inside(p) && !inside(q)) {
                        next[std::size_t(edgeBetween(a, b))] = edgeBetween(p, q);
                        break;
                    }
                }
            }
        }
    }
    CubeCase cc;
    std::array<bool, 12> used{};
    int count = 0;
    for (int e = 0; e < 12; ++e) {
        if (next[std::size_t(e)] < 0 || used[std::size_t(e)]) continue;
        int size = 0;
        for (int cur = e; !used[std::size_t(cur)]; cur = next[std::size_t(cur)]) {
            used[std::size_t(cur)] = true;
            cc.edges[count++] = std::uint8_t(cur);
            cc.edgeMask |= std::uint16_t(1u << cur);
            ++size;
            if (next[std::size_t(cur)] < 0) throw std::logic_error("cube table: open loop");
        }
        if (size >= 4 && !rotateToSafeApex(cc.edges + count - size, size)) throw std::logic_error("cube table: a loop with no safe fan apex");
        cc.loopSize[cc.loopCount++] = std::uint8_t(size);
    }
    return cc;
}

std::array<CubeCase, 256> makeTable() {
    std::array<CubeCase, 256> t;
    for (unsigned c = 0; c < 256; ++c) t[c] = makeCase(c);
    return t;
}

} // namespace

const CubeCase* cubeCaseTable() {
    static const std::array<CubeCase, 256> table = makeTable();
    return table.data();
}

} // namespace vdbsurf
