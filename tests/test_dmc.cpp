// Deformed Marching Cubes: thin parts kept (plates, rods, shells, cracks at random orientations),
// the paper's lens, spikes and rotated cube, topology, determinism, and the switches.
#include "support/formula_text.h"
#include "support/shapes.h"
#include "support/test_support.h"

#include "vdbsurf/core/threads.h"
#include "vdbsurf/dmc/edge_runs.h"
#include "vdbsurf/dmc/lattice_deformation.h"
#include "vdbsurf/dmc/lattice_surface.h"
#include "vdbsurf/dmc/mesher.h"
#include "vdbsurf/dmc/node_gradients.h"
#include "vdbsurf/dmc/node_weld.h"
#include "vdbsurf/dmc/sharp_features.h"
#include "vdbsurf/field/grid_field.h"
#include "vdbsurf/lattice/lattice.h"
#include "vdbsurf/vdb/vdb_file.h"
#include "vdbsurf/field/expression_field.h"
#include "vdbsurf/mesh/mesh_check.h"
#include "vdbsurf/mesh/mesh_distance.h"
#include "vdbsurf/mesh/mesh_io.h"
#include "vdbsurf/mesh/vertex_fans.h"

#include <catch2/catch.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <random>
#include <sstream>
#include <tuple>

using namespace vdbsurf;
using test::dotWith;
using test::eulerCharacteristic;
using test::eulerRotation;
using test::inFrame;
using test::num;
using test::piecesWithoutHandles;
using test::Rotation;

namespace {

constexpr double kPi = 3.14159265358979323846;

Mesh meshFormula(const std::string& formula, const Box3& box, double h, MeshMethod method = MeshMethod::Dmc, bool thin = true,
                 bool sharp = true) {
    ExpressionField f(formula, box);
    MeshRequest req;
    req.voxelSize = h;
    req.method = method;
    req.thin = thin;
    req.sharp = sharp;
    MeshReport rep;
    return meshField(f, req, rep);
}

void requireClosed(const Mesh& m) {
    const MeshTopology t = checkTopology(m);
    INFO("boundary " << t.boundaryEdges << " non-manifold " << t.nonManifoldEdges << " inconsistent " << t.inconsistentEdges
                     << " unused " << t.unusedVertices);
    CHECK(t.closedManifoldOriented());
    CHECK(t.unusedVertices == 0);
}

// Share of the points within `radius` of the mesh.
double coverage(const Mesh& m, const std::vector<Vec3d>& points, double radius) {
    MeshDistance d(m, radius);
    std::size_t near = 0;
    for (const Vec3d& p : points) near += d.distance(p, 2 * radius) <= radius;
    return double(near) / double(points.size());
}

Vec3d randomUnit(std::mt19937& rng) {
    std::normal_distribution<double> g;
    for (;;) {
        const Vec3d v(g(rng), g(rng), g(rng));
        if (length(v) > 1e-3) return normalized(v);
    }
}

// Two unit vectors completing n to an orthonormal frame.
void frameOf(const Vec3d& n, Vec3d& a, Vec3d& b) {
    a = normalized(cross(n, std::fabs(n.x) < 0.9 ? Vec3d(1, 0, 0) : Vec3d(0, 1, 0)));
    b = cross(n, a);
}

std::string radius2(const Vec3d& c) { return "((x-" + num(c.x) + ")^2+(y-" + num(c.y) + ")^2+(z-" + num(c.z) + ")^2)"; }


double nearestVertex(const Mesh& m, const Vec3d& p) {
    double nearest = INFINITY;
    for (const Vec3f& v : m.points) nearest = std::min(nearest, length(Vec3d(v) - p));
    return nearest;
}

const Box3 kBox{{-1.05, -1.05, -1.05}, {1.05, 1.05, 1.05}};
constexpr double kH = 0.1;

// A rod (cylinder of diameter `width`) through c along n, capped by a sphere of radius 0.7.
std::string rodFormula(const Vec3d& n, const Vec3d& c, double width) {
    return "max(sqrt(max(" + radius2(c) + "-" + dotWith(n, c) + "^2, 0))-" + num(width / 2) + ", sqrt(" + radius2(c) + ")-0.7)";
}

// A field meshed by DMC at spacing kH with default options, checked closed.
Mesh dmcAtH(const Field& field, MeshReport& report) {
    MeshRequest req;
    req.voxelSize = kH;
    Mesh m = meshField(field, req, report);
    requireClosed(m);
    return m;
}

// A random point of the centre cell.
Vec3d randomCentre(std::mt19937& rng) {
    std::uniform_real_distribution<double> jitter(-0.5 * kH, 0.5 * kH);
    const double x = jitter(rng), y = jitter(rng);
    return Vec3d(x, y, jitter(rng));
}

// Of `count` formulas made by `shape` from one random generator, how many DMC meshes closed and
// in `pieces` pieces (each one that is not fails a check, unless `allMust` is false).
int randomShapesInPieces(unsigned seed, int count, std::size_t pieces, const std::function<std::string(std::mt19937&)>& shape,
                         bool allMust = true) {
    std::mt19937 rng(seed);
    int whole = 0;
    for (int trial = 0; trial < count; ++trial) {
        const std::string f = shape(rng);
        const Mesh m = meshFormula(f, kBox, kH);
        INFO(f);
        requireClosed(m);
        if (allMust) CHECK(countComponents(m) == pieces);
        whole += countComponents(m) == pieces;
    }
    return whole;
}

// Of `count` rods at random orientations through random points of the centre cell, how many come
// out in one piece.
int randomRodsInOnePiece(unsigned seed, double width, int count) {
    return randomShapesInPieces(seed, count, 1, [&](std::mt19937& rng) {
        const Vec3d n = randomUnit(rng);
        return rodFormula(n, randomCentre(rng), width);
    });
}

// Of `count` spherical shells `width` thick around random points of the centre cell, how many come
// out as two surfaces (outer and inner).
int randomShellsApart(unsigned seed, double width, int count) {
    return randomShapesInPieces(seed, count, 2, [&](std::mt19937& rng) {
        return "abs(sqrt(" + radius2(randomCentre(rng)) + ")-0.7)-" + num(width / 2);
    });
}

// A ball of radius 0.8 around c cut in two by a crack `width` wide across n through c.
std::string crackFormula(const Vec3d& n, const Vec3d& c, double width) {
    return "max(sqrt(" + radius2(c) + ")-0.8, " + num(width / 2) + "-abs(" + dotWith(n, c) + "))";
}

// The same shape as a level-set grid of voxel `voxel`.
GridBasePtr crackLevelSet(const Vec3d& n, const Vec3d& c, double width, double voxel) {
    auto gap = [&](const Vec3d& p) { return std::max(length(p - c) - 0.8, width / 2 - std::fabs(dot(n, p - c))); };
    return test::makeLevelSetFromDistance(gap, Box3{{-1.1, -1.1, -1.1}, {1.1, 1.1, 1.1}}, voxel);
}

// Of `count` balls cut in two by a crack `width` wide at a random orientation through a random
// point of the centre cell, how many come out as two pieces.
int randomCracksApart(unsigned seed, double width, int count, bool allMust = true) {
    return randomShapesInPieces(
        seed, count, 2,
        [&](std::mt19937& rng) {
            const Vec3d n = randomUnit(rng), c = randomCentre(rng);
            return crackFormula(n, c, width);
        },
        allMust);
}

// The crack normal and centre that randomCracksApart draws for trial `trial` from `seed`.
std::pair<Vec3d, Vec3d> randomCrackAt(unsigned seed, int trial) {
    std::mt19937 rng(seed);
    Vec3d n, c;
    for (int t = 0; t <= trial; ++t) {
        n = randomUnit(rng);
        c = randomCentre(rng);
    }
    return {n, c};
}

// Checks that trial `trial`'s crack from `seed`, `width` wide, meshed from its formula at spacing
// kH, comes out closed and in two pieces.
void checkRandomCrackApart(unsigned seed, int trial, double width) {
    const auto [n, c] = randomCrackAt(seed, trial);
    const std::string f = crackFormula(n, c, width);
    INFO("seed " << seed << ", width " << width / kH << " H, trial " << trial << ": " << f);
    const Mesh m = meshFormula(f, kBox, kH);
    requireClosed(m);
    CHECK(countComponents(m) == 2);
}

// The same crack as a level-set grid of voxel H/5, meshed by DMC at spacing kH (checked closed).
Mesh randomCrackLevelSetAtH(unsigned seed, int trial, double width, MeshReport& report) {
    const auto [n, c] = randomCrackAt(seed, trial);
    const GridField field(crackLevelSet(n, c, width, kH / 5), "gap");
    return dmcAtH(field, report);
}

// A frame rotated by R and moved by c, as formula text: its local coordinates, and boxes in them.
struct FormulaFrame {
    std::string l[3];
    FormulaFrame(const Rotation& R, const Vec3d& c) {
        for (int i = 0; i < 3; ++i) l[i] = dotWith(Vec3d(R[0][i], R[1][i], R[2][i]), c);
    }
    // The box of half extents b around p, as the largest of its slabs' distances.
    std::string box(double px, double py, double pz, double bx, double by, double bz) const {
        return "max(max(abs(" + l[0] + "-" + num(px) + ")-" + num(bx) + ",abs(" + l[1] + "-" + num(py) + ")-" + num(by) + "),abs(" + l[2] +
               "-" + num(pz) + ")-" + num(bz) + ")";
    }
};

} // namespace

TEST_CASE("thin plates, rods and shells from a fifth of a cell to a cell wide are kept, closed, in one piece") {
    std::mt19937 rng(20261123);
    std::uniform_real_distribution<double> jitter(-0.5 * kH, 0.5 * kH);
    for (double width : {0.2 * kH, 0.3 * kH, 0.5 * kH, 1.0 * kH}) {
        for (int trial = 0; trial < 2; ++trial) {
            const Vec3d n = randomUnit(rng), c(jitter(rng), jitter(rng), jitter(rng));
            Vec3d a, b;
            frameOf(n, a, b);
            const double R = 0.7;
            std::vector<Vec3d> truth;
            // A disk-shaped plate.
            {
                const std::string f = "max(abs(" + dotWith(n, c) + ")-" + num(width / 2) + ", sqrt(" + radius2(c) + ")-" + num(R) + ")";
                for (int i = 0; i < 400; ++i) {
                    const double r = 0.9 * R * std::sqrt((i + 0.5) / 400), t = i * 2.39996;
                    for (double s : {-1.0, 1.0}) truth.push_back(c + a * (r * std::cos(t)) + b * (r * std::sin(t)) + n * (s * width / 2));
                }
                const Mesh m = meshFormula(f, kBox, kH);
                INFO("plate of width " << width / kH << " H, normal " << n.x << " " << n.y << " " << n.z);
                requireClosed(m);
                CHECK(countComponents(m) == 1);
                CHECK(coverage(m, truth, kH) >= 0.99);
            }
            // A rod (cylinder of diameter `width`) along n, capped by a sphere.
            truth.clear();
            {
                const std::string f = rodFormula(n, c, width);
                for (int i = 0; i < 400; ++i) {
                    const double t = -0.9 * R + 1.8 * R * i / 399.0, phi = i * 2.39996;
                    truth.push_back(c + n * t + (a * std::cos(phi) + b * std::sin(phi)) * (width / 2));
                }
                const Mesh m = meshFormula(f, kBox, kH);
                INFO("rod of width " << width / kH << " H: " << f);
                requireClosed(m);
                CHECK(countComponents(m) == 1);
                CHECK(coverage(m, truth, kH) >= 0.99);
            }
            // A spherical shell.
            truth.clear();
            {
                const std::string f = "abs(sqrt(" + radius2(c) + ")-" + num(R) + ")-" + num(width / 2);
                for (int i = 0; i < 800; ++i) {
                    const Vec3d d = randomUnit(rng);
                    truth.push_back(c + d * (R + (i % 2 ? 1 : -1) * width / 2));
                }
                const Mesh m = meshFormula(f, kBox, kH);
                INFO("shell of width " << width / kH << " H: " << f);
                requireClosed(m);
                const std::size_t pieces = countComponents(m);
                CHECK(pieces == 2); // outer and inner surface
                CHECK(coverage(m, truth, kH) >= 0.99);
            }
        }
    }
}

TEST_CASE("rods a fifth of a cell across, at random orientations, come out in one piece") {
    // The narrowest part the search promises to find: consecutive nodes that moved into the rod
    // often meet across a face or cell diagonal where the rod runs along the edge between their
    // Ω (or clips a corner of the Ω between): the node between moves onto the segment joining
    // them. (Without that, 12 of 60 such rods broke.)
    CHECK(randomRodsInOnePiece(5150, 0.2 * kH, 24) == 24);
}

TEST_CASE("a rod through a lattice face whose corners all lie outside it stays in one piece") {
    // This rod (found among random ones) passes from a cell with one inside corner to the next
    // cell through the interior of their shared face, touching none of its edges or diagonals:
    // the two inside nodes are two steps apart and marching cubes alone cuts the rod there. One
    // of the face's corners moves into it (bridging, "pierced faces").
    const std::string f = rodFormula(normalized(Vec3d(-0.402611, 0.857697, 0.319783)), Vec3d(-0.021874, 0.017538, 0.002351), 0.3 * kH);
    const Mesh m = meshFormula(f, kBox, kH);
    requireClosed(m);
    CHECK(countComponents(m) == 1);
    // And random rods of that width and a little wider stay whole too.
    CHECK(randomRodsInOnePiece(31337, 0.3 * kH, 12) == 12);
    CHECK(randomRodsInOnePiece(31338, 0.5 * kH, 12) == 12);
}

namespace {

// The union of two shapes that cross: whether DMC at kH gives one closed piece without a handle.
bool unionWhole(const std::string& shapeA, const std::string& shapeB) {
    const std::string f = "min(" + shapeA + ", " + shapeB + ")";
    const Mesh m = meshFormula(f, kBox, kH);
    INFO(f);
    requireClosed(m);
    return piecesWithoutHandles(m, 1);
}

// Two rods `width`s across crossing at c along a and b.
bool crossingRodsWhole(const Vec3d& a, const Vec3d& b, const Vec3d& c, double widthA, double widthB) {
    return unionWhole(rodFormula(a, c, widthA), rodFormula(b, c, widthB));
}

// A plate (slab `width` thick) through c across n, cut to a disc by a sphere of radius 0.7.
std::string plateFormula(const Vec3d& n, const Vec3d& c, double width) {
    return "max(abs(" + dotWith(n, c) + ")-" + num(width / 2) + ", sqrt(" + radius2(c) + ")-0.7)";
}

using ThinPart = std::function<std::string(const Vec3d&, const Vec3d&, double)>; // direction, centre, width

// The part of `shape` on the side of the plane through c across n that n points to.
std::string onSideOf(const Vec3d& n, const Vec3d& c, const std::string& shape) { return "max(" + shape + ", -" + dotWith(n, c) + ")"; }

// Of `count` random pairs of thin parts made by `part` (a formula from a direction, a centre and a
// width), a fifth to `widest` cells across, at least `degrees` apart, crossing in the centre cell:
// how many DMC meshes are one piece without a handle.
int crossingPairsWhole(unsigned seed, int count, double widest, double degrees, const ThinPart& part) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> width(0.2 * kH, widest * kH);
    int whole = 0;
    for (int trial = 0; trial < count; ++trial) {
        const Vec3d a = randomUnit(rng), c = randomCentre(rng);
        Vec3d b = randomUnit(rng);
        while (std::fabs(dot(a, b)) > std::cos(degrees * kPi / 180)) b = randomUnit(rng);
        const double wa = width(rng), wb = width(rng);
        whole += unionWhole(part(a, c, wa), part(b, c, wb));
    }
    return whole;
}

// Of 24 random thin parts made by `part`, 0.2-0.6 cells across, through the centre cell and
// standing out of a ball of radius 0.5 around it: how many DMC meshes are one piece without a
// handle (the part's root is where the sharp pass may cut it off or tunnel under it).
int partsOnBallWhole(unsigned seed, const ThinPart& part) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> width(0.2 * kH, 0.6 * kH);
    int whole = 0;
    for (int trial = 0; trial < 24; ++trial) {
        const Vec3d n = randomUnit(rng), c = randomCentre(rng);
        const std::string f = "min(sqrt(" + radius2(c) + ")-0.5, " + part(n, c, width(rng)) + ")";
        const Mesh m = meshFormula(f, kBox, kH);
        INFO(f);
        requireClosed(m);
        whole += piecesWithoutHandles(m, 1);
    }
    return whole;
}

// Of `count` random plates 0.3-0.8 cells thick through the centre cell, each with a part made by
// `part` (0.3-0.8 cells across) that ends on it — on one side of it only — at least 40 degrees
// from lying in it (`rod`: `part` runs along its direction, else across it): how many DMC meshes
// are one piece without a handle.
int teesWhole(unsigned seed, int count, const ThinPart& part, bool rod) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> width(0.3 * kH, 0.8 * kH);
    const double sin40 = std::sin(40 * kPi / 180);
    int whole = 0;
    for (int trial = 0; trial < count; ++trial) {
        const Vec3d a = randomUnit(rng), c = randomCentre(rng);
        Vec3d b = randomUnit(rng);
        // The sine of the angle between the part and the plate: |a·b| along a rod, else across.
        while ((rod ? std::fabs(dot(a, b)) : std::sqrt(std::max(0.0, 1 - dot(a, b) * dot(a, b)))) < sin40) b = randomUnit(rng);
        const double wa = width(rng), wb = width(rng);
        whole += unionWhole(plateFormula(a, c, wa), onSideOf(a, c, part(b, c, wb)));
    }
    return whole;
}

// A plate `plateWidth` thick through c across n (a disc, plateFormula) with a rod `rodWidth`
// across standing on it along m, on the side n points to: whether DMC at kH gives one closed
// piece without a handle.
bool teeWhole(const Vec3d& n, const Vec3d& m, const Vec3d& c, double plateWidth, double rodWidth) {
    return unionWhole(plateFormula(n, c, plateWidth), onSideOf(n, c, rodFormula(m, c, rodWidth)));
}

// Three rods `widths` across crossing at right angles at c, along a, b and a × b (a and b
// orthonormal): whether DMC at kH gives one closed piece without a handle.
bool junctionWhole(const Vec3d& a, const Vec3d& b, const Vec3d& c, const std::array<double, 3>& widths) {
    return unionWhole(rodFormula(a, c, widths[0]),
                      "min(" + rodFormula(b, c, widths[1]) + ", " + rodFormula(normalized(cross(a, b)), c, widths[2]) + ")");
}

// Of `count` random junctions of three rods 0.3-0.5 cells across (junctionWhole) in the centre
// cell, how many are whole.
int junctionsWhole(unsigned seed, int count) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> width(0.3 * kH, 0.5 * kH);
    int whole = 0;
    for (int trial = 0; trial < count; ++trial) {
        const Vec3d a = randomUnit(rng), b = normalized(cross(a, randomUnit(rng))), c = randomCentre(rng);
        const std::array<double, 3> widths{width(rng), width(rng), width(rng)};
        whole += junctionWhole(a, b, c, widths);
    }
    return whole;
}

