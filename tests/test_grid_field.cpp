// GridField: trilinear sampling, conservative bounds, domain, classes and bad grids; grids read
// from files, whatever layout OpenVDB wrote them in, and damaged files refused before they are read.
#include "support/test_support.h"

#include "vdbsurf/core/error.h"
#include "vdbsurf/field/grid_field.h"
#include "vdbsurf/vdb/vdb_file.h"
#include "vdbsurf/vdb/vdb_layout.h"

#include <catch2/catch.hpp>
#include <openvdb/openvdb.h>
#include <openvdb/tools/Interpolation.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <random>

using namespace vdbsurf;

namespace {

openvdb::FloatGrid::Ptr noiseGrid(int n, double voxel, unsigned seed) {
    initializeOpenVdb();
    auto g = openvdb::FloatGrid::create(1.0f);
    g->setTransform(openvdb::math::Transform::createLinearTransform(voxel));
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(-1.f, 1.f);
    auto acc = g->getAccessor();
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j)
            for (int k = 0; k < n; ++k) acc.setValue({i - n / 2, j - n / 2, k - n / 2}, u(rng));
    return g;
}

// The transform the rotated cases use: voxel 0.25, turned about z and then x.
openvdb::math::Transform::Ptr rotatedTransform() {
    auto xf = openvdb::math::Transform::createLinearTransform(0.25);
    xf->postRotate(0.4, openvdb::math::Z_AXIS);
    xf->postRotate(0.3, openvdb::math::X_AXIS);
    return xf;
}

} // namespace

TEST_CASE("values are the grid's at voxel centres and trilinear between them") {
    auto g = noiseGrid(12, 0.5, 1);
    GridField f(g, "noise");
    auto acc = g->getConstAccessor();
    const openvdb::Coord a(0, 0, 0), b(1, 0, 0);
    CHECK(f.value({0, 0, 0}) == Approx(acc.getValue(a)));
    CHECK(f.value({0.5, 0, 0}) == Approx(acc.getValue(b)));
    CHECK(f.value({0.25, 0, 0}) == Approx(0.5 * (acc.getValue(a) + acc.getValue(b))));
    // Far outside the data: the background.
    CHECK(f.value({100, 0, 0}) == Approx(1.0));
}

TEST_CASE("grid bounds contain every sampled value, for aligned and rotated transforms") {
    for (bool rotate : {false, true}) {
        auto g = noiseGrid(20, 0.25, 2);
        if (rotate) {
            auto xf = rotatedTransform();
            xf->postTranslate(openvdb::Vec3d(0.1, -0.2, 0.3));
            g->setTransform(xf);
        }
        GridField f(g, "noise");
        std::mt19937 rng(3);
        std::uniform_real_distribution<double> c(-3.5, 3.5), s(0.0, 1.2), t(0.0, 1.0);
        for (int b = 0; b < 300; ++b) {
            const Vec3d centre(c(rng), c(rng), c(rng));
            const Vec3d half(s(rng), s(rng), s(rng));
            const Box3 box{centre - half, centre + half};
            const Interval iv = f.bounds(box);
            for (int k = 0; k < 60; ++k) {
                Vec3d q;
                for (std::size_t a = 0; a < 3; ++a)
                    q[a] = std::clamp(box.min[a] + t(rng) * 2 * half[a], box.min[a], box.max[a]);
                const double v = f.value(q);
                INFO("rotated " << rotate << " value " << v << " in [" << iv.lo << ", " << iv.hi << "]");
                CHECK(iv.contains(v));
            }
        }
        // A box wholly outside the data holds only the background.
        const Interval out = f.bounds(Box3{{40, 40, 40}, {41, 41, 41}});
        CHECK(out.lo == Approx(1.0));
        CHECK(out.hi == Approx(1.0));
    }
}

TEST_CASE("mayStraddle answers as straddles(bounds) does, aligned and rotated, small boxes and large") {
    // It may rule a box out from the range of the voxels it reads before the exact range: the
    // answer must be the same, whatever the iso value.
    for (bool rotate : {false, true}) {
        auto g = noiseGrid(20, 0.25, 5);
        if (rotate) g->setTransform(rotatedTransform());
        GridField f(g, "noise");
        std::mt19937 rng(9);
        std::uniform_real_distribution<double> c(-3.0, 3.0), s(0.0, 0.6), iso(-1.1, 1.1);
        std::size_t yes = 0, no = 0;
        for (int b = 0; b < 4000; ++b) {
            Vec3d centre(c(rng), c(rng), c(rng));
            const Vec3d half(s(rng), s(rng), s(rng));
            // Half the boxes (unrotated) start on a voxel centre: their range can then end at the
            // value of the first voxel they read.
            if (!rotate && b % 2 == 0)
                for (std::size_t a = 0; a < 3; ++a) centre[a] = 0.25 * std::round((centre[a] - half[a]) / 0.25) + half[a];
            const Box3 box{centre - half, centre + half};
            const Interval iv = f.bounds(box);
            // Iso values at random, and just inside and just outside the exact range.
            for (double v : {iso(rng), iv.lo, iv.hi, iv.lo - 1e-7, iv.hi + 1e-7}) {
                INFO("rotated " << rotate << " iso " << v << " bounds [" << iv.lo << ", " << iv.hi << "]");
                const bool answer = f.mayStraddle(box, v);
                REQUIRE(answer == straddles(iv, v));
                ++(answer ? yes : no);
            }
        }
        CHECK(yes > 2000);
        CHECK(no > 2000);
    }
}

