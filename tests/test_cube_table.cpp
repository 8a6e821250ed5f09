// The generated marching-cubes table: every crossing edge used once, loops closed and oriented.
#include "vdbsurf/dmc/cube_table.h"

#include <catch2/catch.hpp>

#include <set>

using namespace vdbsurf;

namespace {
int cornerOf(const Vec3i& o) { return o.x | (o.y << 1) | (o.z << 2); }
Vec3d cornerPos(int c) { return {double(c & 1), double((c >> 1) & 1), double((c >> 2) & 1)}; }
} // namespace

TEST_CASE("edge numbering round-trips") {
    for (int e = 0; e < 12; ++e) CHECK(cubeEdgeIndex(cubeEdgeAxis(e), cubeEdgeOrigin(e)) == e);
    std::set<std::pair<int, int>> seen;
    for (int e = 0; e < 12; ++e) {
        const Vec3i o = cubeEdgeOrigin(e);
        Vec3i b = o;
        b[std::size_t(cubeEdgeAxis(e))] += 1;
        CHECK(o[std::size_t(cubeEdgeAxis(e))] == 0);
        seen.insert({cornerOf(o), cornerOf(b)});
    }
    CHECK(seen.size() == 12);
}

TEST_CASE("every case uses exactly its crossing edges, once, in closed loops") {
    int maxLoops = 0;
    for (unsigned config = 0; config < 256; ++config) {
        const CubeCase& cc = cubeCase(config);
        std::uint16_t crossing = 0;
        for (int e = 0; e < 12; ++e) {
            const Vec3i o = cubeEdgeOrigin(e);
            Vec3i b = o;
            b[std::size_t(cubeEdgeAxis(e))] += 1;
            if (((config >> cornerOf(o)) & 1u) != ((config >> cornerOf(b)) & 1u)) crossing |= std::uint16_t(1u << e);
        }
        INFO("config " << config);
        CHECK(cc.edgeMask == crossing);
        int total = 0;
        std::uint16_t used = 0;
        for (int l = 0; l < cc.loopCount; ++l) {
            CHECK(cc.loopSize[l] >= 3);
            for (int i = 0; i < cc.loopSize[l]; ++i) {
                const int e = cc.edges[total + i];
                CHECK(!(used & (1u << e)));
                used |= std::uint16_t(1u << e);
            }
            total += cc.loopSize[l];
        }
        CHECK(used == crossing);
        maxLoops = std::max(maxLoops, int(cc.loopCount));
    }
    CHECK(maxLoops == 4);
    CHECK(cubeCase(0).loopCount == 0);
    CHECK(cubeCase(255).loopCount == 0);
}

TEST_CASE("loops face from inside to outside") {
    // With crossings at edge midpoints, each loop's area vector must point away from the inside
    // corners it separates (checked on cases with one inside or one outside corner, and their
    // complements, whose loops must be reversed).
    for (int c = 0; c < 8; ++c) {
        for (bool invert : {false, true}) {
            const unsigned config = invert ? (255u & ~(1u << c)) : (1u << c);
            const CubeCase& cc = cubeCase(config);
            REQUIRE(cc.loopCount == 1);
            REQUIRE(cc.loopSize[0] == 3);
            Vec3d p[3];
            for (int i = 0; i < 3; ++i) {
                const int e = cc.edges[i];
                const Vec3i o = cubeEdgeOrigin(e);
                Vec3d m(o);
                m[std::size_t(cubeEdgeAxis(e))] += 0.5;
                p[i] = m;
            }
            const Vec3d n = cross(p[1] - p[0], p[2] - p[0]);
            const Vec3d centroid = (p[0] + p[1] + p[2]) / 3.0;
            const Vec3d towardCorner = cornerPos(c) - centroid;
            INFO("corner " << c << (invert ? " outside" : " inside"));
            if (invert) CHECK(dot(n, towardCorner) > 0); // the lone corner is outside: normal points at it
            else CHECK(dot(n, towardCorner) < 0);
        }
    }
}

TEST_CASE("a fan from each loop's first vertex draws no diagonal along a cube face") {
    // The neighbour across that face could draw the same diagonal: two polygons on one edge
    // twice over, a non-manifold mesh.
    int fans = 0;
    for (unsigned config = 0; config < 256; ++config) {
        const CubeCase& cc = cubeCase(config);
        INFO("config " << config);
        for (int l = 0, k0 = 0; l < cc.loopCount; k0 += cc.loopSize[l], ++l) {
            const int k = cc.loopSize[l];
            for (int j = 2; j <= k - 2; ++j) CHECK(!cubeEdgesShareFace(cc.edges[k0], cc.edges[k0 + j]));
            fans += k >= 4;
        }
    }
    CHECK(fans == 66 + 72 + 52 + 24); // the loops of 4 to 7 crossings
}