// A cubic truss of 27 wires 0.3-0.6 cells across, three a side 4 cells apart along each axis of
// a random frame (the wires run 2 cells past the outer junctions), through the centre cell:
// whether DMC at kH gives one closed piece with its 28 loops (genus 28) and no other handle.
bool trussWhole(std::mt19937& rng) {
    std::uniform_real_distribution<double> width(0.3 * kH, 0.6 * kH);
    const Vec3d a = randomUnit(rng), b = normalized(cross(a, randomUnit(rng))), axes[3] = {a, b, cross(a, b)};
    const Vec3d c = randomCentre(rng);
    const double spacing = 4 * kH;
    std::string f = "min(";
    for (int axis = 0; axis < 3; ++axis)
        for (int j = -1; j <= 1; ++j)
            for (int k = -1; k <= 1; ++k) {
                const Vec3d& n = axes[axis];
                const Vec3d at = c + axes[(axis + 1) % 3] * (j * spacing) + axes[(axis + 2) % 3] * (k * spacing);
                f += std::string(axis + j + k == -2 ? "" : ", ") + "max(sqrt(max(" + radius2(at) + "-" + dotWith(n, at) + "^2, 0))-" +
                     num(width(rng) / 2) + ", abs(" + dotWith(n, at) + ")-" + num(spacing + 2 * kH) + ")";
            }
    f += ")";
    const Mesh m = meshFormula(f, kBox, kH);
    INFO(f);
    requireClosed(m);
    return countComponents(m) == 1 && eulerCharacteristic(m) == 2 - 2 * 28;
}

} // namespace

TEST_CASE("three thin rods crossing at right angles stay joined at their junction") {
    // Between the rods, the outside reaches through a face whose four corners lie in the rods, to
    // outside nodes on both sides of it. Bridging moved one of those corners out to join them
    // (a pierced face); it was the node that held a rod to the junction, which came off. Outside
    // nodes the lattice joins nearby already are not bridged so now. These three came out in two
    // pieces. Random junctions 0.3-0.5 H thick, ten sets of 24 from this generator: 10 not whole
    // before, 2 now (this set: 3 before); 0.2-1 H, five sets of 100 from another: 14 before, 6 now.
    CHECK(junctionWhole(Vec3d(-0.829114, -0.049782, -0.556859), Vec3d(-0.554940, 0.194266, 0.808889),
                        Vec3d(-0.042800, -0.044244, 0.007526), {0.044847, 0.047569, 0.032687}));
    CHECK(junctionWhole(Vec3d(-0.463677, 0.230134, 0.855594), Vec3d(0.859139, -0.119213, 0.497664),
                        Vec3d(0.013687, 0.022041, -0.047238), {0.033200, 0.038821, 0.043002}));
    CHECK(junctionWhole(Vec3d(0.120845, 0.559602, 0.819904), Vec3d(0.991747, -0.032427, -0.124040),
                        Vec3d(0.039740, 0.038533, -0.030347), {0.030370, 0.046566, 0.049216}));
    // The thinnest rod leaves the junction along the edge where four Ω meet, clipping two of them
    // by a sliver no sample finds; its first node meets the junction's across a face diagonal, and
    // the straight segment between them passes outside: the node between moves onto the bent path
    // found instead. It came off.
    CHECK(junctionWhole(Vec3d(-0.524928, 0.336541, -0.781787), Vec3d(0.336273, -0.761784, -0.553720),
                        Vec3d(-0.015526, -0.040628, 0.018240), {0.097541, 0.067381, 0.020293}));
    // Not to a node two steps away: there the path ran round through the junction, which the
    // lattice joins further on, and the node moved onto it closed a loop (a handle).
    CHECK(junctionWhole(Vec3d(-0.566182, 0.216439, 0.795357), Vec3d(0.154699, 0.975666, -0.155382),
                        Vec3d(0.021809, 0.017854, 0.006639), {0.034558, 0.071653, 0.070471}));
    // A corner of a truss: the wire nearly along a lattice axis came off two cells from the
    // junction. The node that had to move into it was refused because the outside node amid the
    // three wires would have had no outside neighbour left along an edge; marching cubes joins it
    // to the outside across face diagonals, which now count for an outside node.
    CHECK(junctionWhole(Vec3d(-0.999601, 0.027342, -0.007050), Vec3d(0.028025, 0.930254, -0.365845),
                        Vec3d(-0.397726, -0.221942, 0.512335), {0.032992, 0.037055, 0.050234}));
    CHECK(junctionsWhole(4, 24) == 24);
}

TEST_CASE("a cubic truss of wires thinner than a cell keeps every loop") {
    // A wire's node next to a junction was joined to the junction only the long way round a
    // square of the truss (4 cells a side), which the lattice's own join test counted: bridging
    // left it apart, and the square's loop broke there. Now only paths of up to 8 steps count
    // (6 until a sheared grid's torus got a handle: test_grid_frames; these counts held).
    // Six sets of three random trusses: 5 of 18 whole before, 13 after that, 16 now (outside
    // nodes counting across face diagonals for company, EdgeRuns::moveEffect); this set: 1 of 3
    // before.
    std::mt19937 rng(4);
    int whole = 0;
    for (int trial = 0; trial < 3; ++trial) whole += trussWhole(rng);
    CHECK(whole == 3);
}

TEST_CASE("thin rods crossing near a node stay joined where the straight segment between their nodes leaves both") {
    // Nodes moved into each rod next to the crossing meet across a diagonal; the segment between
    // them leaves the one rod before it enters the other, so only a path through the crossing
    // joins them (EdgeRuns::joinedNearby, a cell around them). Both came out in two pieces.
    CHECK(crossingRodsWhole(normalized(Vec3d(-0.469342, -0.633408, -0.615234)), normalized(Vec3d(-0.292934, 0.929174, 0.225445)),
                            Vec3d(0.029781, 0.001660, -0.027680), 0.045756, 0.02931));
    CHECK(crossingRodsWhole(normalized(Vec3d(0.088645, -0.718676, 0.689672)), normalized(Vec3d(0.841342, -0.539713, -0.029220)),
                            Vec3d(0.024401, -0.039717, 0.041076), 0.023004, 0.039562));
    // Random pairs at least 40 degrees apart, a fifth to half a cell across, crossing in the centre
    // cell: 22 of 24 whole (17 where the path round the crossing was sought within half a cell and
    // 20 samples a step, EdgeRuns::kRimReach; 11 with straight segments alone). Where a node is
    // needed by both rods at once, one rod still comes off: moving it into the one would join its
    // edge to a node of the other across the gap between them (a handle), and one node a cell
    // cannot stand for two parts.
    CHECK(crossingPairsWhole(2718, 24, 0.5, 40, rodFormula) >= 21);
}

TEST_CASE("thin plates crossing at random angles mostly come out without holes or handles") {
    // Near the line where they cross, nodes of the one plate sit next to nodes of the other; a
    // node moves into its plate only if the edge it then shares with the other plate's node
    // crosses the wedge between them where the two are joined nearby (through the crossing), else
    // the plate keeps a hole there. Pairs a fifth to 0.7 cells thick, at least 40 degrees apart,
    // crossing in the centre cell: 20 of 24 whole (14 when the path round the crossing was sought
    // within half a cell and 20 samples a step). The rest, mostly 40-55 degrees apart (the wedge
    // stays narrower than a cell for two cells out), get handles: webs across the wedge a cell or
    // more from the line, with outside beneath them, or a plate holed beside one.
    CHECK(crossingPairsWhole(1618, 24, 0.7, 40, plateFormula) >= 19);
    // A move into one plate next to the line was refused where it left an outside node of the
    // wedge with outside neighbours only across face diagonals (which marching cubes joins): two
    // more sets, 38 of 48 whole before they counted, 42 now (five sets: 97 -> 105 of 120).
    CHECK(crossingPairsWhole(1620, 24, 0.7, 40, plateFormula) + crossingPairsWhole(1621, 24, 0.7, 40, plateFormula) >= 41);
}

TEST_CASE("thin plates and rods ending on a thin plate stay attached and mostly without holes") {
    // The junction is a crossing cut in half: nodes of the two parts meet across the wedge
    // between them, joined round the foot of the one on the other (EdgeRuns::kJunctionReach).
    // 22 and 24 of 24 whole (18 and 19 with the outside's reach: holes in a plate beside the
    // foot, a rod's foot cut off).
    CHECK(teesWhole(4242, 24, plateFormula, false) >= 21);
    CHECK(teesWhole(4243, 24, rodFormula, true) >= 23);
}

TEST_CASE("a rod thinner than a cell standing on a plate thinner than a cell stays attached") {
    // The rod's stretch next to the plate crosses cells that have a corner in the plate, so no
    // node there searches for it; its nearest nodes meet the plate's across a face or cell
    // diagonal, and the path between them bends at the rod's foot. The search for that path heads
    // for its goal greedily: from the plate's node it spread over the plate and gave up, from the
    // rod's it runs down the rod (now made from both ends, and from a rod's node at rest too).
    // These came off. Random rods and plates 0.2-1 H, at least 45 degrees apart, five sets of 60:
    // 14 not whole before (8 of them came off), 8 now (1 came off; the rest get a handle in the
    // wedge between rod and plate).
    CHECK(teeWhole(Vec3d(0.767974, 0.416285, -0.486746), Vec3d(0.977544, 0.103292, -0.183682), Vec3d(0.037835, 0.016964, -0.007349),
                   0.023315, 0.036004));
    CHECK(teeWhole(Vec3d(-0.592589, 0.647827, 0.478705), Vec3d(-0.188684, 0.981760, 0.023340), Vec3d(-0.004679, 0.045913, -0.001628),
                   0.065966, 0.041536));
    CHECK(teeWhole(Vec3d(-0.302959, 0.918555, 0.253913), Vec3d(0.369204, 0.897367, 0.241706), Vec3d(-0.048272, 0.017937, -0.004593),
                   0.048160, 0.073159));
    CHECK(teeWhole(Vec3d(0.300836, -0.822558, 0.482594), Vec3d(-0.272443, -0.539876, 0.796435), Vec3d(-0.007354, -0.042887, 0.011215),
                   0.036810, 0.033280));
    // Its first node inside the rod at rest, the plate's across a cell diagonal from it.
    CHECK(teeWhole(Vec3d(-0.422891, -0.395100, 0.815511), Vec3d(-0.734313, -0.205213, 0.647049), Vec3d(0.036925, 0.001613, 0.013697),
                   0.099450, 0.044913));
}

TEST_CASE("rods one to two cells across, at random orientations, come out in one piece with sharp features on") {
    // Their normals turn as fast as at an edge and two tangent planes meet just outside the
    // surface: a feature node placed there would carry the rod's whole cross-section and the
    // weld would cut the rod in two (the solid-behind probe must reach past such a rod).
    CHECK(randomRodsInOnePiece(424242, 1.0 * kH, 8) == 8);
    CHECK(randomRodsInOnePiece(424243, 1.25 * kH, 8) == 8);
    CHECK(randomRodsInOnePiece(424244, 1.5 * kH, 8) == 8);
    CHECK(randomRodsInOnePiece(424245, 2.0 * kH, 8) == 8);
}

namespace {

// Of a wire (rodFormula(n, c, width)) and its mesh: precision, the share of points of the mesh's
// polygons within H/4 of the surface (|f| is the distance to the cylinder, and no more than the
// distance near the caps); recall, the share of points of the wire's side within H/4 of the mesh.
std::pair<double, double> wirePrecisionRecall(const Field& field, const Mesh& m, const Vec3d& n, const Vec3d& c, double width) {
    std::size_t near = 0, samples = 0;
    for (std::size_t p = 0; p < m.polygonCount(); ++p) {
        const std::uint32_t* v = m.polygon(p);
        for (std::uint32_t j = 1; j + 1 < m.polygonSize(p); ++j) {
            const Vec3d a(m.points[v[0]]), b(m.points[v[j]]), d(m.points[v[j + 1]]);
            for (int u = 0; u <= 6; ++u)
                for (int w = 0; u + w <= 6; ++w, ++samples)
                    near += std::fabs(field.value(a + (b - a) * (u / 6.0) + (d - a) * (w / 6.0))) <= kH / 4;
        }
    }
    Vec3d a, b;
    frameOf(n, a, b);
    std::vector<Vec3d> truth;
    for (int i = 0; i < 600; ++i) {
        const double t = -0.6 + 1.2 * i / 599.0, phi = i * 2.39996;
        truth.push_back(c + n * t + (a * std::cos(phi) + b * std::sin(phi)) * (width / 2));
    }
    return {double(near) / double(samples), coverage(m, truth, kH / 4)};
}

} // namespace

TEST_CASE("wires 0.8 to 1 cell thick at random orientations: their nodes are centred, and the mesh hugs the wire") {
    // Such a wire holds about one node per cross-section, and the crossings on its four edges
    // across the wire fall where the lattice lines through it meet the surface: from a node near
    // the wire's side they crowd there, and the polygons between them cut through the wire.
    // Centred on the wire (within its Ω, keeping its side), the node spreads them round it.
    std::mt19937 rng(8081);
    std::uniform_real_distribution<double> widths(0.8 * kH, 1.0 * kH);
    int good = 0;
    double sumF = 0;
    std::uint64_t centred = 0;
    const int count = 16;
    for (int trial = 0; trial < count; ++trial) {
        const Vec3d n = randomUnit(rng), c = randomCentre(rng);
        const double width = widths(rng);
        const std::string f = rodFormula(n, c, width);
        ExpressionField field(f, kBox);
        MeshReport report;
        const Mesh m = dmcAtH(field, report);
        centred += report.thinNodesCentred;
        const auto [precision, recall] = wirePrecisionRecall(field, m, n, c, width);
        const double F = 2 * precision * recall / (precision + recall);
        INFO("wire " << width / kH << " H wide: " << f << ": precision " << precision << ", recall " << recall);
        CHECK(countComponents(m) == 1);
        CHECK(F >= 0.85);
        good += F >= 0.95;
        sumF += F;
    }
    CHECK(centred > 0);
    // All 16 and a mean F of 0.983 (14 of 16 and 0.970 without centring; the worst 0.928).
    CHECK(good >= 15);
    CHECK(sumF / count >= 0.978);
}

TEST_CASE("wires 1 to 1.6 cells thick at random orientations: the surface fit puts vertices where polygons cut across them") {
    // Four to six crossings round such a wire, and one marching-cubes polygon may span more than
    // half of its round: its chords pass through the wire up to half a cell from the surface. The
    // fit splits edges and fans polygons round points projected onto the surface there.
    std::mt19937 rng(9091);
    std::uniform_real_distribution<double> widths(1.0 * kH, 1.6 * kH);
    const int count = 12;
    int good[2] = {0, 0};
    double sumF[2] = {0, 0};
    std::size_t triangles[2] = {0, 0};
    std::uint64_t added = 0;
    for (int trial = 0; trial < count; ++trial) {
        const Vec3d n = randomUnit(rng), c = randomCentre(rng);
        const double width = widths(rng);
        const std::string f = rodFormula(n, c, width);
        ExpressionField field(f, kBox);
        for (int fit = 0; fit < 2; ++fit) {
            MeshRequest req;
            req.voxelSize = kH;
            req.fit = fit == 1;
            MeshReport report;
            const Mesh m = meshField(field, req, report);
            requireClosed(m);
            CHECK(countComponents(m) == 1);
            const auto [precision, recall] = wirePrecisionRecall(field, m, n, c, width);
            const double F = 2 * precision * recall / (precision + recall);
            INFO("wire " << width / kH << " H wide, fit " << fit << ": " << f << ": precision " << precision << ", recall " << recall);
            if (fit) CHECK(F >= 0.95);
            good[fit] += F >= 0.95;
            sumF[fit] += F;
            triangles[fit] += m.fannedTriangleCount();
            if (fit) added += report.fitEdgesSplit + report.fitCentres;
        }
    }
    INFO("F >= 0.95 on " << good[1] << " with the fit (mean " << sumF[1] / count << ", " << triangles[1] << " triangles), " << good[0]
                         << " without (mean " << sumF[0] / count << ", " << triangles[0] << " triangles)");
    CHECK(added > 0);
    CHECK(good[1] == count);
    CHECK(sumF[1] / count >= 0.975);
    CHECK(good[0] < count);
    // The fit adds vertices where they are needed, not everywhere: well under twice the triangles.
    CHECK(triangles[1] < 1.5 * triangles[0]);
}

TEST_CASE("a crack thinner than a cell inside a solid comes out (concave thin part)") {
    std::mt19937 rng(7);
    for (double width : {0.2 * kH, 0.3 * kH}) {
        const Vec3d n = randomUnit(rng), c(0.013, -0.021, 0.017);
        Vec3d a, b;
        frameOf(n, a, b);
        // A ball with a planar crack through its middle: two half-balls a crack apart.
        const std::string f = "max(sqrt(" + radius2(c) + ")-0.8, " + num(width / 2) + "-abs(" + dotWith(n, c) + "))";
        std::vector<Vec3d> crackFaces;
        for (int i = 0; i < 400; ++i) {
            const double r = 0.6 * std::sqrt((i + 0.5) / 400), t = i * 2.39996;
            for (double s : {-1.0, 1.0}) crackFaces.push_back(c + a * (r * std::cos(t)) + b * (r * std::sin(t)) + n * (s * width / 2));
        }
        const Mesh dmc = meshFormula(f, kBox, kH);
        const Mesh mc = meshFormula(f, kBox, kH, MeshMethod::MarchingCubes);
        INFO("crack of width " << width / kH << " H");
        requireClosed(dmc);
        CHECK(coverage(dmc, crackFaces, kH) >= 0.99);
        CHECK(coverage(mc, crackFaces, kH) < 0.9); // what marching cubes loses
    }
}

TEST_CASE("the paper's lens (eq. 13) on 120^3 closes as one watertight piece that marching cubes loses") {
    const std::string f = "max(x^2+y^2+z^2-9, 8.9-x^2-y^2-z^2, y)";
    const Box3 box{{-3.5, -3.5, -3.5}, {3.5, 3.5, 3.5}};
    const double h = 7.0 / 120;
    std::vector<Vec3d> truth;
    std::mt19937 rng(13);
    while (truth.size() < 2000) {
        Vec3d d = randomUnit(rng);
        if (d.y > -0.05) continue;
        truth.push_back(d * (truth.size() % 2 ? 3.0 : std::sqrt(8.9)));
    }
    const Mesh dmc = meshFormula(f, box, h);
    const Mesh mc = meshFormula(f, box, h, MeshMethod::MarchingCubes);
    requireClosed(dmc);
    CHECK(countComponents(dmc) == 1);
    const double covDmc = coverage(dmc, truth, h), covMc = coverage(mc, truth, h);
    INFO("coverage within 1 H: dmc " << covDmc << ", mc " << covMc);
    CHECK(covDmc >= 0.99);
    CHECK(covMc < 0.9);
    CHECK(covDmc > covMc + 0.1);
}