TEST_CASE("mayStraddle over boxes of many voxels answers as straddles(bounds) does, where leaves lie on one side") {
    // Boxes of 5 to 32 voxels a side take the range of the voxels they cover, which mayStraddle
    // finds sooner: it stops at the first proof and takes a partly covered leaf's whole range
    // when that lies on one side of iso. A smooth field (distance from a point, as a level set
    // stores it) puts most leaves on one side; iso values at random, and at the ends of leaves'
    // own ranges (where taking a whole range for a part would show first), must all agree.
    initializeOpenVdb();
    auto g = openvdb::FloatGrid::create(9.0f);
    g->setTransform(openvdb::math::Transform::createLinearTransform(0.25));
    {
        auto acc = g->getAccessor();
        for (int i = -24; i < 24; ++i)
            for (int j = -24; j < 24; ++j)
                for (int k = -24; k < 24; ++k) {
                    if (i > 8 && j > 8) continue; // a column of leaves without data: background there
                    const double d = std::sqrt(double(i * i + j * j + k * k)) * 0.25 - 2.5;
                    acc.setValue({i, j, k}, float(d));
                }
    }
    std::vector<double> leafEnds;
    for (auto leaf = g->tree().cbeginLeaf(); leaf; ++leaf) {
        float lo = 1e30f, hi = -1e30f;
        for (auto v = leaf->cbeginValueAll(); v; ++v) lo = std::min(lo, *v), hi = std::max(hi, *v);
        leafEnds.push_back(lo);
        leafEnds.push_back(hi);
    }
    GridField f(g, "distance");
    std::mt19937 rng(17);
    std::uniform_real_distribution<double> c(-6.5, 6.5), s(0.6, 4.0), iso(-3.0, 9.5);
    std::uniform_int_distribution<std::size_t> pick(0, leafEnds.size() - 1);
    std::size_t yes = 0, no = 0;
    for (int b = 0; b < 3000; ++b) {
        Vec3d centre(c(rng), c(rng), c(rng));
        const Vec3d half(s(rng), s(rng), s(rng));
        // Half the boxes start on a voxel centre (whole leaves then fall inside them exactly).
        if (b % 2 == 0)
            for (std::size_t a = 0; a < 3; ++a) centre[a] = 0.25 * std::round((centre[a] - half[a]) / 0.25) + half[a];
        const Box3 box{centre - half, centre + half};
        const Interval iv = f.bounds(box);
        const double end = leafEnds[pick(rng)];
        for (double v : {iso(rng), iv.lo, iv.hi, iv.lo - 1e-7, iv.hi + 1e-7, end, end - 1e-6, end + 1e-6, 0.0}) {
            INFO("box " << box.min.x << " " << box.min.y << " " << box.min.z << " .. " << box.max.x << " " << box.max.y << " "
                        << box.max.z << " iso " << v << " bounds [" << iv.lo << ", " << iv.hi << "]");
            const bool answer = f.mayStraddle(box, v);
            REQUIRE(answer == straddles(iv, v));
            ++(answer ? yes : no);
        }
    }
    CHECK(yes > 5000);
    CHECK(no > 5000);
}

TEST_CASE("sampleNodes gives value() bit for bit on every kind of lattice frame") {
    // On voxel centres (stride 1 and 2), between them (finer, coarser, offset), and rotated: each
    // path (direct reads, a gathered block of voxels, one sample a node) agrees with value().
    for (bool rotate : {false, true}) {
        auto g = noiseGrid(24, 0.25, 6);
        if (rotate) g->setTransform(rotatedTransform());
        GridField f(g, "noise");
        for (const LatticeFrame frame : {f.naturalFrame(0.25), f.naturalFrame(0.5), LatticeFrame{{0.03, -0.07, 0.11}, 0.0833},
                                         LatticeFrame{{-0.2, 0.1, 0.05}, 0.37}, LatticeFrame{{0.0, 0.0, 0.0}, 2.3}}) {
            for (const Vec3i dims : {Vec3i(9, 9, 9), Vec3i(3, 3, 3), Vec3i(5, 2, 7)}) {
                const Vec3i first(-int(1.2 / frame.h), -int(0.9 / frame.h), -int(1.1 / frame.h));
                const std::size_t count = std::size_t(dims.x * dims.y * dims.z);
                std::vector<std::uint8_t> needed(count);
                for (std::size_t n = 0; n < count; ++n) needed[n] = std::uint8_t(n % 3 != 1);
                std::vector<double> all(count, -7.0), some(count, -7.0);
                f.sampleNodes(frame, first, dims, nullptr, all.data());
                f.sampleNodes(frame, first, dims, needed.data(), some.data());
                std::size_t n = 0;
                for (int k = 0; k < dims.z; ++k)
                    for (int j = 0; j < dims.y; ++j)
                        for (int i = 0; i < dims.x; ++i, ++n) {
                            const double v = f.value(frame.nodeWorld(first + Vec3i(i, j, k)));
                            INFO("rotated " << rotate << " spacing " << frame.h << " node " << i << " " << j << " " << k);
                            REQUIRE(all[n] == v);
                            if (needed[n]) REQUIRE(some[n] == v);
                        }
            }
        }
    }
}

