// The sparse lattice: which cells are active, and that culling follows the surface.
#include "support/test_support.h"

#include "vdbsurf/core/error.h"
#include "vdbsurf/dmc/lattice_deformation.h"
#include "vdbsurf/dmc/mesher.h"
#include "vdbsurf/field/expression_field.h"
#include "vdbsurf/field/grid_field.h"
#include "vdbsurf/lattice/lattice.h"

#include <catch2/catch.hpp>

#include <cmath>

using namespace vdbsurf;
using openvdb::CoordBBox;

namespace {
Lattice build(const Field& f, double h, CellTest test) {
    const LatticeFrame frame = f.naturalFrame(h);
    return buildLattice(f, frame, latticeCellRange(f, frame), f.defaultIso(), test);
}
} // namespace

TEST_CASE("a plate thinner than a cell and between nodes is found by bounds, not by corner signs") {
    // Plate 0.04 <= z <= 0.06; nodes at z = 0 and 0.2 are both outside it.
    ExpressionField plate("abs(z - 0.05) - 0.01", Box3{{-1, -1, -1}, {1, 1, 1}});
    const Lattice byBounds = build(plate, 0.2, CellTest::Bounds);
    const Lattice bySigns = build(plate, 0.2, CellTest::CornerSigns);
    CHECK(bySigns.stats.cellsActive == 0);
    // Exactly the 10 x 10 cells of the layer 0 <= z <= 0.2 (interval bounds of abs() are tight here).
    CHECK(byBounds.stats.cellsActive == 100);
    for (auto it = byBounds.cells->cbeginValueOn(); it; ++it) CHECK(it.getCoord().z() == 5);
}

TEST_CASE("every cell whose corners change side is active") {
    ExpressionField f("sin(3*x)*sin(3*y)*sin(3*z) - 0.1", Box3{{-1, -1, -1}, {1, 1, 1}});
    const double h = 0.05;
    const LatticeFrame frame = f.naturalFrame(h);
    const Lattice lat = buildLattice(f, frame, latticeCellRange(f, frame), 0.0, CellTest::CornerSigns);
    const auto range = lat.cellRange;
    std::size_t changing = 0;
    for (int i = range.min().x(); i <= range.max().x(); ++i)
        for (int j = range.min().y(); j <= range.max().y(); ++j)
            for (int k = range.min().z(); k <= range.max().z(); ++k) {
                bool any = false, all = true;
                for (int c = 0; c < 8; ++c) {
                    const bool in = f.value(frame.nodeWorld(i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1))) < 0;
                    any |= in;
                    all &= in;
                }
                if (any && !all) {
                    ++changing;
                    CHECK(lat.cells->isValueOn(openvdb::Coord(i, j, k)));
                }
            }
    CHECK(changing > 1000);
    CHECK(lat.stats.cellsActive == changing);
}

TEST_CASE("work grows with the surface, not the bounding box") {
    // A small sphere in a huge box: the blocks tested stay near the sphere.
    ExpressionField f("x^2+y^2+z^2-0.25", Box3{{-100, -100, -100}, {100, 100, 100}});
    const Lattice lat = build(f, 0.01, CellTest::Bounds);
    const double boxCells = std::pow(200 / 0.01, 3);
    CHECK(lat.stats.cellsActive > 0);
    CHECK(double(lat.stats.cellsExamined) < 1e-6 * boxCells);
    CHECK(lat.stats.leafBlocksTested < 100000);
}

TEST_CASE("absurd spacings are refused before any work") {
    ExpressionField f("x^2+y^2+z^2-1", Box3{{-2, -2, -2}, {2, 2, 2}});
    for (double h : {0.0, -1.0, std::nan("")}) {
        CHECK_THROWS_WITH(latticeCellRange(f, LatticeFrame{{-2, -2, -2}, h}), Catch::Contains("--voxel-size"));
    }
    CHECK_THROWS_WITH(latticeCellRange(f, LatticeFrame{{-2, -2, -2}, 1e-9}), Catch::Contains("at most"));
    const LatticeFrame fine{{-2, -2, -2}, 2e-5};
    CHECK_THROWS_WITH(buildLattice(f, fine, latticeCellRange(f, fine), 0.0), Catch::Contains("too fine"));
}