TEST_CASE("20 spikes on an 80^3 lattice: every tip is present") {
    // A ball with 20 thin cones along a Fibonacci spiral of directions.
    std::string f = "sqrt(x^2+y^2+z^2)-1";
    std::vector<Vec3d> tips;
    const double tipDistance = 2.6, baseRadius = 0.3;
    for (int i = 0; i < 20; ++i) {
        const double zc = 1 - (i + 0.5) * 2 / 20, r = std::sqrt(1 - zc * zc), phi = i * 2.39996;
        const Vec3d d(r * std::cos(phi), r * std::sin(phi), zc);
        tips.push_back(d * tipDistance);
        const std::string t = "(" + num(d.x) + "*x+" + num(d.y) + "*y+" + num(d.z) + "*z)";
        const std::string radial = "sqrt(max(x^2+y^2+z^2-" + t + "^2, 0))";
        f = "min(" + f + ", max(" + radial + "-" + num(baseRadius / tipDistance) + "*(" + num(tipDistance) + "-" + t + "), -" + t + "))";
    }
    const Box3 box{{-3, -3, -3}, {3, 3, 3}};
    const double h = 6.0 / 80;
    const Mesh dmc = meshFormula(f, box, h);
    const Mesh mc = meshFormula(f, box, h, MeshMethod::MarchingCubes);
    requireClosed(dmc);
    CHECK(countComponents(dmc) <= 2);
    MeshDistance dd(dmc, h), dm(mc, h);
    // The spike is h/5 wide (what the search guarantees) this far from its tip.
    const double guaranteed = (h / 5) / (2 * baseRadius / tipDistance);
    int reachedDmc = 0, reachedMc = 0;
    for (const Vec3d& tip : tips) {
        reachedDmc += dd.distance(tip, 4 * h) <= guaranteed + 0.5 * h;
        reachedMc += dm.distance(tip, 4 * h) <= guaranteed + 0.5 * h;
    }
    INFO("tips reached: dmc " << reachedDmc << ", mc " << reachedMc << " (within " << (guaranteed + 0.5 * h) / h << " H)");
    CHECK(reachedDmc == 20);
    CHECK(reachedMc < 20);
}

TEST_CASE("a rotated cube on a coarse lattice keeps its corners exactly and its edges closer than marching cubes") {
    const Rotation R = eulerRotation(0.3, 0.5, 0.7);
    const Vec3d c(0.013, 0.021, -0.017);
    std::string f = "max(";
    for (int i = 0; i < 3; ++i) f += (i ? ",abs" : "abs") + dotWith(Vec3d(R[0][i], R[1][i], R[2][i]), c);
    f += ")-1";
    const Box3 box{{-2, -2, -2}, {2, 2, 2}};
    for (double h : {0.25, 0.37}) {
        const Mesh dmc = meshFormula(f, box, h);
        const Mesh mc = meshFormula(f, box, h, MeshMethod::MarchingCubes);
        INFO("h " << h);
        requireClosed(dmc);
        CHECK(countComponents(dmc) == 1);
        auto world = [&](const Vec3d& l) { return inFrame(R, c, l); };
        MeshDistance dd(dmc, h), dm(mc, h);
        for (int s = 0; s < 8; ++s) CHECK(nearestVertex(dmc, world({s & 1 ? 1.0 : -1.0, s & 2 ? 1.0 : -1.0, s & 4 ? 1.0 : -1.0})) <= 0.1 * h);
        // Points along the 12 edges: the median distance to the mesh.
        std::vector<double> ed, em;
        for (int axis = 0; axis < 3; ++axis)
            for (int s = 0; s < 4; ++s)
                for (int k = 1; k < 20; ++k) {
                    Vec3d l(s & 1 ? 1.0 : -1.0, s & 2 ? 1.0 : -1.0, 0.0);
                    Vec3d p;
                    p[std::size_t(axis)] = -1 + 2.0 * k / 20;
                    p[std::size_t((axis + 1) % 3)] = l.x;
                    p[std::size_t((axis + 2) % 3)] = l.y;
                    ed.push_back(dd.distance(world(p), 2 * h));
                    em.push_back(dm.distance(world(p), 2 * h));
                }
        std::sort(ed.begin(), ed.end());
        std::sort(em.begin(), em.end());
        INFO("median edge distance: dmc " << ed[ed.size() / 2] / h << " H, mc " << em[em.size() / 2] / h << " H");
        // Edge nodes follow the edges between the cells' choices (the second round): the median
        // point lies on the mesh (0.03 H without that round).
        CHECK(ed[ed.size() / 2] < 0.01 * h);
        CHECK(ed[ed.size() / 2] < 0.5 * em[em.size() / 2]);
    }
}

TEST_CASE("rotated cubes at random orientations and coarse spacings keep all their corners") {
    // About one cube in 60 had a corner whose cell holds no node that could reach it (its
    // nearest node lies outside with no neighbour inside): the polygons round it cut it off, up
    // to 0.9 H (2 of these 200 cubes; 26 of 1,600 over 8 seeds). The surface fit fans them round
    // the point their faces' planes meet at.
    std::mt19937 rng(1);
    std::uniform_real_distribution<double> angle(0, 2 * kPi), spacing(0.2, 0.45), shift(-0.1, 0.1);
    const Box3 box{{-2, -2, -2}, {2, 2, 2}};
    int kept = 0, cubes = 0;
    std::uint64_t featureCentres = 0;
    for (int trial = 0; trial < 200; ++trial) {
        const double ax = angle(rng), ay = angle(rng), az = angle(rng), cx = shift(rng), cy = shift(rng), cz = shift(rng);
        const double h = spacing(rng);
        const Rotation R = eulerRotation(ax, ay, az);
        const Vec3d c(cx, cy, cz);
        std::string f = "max(";
        for (int i = 0; i < 3; ++i) f += (i ? ",abs" : "abs") + dotWith(Vec3d(R[0][i], R[1][i], R[2][i]), c);
        f += ")-1";
        ExpressionField field(f, box);
        MeshRequest req;
        req.voxelSize = h;
        MeshReport rep;
        const Mesh m = meshField(field, req, rep);
        featureCentres += rep.fitFeatureCentres;
        INFO("trial " << trial << " h " << h);
        requireClosed(m);
        CHECK(countComponents(m) == 1);
        bool all = true;
        for (int s = 0; s < 8; ++s) all = nearestVertex(m, inFrame(R, c, {s & 1 ? 1.0 : -1.0, s & 2 ? 1.0 : -1.0, s & 4 ? 1.0 : -1.0})) <= 0.1 * h && all;
        kept += all;
        ++cubes;
    }
    INFO("feature centres " << featureCentres << ", cubes with every corner " << kept);
    CHECK(kept == cubes);
    CHECK(featureCentres > 0);
}

TEST_CASE("square pyramids lower than steep, at random orientations, keep their base corners") {
    // A base corner joins the base to two sides at less than 60 degrees when the pyramid is lower
    // than sqrt(3) half-sides: the sum of its three faces' normals then points out through the
    // base, and the probe for solid behind the corner, taken along it, found none — the corner
    // was rejected, and the mesh cut it off by up to 1.3 H (a corner farther than 0.1 H in 55 of
    // these 60 pyramids). The probe now goes in at one angle to the three faces. Left: one of the
    // 60 (trial 38) still misses a corner by 0.8 H. (Below a height of one half-side the base
    // corners' normals fall under the corner threshold: see the shallow corners' test.)
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> angle(0, 2 * kPi), spacing(0.1, 0.2), shift(-0.1, 0.1), halfSide(0.6, 0.9), slope(1.05, 1.7);
    const Box3 box{{-2, -2, -2}, {2, 2, 2}};
    int kept = 0, pyramids = 0;
    for (int trial = 0; trial < 60; ++trial) {
        const Rotation R = eulerRotation(angle(rng), angle(rng), angle(rng));
        const Vec3d c(shift(rng), shift(rng), shift(rng));
        const double h = spacing(rng), a = halfSide(rng), height = a * slope(rng), s = std::sqrt(height * height + a * a);
        const FormulaFrame frame(R, c);
        const auto& l = frame.l;
        const std::string f = "max((" + num(height) + "*abs" + l[0] + "+" + num(a) + "*" + l[2] + "-" + num(a * height) + ")/" + num(s) + ", (" +
                              num(height) + "*abs" + l[1] + "+" + num(a) + "*" + l[2] + "-" + num(a * height) + ")/" + num(s) + ", -" + l[2] + ")";
        ExpressionField field(f, box);
        MeshRequest req;
        req.voxelSize = h;
        MeshReport rep;
        const Mesh m = meshField(field, req, rep);
        INFO("trial " << trial << " h " << h << " height / half side " << height / a);
        requireClosed(m);
        CHECK(countComponents(m) == 1);
        bool all = true;
        for (int k = 0; k < 4; ++k) all = nearestVertex(m, inFrame(R, c, {k & 1 ? a : -a, k & 2 ? a : -a, 0})) <= 0.1 * h && all;
        kept += all;
        ++pyramids;
    }
    CHECK(kept >= pyramids - 1);
}

namespace {

// Meshes the solid of formula f over [-2, 2]^3 at spacing h and counts the points of `corners`
// that a vertex comes within 0.1 H of; the mesh must be closed, manifold and one piece.
std::size_t cornersKept(const std::string& f, double h, const std::vector<Vec3d>& corners) {
    ExpressionField field(f, Box3{{-2, -2, -2}, {2, 2, 2}});
    MeshRequest req;
    req.voxelSize = h;
    MeshReport rep;
    const Mesh m = meshField(field, req, rep);
    requireClosed(m);
    CHECK(countComponents(m) == 1);
    std::size_t kept = 0;
    for (const Vec3d& p : corners) kept += nearestVertex(m, p) <= 0.1 * h;
    return kept;
}

// Shapes kept whole and corners kept over a test's random shapes.
struct CornerTally {
    int whole = 0, shapes = 0;
    std::size_t kept = 0, corners = 0;
    void add(std::size_t k, std::size_t of) {
        kept += k;
        corners += of;
        whole += k == of;
        ++shapes;
    }
};

} // namespace

TEST_CASE("octahedra at random orientations keep the apexes where four faces meet") {
    // The cell holding an apex sees four planes; the corner test took three and, finding normals
    // that agree with none of them, rejected the cell as curved: 11 of 24 octahedra of a random
    // fuzz missed a vertex by up to 0.9 H, 16 of these 40. A fourth plane through the three's
    // point now belongs to the corner.
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> angle(0, 2 * kPi), spacing(0.1, 0.2), shift(-0.1, 0.1), radius(0.7, 1.4);
    int whole = 0, octahedra = 0;
    for (int trial = 0; trial < 40; ++trial) {
        const Rotation R = eulerRotation(angle(rng), angle(rng), angle(rng));
        const Vec3d c(shift(rng), shift(rng), shift(rng));
        const double h = spacing(rng), r = radius(rng);
        const FormulaFrame frame(R, c);
        const auto& l = frame.l;
        const std::string f = "(abs" + l[0] + "+abs" + l[1] + "+abs" + l[2] + "-" + num(r) + ")*" + num(1 / std::sqrt(3.0));
        std::vector<Vec3d> apexes;
        for (int k = 0; k < 6; ++k) {
            Vec3d q;
            q[std::size_t(k / 2)] = k % 2 ? r : -r;
            apexes.push_back(inFrame(R, c, q));
        }
        INFO("trial " << trial << " h " << h << " r / h " << r / h);
        const std::size_t kept = cornersKept(f, h, apexes);
        CHECK(kept >= 5);
        whole += kept == apexes.size();
        ++octahedra;
    }
    CHECK(whole >= octahedra - 1);
}

TEST_CASE("regular tetrahedra at random orientations keep their acute tips") {
    // A tetrahedron's tip is narrower than a cell near its end: the cell it pokes into sees two of
    // its faces (the third passes by less than a cell), and the cells that see all three lie a
    // cell back, where the planes meet outside them. Such a cell may now place the node nearest
    // the tip though it is a corner of a neighbour, not its own: 6 of 27 tetrahedra of a random
    // fuzz had lost a tip by up to 1 H, 5 of these 60.
    std::mt19937 rng(13);
    std::uniform_real_distribution<double> angle(0, 2 * kPi), spacing(0.1, 0.2), shift(-0.1, 0.1), inradius(0.25, 0.45);
    const double k = 1 / std::sqrt(3.0);
    const Vec3d normals[4] = {{k, k, k}, {k, -k, -k}, {-k, k, -k}, {-k, -k, k}};
    int whole = 0, tetrahedra = 0;
    for (int trial = 0; trial < 60; ++trial) {
        const Rotation R = eulerRotation(angle(rng), angle(rng), angle(rng));
        const Vec3d c(shift(rng), shift(rng), shift(rng));
        const double h = spacing(rng), d = inradius(rng);
        const FormulaFrame frame(R, c);
        const auto& l = frame.l;
        std::string f = "max(";
        std::vector<Vec3d> tips;
        for (const Vec3d& n : normals) {
            f += std::string(tips.empty() ? "" : ", ") + "(" + num(n.x) + "*" + l[0] + "+" + num(n.y) + "*" + l[1] + "+" + num(n.z) + "*" + l[2] +
                 "-" + num(d) + ")";
            tips.push_back(inFrame(R, c, n * (-3 * d))); // opposite its face
        }
        f += ")";
        INFO("trial " << trial << " h " << h << " inradius / h " << d / h);
        const std::size_t kept = cornersKept(f, h, tips);
        CHECK(kept >= 3);
        whole += kept == tips.size();
        ++tetrahedra;
    }
    CHECK(whole >= tetrahedra - 1);
}

TEST_CASE("chamfered boxes, fine prisms and low pyramids at random orientations keep their shallow corners") {
    // Where a third face meets the edge of the other two at a shallow angle, its normal falls
    // under the paper's corner threshold (|n · e| 0.7): a chamfer's corners (0.58), an octagonal
    // to 12-sided prism's rim (0.71-0.5), a pyramid's base corners below a height of one
    // half-side. They came out as edges, cut off by up to 0.6 H: 3 of these 45 shapes were whole,
    // 144 of their 720 corners kept. Now such a corner stands where the surface around it lies on
    // its three planes and another cell's edge runs through it (41 whole, 712 kept).
    std::mt19937 rng(17);
    std::uniform_real_distribution<double> angle(0, 2 * kPi), spacing(0.1, 0.2), shift(-0.1, 0.1), unit(0, 1);
    CornerTally t;
    for (int trial = 0; trial < 45; ++trial) {
        const Rotation R = eulerRotation(angle(rng), angle(rng), angle(rng));
        const Vec3d c(shift(rng), shift(rng), shift(rng));
        const double h = spacing(rng);
        const FormulaFrame frame(R, c);
        const auto& l = frame.l;
        std::string f;
        std::vector<Vec3d> local;
        if (trial % 3 == 0) { // a box of half side b, its corners cut by |x| + |y| + |z| = cut
            const double b = 0.7 + 0.3 * unit(rng), cut = b * (2.3 + 0.4 * unit(rng));
            f = "max(abs" + l[0] + "-" + num(b) + ", abs" + l[1] + "-" + num(b) + ", abs" + l[2] + "-" + num(b) + ", (abs" + l[0] + "+abs" +
                l[1] + "+abs" + l[2] + "-" + num(cut) + ")*" + num(1 / std::sqrt(3.0)) + ")";
            for (int s = 0; s < 8; ++s)
                for (int k = 0; k < 3; ++k) {
                    Vec3d q(b, b, b);
                    q[std::size_t(k)] = cut - 2 * b;
                    local.push_back({s & 1 ? q.x : -q.x, s & 2 ? q.y : -q.y, s & 4 ? q.z : -q.z});
                }
        } else if (trial % 3 == 1) { // a prism of m sides, apothem r, half height t
            const int m = 8 + trial % 5;
            const double r = 0.6 + 0.4 * unit(rng), t = 0.5 + 0.4 * unit(rng);
            f = "max(abs" + l[2] + "-" + num(t);
            for (int k = 0; k < m; ++k)
                f += ", " + num(std::cos(2 * kPi * k / m)) + "*" + l[0] + "+" + num(std::sin(2 * kPi * k / m)) + "*" + l[1] + "-" + num(r);
            f += ")";
            for (int k = 0; k < m; ++k) {
                const double a = 2 * kPi * (k + 0.5) / m, rc = r / std::cos(kPi / m);
                for (double z : {-t, t}) local.push_back({rc * std::cos(a), rc * std::sin(a), z});
            }
        } else { // a square pyramid of half side a, lower than a
            const double a = 0.7 + 0.3 * unit(rng), height = a * (0.6 + 0.35 * unit(rng)), s = std::sqrt(height * height + a * a);
            f = "max((" + num(height) + "*abs" + l[0] + "+" + num(a) + "*" + l[2] + "-" + num(a * height) + ")/" + num(s) + ", (" + num(height) +
                "*abs" + l[1] + "+" + num(a) + "*" + l[2] + "-" + num(a * height) + ")/" + num(s) + ", -" + l[2] + ")";
            for (int k = 0; k < 4; ++k) local.push_back({k & 1 ? a : -a, k & 2 ? a : -a, 0});
        }
        std::vector<Vec3d> points;
        for (const Vec3d& q : local) points.push_back(inFrame(R, c, q));
        INFO("trial " << trial << " h " << h);
        t.add(cornersKept(f, h, points), points.size());
    }
    INFO(t.whole << " of " << t.shapes << " shapes whole, " << t.kept << " of " << t.corners << " corners");
    CHECK(t.whole >= t.shapes - 5);
    CHECK(t.kept * 50 >= t.corners * 49);
}

TEST_CASE("rotated boxes and chamfered boxes on a grid five times finer than the lattice keep their corners") {
    // A grid's gradient blends the faces of a kink within a voxel and a half of it: in a corner's
    // cell at five voxels a cell most crossings' normals were blends, and the corner was cut off
    // or read as an edge: 2 of these 16 shapes were whole, 179 of their 256 corners kept. The
    // crossings now take the normals of the faces sampled around the cell (sampled_planes.h): 7
    // whole, 244 kept (a box still loses a corner now and then, by up to 0.8 H).
    std::mt19937 rng(23);
    std::uniform_real_distribution<double> angle(0, 2 * kPi), spacing(0.1, 0.16), shift(-0.1, 0.1), unit(0, 1);
    CornerTally t;
    for (int trial = 0; trial < 16; ++trial) {
        const Rotation R = eulerRotation(angle(rng), angle(rng), angle(rng));
        const Vec3d c(shift(rng), shift(rng), shift(rng)), b(0.5 + 0.3 * unit(rng), 0.5 + 0.3 * unit(rng), 0.5 + 0.3 * unit(rng));
        // The cut's triangles have sides of 2.5 H or more (smaller ones are beyond the probes of
        // a shallow corner, as on formulas) and leave every edge of the box a part.
        const double least = std::min({b.x, b.y, b.z}), h = spacing(rng);
        const double cut = b.x + b.y + b.z - (1.8 * h + (0.7 * least - 1.8 * h) * unit(rng));
        const bool chamfered = trial % 2 == 1; // corners cut by |x| + |y| + |z| = cut: three each
        auto local = [&](const Vec3d& p) {
            const Vec3d d = p - c;
            return Vec3d(R[0][0] * d.x + R[1][0] * d.y + R[2][0] * d.z, R[0][1] * d.x + R[1][1] * d.y + R[2][1] * d.z,
                         R[0][2] * d.x + R[1][2] * d.y + R[2][2] * d.z);
        };
        const auto grid = test::makeLevelSetFromDistance(
            [&](const Vec3d& p) {
                const Vec3d l = local(p), a(std::fabs(l.x), std::fabs(l.y), std::fabs(l.z));
                const Vec3d q = a - b, out(std::max(q.x, 0.0), std::max(q.y, 0.0), std::max(q.z, 0.0));
                const double box = length(out) + std::min(std::max({q.x, q.y, q.z}), 0.0);
                // (Within the band the chamfer's plane distance is exact enough: the test reads corners.)
                return chamfered ? std::max(box, (a.x + a.y + a.z - cut) / std::sqrt(3.0)) : box;
            },
            Box3{{-1.4, -1.4, -1.4}, {1.4, 1.4, 1.4}}, h / 5);
        const GridField field(grid, "box");
        MeshRequest req;
        req.voxelSize = h;
        MeshReport rep;
        const Mesh m = meshField(field, req, rep);
        INFO("trial " << trial << " h " << h);
        requireClosed(m);
        CHECK(countComponents(m) == 1);
        std::vector<Vec3d> points;
        for (int s = 0; s < 8; ++s) {
            const Vec3d sign(s & 1 ? 1 : -1, s & 2 ? 1 : -1, s & 4 ? 1 : -1);
            if (!chamfered) {
                points.push_back(inFrame(R, c, {sign.x * b.x, sign.y * b.y, sign.z * b.z}));
                continue;
            }
            for (int k = 0; k < 3; ++k) { // where the cut meets the box's three edges at the corner
                Vec3d q = b;
                q[std::size_t(k)] = cut - (b.x + b.y + b.z - b[std::size_t(k)]);
                points.push_back(inFrame(R, c, {sign.x * q.x, sign.y * q.y, sign.z * q.z}));
            }
        }
        std::size_t k = 0;
        for (const Vec3d& p : points) k += nearestVertex(m, p) <= 0.1 * h;
        t.add(k, points.size());
    }
    INFO(t.whole << " of " << t.shapes << " shapes whole, " << t.kept << " of " << t.corners << " corners");
    CHECK(t.whole >= t.shapes - 10);
    CHECK(t.kept * 50 >= t.corners * 47);
}