TEST_CASE("valueAndGradient returns value() bit for bit and OpenVDB's central differences, aligned and rotated") {
    for (bool rotate : {false, true}) {
        auto g = noiseGrid(12, 0.25, 3);
        if (rotate) g->setTransform(rotatedTransform());
        GridField f(g, "noise");
        std::mt19937 rng(7);
        std::uniform_real_distribution<double> u(-1.6, 1.6);
        // Random points, voxel centres and points half-way between them (where ip +- 0.5 lands on
        // voxel boundaries), across the data's edge.
        std::vector<Vec3d> points;
        for (int i = 0; i < 400; ++i) points.push_back({u(rng), u(rng), u(rng)});
        for (int i = -8; i <= 8; ++i) points.push_back({0.125 * i, 0.25 * i, -0.125 * i}), points.push_back({0.25 * i, 0, 0.125});
        // An index coordinate just under a half (aligned: 0.5 - 2^-54): ip + 0.5 rounds up to the
        // next voxel, out of the 3x3x3 block, and the gradient is sampled the long way.
        const double under = std::nextafter(0.125, 0.0);
        points.push_back({under, 0.3, -0.2}), points.push_back({0.3, under, -0.2}), points.push_back({-0.2, 0.3, under});
        // The reference: BoxSampler half a voxel either side of the point in index space, mapped
        // to world space by the transform (gradient() is valueAndGradient's; its arithmetic
        // follows BoxSampler's, so only the world-to-index rounding may differ).
        auto reference = [&](const Vec3d& p) {
            const openvdb::Vec3d ip = g->worldToIndex(openvdb::Vec3d(p.x, p.y, p.z));
            openvdb::Vec3d d;
            for (int a = 0; a < 3; ++a) {
                openvdb::Vec3d lo = ip, hi = ip;
                lo[a] -= 0.5;
                hi[a] += 0.5;
                d[a] = double(openvdb::tools::BoxSampler::sample(g->tree(), hi)) - double(openvdb::tools::BoxSampler::sample(g->tree(), lo));
            }
            const openvdb::Vec3d w = g->transform().baseMap()->applyIJT(d);
            return Vec3d(w.x(), w.y(), w.z());
        };
        std::size_t differ = 0, off = 0;
        double worst = 0;
        for (const Vec3d& p : points) {
            Vec3d gradient;
            const double v = f.valueAndGradient(p, gradient);
            const Vec3d viaGradient = f.gradient(p), expected = reference(p);
            differ += v != f.value(p) || viaGradient.x != gradient.x || viaGradient.y != gradient.y || viaGradient.z != gradient.z;
            const double e = length(gradient - expected) / (1 + length(expected));
            worst = std::max(worst, e);
            off += e > 1e-5;
        }
        INFO("rotated " << rotate << ", largest relative difference from OpenVDB's " << worst);
        CHECK(differ == 0);
        CHECK(off == 0);
    }
}

TEST_CASE("value() is BoxSampler's sample bit for bit, inside leaves and across their edges") {
    // Points at multiples of 1/64 world unit on a grid of 0.25 (index positions exact either way
    // to index space): value() reads the eight voxels from one leaf where they lie in one, else
    // leaf part by leaf part; either way they and their interpolation are BoxSampler's.
    auto g = noiseGrid(12, 0.25, 3);
    GridField f(g, "noise");
    std::mt19937 rng(5);
    std::uniform_int_distribution<int> u(-110, 110);
    std::size_t differ = 0, acrossLeaves = 0;
    for (int i = 0; i < 4000; ++i) {
        const Vec3d p(u(rng) / 64.0, u(rng) / 64.0, u(rng) / 64.0);
        const openvdb::Vec3d ip = g->worldToIndex(openvdb::Vec3d(p.x, p.y, p.z));
        const openvdb::Coord c = openvdb::Coord::floor(ip);
        acrossLeaves += (c.x() & 7) == 7 || (c.y() & 7) == 7 || (c.z() & 7) == 7;
        differ += f.value(p) != double(openvdb::tools::BoxSampler::sample(g->tree(), ip));
    }
    CHECK(differ == 0);
    CHECK(acrossLeaves > 500);
}

TEST_CASE("values over a box are value() bit for bit, aligned and rotated, small boxes and large") {
    for (bool rotate : {false, true}) {
        auto g = noiseGrid(12, 0.25, 3);
        if (rotate) g->setTransform(rotatedTransform());
        GridField f(g, "noise");
        std::mt19937 rng(11);
        std::uniform_real_distribution<double> c(-1.8, 1.8), s(0.0, 1.0), t(0.0, 1.0);
        std::size_t differ = 0, total = 0;
        for (int b = 0; b < 300; ++b) {
            // Half sizes up to 4 voxels (boxes over 8 voxels a side take the one-by-one path).
            const Vec3d centre(c(rng), c(rng), c(rng)), half(s(rng), s(rng), s(rng));
            const Box3 box{centre - half, centre + half};
            std::vector<Vec3d> points;
            for (int k = 0; k < 40; ++k)
                points.push_back({box.min.x + t(rng) * 2 * half.x, box.min.y + t(rng) * 2 * half.y, box.min.z + t(rng) * 2 * half.z});
            for (int k = 0; k < 8; ++k) // its corners
                points.push_back({k & 1 ? box.max.x : box.min.x, k & 2 ? box.max.y : box.min.y, k & 4 ? box.max.z : box.min.z});
            std::vector<double> out(points.size());
            f.values(box, points.data(), points.size(), out.data());
            for (std::size_t k = 0; k < points.size(); ++k) differ += out[k] != f.value(points[k]);
            total += points.size();
        }
        INFO("rotated " << rotate << ": " << differ << " of " << total << " differ");
        CHECK(differ == 0);
    }
}

