#include "vdbsurf/dmc/inside_topology.h"

#include <algorithm>
#include <cstdint>
#include <cstdlib>

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

} // namespace

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