TEST_CASE("a blob curving about a cell gets few shallow corners") {
    // A sphere with bumps whose tops curve about a cell: three tangent planes of a cell there meet
    // at shallow angles near the surface, as a chamfer's faces do, and another cell's tangent
    // line often runs through the point. What tells them apart is farther out: the faces between
    // the lines where the planes meet leave the surface a cell and a half from the point (6
    // corners in 2,468 cells with surface, as before shallow corners; with the lines probed a cell
    // out and the faces not, 51).
    const std::string f = "sqrt(x^2+y^2+z^2)+0.2*sin(7*x)*sin(7*y)*sin(7*z)-1";
    ExpressionField field(f, Box3{{-2, -2, -2}, {2, 2, 2}});
    MeshRequest req;
    req.voxelSize = 0.1;
    MeshReport rep;
    const Mesh m = meshField(field, req, rep);
    requireClosed(m);
    INFO(rep.nodesOnCorners << " nodes on corners, " << rep.nodesOnEdges << " on edges, " << rep.cellsWithSurface << " cells with surface");
    CHECK(rep.nodesOnCorners * 200 <= rep.cellsWithSurface);
}

TEST_CASE("a tetrahedral cavity keeps a concave tip whose node is a neighbouring cell's corner") {
    // One cavity of a random fuzz (a regular tetrahedron cut from a rotated box): the cells that
    // see a tip's three faces lie a cell back from it, and the node nearest the tip is inside the
    // solid. A node from outside the proposing cell takes its side from the lattice, not from the
    // cell's case (which knows only the cell's own corners): taken as outside, it was placed on
    // the wrong side and the tip cut off by 0.5 H. (Other cavities still lose a tip: see the
    // closing note of issue 4.)
    const Vec3d c(-0.040856223, 0.018547644, -0.001055622);
    const Vec3d boxAxes[3] = {{-0.640669908, 0.303850370, 0.705136172}, {0.767568656, 0.276781372, 0.578126657},
                              {-0.019504558, 0.911628776, -0.410551516}};
    const Vec3d tetraAxes[3] = {{0.416180824, 0.907800853, -0.051876137}, {0.287546409, -0.077272493, 0.954644449},
                                {0.862618447, -0.412221510, -0.293194205}};
    const double d = 0.106911619, h = 0.050698, k = 1 / std::sqrt(3.0);
    const Vec3d normals[4] = {{k, k, k}, {k, -k, -k}, {-k, k, -k}, {-k, -k, k}};
    std::string box = "max(", tetra = "max(";
    for (int i = 0; i < 3; ++i) box += std::string(i ? ", " : "") + "abs" + dotWith(boxAxes[i], c) + "-0.55";
    std::vector<Vec3d> tips;
    for (const Vec3d& n : normals) {
        tetra += std::string(tips.empty() ? "" : ", ") + "(" + num(n.x) + "*" + dotWith(tetraAxes[0], c) + "+" + num(n.y) + "*" +
                 dotWith(tetraAxes[1], c) + "+" + num(n.z) + "*" + dotWith(tetraAxes[2], c) + "-" + num(d) + ")";
        tips.push_back(c + (tetraAxes[0] * n.x + tetraAxes[1] * n.y + tetraAxes[2] * n.z) * (-3 * d));
    }
    ExpressionField field("max(" + box + "), -" + tetra + "))", Box3{{-1, -1, -1}, {1, 1, 1}});
    MeshRequest req;
    req.voxelSize = h;
    MeshReport rep;
    const Mesh m = meshField(field, req, rep);
    requireClosed(m);
    CHECK(countComponents(m) == 2); // the box's faces and the cavity's
    for (const Vec3d& tip : tips) CHECK(nearestVertex(m, tip) <= 0.1 * h);
}

namespace {

// The cube [-1, 1]^3 minus a cube of side 2 * notch at its corner (1, 1, 1), rotated by R and
// moved by c: three concave edges meet at the concave corner (1 - notch) * (1, 1, 1).
struct NotchedCube {
    Rotation R;
    Vec3d c;
    double notch;

    std::string formula() const {
        const FormulaFrame frame(R, c);
        const auto& l = frame.l;
        return "max(max(abs" + l[0] + ",abs" + l[1] + ",abs" + l[2] + ")-1, " + num(notch) + "-max(abs(" + l[0] + "-1),abs(" + l[1] +
               "-1),abs(" + l[2] + "-1)))";
    }
    Vec3d world(const Vec3d& q) const { return inFrame(R, c, q); }
    Vec3d concaveCorner() const { return world(Vec3d(1, 1, 1) * (1 - notch)); }
    // Points along the three concave edges (19 each, ends left out).
    std::vector<Vec3d> concaveEdgePoints() const {
        std::vector<Vec3d> points;
        const double k = 1 - notch;
        for (int axis = 0; axis < 3; ++axis)
            for (int s = 1; s < 20; ++s) {
                Vec3d q(k, k, k);
                q[std::size_t(axis)] = k + notch * s / 20;
                points.push_back(world(q));
            }
        return points;
    }
};

const Box3 kNotchBox{{-2, -2, -2}, {2, 2, 2}};

} // namespace

TEST_CASE("a notch cut into a rotated cube keeps its concave corner and edges at random orientations and spacings") {
    // A notch of 0.5 is 1.25 to 2.5 cells deep: cells there hold two features.
    const double notch = GENERATE(0.8, 0.5);
    std::mt19937 rng(notch > 0.6 ? 4242 : 4343);
    std::uniform_real_distribution<double> angle(0, 2 * kPi), spacing(0.2, 0.4), shift(-0.1, 0.1);
    const int trials = 16;
    std::vector<double> dmcEdge, mcEdge;
    int cornersKept = 0;
    for (int trial = 0; trial < trials; ++trial) {
        const double ax = angle(rng), ay = angle(rng), az = angle(rng), cx = shift(rng), cy = shift(rng), cz = shift(rng);
        const NotchedCube shape{eulerRotation(ax, ay, az), Vec3d(cx, cy, cz), notch};
        const double h = spacing(rng);
        const Mesh dmc = meshFormula(shape.formula(), kNotchBox, h);
        const Mesh mc = meshFormula(shape.formula(), kNotchBox, h, MeshMethod::MarchingCubes);
        INFO("notch " << notch << " trial " << trial << " h " << h);
        requireClosed(dmc);
        CHECK(countComponents(dmc) == 1);
        cornersKept += nearestVertex(dmc, shape.concaveCorner()) <= 0.1 * h;
        MeshDistance dd(dmc, h), dm(mc, h);
        for (const Vec3d& p : shape.concaveEdgePoints()) {
            dmcEdge.push_back(dd.distance(p, 2 * h) / h);
            mcEdge.push_back(dm.distance(p, 2 * h) / h);
        }
    }
    std::sort(dmcEdge.begin(), dmcEdge.end());
    std::sort(mcEdge.begin(), mcEdge.end());
    const double dmcMedian = dmcEdge[dmcEdge.size() / 2], mcMedian = mcEdge[mcEdge.size() / 2];
    const double dmcP75 = dmcEdge[dmcEdge.size() * 3 / 4];
    INFO("notch " << notch << ", concave edges' distance to the mesh in H: dmc median " << dmcMedian << " p75 " << dmcP75
                  << ", mc median " << mcMedian << "; concave corners kept " << cornersKept << " of " << trials);
    CHECK(dmcMedian < 0.02);
    // (0.143 H before moves into a crack or notch could hide a rim where it meets the outside
    // nearby, 0.152 after; over 40 other notches per depth the mean of the medians fell, 0.056 ->
    // 0.051 H at 0.5, and the mean of the maxima no more than 0.01 H rose at any depth; 0.165
    // once the sharp pass no longer flips a node whose neighbours the thin search took across,
    // which had made tunnels under crack rims and fin roots.)
    CHECK(dmcP75 < 0.17);
    CHECK(dmcMedian < 0.2 * mcMedian);
    CHECK(cornersKept >= trials - 1);
}

TEST_CASE("notched cubes under two cells deep come out in one piece without a handle") {
    // Where the notch's concave corner and the rim's corners lie a cell or two apart, the sharp
    // pass flips nodes onto tips of both sides, and the bridges that join them can pass round
    // each other: 7 of 120 random notched boxes had a handle (marching cubes none). Now a group
    // of flips that changes the inside's topology is undone, one side's flips first.
    std::mt19937 rng(6060);
    std::uniform_real_distribution<double> angle(0, 2 * kPi), depth(0.2, 0.9), spacing(0.18, 0.55), shift(-0.1, 0.1);
    int cornersKept = 0;
    const int trials = 40;
    for (int trial = 0; trial < trials; ++trial) {
        const double ax = angle(rng), ay = angle(rng), az = angle(rng), cx = shift(rng), cy = shift(rng), cz = shift(rng);
        const NotchedCube shape{eulerRotation(ax, ay, az), Vec3d(cx, cy, cz), depth(rng)};
        const double h = spacing(rng);
        INFO("trial " << trial << ": notch " << shape.notch << " h " << h);
        const Mesh dmc = meshFormula(shape.formula(), kNotchBox, h);
        requireClosed(dmc);
        CHECK(piecesWithoutHandles(dmc, 1));
        cornersKept += nearestVertex(dmc, shape.concaveCorner()) <= 0.1 * h;
    }
    // Undoing flips must not cost the corners they were for: 20 of these 40 kept within 0.1 H
    // (21 before; the others are notches under a cell or so, rounded as marching cubes rounds them).
    CHECK(cornersKept >= 19);
}

namespace {

// The three coordinates of a box rotated by the rows of A and centred at c, as formula text.
std::array<std::string, 3> boxAxes(const std::array<Vec3d, 3>& A, const Vec3d& c) {
    std::array<std::string, 3> l;
    for (int i = 0; i < 3; ++i) l[std::size_t(i)] = test::dotWith(A[std::size_t(i)], c);
    return l;
}

// A disc of radius 0.7 and the given thickness across the third axis of a frame rotated by the
// rows of `axes` and centred at `centre`, with a round hole of the given radius through its middle.
struct HoledDisc {
    std::array<Vec3d, 3> axes;
    Vec3d centre;
    double thickness, radius, h;

    std::string formula() const {
        const auto l = boxAxes(axes, centre);
        const std::string radial = "sqrt(" + l[0] + "^2+" + l[1] + "^2)";
        return "max(abs" + l[2] + "-" + num(thickness / 2) + ", " + num(radius) + "-" + radial + ", " + radial + "-0.7)";
    }
};

// A box of half-size 0.55 rotated by the rows of `axes`, centred at `centre`, with a hole through
// it along its third axis of the given size (a square hole's wall, a round hole's radius),
// meshed at spacing h.
struct HoledBox {
    std::array<Vec3d, 3> axes;
    Vec3d centre;
    double size, h;
};

// A box of half-size 0.55 with a round hole through it, as formula text.
std::string roundHoleBox(const HoledBox& k) {
    const auto l = boxAxes(k.axes, k.centre);
    return "max(max(abs" + l[0] + ",abs" + l[1] + ",abs" + l[2] + ")-0.55, " + num(k.size) + "-sqrt(" + l[0] + "^2+" + l[1] + "^2))";
}

// One closed piece with one hole through it.
void requireOnePieceOfGenusOne(const Mesh& m) {
    requireClosed(m);
    CHECK(countComponents(m) == 1);
    CHECK(eulerCharacteristic(m) == 0);
}

// A box of half-size 0.55 with a square hole through it along its third axis, walls `wall` thick.
std::string squareHoleBox(const std::array<Vec3d, 3>& A, const Vec3d& c, double wall) {
    const auto l = boxAxes(A, c);
    return "max(max(abs" + l[0] + ",abs" + l[1] + ",abs" + l[2] + ")-0.55, " + num(0.55 - wall) + "-max(abs" + l[0] + ",abs" + l[1] + "))";
}

} // namespace

TEST_CASE("where the thin search's moves to both sides cross, the shape keeps its genus") {
    // Found at random (box half-size 0.55, rotated by the rows of A, centred at c). Moves into
    // the material's tip at a hole's rim and out of it into the hole's concave edge, each right
    // alone, bridged over each other: a handle; with one side's moves undone, none.
    {
        // A box with a square hole through it, walls 0.267 (3.5 cells): one piece of genus 1.
        const std::string frame = squareHoleBox({Vec3d(-0.6805536267888344, -0.6074846237755704, -0.40964520373222685),
                                                 Vec3d(0.43028719030376533, -0.7838903000886619, 0.4476258831741067),
                                                 Vec3d(-0.593042742915766, 0.12836833450333998, 0.7948722386470568)},
                                                Vec3d(-0.02578739374998982, -0.03202275585683221, -0.02500339191098431), 0.26728706051800954);
        MeshReport rep;
        ExpressionField f(frame, kBox);
        MeshRequest req;
        req.voxelSize = 0.07581949249887222;
        const Mesh m = meshField(f, req, rep);
        requireClosed(m);
        CHECK(countComponents(m) == 1);
        CHECK(eulerCharacteristic(m) == 0);
        CHECK(rep.thinCrossedUndone > 0);
    }
    {
        // A box notched at a corner by 0.22 of its half-size (1 cell): one piece, no handle.
        const auto l = boxAxes({Vec3d(-0.32758392162301697, -0.5583586910458409, -0.7621839321500159),
                                Vec3d(-0.9262580021109379, 0.03066100978233971, 0.375640807161018),
                                Vec3d(-0.18637298039023537, 0.8290328549657741, -0.5272282594548195)},
                               Vec3d(-0.03281732453645733, 0.028037162822652464, 0.008084530023079496));
        const std::string notched = "max(max(abs" + l[0] + ",abs" + l[1] + ",abs" + l[2] + ")-0.55, " + num(0.21933541101902126 * 0.55) +
                                    "-max(abs(" + l[0] + "-0.55),abs(" + l[1] + "-0.55),abs(" + l[2] + "-0.55)))";
        const Mesh m = meshFormula(notched, kBox, 0.13200461355812582);
        requireClosed(m);
        CHECK(piecesWithoutHandles(m, 1));
    }
}

TEST_CASE("a node moved into a hole's concave edge near its mouth makes no tunnel through the rim") {
    // Found at random: marching cubes joins an outside node to the outside node across each face
    // whose other two corners are inside. A node moved into the hole's concave edge a cell or so
    // from the mouth was joined so to a node beyond the mouth's rim: the two lie in one piece of
    // the outside round the rim, but the lattice joined them already, and the face's own inside
    // parted them: a handle through the rim. A hole under a cell wide is joined to its mouth by
    // just such a face, and keeps it.
    const HoledBox cases[] = {
        // Walls 2 cells, hole 3.5 cells wide: was genus 2.
        {{Vec3d(0.641764912971112, 0.22009890985510921, -0.7346388679887373), Vec3d(0.7665735920813693, -0.15609972756550014, 0.622894696539827),
          Vec3d(0.022421516510875664, -0.9629067166317666, -0.26890134001671206)},
         Vec3d(0.0377176092235426, -0.03965972907903636, -0.039704836588201044),
         0.2948472014568402,
         0.1446202996918451},
        // A hole 0.7 cells wide: was genus 2.
        {{Vec3d(-0.7959338302328137, -0.3123180393588211, 0.5186007907649045), Vec3d(-0.6010670621398729, 0.30557873887591, -0.7384714084902344),
          Vec3d(0.07216456680022784, -0.8994882304055292, -0.4309445424419077)},
         Vec3d(-0.04022681216203777, 0.03310268136396309, -0.03703999803464693),
         0.46975784998014536,
         0.23251505699948616},
        // A hole 0.53 cells wide, open only through such joins at its mouths.
        {{Vec3d(0.49595667646276587, 0.8680268328784204, -0.023587973102115325), Vec3d(-0.7432088016641357, 0.41027894357166794, -0.5284996363202868),
          Vec3d(-0.4490742168071628, 0.27964371236409896, 0.848605763552345)},
         Vec3d(0.048815849860603264, -0.007898641256973274, -0.038444181940772676),
         0.4881056146112842,
         0.23275231834863513},
    };
    for (const HoledBox& k : cases) {
        INFO("walls " << k.size << ", h " << k.h);
        requireOnePieceOfGenusOne(meshFormula(squareHoleBox(k.axes, k.centre, k.size), kBox, k.h));
    }
}

TEST_CASE("holes under a cell wide through plates a few cells thick stay open") {
    // Found at random, where putting back a node moved out of the inside with a face that tunnels
    // closed a hole the shape has: a plate 2.6 cells thick with a hole 0.51 cells wide, where the
    // node's return parted the outside in the hole from the outside beyond; and one 1.7 cells
    // thick with a hole 0.83 cells wide, where its return made a handle instead of taking one.
    const HoledDisc cases[] = {
        {{Vec3d(-0.7251141575417079, -0.4807828390417311, 0.4930084382802712), Vec3d(-0.15422685084716173, 0.8111239627742063, 0.5641737281115058),
          Vec3d(-0.6711360048532238, 0.33305521868969556, -0.6623070921356743)},
         Vec3d(-0.04565127096434726, 0.020338208860383594, 0.048318771730967394),
         0.2862606395060741,
         0.027627685749334083,
         0.10856557036048009},
        {{Vec3d(-0.8526293110058276, -0.23060959848862864, 0.46887361953797424), Vec3d(-0.2385023782423418, -0.6266422162273749, -0.741913841638226),
          Vec3d(0.46490845721117446, -0.7444049609765893, 0.47929258338406205)},
         Vec3d(0.0071968227578637495, 0.005137680681427462, 0.002562721380171676),
         0.14962409788229467,
         0.03607352896328645,
         0.08717193478185631},
    };
    for (const HoledDisc& k : cases) {
        INFO("thickness " << k.thickness << ", hole radius " << k.radius << ", h " << k.h);
        requireOnePieceOfGenusOne(meshFormula(k.formula(), kBox, k.h));
    }
}