TEST_CASE("grid bounds are tight on a level set: boxes away from the surface do not straddle") {
    auto g = test::makeSphereLevelSet(1.0, {0, 0, 0}, 0.05);
    GridField f(g, "sphere");
    CHECK(f.bounds(Box3{{-0.2, -0.2, -0.2}, {0.2, 0.2, 0.2}}).hi < 0);  // deep inside
    CHECK(f.bounds(Box3{{1.5, 1.5, 1.5}, {1.8, 1.8, 1.8}}).lo > 0);     // outside
    const Interval across = f.bounds(Box3{{0.9, -0.05, -0.05}, {1.1, 0.05, 0.05}});
    CHECK(across.lo < 0);
    CHECK(across.hi > 0);
    const Box3 d = f.domain();
    CHECK(d.min.x < -1.1);
    CHECK(d.max.x > 1.1);
    CHECK(d.max.x < 1.5);
}

TEST_CASE("tiles count: the domain covers active tiles that differ from the background, bounds see every tile's value") {
    initializeOpenVdb();
    auto g = openvdb::FloatGrid::create(1.0f);
    g->setTransform(openvdb::math::Transform::createLinearTransform(0.5));
    // A leaf-sized tile (8^3, in a lower internal node), a 128^3 tile (in an upper one), an
    // inactive tile with another value, and one voxel.
    g->tree().fill(openvdb::CoordBBox::createCube({8, 8, 8}, 8), -2.0f, true);
    g->tree().fill(openvdb::CoordBBox::createCube({-256, 0, 0}, 128), -3.0f, true);
    g->tree().fill(openvdb::CoordBBox::createCube({0, 0, 512}, 8), 5.0f, false);
    g->tree().setValue({0, 0, 0}, 0.5f);
    REQUIRE(g->tree().leafCount() == 1);
    GridField f(g, "tiles");
    const Box3 d = f.domain();
    CHECK(d.min.x == Approx(-257 * 0.5));
    CHECK(d.max.x == Approx(16 * 0.5));
    CHECK(d.max.z == Approx(128 * 0.5)); // the active 128^3 tile's; not the inactive tile's 520
    CHECK(f.bounds(Box3{{5, 5, 5}, {6, 6, 6}}).hi == Approx(-2.0));
    CHECK(f.bounds(Box3{{-100, 10, 10}, {-90, 20, 20}}).lo == Approx(-3.0));
    CHECK(f.bounds(Box3{{1, 1, 257}, {2, 2, 258}}).hi == Approx(5.0)); // outside the domain, still a value
    CHECK(f.valueRange().lo == Approx(-3.0));
    CHECK(f.valueRange().hi == Approx(5.0));
    auto nanTile = openvdb::FloatGrid::create(0.f);
    nanTile->tree().fill(openvdb::CoordBBox::createCube({16, 0, 0}, 8), std::numeric_limits<float>::quiet_NaN(), true);
    nanTile->tree().setValue({0, 0, 0}, 1.0f);
    CHECK_THROWS_WITH(GridField(nanTile, "t.vdb:d"), Catch::Contains("t.vdb:d") && Catch::Contains("tile at (16, 0, 0)"));
    // Inactive values alone are no data (bounds see them all the same).
    auto inactive = openvdb::FloatGrid::create(1.0f);
    inactive->tree().setValueOff({40, 0, 0}, -1.0f);
    inactive->tree().fill(openvdb::CoordBBox::createCube({0, 0, 512}, 8), 5.0f, false);
    CHECK_THROWS_WITH(GridField(inactive, "t.vdb:off"), Catch::Contains("t.vdb:off") && Catch::Contains("is empty"));
    inactive->tree().setValueOn({-16, 0, 0}, 0.5f);
    GridField withOne(inactive, "one");
    CHECK(withOne.domain().max.x == Approx(-15.0));
    CHECK(withOne.bounds(Box3{{39.5, -0.5, -0.5}, {40.5, 0.5, 0.5}}).lo == Approx(-1.0));
    CHECK(withOne.bounds(Box3{{1, 1, 513}, {2, 2, 514}}).hi == Approx(5.0));
}

TEST_CASE("an open level set (a terrain clipped by its box) has the domain of its band, not of its flood fill") {
    // The signed flood fill of a band that reaches the sides of its box fills the space under
    // it with inside tiles, far beyond the band. The domain is the band's active voxels (a level
    // set's band holds its surface): before, it spanned the fill's tiles, thousands of voxels.
    const double h = 0.02;
    auto sheet = [](const Vec3d& p) { return p.z - 0.2 * std::sin(2 * p.x) * std::cos(3 * p.y); };
    const GridBasePtr g = test::makeLevelSetFromDistance(sheet, Box3{{-1, -1, -0.5}, {1, 1, 0.5}}, h);
    const auto grid = openvdb::gridPtrCast<openvdb::FloatGrid>(g);
    openvdb::CoordBBox active = grid->evalActiveVoxelBoundingBox();
    REQUIRE(grid->tree().activeTileCount() == 0);
    std::size_t insideTiles = 0;
    for (auto it = grid->tree().cbeginValueOff(); it; ++it)
        if (!it.isVoxelValue() && *it < 0) ++insideTiles;
    REQUIRE(insideTiles > 0); // the fill's tiles are there
    GridField f(g, "terrain");
    const Box3 d = f.domain();
    for (int a = 0; a < 3; ++a) {
        CHECK(d.min[a] == Approx(active.min()[a] * h));
        CHECK(d.max[a] == Approx(active.max()[a] * h));
    }
    CHECK(d.min.z > -0.3);
    CHECK(d.max.z < 0.3);
}

