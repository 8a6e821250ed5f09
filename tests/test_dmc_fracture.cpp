// A solid fractured into pieces with gaps thinner than a cell between them, meshed as one volume
// (an RBD fracture turned into one SDF, as a pipeline does before it meshes): DMC must keep the
// pieces apart where three or more of them meet, not only where two do.
#include "support/formula_text.h"
#include "support/test_support.h"

#include "vdbsurf/dmc/mesher.h"
#include "vdbsurf/field/expression_field.h"
#include "vdbsurf/field/grid_field.h"
#include "vdbsurf/mesh/mesh_check.h"
#include "vdbsurf/vdb/level_set_from_distance.h"

#include <catch2/catch.hpp>

#include <cmath>
#include <random>
#include <string>
#include <vector>

using namespace vdbsurf;
using test::num;

namespace {

constexpr double kH = 0.1;
const Box3 kBox{{-1.05, -1.05, -1.05}, {1.05, 1.05, 1.05}};

// A solid (`outer`, negative inside) cut into the Voronoi cells of `seeds`, each cell shrunk by half
// the gap `width` from every bisector: neighbours lie `width` apart.
std::string fractured(const std::string& outer, const std::vector<Vec3d>& seeds, double width) {
    std::string pieces;
    for (std::size_t i = 0; i < seeds.size(); ++i) {
        std::string cell = outer;
        for (std::size_t j = 0; j < seeds.size(); ++j) {
            if (j == i) continue;
            const Vec3d n = normalized(seeds[j] - seeds[i]), mid = (seeds[i] + seeds[j]) * 0.5;
            cell += ", " + test::dotWith(n, mid) + "+" + num(width / 2);
        }
        pieces += std::string(i ? ", " : "") + "max(" + cell + ")";
    }
    return "min(" + pieces + ")";
}

// A ball of radius 0.8 so fractured: its pieces are convex.
std::string fracturedBall(const std::vector<Vec3d>& seeds, double width) { return fractured("sqrt(x^2+y^2+z^2)-0.8", seeds, width); }

// A cube of half side 0.58 (its corners within the lattice), turned by `rotation`, so fractured:
// gaps that meet its faces, edges and corners, where the sharp pass places nodes too.
std::string fracturedCube(const test::Rotation& rotation, const std::vector<Vec3d>& seeds, double width) {
    std::string faces;
    for (int a = 0; a < 3; ++a)
        faces += std::string(a ? ", " : "") + "abs(" + test::dotWith(Vec3d(rotation[0][a], rotation[1][a], rotation[2][a]), Vec3d()) + ")";
    return fractured("max(" + faces + ")-0.58", seeds, width);
}

// `count` seeds in [-0.5, 0.5]^3, no two closer than 0.35 (every piece then reaches well into the
// ball, and none is thinner than a cell).
std::vector<Vec3d> randomSeeds(std::mt19937& rng, int count) {
    std::uniform_real_distribution<double> u(-0.5, 0.5);
    for (;;) {
        std::vector<Vec3d> s;
        for (int i = 0; i < count; ++i) s.emplace_back(u(rng), u(rng), u(rng));
        bool apart = true;
        for (int i = 0; i < count && apart; ++i)
            for (int j = i + 1; j < count && apart; ++j) apart = length(s[std::size_t(i)] - s[std::size_t(j)]) > 0.35;
        if (apart) return s;
    }
}

// Does DMC at kH mesh the field as exactly `pieces` pieces, each without a handle? The mesh must be
// closed and manifold.
bool meshedInPieces(const Field& field, std::size_t pieces) {
    MeshRequest req;
    req.voxelSize = kH;
    MeshReport report;
    const Mesh m = meshField(field, req, report);
    CHECK(checkTopology(m).closedManifoldOriented());
    return test::piecesWithoutHandles(m, pieces);
}

// The same for formula f.
bool inTheirPieces(const std::string& f, std::size_t pieces) {
    INFO(f);
    return meshedInPieces(ExpressionField(f, kBox), pieces);
}

// Of `count` random fractured balls of `pieces` pieces, gaps 0.2-0.8 H wide, how many DMC meshes at
// kH as exactly their pieces, each without a handle: from the formula, or (`levelSetVoxel` > 0)
// from a level set of that voxel size sampled from it. Every mesh must be closed and manifold.
// With `cube`, a cube turned at random instead of the ball.
int fracturesInTheirPieces(unsigned seed, int pieces, int count, double levelSetVoxel = 0, bool cube = false) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> gap(0.2 * kH, 0.8 * kH), angle(0, 6.283185307179586); // (radians)
    int right = 0;
    for (int trial = 0; trial < count; ++trial) {
        const double width = gap(rng);
        std::string f;
        if (cube) {
            const double ax = angle(rng), ay = angle(rng), az = angle(rng);
            f = fracturedCube(test::eulerRotation(ax, ay, az), randomSeeds(rng, pieces), width);
        } else {
            f = fracturedBall(randomSeeds(rng, pieces), width);
        }
        const ExpressionField formula(f, kBox);
        INFO("trial " << trial << ", gap " << width / kH << " H: " << f);
        if (levelSetVoxel > 0)
            right += meshedInPieces(GridField(levelSetFromDistance([&](const Vec3d& p) { return formula.value(p); }, kBox, levelSetVoxel),
                                              "fractured"),
                                    std::size_t(pieces));
        else
            right += meshedInPieces(formula, std::size_t(pieces));
    }
    return right;
}

} // namespace