TEST_CASE("a hole about a cell wide through a plate two cells thick, open in marching cubes, is not closed by bridging") {
    // Found at random: the one node in the hole was bridged into the plate, to join two of the
    // plate's nodes across a face beside the hole that the lattice joins round the hole anyway.
    const HoledDisc cases[] = {
        {{Vec3d(0.2848428001721588, -0.17280531891621906, 0.942869503666519), Vec3d(0.5646785480047873, 0.8250835359978933, -0.01937255916027092),
          Vec3d(-0.7745984228058364, 0.5379363162861167, 0.3325985613427008)},
         Vec3d(-0.02761030944273061, 0.015515333951485619, 0.034978385967802644),
         0.42301896099723585,
         0.11433125742316008,
         0.20704699868169973},
        {{Vec3d(0.9319855782760335, 0.3178934365900211, -0.17420288418529045), Vec3d(0.33457483515336295, -0.9393091863217524, 0.07588103961905288),
          Vec3d(-0.1395082849424633, -0.12900393584908354, -0.9817817593375113)},
         Vec3d(0.046397058881589445, -0.029667743544816938, -0.04638294350597847),
         0.47452921272410303,
         0.11260071555795574,
         0.20543075370551256},
    };
    for (const HoledDisc& k : cases) {
        INFO("thickness " << k.thickness / k.h << " H, hole " << 2 * k.radius / k.h << " H wide");
        REQUIRE(eulerCharacteristic(meshFormula(k.formula(), kBox, k.h, MeshMethod::MarchingCubes)) == 0);
        requireOnePieceOfGenusOne(meshFormula(k.formula(), kBox, k.h));
    }
}

TEST_CASE("a hole under a cell wide slantwise through a box is kept through the box's faces") {
    // Found at random (boxes of half-size 0.55 with a round hole 0.3-1 H wide; marching cubes
    // loses nearly all): the node in the hole nearest a face could reach the node beyond the face
    // only along a bent path, and the hole ended a cell short of the face (the first two); the
    // node in a hole's mouth was bridged into the box, to join two of its nodes across a face
    // beside the mouth (the third).
    const HoledBox cases[] = {
        {{Vec3d(-0.2702670687420372, -0.7692544318733809, 0.5789674693769491), Vec3d(0.03255207503496038, 0.5937015203390059, 0.8040266582384388),
          Vec3d(-0.9622349369901848, 0.23614852061851832, -0.13541714162239593)},
         Vec3d(0.03941087419840049, -0.005522197535108929, 0.00352428245061924),
         0.0264987159806586,
         0.11036313824741087},
        {{Vec3d(-0.5167544316624206, 0.014919999573256293, 0.8560036512597256), Vec3d(-0.842379350008842, 0.1696424809982212, -0.5114865191962038),
          Vec3d(-0.1528459617913695, -0.9853927248835875, -0.07509520431138661)},
         Vec3d(0.020490182423895456, -0.005919299748582255, 0.043237660991822455),
         0.03310174453909406,
         0.09280516801540628},
        {{Vec3d(0.17279871845488193, -0.2736901735789053, 0.9461682153754157), Vec3d(-0.4990154897884506, -0.852533077107331, -0.15546991152341583),
          Vec3d(0.8491902871862956, -0.4452875939482872, -0.2838922591833073)},
         Vec3d(-0.04929532716083797, -0.046803254572271094, -0.018473190728800506),
         0.04365395263143357,
         0.1284053001995713},
    };
    for (const HoledBox& k : cases) {
        INFO("hole " << 2 * k.size / k.h << " H wide, h " << k.h);
        requireOnePieceOfGenusOne(meshFormula(roundHoleBox(k), kBox, k.h));
    }
}

TEST_CASE("random boxes with a hole under a cell wide through them keep it") {
    // Rotated boxes with a round hole 0.3-1 H wide at random orientations, offsets and spacings:
    // marching cubes loses nearly every hole. Without the bent pierced-face path and the straight
    // bridge's parting test, 12 of these 100 came out with the hole closed or an extra handle; 1
    // with them.
    std::mt19937 rng(6767);
    std::uniform_real_distribution<double> angle(0, 2 * kPi), shift(-0.05, 0.05), spacing(0.08, 0.25), width(0.3, 1.0);
    const int trials = 100;
    int kept = 0;
    for (int trial = 0; trial < trials; ++trial) {
        const Rotation R = eulerRotation(angle(rng), angle(rng), angle(rng));
        HoledBox k{{Vec3d(R[0][0], R[1][0], R[2][0]), Vec3d(R[0][1], R[1][1], R[2][1]), Vec3d(R[0][2], R[1][2], R[2][2])},
                   Vec3d(shift(rng), shift(rng), shift(rng)),
                   0,
                   spacing(rng)};
        k.size = width(rng) * k.h / 2;
        INFO("trial " << trial << ": hole " << 2 * k.size / k.h << " H wide, h " << k.h);
        const Mesh m = meshFormula(roundHoleBox(k), kBox, k.h);
        requireClosed(m);
        kept += countComponents(m) == 1 && eulerCharacteristic(m) == 0;
    }
    WARN("kept " << kept << " of " << trials);
    CHECK(kept >= 97);
}

TEST_CASE("a concave corner 1.4 cells below a notch's rim is kept, not cut off by bridging") {
    // Found at random: the one outside node beside the corner node was bridged into the solid
    // (to join a node flipped onto the rim), the corner node lost its last crossing, and the
    // mesh cut the corner off by 1.25 H.
    const NotchedCube shape{eulerRotation(5.0437253942230225, 0.58306749116262524, 3.2555524615610167),
                            Vec3d(-0.045390004523142485, 0.065920672942187841, 0.06582938217998513), 0.5};
    const double h = 0.36625506137942365;
    const Mesh dmc = meshFormula(shape.formula(), kNotchBox, h);
    requireClosed(dmc);
    CHECK(countComponents(dmc) == 1);
    CHECK(nearestVertex(dmc, shape.concaveCorner()) <= 0.1 * h);
}

TEST_CASE("a notch's node the thin search moved into a wall's wedge is not left as a bubble when the notch's corner flips") {
    // Found at random (notches about a cell deep): the thin search moved the notch's outside node
    // into the wedge between a notch wall and the face it is cut into, where it hung on one inside
    // node; the sharp pass flipped the notch's corner node out (or bridged that node out to join
    // it), and the node was left inside alone — a bubble of 8 triangles beside the notch, flat on
    // its wall or around its rim.
    struct Case {
        double ax, ay, az, cx, cy, cz, notch, h;
    };
    const Case c = GENERATE(Case{0.96345410978425183, 2.2739127200773916, 2.6916060620614668, 0.056391692539094679, 0.083281974636230244,
                                 0.087438065191793424, 0.35, 0.3232657885749689},
                            Case{5.9177360730724944, 2.2324808543895673, 0.40254688876266936, 0.05431899912205429, 0.052584013447027067,
                                 -0.024039341955998134, 0.5, 0.26027210012887048});
    const NotchedCube shape{eulerRotation(c.ax, c.ay, c.az), Vec3d(c.cx, c.cy, c.cz), c.notch};
    ExpressionField f(shape.formula(), kNotchBox);
    MeshRequest req;
    req.voxelSize = c.h;
    MeshReport rep;
    const Mesh dmc = meshField(f, req, rep);
    INFO("notch " << c.notch << " h " << c.h << ": " << rep.nodesFlipped << " nodes flipped");
    requireClosed(dmc);
    CHECK(rep.nodesFlipped > 0);
    CHECK(countComponents(dmc) == 1);
}

TEST_CASE("a notch about a cell deep is not filled flush with the face: its one outside node keeps what its edges show") {
    // Found at random (notches 0.7-1.3 cells deep), each with one node inside the notch. The sharp
    // pass placed that node on the notch's rim (a corner there, or where a concave edge meets the
    // face), which took the crossings on its edges to the notch's far walls with it; or it bridged
    // that node into the solid, to join a node flipped onto the rim. Either way the mesh ran flush
    // over the notch: no vertex nearer its concave corner than the notch is deep.
    struct Case {
        double ax, ay, az, cx, cy, cz, notch, h;
    };
    const Case c = GENERATE(Case{0.22188617899870569, 0.10433864832106152, 4.7960855773015139, 0.097909546871289277,
                                 -0.091165942032968211, -0.072111633266245562, 0.39966163060270066, 0.33683549034438287},
                            Case{3.5806453778803031, 1.5891083479567809, 6.0669518293158857, -0.03949589567811676,
                                 -0.092393818341086925, 0.03516126262695568, 0.33824703145608059, 0.26141860659464816},
                            Case{2.8684064472329638, 2.3968698837056155, 2.7960337472675709, -0.018209795369945811,
                                 0.021405013937063871, -0.066648736958443089, 0.20248334457764694, 0.26422531144620548});
    const NotchedCube shape{eulerRotation(c.ax, c.ay, c.az), Vec3d(c.cx, c.cy, c.cz), c.notch};
    const Mesh dmc = meshFormula(shape.formula(), kNotchBox, c.h);
    const Mesh mc = meshFormula(shape.formula(), kNotchBox, c.h, MeshMethod::MarchingCubes);
    // The notch's three walls, 12 x 12 points each.
    const double k = 1 - c.notch;
    std::vector<Vec3d> walls;
    for (int axis = 0; axis < 3; ++axis)
        for (int a = 0; a < 12; ++a)
            for (int b = 0; b < 12; ++b) {
                Vec3d q(k, k, k);
                q[std::size_t((axis + 1) % 3)] += c.notch * (a + 0.5) / 12;
                q[std::size_t((axis + 2) % 3)] += c.notch * (b + 0.5) / 12;
                walls.push_back(shape.world(q));
            }
    auto meanDistance = [&](const Mesh& m) {
        const MeshDistance d(m, c.h);
        double sum = 0;
        for (const Vec3d& p : walls) sum += d.distance(p, 3 * c.h);
        return sum / double(walls.size()) / c.h;
    };
    const double corner = nearestVertex(dmc, shape.concaveCorner()) / c.h, dmcWalls = meanDistance(dmc), mcWalls = meanDistance(mc);
    INFO("notch " << c.notch / c.h << " H deep: nearest vertex to its concave corner " << corner << " H; walls' mean distance to the mesh dmc "
                  << dmcWalls << " H, mc " << mcWalls << " H");
    requireClosed(dmc);
    CHECK(countComponents(dmc) == 1);
    CHECK(corner < 0.6);
    CHECK(dmcWalls <= mcWalls + 0.01);
}

TEST_CASE("a part within a cell of the domain's edge gives a closed mesh: nodes on the lattice's outer faces keep their side") {
    // The cells beyond the lattice's outer nodes are not meshed, so a node there moved into a part
    // (by the thin search, bridging or the hidden-edge phase) left the mesh open along the
    // domain's edge. (A node flipped onto a tip there sits on the surface: nothing beyond it.)
    SECTION("a ball between the outer layer of nodes and the next, with the sharp pass off and on") {
        const bool sharp = GENERATE(false, true);
        for (double z : {-0.75, -0.78, -0.7}) {
            INFO("ball at z " << z << (sharp ? ", sharp" : ""));
            const Mesh m = meshFormula("sqrt(x^2+y^2+(z-" + num(z) + ")^2)-0.2", Box3{{-1, -1, -1}, {1, 1, 1}}, 0.5, MeshMethod::Dmc,
                                       true, sharp);
            requireClosed(m);
            CHECK(countComponents(m) == 1);
        }
    }
    SECTION("an L of bars 1.2 cells thick reaching within half a cell of the edge (found at random)") {
        const FormulaFrame frame(eulerRotation(4.2369427054564239, 5.7073817674909995, 4.4982310048173471),
                                 Vec3d(0.057808851298658384, -0.082284428762407436, -0.013696355069961141));
        const Mesh m = meshFormula("min(" + frame.box(0, 0, 0, 1, 0.3, 0.3) + "," + frame.box(-0.7, 0.6, 0, 0.3, 0.9, 0.3) + ")", kNotchBox,
                                   0.57003315363455254);
        requireClosed(m);
        CHECK(countComponents(m) == 1);
    }
}

TEST_CASE("a node moved into a step's edge whose surface the nodes placed around it close off goes back: no bubble") {
    // Found at random (a step and a slot cut into rotated boxes): the thin search moved a node into
    // the solid along a convex edge, the sharp pass then placed each of its neighbours on that side
    // on the faces, and the crossings around it sat on those nodes: its surface was a piece of its
    // own touching the rest at their points.
    struct Case {
        double ax, ay, az, cx, cy, cz, h;
        bool slot;
    };
    const Case c = GENERATE(Case{4.3883037863160519, 5.6748380467129875, 3.9770244475076781, -0.098968169988161755, 0.014471298372265197,
                                 -0.027700731676863821, 0.18270242933351039, false},
                            Case{4.6264013414751393, 5.8264106620487457, 4.2991611848861542, -0.015158858040298873, 0.01327027506360361,
                                 -0.057004155565688469, 0.30496088914308928, true});
    const FormulaFrame frame(eulerRotation(c.ax, c.ay, c.az), Vec3d(c.cx, c.cy, c.cz));
    // A box 2 x 2 x 1 with a step (or a slot) cut into its top.
    const std::string cut = c.slot ? frame.box(0, 0, 0.5, 0.25, 1.2, 0.3) : frame.box(0.5, 0, 0.5, 0.5, 1.2, 0.3);
    const Mesh m = meshFormula("max(" + frame.box(0, 0, 0, 1, 1, 0.5) + ",-(" + cut + "))", kNotchBox, c.h);
    INFO((c.slot ? "slot" : "step") << " h " << c.h);
    requireClosed(m);
    CHECK(countComponents(m) == 1);
}

TEST_CASE("random rotated shapes with sharp convex and concave edges come out closed, in one piece, on the surface") {
    // Seven shapes, 40 random orientations, offsets and spacings each (bars and plates 0.6-1 thick,
    // spacing 0.25-0.6): the sweep that found the open meshes at the domain's edge (two of the L's)
    // and the bubbles beside a step's edge.
    const std::string shape = GENERATE(as<std::string>(), "L", "step", "slot", "cross", "cylinder", "lens", "hole");
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> u(0, 1);
    int open = 0, pieces = 0;
    double farthest = 0;
    for (int trial = 0; trial < 40; ++trial) {
        const double ax = u(rng) * 2 * kPi, ay = u(rng) * 2 * kPi, az = u(rng) * 2 * kPi;
        const double cx = (u(rng) - 0.5) * 0.2, cy = (u(rng) - 0.5) * 0.2, cz = (u(rng) - 0.5) * 0.2;
        const double h = 0.25 + 0.35 * u(rng);
        const FormulaFrame frame(eulerRotation(ax, ay, az), Vec3d(cx, cy, cz));
        const std::string* l = frame.l;
        auto ball = [&](double px) { return "sqrt((" + l[0] + "-" + num(px) + ")^2+" + l[1] + "^2+" + l[2] + "^2)-1"; };
        const std::string radial = "sqrt(" + l[0] + "^2+" + l[1] + "^2)";
        std::string f;
        if (shape == "L") f = "min(" + frame.box(0, 0, 0, 1, 0.3, 0.3) + "," + frame.box(-0.7, 0.6, 0, 0.3, 0.9, 0.3) + ")";
        if (shape == "step") f = "max(" + frame.box(0, 0, 0, 1, 1, 0.5) + ",-(" + frame.box(0.5, 0, 0.5, 0.5, 1.2, 0.3) + "))";
        if (shape == "slot") f = "max(" + frame.box(0, 0, 0, 1, 1, 0.5) + ",-(" + frame.box(0, 0, 0.5, 0.25, 1.2, 0.3) + "))";
        if (shape == "cross")
            f = "min(min(" + frame.box(0, 0, 0, 1, 0.3, 0.3) + "," + frame.box(0, 0, 0, 0.3, 1, 0.3) + ")," + frame.box(0, 0, 0, 0.3, 0.3, 1) + ")";
        if (shape == "cylinder") f = "max(" + radial + "-0.8,abs(" + l[2] + ")-0.5)";
        if (shape == "lens") f = "max(" + ball(0.5) + "," + ball(-0.5) + ")";
        if (shape == "hole") f = "max(" + frame.box(0, 0, 0, 1, 1, 0.4) + ",0.45-" + radial + ")";
        ExpressionField field(f, kNotchBox);
        MeshRequest req;
        req.voxelSize = h;
        MeshReport rep;
        const Mesh m = meshField(field, req, rep);
        open += !checkTopology(m).closedManifoldOriented();
        pieces += countComponents(m) != 1;
        for (const Vec3f& p : m.points) farthest = std::max(farthest, std::fabs(field.value(Vec3d(p))) / h);
    }
    INFO(shape << ": " << open << " open, " << pieces << " not in one piece of 40; farthest vertex " << farthest << " H from the surface");
    CHECK(open == 0);
    CHECK(pieces == 0);
    // Features are placed within a fifth of a cell of the surface (estimated from the gradient).
    CHECK(farthest < 0.25);
}

namespace {

// Polygons two of whose vertices share a point: polygons without area.
std::size_t polygonsWithoutArea(const Mesh& m) {
    std::size_t count = 0;
    for (std::size_t f = 0; f < m.polygonCount(); ++f) {
        const std::uint32_t* v = m.polygon(f);
        const std::size_t n = m.polygonSize(f);
        bool shared = false;
        for (std::size_t a = 0; a < n && !shared; ++a)
            for (std::size_t b = a + 1; b < n && !shared; ++b) shared = m.points[v[a]] == m.points[v[b]];
        count += shared;
    }
    return count;
}

// The field meshed by DMC and by marching cubes at each spacing: closed, no polygon without area.
void checkEveryPolygonHasArea(const Field& field, std::initializer_list<double> spacings) {
    for (double h : spacings)
        for (MeshMethod method : {MeshMethod::Dmc, MeshMethod::MarchingCubes}) {
            MeshRequest req;
            req.voxelSize = h;
            req.method = method;
            MeshReport rep;
            const Mesh m = meshField(field, req, rep);
            INFO("spacing " << h << ", " << methodName(method));
            requireClosed(m);
            CHECK(polygonsWithoutArea(m) == 0);
        }
}

} // namespace