TEST_CASE("cells and points without data read only inactive voxels, by the trilinear weights") {
    // Scattered active voxels, inactive values of either sign between them, an active tile. A
    // cell has data when some point of it reads an active voxel (or tile) with a non-zero
    // trilinear weight; checked against a 5^3 sampling of each cell, which meets every voxel
    // interval the cell spans, on lattices at, finer than and coarser than the voxels.
    initializeOpenVdb();
    auto g = openvdb::FloatGrid::create(1.0f);
    g->setGridClass(openvdb::GRID_LEVEL_SET);
    g->setTransform(openvdb::math::Transform::createLinearTransform(0.5));
    std::mt19937 rng(7);
    std::uniform_int_distribution<int> at(-6, 6);
    std::uniform_real_distribution<float> u(-1.f, 1.f);
    {
        auto acc = g->getAccessor();
        for (int i = 0; i < 300; ++i) acc.setValueOff({at(rng), at(rng), at(rng)}, u(rng));
        for (int i = 0; i < 40; ++i) acc.setValueOn({at(rng), at(rng), at(rng)}, u(rng));
    }
    g->tree().addTile(1, openvdb::Coord(8, 0, 0), -1.f, true); // voxels 8..15 x 0..7 x 0..7
    GridField f(g, "scattered");
    auto reads = [&](openvdb::FloatGrid::ConstAccessor& acc, openvdb::Vec3d ip) {
        // Voxels with a non-zero weight at index position ip: floor, and floor + 1 where the
        // fraction is not zero (a position within 1e-9 of a voxel plane is on it: the rounding
        // of the lattice's arithmetic, as in bounds()).
        for (int a = 0; a < 3; ++a)
            if (std::fabs(ip[a] - std::nearbyint(ip[a])) < 1e-9) ip[a] = std::nearbyint(ip[a]);
        const openvdb::Coord b(int(std::floor(ip.x())), int(std::floor(ip.y())), int(std::floor(ip.z())));
        for (int d = 0; d < 8; ++d) {
            const openvdb::Vec3i o(d & 1, (d >> 1) & 1, (d >> 2) & 1);
            bool weighs = true;
            for (int a = 0; a < 3; ++a) weighs = weighs && (o[a] == 0 || ip[a] - b[a] > 0);
            if (weighs && acc.isValueOn(b.offsetBy(o.x(), o.y(), o.z()))) return true;
        }
        return false;
    };
    auto acc = g->getConstAccessor();
    std::size_t kept = 0, dropped = 0;
    for (const LatticeFrame frame : {LatticeFrame{{0, 0, 0}, 0.5}, LatticeFrame{{0.05, -0.1, 0.13}, 0.35},
                                     LatticeFrame{{-0.2, 0.3, 0.01}, 1.3}}) {
        INFO("spacing " << frame.h);
        const int lo = int(std::floor(-4.0 / frame.h)) & ~7, hi = int(std::ceil(8.0 / frame.h));
        for (int bx = lo; bx <= hi; bx += 8)
            for (int by = lo; by <= hi; by += 8)
                for (int bz = lo; bz <= hi; bz += 8) {
                    std::uint64_t words[8];
                    std::fill(words, words + 8, ~std::uint64_t(0));
                    f.dropCellsWithoutData(frame, {bx, by, bz}, words);
                    for (int c = 0; c < 512; ++c) {
                        const Vec3i cell(bx + (c >> 6), by + ((c >> 3) & 7), bz + (c & 7));
                        const Box3 box = frame.cellBox(cell);
                        bool data = false;
                        for (int s = 0; s < 125 && !data; ++s) {
                            const Vec3d t(s % 5 / 4.0, s / 5 % 5 / 4.0, s / 25 / 4.0);
                            const Vec3d e = box.max - box.min;
                            const Vec3d p = box.min + Vec3d(e.x * t.x, e.y * t.y, e.z * t.z);
                            data = reads(acc, g->worldToIndex(openvdb::Vec3d(p.x, p.y, p.z)));
                        }
                        const bool keptCell = (words[c >> 6] >> (c & 63)) & 1;
                        INFO("cell " << cell.x << " " << cell.y << " " << cell.z);
                        REQUIRE(keptCell == data);
                        ++(keptCell ? kept : dropped);
                    }
                    // Cells not asked about stay dropped.
                    std::fill(words, words + 8, std::uint64_t(0));
                    f.dropCellsWithoutData(frame, {bx, by, bz}, words);
                    REQUIRE(std::all_of(words, words + 8, [](std::uint64_t w) { return w == 0; }));
                }
    }
    CHECK(kept > 5000);
    CHECK(dropped > 5000);

    // Points: anywhere, on voxel lines (two whole coordinates) and at voxel centres.
    std::uniform_real_distribution<double> w(-4.0, 8.0);
    std::vector<Vec3f> points;
    for (int i = 0; i < 30000; ++i) {
        Vec3d p(w(rng), w(rng), w(rng));
        const int whole = i % 4; // 0: none, 1: one axis, 2: two axes, 3: all three on voxel planes
        for (int a = 0; a < whole; ++a) {
            const std::size_t axis = std::size_t((i / 4 + a) % 3);
            p[axis] = 0.5 * std::round(p[axis] / 0.5);
        }
        points.push_back(Vec3f(p));
    }
    std::vector<std::uint8_t> has(points.size(), 7);
    f.pointsWithData(points.data(), points.size(), has.data());
    std::size_t with = 0;
    for (std::size_t i = 0; i < points.size(); ++i) {
        const Vec3d p(points[i]);
        INFO("point " << p.x << " " << p.y << " " << p.z);
        REQUIRE(has[i] == std::uint8_t(reads(acc, g->worldToIndex(openvdb::Vec3d(p.x, p.y, p.z)))));
        with += has[i];
    }
    CHECK(with > 1000);
    CHECK(with < points.size() - 1000);

    // A float one ulp off a voxel plane (a mesh vertex computed on a lattice edge) is on it.
    std::vector<Vec3f> nudged(points);
    for (std::size_t i = 0; i < nudged.size(); ++i)
        for (std::size_t a = 0; a < 3; ++a)
            nudged[i][a] = std::nextafter(nudged[i][a], i % 2 ? 100.f : -100.f);
    std::vector<std::uint8_t> hasNudged(nudged.size(), 7);
    f.pointsWithData(nudged.data(), nudged.size(), hasNudged.data());
    std::size_t differ = 0;
    for (std::size_t i = 0; i < points.size(); ++i)
        if (i % 4 != 0) differ += hasNudged[i] != has[i]; // (points off the planes may move across a voxel)
    CHECK(differ == 0);
}