TEST_CASE("a lattice that would need more memory to mesh than it may use stops while it is built, naming the voxel size") {
    ExpressionField f("x^2+y^2+z^2-1", Box3{{-2, -2, -2}, {2, 2, 2}});
    const LatticeFrame frame = f.naturalFrame(0.02); // about 4π / 0.02² = 31,000 cells on the sphere
    const CoordBBox range = latticeCellRange(f, frame);
    const Lattice lat = buildLattice(f, frame, range, 0.0, CellTest::Bounds, nullptr, 1e9);
    const double needs = double(lat.stats.cellsActive) * kMeshBytesPerActiveCell;
    REQUIRE(lat.stats.cellsActive > 20000);
    CHECK_THROWS_WITH(buildLattice(f, frame, range, 0.0, CellTest::Bounds, nullptr, 0.5 * needs),
                      Catch::Contains("--voxel-size") && Catch::Contains("memory") && Catch::Contains("x^2+y^2+z^2-1"));
    CHECK_NOTHROW(buildLattice(f, frame, range, 0.0, CellTest::Bounds, nullptr, 1.01 * needs));
    // A lattice of more blocks is judged from a sample of them first, before most are examined.
    const LatticeFrame finer = f.naturalFrame(0.005);
    const CoordBBox finerRange = latticeCellRange(f, finer);
    const Lattice big = buildLattice(f, finer, finerRange, 0.0, CellTest::Bounds, nullptr, 1e10);
    REQUIRE(big.stats.leafBlocksVisited > 2 * 4096);
    const double bigNeeds = double(big.stats.cellsActive) * kMeshBytesPerActiveCell;
    // Every second block is in the sample: half the cells, under the limit, estimate the total over it.
    CHECK_THROWS_WITH(buildLattice(f, finer, finerRange, 0.0, CellTest::Bounds, nullptr, 0.7 * bigNeeds),
                      Catch::Contains("estimated from") && Catch::Contains("memory"));
    CHECK_NOTHROW(buildLattice(f, finer, finerRange, 0.0, CellTest::Bounds, nullptr, 1.01 * bigNeeds));
    // Through the mesher, the limit it is given.
    MeshRequest req;
    req.voxelSize = 0.02;
    req.memoryLimit = 0.5 * needs;
    MeshReport rep;
    CHECK_THROWS_WITH(meshField(f, req, rep), Catch::Contains("--voxel-size") && Catch::Contains("memory"));
}

TEST_CASE("a formula undefined on the lattice is reported with the point") {
    ExpressionField f("sqrt(x) - 0.5", Box3{{-1, -1, -1}, {1, 1, 1}});
    const LatticeFrame frame = f.naturalFrame(0.1);
    CHECK_THROWS_WITH(buildLattice(f, frame, latticeCellRange(f, frame), 0.0), Catch::Contains("NaN") && Catch::Contains("sqrt(x)"));
}

TEST_CASE("a sparse cell tree converts to OpenVDB's standard mask tree cell for cell, tiles included") {
    // The lattice keeps its cells in a tree of small internal nodes (sparse_tree.h); files get
    // the standard configuration, which other tools read. Cells in all eight octants around the
    // origin, one far away, and an active tile of 8^3 cells.
    CellTree cells(false);
    std::vector<openvdb::Coord> on;
    for (int d = 0; d < 8; ++d) on.emplace_back((d & 1) ? 3 : -5, (d & 2) ? 17 : -1, (d & 4) ? 100 : -300);
    on.emplace_back(123456, -7, 42);
    for (const auto& c : on) cells.setValueOn(c);
    cells.addTile(1, openvdb::Coord(64, 64, 64), true, true);
    REQUIRE(cells.activeVoxelCount() == on.size() + 512);
    const openvdb::MaskTree::Ptr standard = toStandardMaskTree(cells);
    CHECK(standard->activeVoxelCount() == cells.activeVoxelCount());
    for (const auto& c : on) CHECK(standard->isValueOn(c));
    CHECK(standard->isValueOn(openvdb::Coord(64, 64, 64)));
    CHECK(standard->isValueOn(openvdb::Coord(71, 71, 71)));
    CHECK_FALSE(standard->isValueOn(openvdb::Coord(72, 64, 64)));
    CHECK_FALSE(standard->isValueOn(openvdb::Coord(0, 0, 0)));
}