TEST_CASE("few polygons without area: crossings that round to a node are the node's, and a pinched weld keeps one node apart") {
    // Vertices at one point came from two sources. A crossing a rounding error from its node (a
    // level set's voxels on a box's face are stored a hair inside) was a vertex of its own at the
    // node's point: a box's corners were capped by triangles of no area, and at 4 voxels a cell
    // the nodes bridged onto the faces of the shared cube carried hundreds. And where welding two
    // feature nodes side by side would pinch the edge between them, both kept their vertices apart,
    // with slivers of no area among them, though one of them alone had sufficed.
    SECTION("random rotated cubes and slotted boxes") {
        std::mt19937 rng(17);
        std::uniform_real_distribution<double> u(0, 1);
        std::size_t meshes = 0, withoutArea = 0, polygons = 0;
        for (int trial = 0; trial < 60; ++trial) {
            const FormulaFrame frame(eulerRotation(u(rng) * 2 * kPi, u(rng) * 2 * kPi, u(rng) * 2 * kPi),
                                     Vec3d((u(rng) - 0.5) * 0.2, (u(rng) - 0.5) * 0.2, (u(rng) - 0.5) * 0.2));
            const double h = 0.08 + 0.17 * u(rng);
            const std::string shape = trial % 2 ? frame.box(0, 0, 0, 0.6, 0.6, 0.6)
                                                : "max(" + frame.box(0, 0, 0, 1, 1, 0.5) + ",-(" + frame.box(0, 0, 0.5, 0.25, 1.2, 0.3) + "))";
            const Mesh m = meshFormula(shape, kNotchBox, h);
            const std::size_t n = polygonsWithoutArea(m);
            ++meshes;
            withoutArea += n > 0;
            polygons += n;
        }
        // 42 measured, in 9 of the 60 (70 in 10 with both nodes of a pinched edge kept apart): what
        // is left is a node pinched against a vertex off the nodes, which must stay apart.
        INFO(polygons << " polygons without area in " << withoutArea << " of " << meshes << " meshes");
        CHECK(polygons <= 50);
    }
    SECTION("a level-set box whose faces lie a rounding error beyond voxel planes, at its voxel size and at 4 voxels a cell (DMC and MC)") {
        // As in the shared cube: the voxels on the faces hold -1e-7 rather than 0, less than half
        // the float spacing of the coordinates there. At 4 voxels a cell the faces lie half way
        // between nodes, where the sharp pass flips the nodes beyond the edges onto them and
        // bridges their neighbours onto the faces, a rounding error inside.
        const double voxel = 0.25, half = 5.5 + 1e-7;
        const auto grid = test::makeLevelSetFromDistance(
            [&](const Vec3d& p) {
                const Vec3d q(std::fabs(p.x) - half, std::fabs(p.y) - half, std::fabs(p.z) - half);
                const Vec3d out(std::max(q.x, 0.0), std::max(q.y, 0.0), std::max(q.z, 0.0));
                return length(out) + std::min(std::max({q.x, q.y, q.z}), 0.0);
            },
            Box3{{-6.5, -6.5, -6.5}, {6.5, 6.5, 6.5}}, voxel);
        checkEveryPolygonHasArea(GridField(grid, "box"), {voxel, 4 * voxel});
    }
    SECTION("the same box half a million units from the origin, where the float spacing is a quarter voxel") {
        // There a crossing 0.04 voxels inside a node rounds to the node's point in float though it
        // lies far beyond kOnNode: the rounding test must still see it (the first pass skips that
        // test only where a crossing is too far from both ends to round onto either).
        const double voxel = 0.25, half = 5.5 + 0.01, c = 524288.0;
        const auto grid = test::makeLevelSetFromDistance(
            [&](const Vec3d& p) {
                const Vec3d q(std::fabs(p.x - c) - half, std::fabs(p.y - c) - half, std::fabs(p.z - c) - half);
                const Vec3d out(std::max(q.x, 0.0), std::max(q.y, 0.0), std::max(q.z, 0.0));
                return length(out) + std::min(std::max({q.x, q.y, q.z}), 0.0);
            },
            Box3{{c - 6.5, c - 6.5, c - 6.5}, {c + 6.5, c + 6.5, c + 6.5}}, voxel);
        checkEveryPolygonHasArea(GridField(grid, "far box"), {voxel, 4 * voxel});
    }
    SECTION("the shared sharp cube at its own voxel size and at 4 voxels a cell (DMC and MC)") {
        const std::string path = test::sharedData("vdb/cube_levelset_sharp.vdb");
        if (path.empty()) {
            WARN("../shared/data absent: cube case skipped");
            return;
        }
        checkEveryPolygonHasArea(GridField(readScalarGrid(path, "").grid, "cube"), {0.05, 0.2});
    }
}

TEST_CASE("welding groups a node's vertices alike wherever its lattice coordinates lie") {
    // Nodes sort as one packed integer where they span less than 2^21 along each axis and as
    // triples beyond: a cube whose corners 0 and 6 are split into a copy per quad (as crossings
    // at a node are) welds back to the cube either way, the same mesh; a node with one vertex is
    // left alone.
    std::vector<Mesh> welded;
    for (const Vec3i& offset : {Vec3i(0, 0, 0), Vec3i(3000000, -2500000, 7)}) {
        Mesh m = test::cubeMesh();
        m.points.push_back(m.points[0]); // 8, 9: corner 0 of quads 2 and 5
        m.points.push_back(m.points[0]);
        m.points.push_back(m.points[6]); // 10, 11: corner 6 of quads 3 and 4
        m.points.push_back(m.points[6]);
        auto replace = [&](std::size_t polygon, std::uint32_t from, std::uint32_t to) {
            for (std::uint32_t i = m.offsets[polygon]; i < m.offsets[polygon + 1]; ++i)
                if (m.indices[i] == from) m.indices[i] = to;
        };
        replace(2, 0, 8), replace(5, 0, 9), replace(3, 6, 10), replace(4, 6, 11);
        INFO("node offset " << offset.x << ", " << offset.y << ", " << offset.z);
        REQUIRE(checkTopology(m).boundaryEdges > 0);
        const Vec3i n0(0, 0, 0), n6 = Vec3i(1, 1, 1) + offset, n3(0, 1, 0);
        const std::vector<std::pair<std::uint32_t, Vec3i>> atNode = {{0, n0}, {10, n6}, {8, n0}, {3, n3}, {6, n6}, {9, n0}, {11, n6}};
        // The mesher hands the weld the polygons through these (the node of 3 has no other).
        const std::vector<std::uint32_t> toWeld = verticesToWeld(atNode);
        CHECK(toWeld == std::vector<std::uint32_t>{0, 6, 8, 9, 10, 11});
        std::vector<std::uint32_t> through;
        for (std::uint32_t f = 0; f < m.polygonCount(); ++f)
            for (std::uint32_t i = m.offsets[f]; i < m.offsets[f + 1]; ++i)
                if (std::binary_search(toWeld.begin(), toWeld.end(), m.indices[i])) {
                    through.push_back(f);
                    break;
                }
        Mesh listed = m, grouped = m, wrong = m;
        CHECK(weldNodeVertices(listed, atNode, {}, {}, &through).weldedVertices == 4);
        // The mesher sorts atNode by node once, for both: the same weld.
        const NodeGroups groups = groupByNode(atNode);
        CHECK(groups.representative == std::vector<std::uint32_t>{0, 10, 0, 3, 10, 0, 10});
        CHECK(groups.listed == std::vector<std::uint32_t>{3, 3, 3, 1, 3, 3, 3});
        CHECK(verticesToWeld(atNode, groups) == toWeld);
        CHECK(weldNodeVertices(grouped, atNode, {}, {}, &through, &groups).weldedVertices == 4);
        CHECK(weldNodeVertices(m, atNode).weldedVertices == 4);
        CHECK(listed.points == m.points);
        CHECK(listed.offsets == m.offsets);
        CHECK(listed.indices == m.indices);
        CHECK(grouped.points == m.points);
        CHECK(grouped.offsets == m.offsets);
        CHECK(grouped.indices == m.indices);
        NodeGroups shortGroups = groups; // (not atNode's: refused before the mesh is touched)
        shortGroups.listed.pop_back();
        CHECK_THROWS_AS(weldNodeVertices(wrong, atNode, {}, {}, &through, &shortGroups), std::logic_error);
        CHECK(m.points.size() == 8);
        CHECK(m.polygonCount() == 6);
        requireClosed(m);
        welded.push_back(m);
    }
    CHECK(welded[0].points == welded[1].points);
    CHECK(welded[0].indices == welded[1].indices);
    auto sorted = [](std::vector<Vec3f> p) {
        std::sort(p.begin(), p.end(), [](const Vec3f& a, const Vec3f& b) { return std::tie(a.x, a.y, a.z) < std::tie(b.x, b.y, b.z); });
        return p;
    };
    CHECK(sorted(welded[0].points) == sorted(test::cubeMesh().points));
}

TEST_CASE("a weld given its polygons drops the points of collapsed ones that no other polygon uses") {
    // Vertices 0 and 1 share node n; triangle (0, 1, 2) collapses when they are welded. The weld
    // given its polygons (as the mesher hands them, every point on a polygon) looks only at
    // theirs for points to drop: vertex 2 must stay where a polygon through no node vertex holds
    // it, and go where it does not; the same meshes the scan of every polygon gives.
    for (const bool otherHolds : {true, false}) {
        Mesh m;
        m.points = {Vec3f(0, 0, 0), Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0), Vec3f(1, 1, 0)};
        m.offsets = {0};
        auto add = [&](std::initializer_list<std::uint32_t> p) {
            m.indices.insert(m.indices.end(), p);
            m.offsets.push_back(std::uint32_t(m.indices.size()));
        };
        add({0, 1, 2});
        add({1, 3, 4});
        if (otherHolds) {
            m.points.push_back(Vec3f(2, 0, 0));
            add({2, 4, 5});
        }
        const std::vector<std::pair<std::uint32_t, Vec3i>> atNode = {{0, Vec3i(0, 0, 0)}, {1, Vec3i(0, 0, 0)}};
        const std::vector<std::uint32_t> through = {0, 1};
        Mesh listed = m;
        INFO("another polygon holds vertex 2: " << otherHolds);
        CHECK(weldNodeVertices(listed, atNode, {}, {}, &through).weldedVertices == 1);
        weldNodeVertices(m, atNode);
        CHECK(listed.points == m.points);
        CHECK(listed.offsets == m.offsets);
        CHECK(listed.indices == m.indices);
        REQUIRE(listed.polygonCount() == (otherHolds ? 2u : 1u));
        CHECK(listed.points.size() == (otherHolds ? 5u : 3u));
        const bool keepsTwo = std::find(listed.points.begin(), listed.points.end(), Vec3f(1, 0, 0)) != listed.points.end();
        CHECK(keepsTwo == otherHolds);
        CHECK(checkTopology(listed).degeneratePolygons == 0);
    }
}

TEST_CASE("splitting fans with a caller's scratch array gives the same mesh and leaves the array as it came") {
    // Two octahedra touching at one vertex: it gets a copy for the second fan. The weld lends
    // splitFansAt its node numbering (every entry ~0u by then) instead of a fresh array.
    const Mesh one = test::octahedronMesh();
    Mesh two = one;
    const std::uint32_t n = std::uint32_t(one.points.size());
    for (const Vec3f& p : one.points) two.points.push_back(p + (one.points[0] - one.points[1]));
    for (std::size_t f = 0; f < one.polygonCount(); ++f) {
        std::vector<std::uint32_t> vs(one.polygon(f), one.polygon(f) + one.polygonSize(f));
        for (std::uint32_t& v : vs) v = v == 1 ? 0 : v + n; // its vertex 1 on the first one's vertex 0
        two.addPolygon(vs.data(), vs.size());
    }
    Mesh plain = two;
    CHECK(splitFansAt(plain, {0, 2}) == 1);
    CHECK(checkTopology(plain).nonManifoldVertices == 0);
    std::vector<std::uint32_t> scratch(3, ~0u); // shorter than the points: it grows
    for (int round = 0; round < 2; ++round) {
        Mesh lent = two;
        CHECK(splitFansAt(lent, {0, 2}, nullptr, &scratch) == 1);
        CHECK(lent.points == plain.points);
        CHECK(lent.indices == plain.indices);
        CHECK(scratch.size() >= two.points.size());
        CHECK(std::all_of(scratch.begin(), scratch.end(), [](std::uint32_t v) { return v == ~0u; }));
    }
}

TEST_CASE("the fan that comes first in polygon order keeps the vertex whatever order the threads group corners in") {
    // Two octahedra touching at vertex 0, their polygons thousands apart in the list (the corners
    // at a vertex are gathered in parallel over chunks of polygons, then put in order): the first
    // octahedron's polygons keep vertex 0 and the last one's get the copy, every time.
    const Mesh one = test::octahedronMesh();
    Mesh base;
    base.points = one.points;
    base.offsets = {0};
    auto filler = [&](int count) { // far away, apart from everything
        for (int t = 0; t < count; ++t) {
            const std::uint32_t b = std::uint32_t(base.points.size());
            for (int k = 0; k < 3; ++k) base.points.push_back(Vec3f(10.0f + float(b), float(k == 1), float(k == 2)));
            const std::uint32_t tri[3] = {b, b + 1, b + 2};
            base.addPolygon(tri, 3);
        }
    };
    // The first octahedron last in the first thousand polygons, the other first after thousands.
    filler(1010);
    const std::size_t firstFirst = base.polygonCount();
    for (std::size_t f = 0; f < one.polygonCount(); ++f) base.addPolygon(one.polygon(f), one.polygonSize(f));
    const std::size_t firstEnd = base.polygonCount();
    filler(1030);
    const std::uint32_t n = std::uint32_t(base.points.size());
    for (const Vec3f& p : one.points) base.points.push_back(p + (one.points[0] - one.points[1]));
    const std::size_t lastFirst = base.polygonCount();
    for (std::size_t f = 0; f < one.polygonCount(); ++f) {
        std::vector<std::uint32_t> vs(one.polygon(f), one.polygon(f) + one.polygonSize(f));
        for (std::uint32_t& v : vs) v = v == 1 ? 0 : v + n; // its vertex 1 on the first one's vertex 0
        base.addPolygon(vs.data(), vs.size());
    }
    ThreadLimit two(2);
    for (int run = 0; run < 50; ++run) {
        Mesh m = base;
        REQUIRE(splitFansAt(m, {0}) == 1);
        const std::uint32_t copy = std::uint32_t(m.points.size() - 1);
        bool firstKeeps = true, lastMoved = true;
        for (std::size_t f = 0; f < m.polygonCount(); ++f)
            for (std::uint32_t i = m.offsets[f]; i < m.offsets[f + 1]; ++i) {
                if (f >= firstFirst && f < firstEnd && m.indices[i] == copy) firstKeeps = false;
                if (f >= lastFirst && m.indices[i] == 0) lastMoved = false;
            }
        INFO("run " << run);
        CHECK(firstKeeps);
        CHECK(lastMoved);
    }
}

TEST_CASE("a weld that splits a pinched polygon rewrites the mesh whether its polygons grow or shrink") {
    // The weld rewrites the polygons in place when the output never runs ahead of the input, and
    // the offsets into a new array when a pinched polygon splits before enough others collapse.
    // Either way: every polygon left is the one expected, by its corners' positions, and the
    // polygons after the welded ones keep their points.
    auto corners = [](const Mesh& m) {
        std::vector<std::vector<std::array<float, 3>>> polys;
        for (std::size_t f = 0; f < m.polygonCount(); ++f) {
            std::vector<std::array<float, 3>> c;
            for (std::uint32_t i = m.offsets[f]; i < m.offsets[f + 1]; ++i) {
                const Vec3f& p = m.points[m.indices[i]];
                c.push_back({p.x, p.y, p.z});
            }
            std::rotate(c.begin(), std::min_element(c.begin(), c.end()), c.end()); // one start per cycle
            polys.push_back(c);
        }
        std::sort(polys.begin(), polys.end());
        return polys;
    };
    for (bool collapseFirst : {false, true}) {
        INFO((collapseFirst ? "a collapsing triangle first" : "the pinched hexagon first"));
        Mesh m;
        // A hexagon whose corners 2 and 5 lie on one node (the pinch), a triangle with two
        // corners on another node (collapses), and a triangle of points after them all.
        m.points = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {2, 2, 0}, {0, 2, 0}, {1, 1, 0},
                    {5, 0, 0}, {6, 0, 0}, {6, 0, 0}, {9, 0, 0}, {9, 1, 0}, {8, 1, 0}};
        const std::vector<std::uint32_t> hexagon = {0, 1, 2, 3, 4, 5}, collapsing = {6, 7, 8}, last = {9, 10, 11};
        for (const auto* poly : collapseFirst ? std::vector<const std::vector<std::uint32_t>*>{&collapsing, &hexagon, &last}
                                              : std::vector<const std::vector<std::uint32_t>*>{&hexagon, &collapsing, &last}) {
            m.indices.insert(m.indices.end(), poly->begin(), poly->end());
            m.offsets.push_back(std::uint32_t(m.indices.size()));
        }
        const std::vector<std::pair<std::uint32_t, Vec3i>> atNode = {{2, {1, 1, 0}}, {5, {1, 1, 0}}, {7, {6, 0, 0}}, {8, {6, 0, 0}}};
        const NodeWeldStats stats = weldNodeVertices(m, atNode);
        CHECK(stats.weldedVertices == 2);
        CHECK(stats.collapsedPolygons == 1);
        CHECK(stats.splitVertices == 1); // the pinch's two triangles meet at one point: a vertex each
        CHECK(m.offsets.size() == 4);
        CHECK(m.offsets.back() == m.indices.size());
        using C = std::vector<std::array<float, 3>>;
        // (Each copy of the pinch point moved 5 % of the way to its triangle's other corners'
        // centroid: mesh/separate_points.h.)
        CHECK(corners(m) == std::vector<C>{C{{0, 0, 0}, {1, 0, 0}, {0.975f, 0.95f, 0}}, C{{0, 2, 0}, {1, 1.05f, 0}, {2, 2, 0}},
                                           C{{8, 1, 0}, {9, 0, 0}, {9, 1, 0}}});
        // The points the collapsed triangle alone used are gone; one copy of the pinch point was added.
        CHECK(m.points.size() == 9);
        REQUIRE(checkTopology(m).boundaryEdges == 9);
    }
}

TEST_CASE("a weld that leaves two polygons folded at a vertex closes the fold") {
    // Quads P = (v, a, x, b) and Q = (v, c, y, a) around v, with the triangle (v, b, c) between
    // them; b and c lie on one node. Welded, the triangle collapses and P and Q meet at v along
    // both edges, folded onto each other: v leaves both, and the mesh. Triangles elsewhere use a,
    // and u, whose one polygon at the node, (u, b, c), collapses too: both stay.
    Mesh m;
    m.points = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0.5f, -1, 0}, {-1, 0.5f, 0}, {2, 0, 1}, {2, 1, 1},
                {3, 3, 0}, {4, 3, 1}, {4, 4, 1}};
    const std::uint32_t v = 0, a = 1, b = 2, c = 3, x = 4, y = 5, u = 8;
    for (const std::vector<std::uint32_t>& poly :
         {std::vector<std::uint32_t>{v, a, x, b}, {v, b, c}, {v, c, y, a}, {a, 6, 7}, {u, b, c}, {u, 9, 10}}) {
        m.indices.insert(m.indices.end(), poly.begin(), poly.end());
        m.offsets.push_back(std::uint32_t(m.indices.size()));
    }
    const std::vector<std::pair<std::uint32_t, Vec3i>> atNode = {{b, {1, 1, 0}}, {c, {1, 1, 0}}};
    const NodeWeldStats stats = weldNodeVertices(m, atNode);
    CHECK(stats.weldedVertices == 1);
    CHECK(stats.foldsClosed == 1);
    CHECK(m.polygonCount() == 4);
    CHECK(std::find(m.points.begin(), m.points.end(), Vec3f(3, 3, 0)) != m.points.end()); // u stays
    CHECK(std::find(m.points.begin(), m.points.end(), Vec3f(0, 0, 0)) == m.points.end()); // v is gone
    CHECK(checkTopology(m).unusedVertices == 0);
}

TEST_CASE("on a smooth torus, few nodes go onto edges: curvature's lines differ from cell to cell") {
    // Tangent planes of a tube 1.5 to 3 cells thick meet at more than the edge angle, so cells
    // there propose "edges"; their lines differ from cell to cell, so another cell rarely confirms
    // one. Unconfirmed, a quarter of the surface cells put a node on an edge over the three
    // spacings (13-34 % each); confirmed, about a tenth (most at the tube 2 cells thick, whose
    // tangents, curving 7 cells around, look like those of a curved edge).
    std::uint64_t onEdges = 0, cells = 0;
    for (double h : {0.1, 0.15, 0.2}) {
        ExpressionField f("sqrt((sqrt(x^2+y^2)-1)^2+z^2)-0.3", Box3{{-1.5, -1.5, -0.5}, {1.5, 1.5, 0.5}});
        MeshRequest req;
        req.voxelSize = h;
        MeshReport rep;
        const Mesh m = meshField(f, req, rep);
        INFO("h " << h << ": " << rep.nodesOnEdges << " nodes on edges, " << rep.nodesAlongEdges << " in the second round, "
                  << rep.cellsWithSurface << " cells with surface");
        requireClosed(m);
        onEdges += rep.nodesOnEdges;
        cells += rep.cellsWithSurface;
    }
    INFO(onEdges << " nodes on edges, " << cells << " cells with surface");
    CHECK(onEdges * 100 <= cells * 15);
}