TEST_CASE("grid class decides inside and the default iso") {
    auto ls = test::makeSphereLevelSet(1.0, {0, 0, 0}, 0.1);
    GridField a(ls, "ls");
    CHECK(a.inside() == Inside::Below);
    CHECK(a.defaultIso() == 0.0);
    auto fog = test::makeSphereFog(1.0, 0.3, 0.1);
    GridField b(fog, "fog");
    CHECK(b.inside() == Inside::Above);
    CHECK(b.defaultIso() == 0.5);
    auto unknown = noiseGrid(4, 1.0, 4); // background 1 > 0: a distance-like field
    GridField c(unknown, "noise");
    CHECK(c.gridClass() == "unknown");
    CHECK(c.inside() == Inside::Below);
    GridField d(unknown, "noise", Inside::Above);
    CHECK(d.inside() == Inside::Above);
}

TEST_CASE("piecewise-linear crossings along a coarse lattice edge are exact") {
    // Values along x: 1, 1, -1 at x = 0, 1, 2 (voxel 1); an edge from 0 to 2 crosses at 1.5, where
    // linear interpolation of the end values would say 1.0.
    initializeOpenVdb();
    auto g = openvdb::FloatGrid::create(1.0f);
    g->setGridClass(openvdb::GRID_LEVEL_SET);
    auto acc = g->getAccessor();
    acc.setValue({0, 0, 0}, 1.f);
    acc.setValue({1, 0, 0}, 1.f);
    acc.setValue({2, 0, 0}, -1.f);
    GridField f(g, "ramp");
    const double t = f.edgeCrossing({0, 0, 0}, {2, 0, 0}, 1.0, -1.0, 0.0);
    CHECK(t * 2 == Approx(1.5));
}

TEST_CASE("bad grids are refused with a message naming them") {
    initializeOpenVdb();
    auto nan = openvdb::FloatGrid::create(0.f);
    nan->tree().setValue({3, 4, 5}, std::numeric_limits<float>::quiet_NaN());
    CHECK_THROWS_WITH(GridField(nan, "nan.vdb:density"), Catch::Contains("nan.vdb:density") && Catch::Contains("NaN") &&
                                                             Catch::Contains("(3, 4, 5)"));
    auto inf = openvdb::FloatGrid::create(0.f);
    inf->tree().setValue({1, 1, 1}, std::numeric_limits<float>::infinity());
    CHECK_THROWS_WITH(GridField(inf, "inf"), Catch::Contains("infinite"));
    auto empty = openvdb::FloatGrid::create(0.f);
    CHECK_THROWS_WITH(GridField(empty, "empty.vdb:x"), Catch::Contains("empty"));
    auto vec = openvdb::Vec3SGrid::create();
    vec->tree().setValue({0, 0, 0}, openvdb::Vec3s(1, 2, 3));
    CHECK_THROWS_WITH(GridField(vec, "v"), Catch::Contains("vec3s"));
    auto dbl = openvdb::DoubleGrid::create(1.0);
    dbl->tree().setValue({0, 0, 0}, -1.0);
    CHECK_NOTHROW(GridField(dbl, "double"));
}