TEST_CASE("a ball fractured into Voronoi pieces with gaps under a cell wide comes out in its pieces") {
    // Where three pieces meet, the node that must move into one gap often makes a face ambiguous
    // towards a node already in the other gap, which the outside reaches only round the junction:
    // refused, the gap stayed hidden and two pieces were one: 50 of 60 and 16 of 30 right before
    // the last resort in hidden_edges.cpp, 57 and 23 with it, 58 and 23 with tips that stood alone
    // back at rest (cutOffTips). Known shortfall: gaps near where a junction meets the ball's
    // surface, a cell holding a wedge of one piece between two gaps (its one node there may not
    // leave), or two pieces' nodes meeting across a diagonal.
    CHECK(fracturesInTheirPieces(20261207, 5, 60) >= 57);
    CHECK(fracturesInTheirPieces(20261208, 8, 30) >= 22);
}

TEST_CASE("a fractured ball as a level set five times finer than the lattice comes out in its pieces") {
    // What a pipeline meshes: the fragments' union as one level set, gaps of 1-4 voxels, meshed
    // at 5 voxels a cell: 10 of 12 before the last resort in hidden_edges.cpp, 12 with it, 11 with
    // tips back at rest: one ball's two welded pieces had come out as eight with a bubble.
    CHECK(fracturesInTheirPieces(20261210, 8, 12, kH / 5) >= 11);
}

TEST_CASE("where a gap meets a junction, the node that must move into it may join it to the other gap round the junction") {
    // Two balls of the random fractures above that welded two pieces (seeds and gap as drawn).
    // First: both ends of the edge across the gap were refused for a face they turn ambiguous
    // towards a node in the other gap (4de808c). Second: one end for that, the other because its
    // far neighbour, in the other gap, would come to its side across the solid (b084cfa).
    const std::vector<Vec3d> faceCase{{0.10594416567846243, 0.10680173364083789, 0.081204017112003091},
                                      {-0.34161712974519443, -0.069330359708731359, -0.10646817979462864},
                                      {0.22301208123746585, 0.49481956294974272, 0.44939547309324357},
                                      {0.044177047429320826, -0.055145811274146417, -0.2317592583506719},
                                      {-0.46407567060714239, -0.47255514290918099, -0.035106137902687906}};
    const std::vector<Vec3d> edgeCase{{0.07159713451611105, 0.2789155374882366, -0.27021356072242264},
                                      {-0.16520428665780595, -0.4097920292984252, -0.3132476607910042},
                                      {-0.06294371031212453, -0.08895042799804032, 0.15677774725445048},
                                      {0.3335816410990964, -0.16583302297296365, 0.42550360036965174},
                                      {0.15314903527684698, -0.15516056176806725, -0.31522515768537074}};
    CHECK(inTheirPieces(fracturedBall(faceCase, 0.038488187455348662), 5));
    CHECK(inTheirPieces(fracturedBall(edgeCase, 0.037695588900326357), 5));
}

TEST_CASE("a turned cube fractured into Voronoi pieces with gaps under a cell wide comes out in its pieces") {
    // Gaps that meet the cube's faces and edges, beside nodes the sharp pass places: 9 of 16 before
    // the last resort in hidden_edges.cpp (4de808c, b084cfa), 13 with it.
    CHECK(fracturesInTheirPieces(20261211, 5, 16, 0, true) >= 12);
}

TEST_CASE("a piece's tip that the lattice cannot join to the piece is not left as a bubble of its own") {
    // Where two gaps and the ball's surface meet, a node moved into the tip of a piece stood alone:
    // every node between it and the piece would join the piece across a gap too. It was a bubble of
    // 4 vertices, a ninth piece (thin_search.cpp, cutOffTips; seeds and gap as the random
    // fractures drew them).
    const std::vector<Vec3d> seeds{{-0.042831446570413712, -0.032051594055088062, -0.18831039984448006},
                                   {-0.26406428585925945, 0.48849781271388937, -0.36476395548870366},
                                   {-0.45209665781882036, 0.28213783902460599, 0.45447927330754234},
                                   {0.49955723466210578, 0.13551849374673552, -0.34353036233157119},
                                   {0.17391520365156832, -0.17214437470312116, 0.26533675711583982},
                                   {-0.32572489264370164, 0.19026527207844113, 0.011383871836423975},
                                   {0.074472305432751962, -0.37365717016978706, -0.46557556023694346},
                                   {0.17337699888430613, 0.49111006338588525, -0.45640317623106208}};
    CHECK(inTheirPieces(fracturedBall(seeds, 0.053424406021060813), 8));
}

TEST_CASE("moves into a gap and into a piece's tip beside it, which only together join the tip, are kept") {
    // Found at random (gap 0.23 H): the crossed-moves check (crossed_moves.h) took the moves into
    // the tip back as a handle they made with the gap's, and the tip came off as a sixth piece.
    // Together they joined it: the pieces around them changed, and such moves now stay.
    const std::vector<Vec3d> seeds{{-0.25022676812224665, 0.38417910323319115, -0.06362255263341343},
                                   {0.318283015088181, -0.36264647248502513, -0.09947824732911947},
                                   {-0.15463471044730792, -0.21554607173329043, -0.06628826695952517},
                                   {0.23383561363381056, 0.34971792225332343, -0.13308656584778256},
                                   {0.3627894592347932, 0.407407750567123, 0.3038526915922194}};
    CHECK(inTheirPieces(fracturedBall(seeds, 0.023042239347339832), 5));
}