TEST_CASE("a deformation's trees are freed whole, and a tree another owner shares is left to it") {
    // clearTree frees a small tree's nodes on the calling thread, a large one's as OpenVDB does:
    // either way the tree is empty after. release() frees only what the deformation alone holds.
    for (int spread : {3, 60}) {
        INFO("nodes " << spread << " apart");
        NodeMaskTree tree(false);
        for (int i = 0; i < 2000; ++i) tree.setValueOn(openvdb::Coord(i * spread, (i * 7) % 50, -i));
        REQUIRE(tree.leafCount() > 10);
        clearTree(tree, spread == 3 ? 0 : 16384); // the parallel path, then the serial one
        CHECK(tree.empty());
        CHECK(tree.leafCount() == 0);
        CHECK(tree.activeVoxelCount() == 0);
    }
    LatticeDeformation deformation;
    deformation.offsets->setValue(openvdb::Coord(1, 2, 3), openvdb::Vec3f(0.1f, 0.0f, 0.0f));
    deformation.onSurface->setValueOn(openvdb::Coord(1, 2, 3));
    deformation.insideOnSurface->setValueOn(openvdb::Coord(4, 5, 6));
    const OffsetTree::Ptr kept = deformation.offsets; // (as --lattice-out might hold it)
    deformation.release();
    CHECK(deformation.empty());
    CHECK(deformation.insideOnSurface->empty());
    CHECK(kept->activeVoxelCount() == 1);
    CHECK(kept->getValue(openvdb::Coord(1, 2, 3)) == openvdb::Vec3f(0.1f, 0.0f, 0.0f));
}

TEST_CASE("nodes alone inside among their six neighbours are listed where the corner signs decide") {
    // A field whose inside is specks a cell or two wide: thousands of lone nodes, on block borders
    // too (node coordinates that are multiples of 8, whose lower neighbour the block did not
    // read), and pairs across those borders, neither of them alone.
    ExpressionField f("sin(37*x + 1)*sin(41*y + 2)*sin(43*z + 0.5) + 0.6", Box3{{-1, -1, -1}, {1, 1, 1}});
    const double h = 0.045;
    const LatticeFrame frame = f.naturalFrame(h);
    const CoordBBox range = latticeCellRange(f, frame);
    const Lattice lat = buildLattice(f, frame, range, 0.0, CellTest::CornerSigns);
    auto inside = [&](int i, int j, int k) { return f.value(frame.nodeWorld(i, j, k)) < 0; };
    std::vector<openvdb::Coord> expected;
    std::size_t onBorders = 0, pairsAcross = 0;
    for (int i = range.min().x() + 1; i <= range.max().x(); ++i)
        for (int j = range.min().y() + 1; j <= range.max().y(); ++j)
            for (int k = range.min().z() + 1; k <= range.max().z(); ++k) {
                if (!inside(i, j, k) || inside(i + 1, j, k) || inside(i, j + 1, k) || inside(i, j, k + 1)) continue;
                // The lower neighbours, and whether one across a block border is inside.
                const bool lower[3] = {inside(i - 1, j, k), inside(i, j - 1, k), inside(i, j, k - 1)};
                const int at[3] = {i, j, k};
                bool seenInside = false, acrossInside = false;
                for (int a = 0; a < 3; ++a) (at[a] % 8 == 0 ? acrossInside : seenInside) |= lower[a];
                if (seenInside) continue;
                if (acrossInside) {
                    ++pairsAcross;
                    continue;
                }
                expected.emplace_back(i, j, k);
                onBorders += (i % 8 == 0) || (j % 8 == 0) || (k % 8 == 0);
            }
    INFO(expected.size() << " lone nodes, " << onBorders << " on block borders; " << pairsAcross << " pairs across them");
    REQUIRE(range.min() == openvdb::Coord(0, 0, 0)); // (block borders at multiples of 8)
    REQUIRE(expected.size() > 1000);
    REQUIRE(onBorders > 100);
    REQUIRE(pairsAcross > 10);
    CHECK(lat.loneInsideNodes == expected);
    // Where cells are asked for their bounds, nodes do not decide what a cell holds: none listed.
    CHECK(build(f, h, CellTest::Bounds).loneInsideNodes.empty());
}