namespace {

// A tree with every kind of node content a writer meets: a root tile, tiles in both internal
// levels, full leaves, and leaves whose inactive values are the ±background, one other value,
// two other values, or many (OpenVDB's six value-compression cases).
template <typename GridT>
typename GridT::Ptr everyNodeKind(typename GridT::ValueType background, typename GridT::ValueType other,
                                  typename GridT::ValueType third) {
    using V = typename GridT::ValueType;
    auto g = GridT::create(background);
    auto& t = g->tree();
    t.addTile(3, {4096, 0, 0}, other, true); // a root tile
    t.addTile(2, {0, 0, 128}, other, false);
    t.addTile(1, {0, 8, 0}, third, true);
    auto acc = g->getAccessor();
    for (int i = 0; i < 8; ++i)
        for (int j = 0; j < 8; ++j)
            for (int k = 0; k < 8; ++k) {
                const int n = i * 64 + j * 8 + k;
                const V v = V(n % 7) * other + V(n % 3) * third;
                acc.setValue({i + 16, j, k}, v);                                 // all active
                acc.setValue({i + 24, j, k}, v);                                 // inactive: ±background
                if (n % 2) acc.setValueOff({i + 24, j, k}, n % 4 == 1 ? background : -background);
                acc.setValue({i + 32, j, k}, v);                                 // inactive: one other value
                if (n % 2) acc.setValueOff({i + 32, j, k}, other);
                acc.setValue({i + 40, j, k}, v);                                 // inactive: two other values
                if (n % 2) acc.setValueOff({i + 40, j, k}, n % 4 == 1 ? other : third);
                acc.setValue({i + 48, j, k}, v);                                 // inactive: many values
                if (n % 2) acc.setValueOff({i + 48, j, k}, v + other);
            }
    acc.setValue({-3000, 5, 9}, other); // a second root child
    return g;
}

void writeWithCompression(const std::string& path, openvdb::GridBase::Ptr grid, std::uint32_t compression) {
    openvdb::io::File file(path);
    file.setCompression(compression);
    file.write(openvdb::GridPtrVec{grid});
    file.close();
}

} // namespace

TEST_CASE("the first NaN or infinity in tree order is the one named, wherever in the tree it lies") {
    initializeOpenVdb();
    // Voxels in two leaves: the one first in the tree is named, whichever was set first.
    auto voxels = openvdb::FloatGrid::create(0.f);
    voxels->tree().setValue({600, 0, 0}, std::numeric_limits<float>::infinity());
    voxels->tree().setValue({3, 4, 5}, std::numeric_limits<float>::quiet_NaN());
    CHECK_THROWS_WITH(GridField(voxels, "v"), Catch::Contains("NaN") && Catch::Contains("(3, 4, 5)"));
    // A tile of an upper node (128³, slot 1 of its node) against an 8³ tile in a lower node
    // before it (slot 0) and after it (slot 2): the upper node's tiles are read in chunks apart
    // from its children, and the order between them still decides.
    for (const bool lowerFirst : {true, false}) {
        auto g = openvdb::FloatGrid::create(0.f);
        g->tree().setValue({-5, -5, -5}, 1.0f);
        g->tree().addTile(2, {0, 0, 128}, std::numeric_limits<float>::quiet_NaN(), true);
        g->tree().addTile(1, {0, 0, lowerFirst ? 8 : 256}, std::numeric_limits<float>::infinity(), false);
        INFO("lower node's tile first: " << lowerFirst);
        if (lowerFirst) CHECK_THROWS_WITH(GridField(g, "t"), Catch::Contains("infinite") && Catch::Contains("tile at (0, 0, 8)"));
        else CHECK_THROWS_WITH(GridField(g, "t"), Catch::Contains("NaN") && Catch::Contains("tile at (0, 0, 128)"));
    }
}

TEST_CASE("the value range is the least and greatest value the tree holds, float and double grids") {
    initializeOpenVdb();
    auto check = [](auto grid) {
        using ValueT = typename std::decay_t<decltype(*grid)>::ValueType;
        std::mt19937 rng(11);
        std::uniform_real_distribution<double> u(-1.0, 1.0);
        auto acc = grid->getAccessor();
        for (int i = -20; i < 20; ++i) // eight upper nodes meet at the origin
            for (int j = -20; j < 20; ++j)
                for (int k = -20; k < 20; ++k) acc.setValue({i, j, k}, ValueT(u(rng)));
        // The extremes at the last values of a leaf's rows, where the last lanes read them.
        acc.setValue({-9, 3, 7}, ValueT(-7.5));
        acc.setValue({12, -2, -2}, ValueT(9.25));
        grid->tree().addTile(1, {512, 0, 0}, ValueT(3.0), false);
        GridField f(grid, "g");
        CHECK(f.valueRange().lo == -7.5);
        CHECK(f.valueRange().hi == 9.25);
        // A box over whole leaves reads their cached ranges; one inside a leaf, its voxels.
        CHECK(f.bounds(Box3{{-16, -16, -16}, {15, 15, 15}}).lo == Approx(-7.5));
        CHECK(f.bounds(Box3{{8, -8, -8}, {15, -1, -1}}).hi == Approx(9.25));
        CHECK(f.bounds(Box3{{9, 1, 1}, {10, 2, 2}}).hi < 1.0);
        CHECK(f.bounds(Box3{{513, 1, 1}, {514, 2, 2}}).hi == Approx(3.0));
    };
    auto fog = openvdb::FloatGrid::create(0.f);
    check(fog);
    auto dbl = openvdb::DoubleGrid::create(0.0);
    check(dbl);
}

TEST_CASE("a grid changed under its GridField is a programming error, reported rather than read past") {
    initializeOpenVdb();
    auto g = openvdb::FloatGrid::create(0.f);
    g->tree().setValue({0, 0, 0}, 1.0f);
    g->tree().setValue({8192, 0, 0}, 1.0f);
    GridField f(g, "g");
    CHECK(f.bounds(Box3{{4095, -1, -1}, {4100, 1, 1}}).hi == Approx(0.0)); // an empty upper node's space
    g->tree().setValue({4096, 0, 0}, 2.0f); // a new upper node the ranges never saw
    CHECK_THROWS_AS(f.bounds(Box3{{4095, -1, -1}, {4100, 1, 1}}), std::logic_error);
}