TEST_CASE("on noisy fog (smoke_fog at its voxel size), few nodes go onto edges: only proposals that pass confirm others") {
    // Noise makes most cells of this file propose an edge. A proposal stands when another cell's
    // proposal, itself near the surface on flat faces with solid behind, lies on its line: about
    // 0.9 % of the surface cells then carry an edge node. Unconfirmed, six in a hundred did; with
    // proposals that fail their own field checks counted as confirmations, 1.3 in a hundred.
    const std::string path = test::sharedData("vdb/smoke_fog.vdb");
    if (path.empty()) {
        WARN("../shared/data absent: smoke_fog case skipped");
        return;
    }
    const GridField field(readScalarGrid(path, "").grid, "smoke");
    MeshRequest req;
    req.iso = 0.5;
    MeshReport rep;
    const Mesh m = meshField(field, req, rep);
    INFO(rep.nodesOnEdges << " nodes on edges (" << rep.nodesAlongEdges << " in the second round), " << rep.nodesOnCorners
                          << " on corners, " << rep.cellsWithSurface << " cells with surface");
    CHECK(rep.nodesOnEdges * 100 <= rep.cellsWithSurface);
    CHECK(rep.nodesOnEdges > 0); // the file's sharp ridges are still found
}

TEST_CASE("on a noisy grid at its own voxel size, leaves whose surface is not resolved get no sharp feature") {
    // A fog ball with noise in every voxel: nearly every surface cell's normals turn past the edge
    // threshold, and the tangent planes meet anywhere. Those leaves hold no candidates, so DMC
    // (nothing to move into at the grid's own voxel size but the joins of lone nodes, here left
    // out) is marching cubes there; without the rule the sharp pass placed nodes on noise. A
    // clean grid keeps every leaf (the cube's edges in "skipping cells whose corner gradients
    // rule out an edge" below).
    auto noisyBall = [](float amplitude) {
        const GridBasePtr base = test::makeSphereFog(1.0, 0.3, 0.05);
        const auto grid = openvdb::gridPtrCast<openvdb::FloatGrid>(base);
        std::mt19937 rng(3);
        std::uniform_real_distribution<float> noise(-amplitude, amplitude);
        for (auto it = grid->tree().beginValueOn(); it; ++it) it.setValue(std::clamp(*it + noise(rng), 0.0f, 1.0f));
        return base;
    };
    auto mesh = [](const Field& field, MeshMethod method, double share, MeshReport& rep, bool thin = true) {
        MeshRequest req;
        req.iso = 0.5;
        req.method = method;
        req.sharpNoiseShare = share;
        req.thin = thin;
        return meshField(field, req, rep);
    };
    {
        const GridField field(noisyBall(0.25f), "noisy fog");
        MeshReport mcReport, rep;
        const Mesh mc = mesh(field, MeshMethod::MarchingCubes, 0.95, mcReport);
        const Mesh dmc = mesh(field, MeshMethod::Dmc, 0.95, rep, false);
        INFO(rep.unresolvedLeaves << " unresolved leaves, " << rep.nodesOnEdges << " nodes on edges, " << rep.nodesOnCorners
                                  << " on corners, " << rep.cellsWithSurface << " cells with surface");
        CHECK(rep.unresolvedLeaves > 0);
        CHECK(rep.nodesOnEdges + rep.nodesOnCorners == 0);
        CHECK(dmc.points == mc.points);
        CHECK(dmc.indices == mc.indices);
    }
    // --sharp-noise on milder noise, where leaves differ: a lower share takes more leaves for
    // noise, 1 only those where every surface cell may hold an edge (103 / 35 / 1 leaves).
    const GridField field(noisyBall(0.1f), "noisy fog");
    std::uint64_t unresolved[3];
    const double shares[3] = {0.8, 0.95, 1.0};
    for (int k = 0; k < 3; ++k) {
        MeshReport r;
        mesh(field, MeshMethod::Dmc, shares[k], r);
        unresolved[k] = r.unresolvedLeaves;
    }
    INFO("unresolved leaves at shares 0.8 / 0.95 / 1: " << unresolved[0] << " / " << unresolved[1] << " / " << unresolved[2]);
    CHECK(unresolved[0] > unresolved[1]);
    CHECK(unresolved[1] > unresolved[2]);
}

TEST_CASE("a cylinder's rims, curved edges 4 cells around, lie on the mesh") {
    // Neighbouring cells see two tangents of the rim, not one line: they confirm each other where
    // the tangents meet nearby at a small angle (with straight lines alone the rims lay 0.048 H
    // from the mesh at the median, over these 6 orientations; 0.013 now).
    std::mt19937 rng(1);
    std::normal_distribution<double> g;
    double sumOfMedians = 0;
    const int trials = 6;
    for (int t = 0; t < trials; ++t) {
        const Vec3d a = normalized(Vec3d(g(rng), g(rng), g(rng)));
        const Vec3d u = normalized(cross(a, std::fabs(a.x) < 0.9 ? Vec3d(1, 0, 0) : Vec3d(0, 1, 0))), v = cross(a, u);
        const double r = 0.6, h = r / 4;
        const std::string along = "(" + num(a.x) + "*x+" + num(a.y) + "*y+" + num(a.z) + "*z)";
        const Mesh m = meshFormula("max(sqrt(max(x^2+y^2+z^2-" + along + "^2,0))-" + num(r) + ", abs" + along + "-0.5)",
                                   Box3{{-1, -1, -1}, {1, 1, 1}}, h);
        requireClosed(m);
        const MeshDistance d(m, h);
        std::vector<double> ds;
        for (int s = -1; s <= 1; s += 2)
            for (int i = 0; i < 200; ++i) {
                const double phi = 2 * M_PI * i / 200;
                ds.push_back(d.distance(a * (0.5 * s) + (u * std::cos(phi) + v * std::sin(phi)) * r, 2 * h) / h);
            }
        std::nth_element(ds.begin(), ds.begin() + std::ptrdiff_t(ds.size() / 2), ds.end());
        sumOfMedians += ds[ds.size() / 2];
    }
    INFO("mean of the rims' median distances " << sumOfMedians / trials << " H");
    CHECK(sumOfMedians / trials < 0.03);
}

TEST_CASE("on a grid at its own voxel size, skipping cells whose corner gradients rule out an edge changes no sharp feature") {
    // A rotated, slightly rounded cube and a smooth ball as level-set grids meshed at their voxel
    // size: crossing normals come from interpolated node gradients, and the sharp pass visits
    // only the cells the gradients leave open. The result must be exactly that of visiting all.
    const Rotation R = eulerRotation(0.4, 0.2, 0.9);
    auto cube = [&](const Vec3d& p) {
        double d = -INFINITY;
        for (int i = 0; i < 3; ++i) d = std::max(d, std::fabs(R[0][i] * p.x + R[1][i] * p.y + R[2][i] * p.z));
        return d - 0.7;
    };
    auto ball = [](const Vec3d& p) { return length(p - Vec3d(0.1, -0.05, 0.02)) - 0.8; };
    const Box3 box{{-1.3, -1.3, -1.3}, {1.3, 1.3, 1.3}};
    int shape = 0;
    for (const std::function<double(const Vec3d&)>& sdf : {std::function<double(const Vec3d&)>(cube), std::function<double(const Vec3d&)>(ball)}) {
        INFO("shape " << shape++);
        const GridField field(test::makeLevelSetFromDistance(sdf, box, 0.05), "grid");
        const LatticeFrame frame = field.naturalFrame(*field.naturalSpacing());
        REQUIRE(field.edgesAreLinear(frame));
        std::vector<std::pair<openvdb::Coord, openvdb::Vec3f>> placed[2];
        SharpStats stats[2];
        for (int all = 0; all < 2; ++all) {
            Lattice lattice = buildLattice(field, frame, latticeCellRange(field, frame), 0.0, CellTest::CornerSigns);
            SurfaceOptions so;
            so.normals = true;
            so.sharpEdgeCosine = all ? 1.0 : 0.9;
            LatticeSurface surface(field, lattice, nullptr, so);
            CHECK(surface.stats().unresolvedLeaves == 0); // a resolved surface: every leaf is judged
            LatticeDeformation deformation;
            SharpOptions sh;
            placeSharpFeatures(field, lattice, surface, sh, deformation, &stats[all]);
            for (auto it = deformation.offsets->cbeginValueOn(); it; ++it) placed[all].emplace_back(it.getCoord(), *it);
        }
        CHECK(stats[0].edgeCells == stats[1].edgeCells);
        CHECK(stats[0].cornerCells == stats[1].cornerCells);
        CHECK(stats[0].rejected == stats[1].rejected);
        CHECK(placed[0] == placed[1]);
        INFO("edge cells " << stats[0].edgeCells << " corner cells " << stats[0].cornerCells << " rejected " << stats[0].rejected << " on edges " << stats[0].nodesOnEdges << " on corners " << stats[0].nodesOnCorners);
        // The cube's edges are found (its corners, smoothed by central differences at this
        // resolution, are not: see the closing note of issue 4); the ball has no feature.
        if (shape == 1) CHECK(stats[0].nodesOnEdges >= 50);
        else CHECK(stats[0].nodesOnCorners + stats[0].nodesOnEdges == 0);
    }
}

TEST_CASE("the corner-gradient edge test: a box of unit gradients narrower than the edge angle rules out only cells with no wider pair") {
    // SharpEdgeLimit decides, from squared products of raw gradients, whether two lie farther
    // apart than the edge angle (pairWider) and whether unit vectors whose box has a given
    // squared diagonal are surely all within the angle of each other (unitsWithin).
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> u(-1, 1), scale(0.05, 20);
    auto randomUnit = [&] {
        for (;;) {
            const Vec3d v(u(rng), u(rng), u(rng));
            if (dot(v, v) > 1e-4 && dot(v, v) <= 1) return normalized(v);
        }
    };
    auto angle = [](const Vec3d& a, const Vec3d& b) { return std::acos(std::clamp(dot(normalized(a), normalized(b)), -1.0, 1.0)); };
    for (double edgeCosine : {0.99, 0.9, 0.5, 0.0, -0.6}) {
        INFO("edge cosine " << edgeCosine);
        const SharpEdgeLimit limit(edgeCosine);
        const double edgeAngle = std::acos(edgeCosine + 1e-5);
        int setsWithin = 0, pairsChecked = 0;
        for (int set = 0; set < 4000; ++set) {
            // Eight gradients of random lengths around one direction, spread up to 1.2 edge angles
            // (the last quarter of the sets within a quarter of it: their sum is within a quarter
            // too, so the cone must take them).
            const bool tight = set >= 3000;
            const Vec3d axis = randomUnit();
            const double spread = tight ? 0.24 * edgeAngle : 1.2 * edgeAngle * std::fabs(u(rng));
            Vec3d g[8], lo(INFINITY, INFINITY, INFINITY), hi(-INFINITY, -INFINITY, -INFINITY);
            double gg[8];
            for (int c = 0; c < 8; ++c) {
                Vec3d d;
                do d = axis + randomUnit() * std::tan(std::min(spread, 1.5)) * std::fabs(u(rng));
                while (angle(d, axis) > spread);
                g[c] = normalized(d) * scale(rng);
                gg[c] = dot(g[c], g[c]);
                // (Rounded to float, as the mesher keeps them.)
                const Vec3d unit(Vec3f(g[c] / std::sqrt(gg[c])));
                for (std::size_t a = 0; a < 3; ++a) lo[a] = std::min(lo[a], unit[a]), hi[a] = std::max(hi[a], unit[a]);
            }
            double widest = 0;
            for (int a = 0; a < 8; ++a)
                for (int b = a + 1; b < 8; ++b) {
                    const double cosine = dot(normalized(g[a]), normalized(g[b]));
                    widest = std::max(widest, angle(g[a], g[b]));
                    if (std::fabs(cosine - (edgeCosine + 1e-5)) < 1e-9) continue;
                    ++pairsChecked;
                    REQUIRE(limit.pairWider(g[a], gg[a], g[b], gg[b]) == (cosine < edgeCosine + 1e-5));
                }
            const bool within = limit.unitsWithin(dot(hi - lo, hi - lo));
            if (within) {
                ++setsWithin;
                REQUIRE(widest <= edgeAngle);
            }
            if (tight) REQUIRE(within);
        }
        CHECK(pairsChecked > 50000);
        CHECK(setsWithin >= 1000);
    }
}

TEST_CASE("two balls touching exactly at a lattice node stay two vertex-manifold pieces") {
    // The node between them has the iso value itself: every edge at it crosses there, and the
    // welded vertex would join two separate fans. Each fan gets its own copy instead.
    const std::string f = "min(sqrt((x+0.3)^2+y^2+z^2)-0.3, sqrt((x-0.3)^2+y^2+z^2)-0.3)";
    const Box3 box{{-1, -1, -1}, {1, 1, 1}};
    for (MeshMethod method : {MeshMethod::MarchingCubes, MeshMethod::Dmc}) {
        const Mesh m = meshFormula(f, box, 0.1, method);
        INFO(methodName(method));
        const MeshTopology t = checkTopology(m);
        CHECK(t.nonManifoldVertices == 0);
        requireClosed(m);
        CHECK(countComponents(m) == 2);
        // Both copies of the touching point are there, one per ball, each moved a hair into its
        // own ball's fan (mesh/separate_points.h): the balls no longer share a point.
        std::vector<Vec3f> nearOrigin;
        for (const Vec3f& p : m.points)
            if (length(Vec3d(p)) < 0.05 * 0.1) nearOrigin.push_back(p);
        REQUIRE(nearOrigin.size() == 2);
        CHECK(nearOrigin[0].x * nearOrigin[1].x < 0);
        CHECK(countCoincidentPoints(m) == 0);
    }
}

TEST_CASE("after nodes flip onto feature tips, patching the leaves around them gives the mesh a full rebuild gives") {
    // Two cones on a ball at H 0.05 (2 flips); the armadillo and smoke grids (15 flips, and 1 on
    // smoke with edge and corner thresholds of 0.5), when the shared data is there. The patch recomputes
    // only leaves near changed nodes or with new cells.
    auto both = [](const Field& field, std::optional<double> h, double sharpCorner = 0.7, double sharpEdge = 0.9) {
        Mesh meshes[2];
        MeshReport reports[2];
        for (int patch = 0; patch < 2; ++patch) {
            MeshRequest req;
            req.voxelSize = h;
            req.sharpCorner = sharpCorner;
            req.sharpEdge = sharpEdge;
            req.patchAfterFlips = patch == 1;
            meshes[patch] = meshField(field, req, reports[patch]);
        }
        INFO(field.describe());
        CHECK(reports[0].nodesFlipped > 0);
        CHECK(meshes[0].points == meshes[1].points);
        CHECK(meshes[0].offsets == meshes[1].offsets);
        CHECK(meshes[0].indices == meshes[1].indices);
        requireClosed(meshes[1]);
    };
    std::string f = "sqrt(x^2+y^2+z^2)-1";
    for (int i : {3, 11}) {
        const double zc = 1 - (i + 0.5) * 2 / 20, r = std::sqrt(1 - zc * zc), phi = i * 2.39996;
        const std::string t = "(" + num(r * std::cos(phi)) + "*x+" + num(r * std::sin(phi)) + "*y+" + num(zc) + "*z)";
        f = "min(" + f + ", max(sqrt(max(x^2+y^2+z^2-" + t + "^2, 0))-" + num(0.3 / 2.6) + "*(" + num(2.6) + "-" + t + "), -" + t + "))";
    }
    both(ExpressionField(f, Box3{{-3, -3, -3}, {3, 3, 3}}), 0.05);
    const std::string armadillo = test::sharedData("vdb/armadillo_levelset.vdb");
    if (armadillo.empty()) {
        WARN("../shared/data absent: armadillo case skipped");
        return;
    }
    both(GridField(readScalarGrid(armadillo, "").grid, "armadillo"), std::nullopt);
    // Fog whose voxels hold the iso value exactly, some of them placed on features: their
    // vertices must follow the node in leaves that are not recomputed too.
    // Most of its leaves are too noisy for features at the default edge threshold (no flip there);
    // with lower thresholds fewer leaves are, and three corners flip (at 0.5 and 0.5 one did,
    // until flips that split the surface around the node were refused).
    both(GridField(readScalarGrid(test::sharedData("vdb/smoke_fog.vdb"), "").grid, "smoke"), std::nullopt, 0.3, 0.5);
}

TEST_CASE("DMC output is byte-identical at 1 and 2 threads") {
    test::TempDir dir;
    std::string files[2];
    for (int threads : {1, 2}) {
        ThreadLimit limit(threads);
        // A thin half shell on a box, and a crack through a ball (many hidden edges, many rounds).
        for (const char* formula : {"min(max(x^2+y^2+z^2-0.81, 0.78-x^2-y^2-z^2, y), max(abs(x)-0.6,abs(y-0.3)-0.6,abs(z)-0.6))",
                                    "max(sqrt(x^2+y^2+z^2)-0.8, 0.015-abs(0.48*x+0.6*y+0.64*z-0.013))"}) {
            const Mesh m = meshFormula(formula, kBox, kH);
            const std::string path = dir.path("t" + std::to_string(threads) + ".obj");
            writeMesh(path, m);
            files[threads - 1] += test::readFile(path);
        }
    }
    CHECK(files[0].size() > 1000);
    CHECK(files[0] == files[1]);
}

TEST_CASE("DMC with thin search and sharp features off is plain marching cubes, and each step changes a shape that needs it") {
    const std::string lens = "max(x^2+y^2+z^2-0.81, 0.8-x^2-y^2-z^2, y)";
    const Mesh plain = meshFormula(lens, kBox, kH, MeshMethod::MarchingCubes);
    const Mesh off = meshFormula(lens, kBox, kH, MeshMethod::Dmc, false, false);
    CHECK(plain.points == off.points);
    CHECK(plain.indices == off.indices);
    CHECK(plain.offsets == off.offsets);
    const Mesh thin = meshFormula(lens, kBox, kH, MeshMethod::Dmc, true, false);
    CHECK(thin.points.size() > plain.points.size());
    const std::string cube = "max(abs(0.8*x+0.6*y),abs(-0.6*x+0.8*y),abs(z-0.01))-0.5";
    const Mesh flat = meshFormula(cube, kBox, kH, MeshMethod::Dmc, true, false);
    const Mesh sharp = meshFormula(cube, kBox, kH, MeshMethod::Dmc, true, true);
    CHECK_FALSE(flat.points == sharp.points);
}

TEST_CASE("a spherical shell 0.3 H thick keeps its inner and outer surfaces apart") {
    // Lattice edges and face diagonals from the cavity to the outside cross the sheet with both
    // ends outside; without the hidden-edge phase marching cubes joins the two sides there.
    const ExpressionField f("abs(sqrt((x-0.01)^2+(y+0.02)^2+(z-0.03)^2)-0.7)-0.015", kBox);
    MeshReport report;
    const Mesh dmc = dmcAtH(f, report);
    CHECK(countComponents(dmc) == 2);
    CHECK(report.thinEdgesSplit > 0);
    CHECK(report.thinEdgesSplit <= report.thinNodesMoved);
}