TEST_CASE("the domain of a grid is the box of its active voxels, voxel for voxel") {
    initializeOpenVdb();
    std::mt19937 rng(5);
    std::uniform_int_distribution<int> coord(-40, 40), count(1, 4);
    for (int trial = 0; trial < 200; ++trial) {
        auto g = openvdb::FloatGrid::create(1.f);
        g->setGridClass(openvdb::GRID_LEVEL_SET); // the domain is the active voxels' box, not one voxel out
        for (int n = count(rng); n > 0; --n) g->tree().setValueOn({coord(rng), coord(rng), coord(rng)}, -0.5f);
        const openvdb::CoordBBox expected = g->evalActiveVoxelBoundingBox();
        const Box3 d = GridField(g, "g").domain();
        INFO("trial " << trial);
        CHECK(d.min.x == expected.min().x());
        CHECK(d.min.y == expected.min().y());
        CHECK(d.min.z == expected.min().z());
        CHECK(d.max.x == expected.max().x());
        CHECK(d.max.y == expected.max().y());
        CHECK(d.max.z == expected.max().z());
    }
}

TEST_CASE("every tree layout OpenVDB writes is read: value types, half floats, compressions") {
    initializeOpenVdb();
    test::TempDir dir;
    using openvdb::io::COMPRESS_ACTIVE_MASK;
    const std::uint32_t compressions[] = {openvdb::io::COMPRESS_NONE, openvdb::io::COMPRESS_ZIP,
                                          openvdb::io::COMPRESS_ZIP | COMPRESS_ACTIVE_MASK, openvdb::io::COMPRESS_BLOSC,
                                          openvdb::io::COMPRESS_BLOSC | COMPRESS_ACTIVE_MASK, COMPRESS_ACTIVE_MASK};
    std::vector<openvdb::GridBase::Ptr> grids = {
        everyNodeKind<openvdb::FloatGrid>(3.f, 0.25f, -1.5f), everyNodeKind<openvdb::DoubleGrid>(3.0, 0.25, -1.5),
        everyNodeKind<openvdb::Int32Grid>(3, 5, -7), everyNodeKind<openvdb::Int64Grid>(3, 5, -7),
        everyNodeKind<openvdb::Vec3SGrid>(openvdb::Vec3s(3, 0, 1), openvdb::Vec3s(0.25f, 1, 2), openvdb::Vec3s(-1.5f, 0, 3)),
        everyNodeKind<openvdb::Vec3DGrid>(openvdb::Vec3d(3, 0, 1), openvdb::Vec3d(0.25, 1, 2), openvdb::Vec3d(-1.5, 0, 3))};
    int read = 0;
    for (auto& grid : grids)
        for (const bool half : {false, true})
            for (const std::uint32_t c : compressions) {
                grid->setSaveFloatAsHalf(half);
                grid->setName("g");
                const std::string path = dir.path("layout.vdb");
                writeWithCompression(path, grid, c);
                INFO(grid->valueType() << (half ? " as half" : "") << ", compression " << c);
                const std::vector<GridSummary> s = summarizeVdbFile(path, /*verify=*/true); // reads the grid
                REQUIRE(s.size() == 1);
                CHECK(s[0].activeVoxels == grid->activeVoxelCount());
                if (grid->isType<openvdb::FloatGrid>() || grid->isType<openvdb::DoubleGrid>()) {
                    const LoadedGrid g = readScalarGrid(path, "g");
                    CHECK(g.grid->activeVoxelCount() == grid->activeVoxelCount());
                }
                ++read;
            }
    CHECK(read == 72);
}

TEST_CASE("a value chunk whose stated length overruns its node is refused before OpenVDB reads it") {
    // OpenVDB 10 copies an uncompressed chunk into a buffer of the node's size before comparing
    // the stated length with it: without the tree walk this file overruns the heap.
    initializeOpenVdb();
    test::TempDir dir;
    auto fog = openvdb::FloatGrid::create(0.f);
    fog->setName("density");
    fog->setGridClass(openvdb::GRID_FOG_VOLUME);
    fog->setSaveFloatAsHalf(true);
    auto acc = fog->getAccessor();
    for (int i = 0; i < 16; ++i)
        for (int j = 0; j < 16; ++j)
            for (int k = 0; k < 16; ++k) acc.setValue({i, j, k}, float((i * 7 + j * 3 + k) % 11) / 10.f);
    const std::string path = dir.path("damaged.vdb");
    writeWithCompression(path, fog, openvdb::io::COMPRESS_BLOSC | openvdb::io::COMPRESS_ACTIVE_MASK);
    REQUIRE_NOTHROW(readScalarGrid(path, ""));

    // The first leaf's buffer: its value mask, the compression marker (0: every value stored),
    // then the chunk's stated length. Say the chunk is 4096 uncompressed bytes; 512 halves are 1024.
    const std::int64_t at = checkVdbLayout(path).grids.at(0).blockPos + 64 + 1;
    std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
    std::int64_t stated = 0;
    f.seekg(at - 1);
    REQUIRE(f.get() == 0);
    f.read(reinterpret_cast<char*>(&stated), 8);
    REQUIRE((stated > 0 || stated == -1024));
    const std::int64_t damaged = -4096;
    f.seekp(at);
    f.write(reinterpret_cast<const char*>(&damaged), 8);
    f.close();
    CHECK_THROWS_WITH(readScalarGrid(path, ""), Catch::Contains("damaged.vdb") && Catch::Contains("is damaged") &&
                                                    Catch::Contains("4096 uncompressed bytes where the node holds 1024"));
    CHECK_THROWS_WITH(summarizeVdbFile(path, true), Catch::Contains("is damaged"));
}