TEST_CASE("spherical shells a fifth to half a cell thick, at random centres, keep their two surfaces apart") {
    // A sphere's chord between two nodes in the sheet dips out of it: a node may move into the
    // sheet although its edge to such a neighbour then crosses the curved surface (the ends stay
    // joined by a bent path), and a node that leaves the sheet must not make a face ambiguous
    // across it, nor may bridging step over the sheet between two outside nodes (without these,
    // 20 of 30 shells 0.2 H thick came out as one surface).
    CHECK(randomShellsApart(606, 0.2 * kH, 16) == 16);
    CHECK(randomShellsApart(607, 0.3 * kH, 8) == 8);
    CHECK(randomShellsApart(608, 0.5 * kH, 8) == 8);
}

// Near the rim, where the crack opens to the outside, a node moved into the crack once made an
// edge to the outside hide the half-ball's rim (refused, so the crack stayed hidden there), and
// bridging pulled crack nodes into the solid beside them (joining the halves).
TEST_CASE("a crack separates the two halves of a ball") {
    const std::string f = "max(sqrt(x^2+y^2+z^2)-0.8, 0.015-abs(0.48*x+0.6*y+0.64*z-0.013))";
    const Mesh dmc = meshFormula(f, kBox, kH);
    CHECK(countComponents(dmc) == 2);
}

TEST_CASE("cracks 1.2 to 2 cells wide, at random orientations, separate the two halves with sharp features on") {
    // Marching cubes alone keeps these apart; the steps of DMC must not join them: a node beyond
    // the rim flipped onto one half's rim edge, nodes bridged to it, or two nodes of the crack
    // each moved into the half on its side, all made an edge across the crack with both ends
    // inside (8 to 12 of 20 cracks 1 H wide were one piece). Every such move now keeps what the
    // node's edges show, checked again where a neighbour moved in the same batch.
    CHECK(randomCracksApart(909, 1.2 * kH, 8) == 8);
    CHECK(randomCracksApart(910, 1.5 * kH, 8) == 8);
    CHECK(randomCracksApart(911, 2.0 * kH, 8) == 8);
}

TEST_CASE("a gap 0.3 H wide through a level-set ball leaves two halves and no bubble") {
    // bench_thin's second gap: crack nodes bridged into the gap one at a time around a node of
    // the half beside it left that node alone, an 8-triangle bubble (a move may no longer leave
    // a neighbour of its side with no neighbour of its own side).
    const Vec3d n(0.33696394958805831, 0.5789636504922826, 0.7424664221947459);
    const Vec3d c(0.010181175227901004, 0.03974122597511974, -0.0091879030278651935);
    const GridField field(crackLevelSet(n, c, 0.3 * kH, 0.02), "gap");
    MeshReport report;
    const Mesh dmc = dmcAtH(field, report);
    CHECK(countComponents(dmc) == 2);
}

TEST_CASE("a level-set wire 0.3 H thick whose node lies at its side stays in one piece") {
    // A wire 1.5 voxels thick at H/5 voxels (bench_thin's kind, found among random ones): a node
    // barely inside it at its side, its neighbour along the wire moved into the wire's middle; the
    // segment between them leaves the wire. The hidden-edge phase took that for a part to show
    // and moved the first node out, cutting the wire in two; a search over samples joins the two
    // inside the wire, as a bent path does not.
    const Vec3d n(0.97026814167612152, -0.039764073963577486, -0.238743694513981);
    const Vec3d c(0.017433042616255973, -0.010705769053172762, -0.016916075167159109);
    const double width = 0.3 * kH;
    auto rod = [&](const Vec3d& p) {
        const Vec3d d = p - c;
        const double along = dot(n, d);
        return std::max(std::sqrt(std::max(dot(d, d) - along * along, 0.0)) - width / 2, std::fabs(along) - 0.7);
    };
    const GridField field(test::makeLevelSetFromDistance(rod, Box3{{-1.1, -1.1, -1.1}, {1.1, 1.1, 1.1}}, kH / 5), "wire");
    MeshReport report;
    const Mesh m = dmcAtH(field, report);
    CHECK(countComponents(m) == 1);
}

TEST_CASE("cracks a fifth of a cell to a cell wide leave halves without handles where they meet the surface") {
    // The rim is two convex edges a crack's width apart. An outside node beyond the ball whose
    // neighbours on the rim the thin search took into the crack had no edge to the inside left,
    // and the sharp pass flipped it onto the rim's edge as if a tip of the solid were there: a
    // tunnel under the rim (random cracks 0.2-0.5 H wide: 11 of 120 with one or two, 0.5-1 H: 3
    // of 60; none without the sharp pass). Those flips are no longer made: 30 of 30 clean here
    // (28 with them).
    std::mt19937 rng(60606);
    std::uniform_real_distribution<double> width(0.2 * kH, kH);
    int clean = 0;
    for (int trial = 0; trial < 30; ++trial) {
        const Vec3d n = randomUnit(rng), c = randomCentre(rng);
        const std::string f = crackFormula(n, c, width(rng));
        const Mesh m = meshFormula(f, kBox, kH);
        INFO(f);
        requireClosed(m);
        clean += piecesWithoutHandles(m, 2);
    }
    CHECK(clean == 30);
}

TEST_CASE("a thin fin through a ball keeps no tunnel under its root") {
    // The mirror of a crack's rim: where a plate thinner than a cell leaves a ball, its root is two
    // concave edges a plate's width apart, and a node of the ball whose neighbours the thin search
    // took into the fin was flipped out onto the root's edge: a tunnel under the fin. Random fins
    // 0.2-0.6 H thick: 8 of 24 clean with those flips, 20 without them, where the fin's nodes at
    // rest still left the ball's node no edge to the outside and its flip joined the outside on
    // both sides of the fin; 23 of 24 now that a flip must leave each side one group around it
    // (the last has its handle with the sharp pass off too: the thin search's own).
    CHECK(partsOnBallWhole(70707, plateFormula) >= 23);
}

TEST_CASE("thin rods standing out of a ball stay attached at their roots") {
    // A rod thinner than a cell through a ball: at each root the sharp pass saw a corner (the
    // ball's face and two of the rod's). The node the thin search had moved into the rod went
    // onto it, beside the rod, with the rod's nodes above it and the ball's below: a vertex
    // where two parts of the inside met, split apart, and the rod came off (or a neighbour of
    // that node, flipped next, cut it off). Random rods 0.2-0.6 H thick: 21 of 24 attached
    // before; 23 now (the last the thin search itself leaves apart, the sharp pass off or on).
    CHECK(partsOnBallWhole(80808, rodFormula) >= 23);
}

TEST_CASE("most cracks a fifth to half a cell wide separate the two halves") {
    // Known shortfall: a rare random crack still joins the halves near the rim (1 of 1,080 over
    // six other seeds; 46 and 24 before the last rules below). These 20 each
    // come out apart; each rule, switched off, loses one: a node moved into the crack may hide the
    // rim's wedge on an edge or face to the outside where the crack and the outside meet within
    // half a cell; no move may join an edge's ends across the crack; joins left as bubbles, nodes
    // flipped onto the rim among them, go back to rest (without these three: 15, 14 and 2 of 20);
    // a node that moved to its side needs no company from the node moving into the crack (19 at
    // 0.5 H without); bowed paths step at most h/k anywhere (19 at 0.2 H without); a flip undone
    // goes back to where the thin search had put the node (19 at 0.2 H without).
    CHECK(randomCracksApart(912, 0.5 * kH, 20, false) == 20);
    CHECK(randomCracksApart(913, 0.3 * kH, 20, false) == 20);
    CHECK(randomCracksApart(914, 0.2 * kH, 20, false) == 20);
}

TEST_CASE("where the crack meets the outside, the node across it from one that must move goes into it beside their edge") {
    // Random cracks that joined the halves at the rim: an edge from node c of one half to node L
    // of the other hides the crack; only c's Ω holds the crack along the edge, and c may not move
    // into it (it would leave L alone on its side, tied to its half by face diagonals only, or it
    // would make a face hide the rim). L's Ω holds the crack beside the edge, where L goes now.
    // Each of these came out in one piece before (trial t of randomCracksApart's generator).
    struct Case {
        unsigned seed;
        double width;
        int trial;
    };
    for (const Case& k : {Case{7, 0.2, 54}, Case{7, 0.3, 55}, Case{11, 0.2, 27}, Case{11, 0.2, 47}, Case{21, 0.3, 23},
                          Case{31, 0.2, 28}, Case{41, 0.2, 8}, Case{41, 0.2, 38}, Case{51, 0.2, 9}, Case{51, 0.3, 45}})
        checkRandomCrackApart(k.seed, k.trial, k.width * kH);
}

TEST_CASE("no move cuts off two nodes that only have each other") {
    // Random cracks 0.3 H wide where bridging moved the links of two nodes of one half, at the rim,
    // into the crack one by one: each move left the two with each other for company, and together
    // they were cut off, a 10-vertex bubble beside the crack (trial t of randomCracksApart's
    // generator).
    checkRandomCrackApart(7, 24, 0.3 * kH);
    checkRandomCrackApart(41, 53, 0.3 * kH);
}

TEST_CASE("a node goes into a gap that crosses only a corner of its Ω") {
    // A gap 0.25 H wide through a level-set ball (voxel H/5): by the rim, the one node whose Ω
    // holds the gap along the edge across it may not move (a node of its half at the rim leans on
    // it alone), and the gap crosses only a corner of the other node's Ω, beyond every point of a
    // grid of steps H/k centred in Ω; places beside the edge reach Ω's borders.
    MeshReport report;
    CHECK(countComponents(randomCrackLevelSetAtH(7, 51, 0.25 * kH, report)) == 2);
}

TEST_CASE("no flip beside a node the thin search took into a rod and the sharp pass placed at its root") {
    // Rods about a quarter of a cell thick through a ball: the node the thin search had moved
    // into the rod went onto a corner at its root, on the rod's side; its neighbour in the ball,
    // left with no edge to the outside, was flipped next, and the rod came off. A placed node
    // that was taken across counts as taken across for its neighbours' flips too.
    struct Rod {
        Vec3d n, c;
        double width;
    };
    for (const Rod& r : {Rod{Vec3d(0.2089614377748705, -0.97071299746451645, -0.11853857632227784),
                             Vec3d(0.048174864953187652, -0.0076047480728255179, -0.029208315824256672), 0.022373580951156973},
                         Rod{Vec3d(-0.053277499459185362, -0.21030697300150375, -0.97618260851047811),
                             Vec3d(-0.0013493308527616973, 0.021558665931967202, -0.0015750545812327488), 0.023027373111460983}}) {
        const std::string f = "min(sqrt(" + radius2(r.c) + ")-0.5, " + rodFormula(r.n, r.c, r.width) + ")";
        const Mesh m = meshFormula(f, kBox, kH);
        INFO(f);
        requireClosed(m);
        CHECK(piecesWithoutHandles(m, 1));
    }
}

TEST_CASE("a rod whose first node meets the ball's across a face diagonal stays attached") {
    // A rod 0.56 H thick standing on a ball: its node next to the ball lies just outside both, no
    // cell there is hidden, and the rod's first node meets the ball's across a face diagonal that
    // marching cubes never joins, the straight segment between them leaving the inside. Bridging
    // moves one of the face's outside corners to a point of its Ω joining both by straight
    // segments. (Marching cubes at H leaves the rod apart too.)
    const Vec3d n(0.094603960554463948, 0.25451339977615328, -0.96243078711239971),
        c(0.011179395073635114, 0.0090164402159797069, -0.026215359033632857);
    const std::string f = "min(sqrt(" + radius2(c) + ")-0.5, " + rodFormula(n, c, 0.056127292923334515) + ")";
    const Mesh m = meshFormula(f, kBox, kH);
    requireClosed(m);
    CHECK(piecesWithoutHandles(m, 1));
}

namespace {

// A cone of half-angle tangent `tan` from centre c along d, its tip 0.9 out, standing out of a
// ball of radius 0.3 about c (a spike of the random stars these cases come from).
std::string spikeOnBall(const Vec3d& c, const Vec3d& d, double tan) {
    const std::string along = test::dotWith(d, c);
    const std::string cone = "max(sqrt(max(" + radius2(c) + "-" + along + "^2,0))-" + num(tan) + "*(0.9-" + along + "), -" + along + ")";
    return "min(sqrt(" + radius2(c) + ")-0.3, " + cone + ")";
}

} // namespace

TEST_CASE("a spike whose first node meets the ball's across a face diagonal stays on") {
    // Found at random: a cone (half-angle tangent 0.092, 5.4 cells long) standing out of a ball at
    // spacing 0.11. Its node next to the ball is inside it at rest, the ball's node across a face
    // diagonal from it, and the straight segment between them leaves the inside where the cone
    // meets the ball. The node did not move, so no bent path was sought from it (only from moved
    // nodes, and across cell diagonals from nodes at rest): the spike came off (marching cubes at
    // this spacing leaves it apart too). Now a bent path is sought from nodes at rest across face
    // diagonals as well.
    const Mesh m = meshFormula(spikeOnBall(Vec3d(0.033770107015396442, 0.043218747189362736, -0.015615018520918025),
                                           Vec3d(-0.7788185050252463, 0.49737033587865581, 0.38218383694001684), 0.092442881201499252),
                               kBox, 0.11063178501566004);
    requireClosed(m);
    CHECK(piecesWithoutHandles(m, 1));
}

TEST_CASE("a spike's root node does not move out for an edge beside it that the ball's surface grazes") {
    // Found at random: a cone (tangent 0.098) out of a ball at spacing 0.107. The ball's surface
    // grazes the edge from the root node to a ball node just outside (a sliver inside it, an
    // outside sample after), and the hidden-edge phase moved the root node out into that sample:
    // the spike's other nodes, which had each other for company, came off with the spike. A move
    // out that parts the two inside nodes across the node along an axis, which the lattice joins
    // nowhere else near and a path bowing less than a cell joins in the field, is refused now.
    const Mesh m = meshFormula(spikeOnBall(Vec3d(-0.0050895580162997472, 0.042170242612033254, -0.034559053226926498),
                                           Vec3d(0.38073327883417579, 0.26772747426658783, 0.88507862357590095), 0.098484368566074107),
                               kBox, 0.10704294377048343);
    requireClosed(m);
    CHECK(piecesWithoutHandles(m, 1));
}

TEST_CASE("a gap one cell wide leaves no bubble where it meets the outside") {
    // A gap one cell wide through a level-set ball (voxel H/5): the sharp pass flipped a node onto
    // the rim edge where the gap meets the outside, and bridging from it moved a node into the
    // half's rim wedge that touched the rest of the half only through that node: a 6-vertex
    // bubble, until a node bridged to a node on the surface, and to nothing else, went back to
    // rest. The flip itself is refused now: the nodes around that node on one side form two
    // groups there, which the flip would join through it.
    MeshReport report;
    const Mesh dmc = randomCrackLevelSetAtH(21, 52, 1.0 * kH, report);
    CHECK(report.nodesFlipped == 0);
    CHECK(countComponents(dmc) == 2);
    CHECK(piecesWithoutHandles(dmc, 2));
}

TEST_CASE("a bowed path never steps over a crack h/k wide, even where the crack lies next to its end") {
    // bentPathJoins tells a crack's slanted wall from a crack between two nodes; a path that
    // stepped over the crack would join the two halves of a ball. A path bowed by b·h leaves its
    // end at speed |d + 4·b·h·dir|; its steps were counted by its length, so along that tangent
    // the first step was longer than h/k, and a crack h/k wide across it, beside the end, went
    // unseen. Here the crack lies across each bow's first step (the ends 1.2 cells apart along z,
    // the bows in eight directions around z), and at random orientations.
    std::mt19937 rng(4242);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    const LatticeFrame frame{{-1.05, -1.05, -1.05}, kH};
    auto joinsAcross = [&](const Vec3d& n, int steps, const Vec3d& from, const Vec3d& to) {
        const double width = kH / steps;
        // Solid everywhere but a crack `width` wide across n, its near face a hair beyond `from`.
        const Vec3d shift = from + n * (width / 2 + 1e-4 * kH);
        const ExpressionField field(num(width / 2) + "-abs(" + dotWith(n, shift) + ")", kBox);
        const Lattice lattice = buildLattice(field, frame, latticeCellRange(field, frame), 0.0, CellTest::CornerSigns);
        const EdgeRuns runs(field, lattice, 0.0, steps);
        INFO("steps " << steps << ", crack normal " << n.x << " " << n.y << " " << n.z);
        REQUIRE(field.value(from) < 0);
        REQUIRE(field.value(to) < 0);
        std::uint64_t evaluated = 0;
        return runs.bentPathJoins(from, to, true, evaluated) || runs.bentPathJoins(to, from, true, evaluated);
    };
    const Vec3d from(0.013, -0.021, 0.007), to = from + Vec3d(0, 0, 1.2 * kH);
    for (int steps : {3, 5})
        for (double bow : {0.5, 0.75})
            for (int j = 0; j < 8; ++j) {
                const Vec3d dir(-std::sin(j * kPi / 4), std::cos(j * kPi / 4), 0);
                CHECK_FALSE(joinsAcross(normalized((to - from) + dir * (4 * bow * kH)), steps, from, to));
            }
    for (int trial = 0; trial < 12; ++trial) {
        const Vec3d n = randomUnit(rng);
        Vec3d a, b;
        frameOf(n, a, b);
        const Vec3d near = a * (0.1 * unit(rng));
        const Vec3d far = near + n * (0.6 * kH + 0.4 * kH * unit(rng)) + b * (0.5 * kH * unit(rng));
        CHECK_FALSE(joinsAcross(n, 5, near, far));
    }
}

TEST_CASE("a crack's outside meets the outside round the rim, a shell's cavity never does, at any search steps") {
    // The local search behind moves into a crack near its rim (edge_runs.h, joinedNearby): the
    // crack (0.3 H wide, along z = 0) and the outside beyond the ball meet within half a cell,
    // though every bowed path from the crack to that point crosses the half above it; a shell
    // 0.3 H thick keeps its cavity and the outside apart. 64 steps take the search's large-box path.
    const ExpressionField crack("max(sqrt(x^2+y^2+z^2)-0.8, 0.015-abs(z))", kBox);
    const ExpressionField shell("abs(sqrt(x^2+y^2+z^2)-0.7)-0.015", kBox);
    const LatticeFrame frame{{-1.05, -1.05, -1.05}, kH};
    const Lattice crackLattice = buildLattice(crack, frame, latticeCellRange(crack, frame), 0.0, CellTest::CornerSigns);
    const Lattice shellLattice = buildLattice(shell, frame, latticeCellRange(shell, frame), 0.0, CellTest::CornerSigns);
    for (int steps : {5, 64}) {
        INFO("search steps " << steps);
        const EdgeRuns crackRuns(crack, crackLattice, 0.0, steps), shellRuns(shell, shellLattice, 0.0, steps);
        std::uint64_t evaluated = 0;
        const Vec3d inCrack(0.72, 0.01, 0.0), beyondRim(0.8, 0.01, 0.04);
        CHECK(crack.value(inCrack) > 0);
        CHECK(crack.value(beyondRim) > 0);
        CHECK(crack.value((inCrack + beyondRim) * 0.5) < 0); // the straight way crosses the upper half
        CHECK_FALSE(crackRuns.bentPathJoins(inCrack, beyondRim, false, evaluated));
        CHECK(crackRuns.joinedNearby(inCrack, beyondRim, false, evaluated));
        const Vec3d inCavity(0.66, 0.02, 0.01), outside(0.74, 0.02, 0.01);
        CHECK_FALSE(shellRuns.joinedNearby(inCavity, outside, false, evaluated));
        CHECK(shellRuns.joinedNearby(inCavity, Vec3d(0.6, -0.03, 0.02), false, evaluated)); // both in the cavity
        CHECK(evaluated > 0);
    }
}

