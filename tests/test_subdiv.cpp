// √2-subdivision against OpenSubdiv Far (Catmull-Clark, edge-only boundaries), adaptive and
// view-dependent refinement (closed, manifold, oriented for any depth map), errors, determinism.
#include "support/shapes.h"
#include "support/test_support.h"

#include "osd_catmark.h"
#include "vdbsurf/core/error.h"
#include "vdbsurf/mesh/mesh_check.h"
#include "vdbsurf/mesh/mesh_io.h"
#include "vdbsurf/subdiv/sqrt2_subdivision.h"
#include "vdbsurf/subdiv/view_refine.h"

#include <catch2/catch.hpp>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <random>
#include <tuple>
#include <unordered_map>

using namespace vdbsurf;

namespace {

double diagonal(const std::vector<Vec3d>& pts) {
    Vec3d lo = pts.front(), hi = pts.front();
    for (const Vec3d& p : pts) {
        lo = vmin(lo, p);
        hi = vmax(hi, p);
    }
    return length(hi - lo);
}

// Faces as vertex lists rotated to start at their smallest index (orientation kept), sorted.
std::vector<std::vector<std::uint32_t>> canonicalFaces(const std::vector<std::uint32_t>& offsets, const std::vector<std::uint32_t>& indices,
                                                       const std::vector<std::uint32_t>* remap) {
    std::vector<std::vector<std::uint32_t>> faces;
    for (std::size_t f = 0; f + 1 < offsets.size(); ++f) {
        std::vector<std::uint32_t> v(indices.begin() + offsets[f], indices.begin() + offsets[f + 1]);
        if (remap)
            for (auto& i : v) i = (*remap)[i];
        std::rotate(v.begin(), std::min_element(v.begin(), v.end()), v.end());
        faces.push_back(v);
    }
    std::sort(faces.begin(), faces.end());
    return faces;
}

// True when `ours` and the reference are the same mesh up to vertex order: every reference
// vertex has exactly one of ours within tol, and the faces map onto each other with orientation.
// `worst` receives the largest position difference.
bool sameMesh(const Mesh& oursMesh, const std::vector<Vec3d>& ours, const reference::CatmarkResult& ref, double tol, double& worst,
              std::string& why) {
    worst = 0;
    if (ours.size() != ref.positions.size()) {
        why = "vertex counts " + std::to_string(ours.size()) + " vs " + std::to_string(ref.positions.size());
        return false;
    }
    const double cell = tol * 4;
    auto key = [&](const Vec3d& p) {
        return std::make_tuple(std::llround(p.x / cell), std::llround(p.y / cell), std::llround(p.z / cell));
    };
    std::map<std::tuple<long long, long long, long long>, std::vector<std::uint32_t>> grid;
    for (std::uint32_t i = 0; i < ours.size(); ++i) grid[key(ours[i])].push_back(i);
    std::vector<std::uint32_t> refToOurs(ref.positions.size());
    std::vector<char> taken(ours.size(), 0);
    for (std::uint32_t r = 0; r < ref.positions.size(); ++r) {
        const Vec3d& p = ref.positions[r];
        const auto [kx, ky, kz] = key(p);
        double best = tol;
        long long found = -1;
        for (int dx = -1; dx <= 1; ++dx)
            for (int dy = -1; dy <= 1; ++dy)
                for (int dz = -1; dz <= 1; ++dz) {
                    const auto it = grid.find({kx + dx, ky + dy, kz + dz});
                    if (it == grid.end()) continue;
                    for (std::uint32_t i : it->second)
                        if (length(ours[i] - p) <= best) {
                            best = length(ours[i] - p);
                            found = i;
                        }
                }
        if (found < 0 || taken[std::size_t(found)]) {
            why = "reference vertex " + std::to_string(r) + " has no unique match within tolerance";
            return false;
        }
        taken[std::size_t(found)] = 1;
        refToOurs[r] = std::uint32_t(found);
        worst = std::max(worst, best);
    }
    if (canonicalFaces(ref.offsets, ref.indices, &refToOurs) != canonicalFaces(oursMesh.offsets, oursMesh.indices, nullptr)) {
        why = "faces differ";
        return false;
    }
    return true;
}

void checkAgainstOpenSubdiv(const Mesh& input, int levels) {
    Sqrt2Subdivider s(input, "test mesh");
    for (int i = 0; i < 2 * levels; ++i) s.step();
    const reference::CatmarkResult ref = reference::catmullClark(input, levels);
    const std::vector<Vec3d> ours = s.positions();
    const double tol = 1e-6 * diagonal(ref.positions);
    double worst = 0;
    std::string why;
    INFO("levels " << levels << ", " << ours.size() << " vertices");
    const bool same = sameMesh(s.mesh(), ours, ref, tol, worst, why);
    INFO(why << "; worst distance " << worst << " (tolerance " << tol << ")");
    CHECK(same);
}

} // namespace

TEST_CASE("two sqrt2 steps equal one Catmull-Clark level of OpenSubdiv on closed meshes") {
    const std::vector<std::pair<std::string, Mesh>> meshes = {
        {"cube", test::cubeMesh()},         {"pyramid", test::pyramidMesh()},
        {"pentagonal prism", test::pentagonalPrismMesh()}, {"octahedron", test::octahedronMesh()},
        {"mixed", test::mixedClosedMesh()}, {"torus", test::quadTorusMesh(7, 5, 2.0, 0.6)}};
    for (const auto& [name, mesh] : meshes)
        for (int levels = 1; levels <= 3; ++levels) {
            INFO(name);
            checkAgainstOpenSubdiv(mesh, levels);
        }
}

TEST_CASE("two sqrt2 steps equal OpenSubdiv's edge-only boundary rules on open meshes") {
    const std::vector<std::pair<std::string, Mesh>> meshes = {
        {"grid", test::openGridMesh(4)}, {"open cube", test::openCubeMesh()}, {"triangle fan", test::triangleFanDisc(7)}};
    for (const auto& [name, mesh] : meshes)
        for (int levels = 1; levels <= 3; ++levels) {
            INFO(name);
            checkAgainstOpenSubdiv(mesh, levels);
        }
}

TEST_CASE("sqrt2 matches OpenSubdiv on the shared real meshes") {
    for (const char* file : {"mesh/spot.obj", "mesh/horse_quad.obj", "mesh/suzanne_mixed_open.obj", "mesh/bishop_quad_tri.obj"}) {
        const std::string path = test::sharedData(file);
        if (path.empty() || !test::fileExists(path)) {
            WARN("skipped: ../shared/data/" << file << " is absent");
            continue;
        }
        INFO(file);
        const Mesh mesh = readMesh(path);
        checkAgainstOpenSubdiv(mesh, 1);
        checkAgainstOpenSubdiv(mesh, 2);
    }
}

TEST_CASE("the odd step makes one quad per edge around face points") {
    const Mesh input = test::mixedClosedMesh();
    const MeshTopology t = checkTopology(input);
    Sqrt2Subdivider s(input, "mixed");
    s.step();
    const Mesh m = s.mesh();
    CHECK(m.polygonCount() == t.edges);
    CHECK(m.countPolygonsOfSize(4) == t.edges);
    CHECK(m.points.size() == input.points.size() + input.polygonCount());
    // Face points are vertex averages of the input's polygons.
    const std::vector<Vec3d> pos = s.positions();
    for (std::size_t f = 0; f < input.polygonCount(); ++f) {
        Vec3d c(0, 0, 0);
        for (std::uint32_t k = 0; k < input.polygonSize(f); ++k) c += Vec3d(input.points[input.polygon(f)[k]]);
        c = c / double(input.polygonSize(f));
        CHECK(length(pos[input.points.size() + f] - c) < 1e-12);
    }
    CHECK(checkTopology(m).closedManifoldOriented());
}

TEST_CASE("a half level of an open mesh keeps the boundary and stays manifold") {
    for (const Mesh& input : {test::openGridMesh(3), test::triangleFanDisc(5), test::openCubeMesh()}) {
        Sqrt2Subdivider s(input, "open");
        for (int i = 1; i <= 3; ++i) {
            s.step();
            const MeshTopology t = checkTopology(s.mesh());
            CHECK(t.nonManifoldEdges == 0);
            CHECK(t.inconsistentEdges == 0);
            CHECK(t.degeneratePolygons == 0);
            // The boundary's edge count doubles every two steps (one Catmull-Clark level).
            const std::size_t base = checkTopology(input).boundaryEdges;
            CHECK(t.boundaryEdges == base << (i / 2));
        }
    }
}

TEST_CASE("adaptive refinement stays closed, manifold and oriented for random depth maps") {
    std::mt19937 rng(7);
    const std::vector<Mesh> meshes = {test::cubeMesh(), test::mixedClosedMesh(), test::quadTorusMesh(6, 4, 2, 0.7), test::octahedronMesh()};
    for (const Mesh& input : meshes)
        for (int trial = 0; trial < 12; ++trial) {
            std::vector<int> depth(input.polygonCount());
            for (int& d : depth) d = int(rng() % 7);
            const Mesh out = subdivideAdaptive(input, depth, "random depths");
            const MeshTopology t = checkTopology(out);
            INFO("trial " << trial);
            CHECK(t.closedManifoldOriented());
            CHECK(t.degeneratePolygons == 0);
            CHECK(t.unusedVertices == 0);
            CHECK(countComponents(out) == countComponents(input));
            CHECK(enclosedVolume(out) > 0);
        }
}

TEST_CASE("adaptive refinement keeps faces of depth 0 and matches uniform refinement for a constant depth") {
    const Mesh input = test::mixedClosedMesh();
    std::vector<int> depth(input.polygonCount(), 4);
    const Mesh uniform = subdivideUniform(input, 4, "mixed");
    const Mesh adaptive = subdivideAdaptive(input, depth, "mixed");
    CHECK(adaptive.points == uniform.points);
    CHECK(adaptive.indices == uniform.indices);

    // Refine only the pentagon (face 8): every other polygon is final from the start and no vertex
    // of it moves (none has all its faces refined), so all eleven come out exactly as they went in.
    std::fill(depth.begin(), depth.end(), 0);
    depth[8] = 3;
    const Mesh partial = subdivideAdaptive(input, depth, "mixed");
    CHECK(checkTopology(partial).closedManifoldOriented());
    auto polygonsAsPoints = [](const Mesh& m) {
        std::vector<std::vector<Vec3f>> out;
        for (std::size_t f = 0; f < m.polygonCount(); ++f) {
            std::vector<Vec3f> p;
            for (std::uint32_t k = 0; k < m.polygonSize(f); ++k) p.push_back(m.points[m.polygon(f)[k]]);
            out.push_back(p);
        }
        return out;
    };
    const auto out = polygonsAsPoints(partial);
    std::size_t kept = 0;
    for (const auto& p : polygonsAsPoints(input))
        if (std::find(out.begin(), out.end(), p) != out.end()) ++kept;
    CHECK(kept == input.polygonCount() - 1);
    CHECK(partial.polygonCount() > input.polygonCount());
    CHECK(partial.polygonCount() < subdivideUniform(input, 3, "mixed").polygonCount());
}

TEST_CASE("a step refining every face makes the same mesh, kinds and tags as the general path") {
    // The full-refinement path numbers its elements arithmetically; the general (adaptive) path
    // links polygon lists. Same surface, same polygons with orientation, same per-face tags, at
    // every half level — also after an adaptive first step has left faces of mixed kinds, and on
    // open meshes where the even step splits boundary edges.
    std::mt19937 rng(11);
    const std::vector<Mesh> meshes = {test::mixedClosedMesh(), test::quadTorusMesh(5, 4, 2, 0.7), test::openGridMesh(3),
                                      test::triangleFanDisc(5), test::openCubeMesh(), test::pyramidMesh()};
    for (std::size_t k = 0; k < meshes.size(); ++k)
        for (int adaptiveFirst = 0; adaptiveFirst < 2; ++adaptiveFirst) {
            Sqrt2Subdivider fast(meshes[k], "fast"), general(meshes[k], "general");
            general.setAlwaysGeneral(true);
            std::vector<std::uint32_t> tags(meshes[k].polygonCount());
            for (std::uint32_t& t : tags) t = 1u << (rng() % 8);
            fast.setTags(tags, Sqrt2Subdivider::TagMerge::BitOr);
            general.setTags(tags, Sqrt2Subdivider::TagMerge::BitOr);
            if (adaptiveFirst) {
                std::vector<std::uint8_t> some(meshes[k].polygonCount());
                for (std::uint8_t& r : some) r = std::uint8_t(rng() % 2);
                some[0] = 1;
                fast.step(some);
                general.step(some);
            }
            for (int step = 1; step <= 4; ++step) {
                fast.step();
                general.step();
                INFO("mesh " << k << ", adaptive first step " << adaptiveFirst << ", full step " << step);
                const Mesh g = general.mesh();
                reference::CatmarkResult asReference;
                asReference.positions = general.positions();
                asReference.offsets = g.offsets;
                asReference.indices = g.indices;
                double worst = 0;
                std::string why;
                const bool same = sameMesh(fast.mesh(), fast.positions(), asReference, 1e-12 * diagonal(asReference.positions), worst, why);
                INFO(why);
                REQUIRE(same);
                // Tags travel with their faces: compare (rounded face centroid, tag) lists. The offset
                // keeps dyadic centroids (common here) off the rounding boundaries.
                auto tagged = [](const Sqrt2Subdivider& s) {
                    std::vector<std::tuple<long long, long long, long long, std::uint32_t>> out;
                    const std::vector<std::uint32_t> t = s.tags();
                    std::vector<Vec3d> corners;
                    for (std::size_t f = 0; f < s.faceCount(); ++f) {
                        s.faceCorners(f, corners);
                        Vec3d c(0, 0, 0);
                        for (const Vec3d& p : corners) c += p;
                        c = c / double(corners.size());
                        auto q = [](double x) { return std::llround(x * 1e7 + 0.318309886); };
                        out.emplace_back(q(c.x), q(c.y), q(c.z), t[f]);
                    }
                    std::sort(out.begin(), out.end());
                    return out;
                };
                CHECK(tagged(fast) == tagged(general));
                CHECK(checkTopology(fast.mesh()).inconsistentEdges == 0);
            }
        }
}

TEST_CASE("a step's polygon count is known before it runs, and refinement past the memory limit stops first, naming the input") {
    std::mt19937 rng(11);
    // Closed meshes: one polygon per unrefined face and per edge beside a refined one, exactly.
    for (const Mesh& input : {test::cubeMesh(), test::mixedClosedMesh(), test::quadTorusMesh(6, 4, 2, 0.7)}) {
        Sqrt2Subdivider s(input, "closed");
        for (int i = 0; i < 5; ++i) {
            std::vector<std::uint8_t> refine(s.faceCount());
            for (auto& r : refine) r = std::uint8_t(rng() % 3 != 0);
            if (i == 2) std::fill(refine.begin(), refine.end(), std::uint8_t(1));
            const std::size_t predicted = s.facesAfterStep(refine);
            s.step(refine);
            CHECK(s.faceCount() == predicted);
        }
    }
    // Open meshes: the even step splits a boundary edge instead of fanning the triangle beside
    // it, which makes fewer polygons than the count: never more, and within one per boundary edge.
    for (const Mesh& input : {test::openGridMesh(3), test::openCubeMesh()}) {
        Sqrt2Subdivider s(input, "open");
        for (int i = 0; i < 4; ++i) {
            const std::vector<std::uint8_t> all(s.faceCount(), 1);
            const std::size_t predicted = s.facesAfterStep(all);
            const std::size_t boundary = checkTopology(s.mesh()).boundaryEdges;
            s.step();
            CHECK(s.faceCount() <= predicted);
            CHECK(s.faceCount() + boundary >= predicted);
        }
    }
    // Uniform steps: known before any work; a limit below the result stops them with the input's
    // name, one above lets them run.
    const Mesh torus = test::quadTorusMesh(12, 8, 2, 0.7); // 96 quads, 192 edges: 192 · 2^5 after 6 steps
    Sqrt2Subdivider s(torus, "torus.obj");
    const double sixSteps = 192.0 * 32 * Sqrt2Subdivider::kBytesPerFace;
    s.setMemoryLimit(0.99 * sixSteps);
    CHECK_NOTHROW(s.checkUniformSteps(5));
    CHECK_THROWS_WITH(s.checkUniformSteps(6), Catch::Contains("torus.obj") && Catch::Contains("6 sqrt2 steps") &&
                                                  Catch::Contains("refine it less"));
    // Step by step: the step that would pass the limit stops before it changes anything.
    for (int i = 0; i < 5; ++i) s.step();
    CHECK(s.faceCount() == 192u * 16);
    CHECK_THROWS_WITH(s.step(), Catch::Contains("torus.obj"));
    CHECK(s.faceCount() == 192u * 16);
    CHECK(s.stepsDone() == 5);
    s.setMemoryLimit(1.01 * sixSteps);
    s.step();
    CHECK(s.faceCount() == 192u * 32);
}

TEST_CASE("subdivision output does not depend on the thread count") {
    const Mesh input = test::quadTorusMesh(9, 6, 2, 0.5);
    Mesh one, two;
    tbb::task_arena(1).execute([&] { one = subdivideUniform(input, 5, "torus"); });
    tbb::task_arena(2).execute([&] { two = subdivideUniform(input, 5, "torus"); });
    CHECK(one.points == two.points);
    CHECK(one.indices == two.indices);
}

TEST_CASE("subdivision refuses non-manifold edges and inconsistent orientation, naming the input, and splits non-manifold vertices") {
    Mesh fin = test::cubeMesh(); // a third polygon on the edge 0-1
    fin.points.emplace_back(0.5f, -1.f, -1.f);
    fin.addPolygon({0, 1, 8});
    CHECK_THROWS_WITH(Sqrt2Subdivider(fin, "fin.obj"), Catch::Contains("fin.obj") && Catch::Contains("edge 0-1"));
    Mesh flipped = test::cubeMesh();
    std::reverse(flipped.indices.begin() + 4, flipped.indices.begin() + 8);
    CHECK_THROWS_WITH(Sqrt2Subdivider(flipped, "flipped.obj"), Catch::Contains("flipped.obj") && Catch::Contains("oriented"));
    Mesh repeated = test::cubeMesh();
    repeated.addPolygon({0, 1, 1});
    CHECK_THROWS_WITH(Sqrt2Subdivider(repeated, "rep.obj"), Catch::Contains("repeats"));
    // Two cubes touching at one corner: a non-manifold vertex.
    Mesh bowtie = test::cubeMesh();
    const Mesh other = test::cubeMesh();
    for (const Vec3f& p : other.points) bowtie.points.push_back(p + Vec3f(1, 1, 1));
    for (std::size_t f = 0; f < other.polygonCount(); ++f) {
        std::vector<std::uint32_t> v;
        for (std::uint32_t k = 0; k < 4; ++k) {
            const std::uint32_t i = other.polygon(f)[k];
            v.push_back(i == 0 ? 6 : i + 8); // its corner 0 is the first cube's corner 6
        }
        bowtie.addPolygon(v.data(), v.size());
    }
    // Two cubes touching at one corner: the shared vertex is split, one copy per cube.
    Sqrt2Subdivider s(bowtie, "bowtie.obj");
    CHECK(s.splitVertices() == 1);
    s.step();
    s.step();
    const Mesh out = s.mesh();
    CHECK(checkTopology(out).closedManifoldOriented());
    CHECK(countComponents(out) == 2);
    CHECK(out.points.size() == 2 * subdivideUniform(test::cubeMesh(), 2, "cube").points.size());
}

namespace {

// A closed, finely tessellated ball: the cube after three Catmull-Clark levels, scaled up.
Mesh ballMesh() {
    Mesh m = subdivideUniform(test::cubeMesh(), 6, "cube");
    for (Vec3f& p : m.points) p = (p - Vec3f(0.5f, 0.5f, 0.5f)) * 4.f;
    return m;
}

} // namespace

TEST_CASE("view-dependent refinement: silhouette deeper than front, back and unseen faces untouched, no cracks") {
    const Mesh input = ballMesh();
    ViewCamera cam;
    cam.position = {0, 0, 12};
    cam.target = {0, 0, 0};
    cam.fovDegrees = 40;
    cam.width = 800;
    cam.height = 600;
    ViewRefineOptions opt;
    opt.frontDepth = 2;
    opt.silhouetteDepth = 5;
    ViewRefineReport rep;
    const Mesh out = subdivideForView(input, cam, opt, "ball", &rep);
    CHECK(checkTopology(out).closedManifoldOriented());
    CHECK(rep.initialFront > 0);
    CHECK(rep.initialSilhouette > 0);
    REQUIRE(rep.refinedPerStep.size() == 5);
    // Steps 3-5 refine silhouette faces only: far fewer than the front steps touched.
    CHECK(rep.refinedPerStep[2] < rep.refinedPerStep[1]);

    // Every back-facing input polygon that holds no silhouette vertex is still there, unchanged.
    std::size_t backKept = 0, backTotal = 0;
    using Key = std::vector<std::tuple<float, float, float>>;
    std::map<Key, int> outPolys;
    for (std::size_t f = 0; f < out.polygonCount(); ++f) {
        Key p;
        for (std::uint32_t k = 0; k < out.polygonSize(f); ++k) {
            const Vec3f q = out.points[out.polygon(f)[k]];
            p.emplace_back(q.x, q.y, q.z);
        }
        outPolys[p] = 1;
    }
    for (std::size_t f = 0; f < input.polygonCount(); ++f) {
        Key p;
        bool deepBack = true;
        for (std::uint32_t k = 0; k < input.polygonSize(f); ++k) {
            const Vec3f q = input.points[input.polygon(f)[k]];
            p.emplace_back(q.x, q.y, q.z);
            deepBack &= q.z < -0.4f * float(input.bounds().max.z); // well behind the silhouette near z = 0
        }
        if (!deepBack) continue;
        ++backTotal;
        backKept += outPolys.count(p);
    }
    CHECK(backTotal > 0);
    CHECK(backKept == backTotal);

    // Faces on the silhouette end smaller than front faces (near the view axis). Seen from
    // distance d, a ball of radius R has its silhouette where z / |p| = R / d.
    const double radius = input.bounds().max.z;
    const double silhouetteZ = radius / 12.0;
    double silhouetteEdge = 0, frontEdge = 0;
    int silhouetteCount = 0, frontCount = 0;
    for (std::size_t f = 0; f < out.polygonCount(); ++f) {
        Vec3f c(0, 0, 0);
        const std::uint32_t n = out.polygonSize(f);
        for (std::uint32_t k = 0; k < n; ++k) c += out.points[out.polygon(f)[k]];
        c = c / float(n);
        const double zr = c.z / length(Vec3d(c));
        const double edge = length(Vec3d(out.points[out.polygon(f)[0]] - out.points[out.polygon(f)[1]]));
        if (std::abs(zr - silhouetteZ) < 0.04) {
            silhouetteEdge += edge;
            ++silhouetteCount;
        } else if (zr > 0.9) {
            frontEdge += edge;
            ++frontCount;
        }
    }
    REQUIRE(silhouetteCount > 0);
    REQUIRE(frontCount > 0);
    // Three more √2 steps shrink edges by (1/√2)^3 = 0.35.
    CHECK(silhouetteEdge / silhouetteCount < 0.6 * frontEdge / frontCount);

    // A camera looking away sees nothing: nothing is refined.
    ViewCamera away = cam;
    away.target = {0, 0, 24};
    const Mesh none = subdivideForView(input, away, opt, "ball", &rep);
    CHECK(none.polygonCount() == input.polygonCount());
    CHECK(rep.outsideView == input.polygonCount());

    // A far camera: faces soon cover less than a pixel and stop.
    ViewCamera far = cam;
    far.position = {0, 0, 4000};
    const Mesh tiny = subdivideForView(input, far, opt, "ball", &rep);
    CHECK(tiny.polygonCount() < out.polygonCount() / 4);
}

TEST_CASE("view-dependent refinement stays closed and manifold from many cameras") {
    const Mesh input = test::quadTorusMesh(12, 8, 2.0, 0.7);
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> u(-1, 1);
    for (int trial = 0; trial < 10; ++trial) {
        ViewCamera cam;
        cam.position = normalized(Vec3d(u(rng), u(rng), u(rng))) * (4 + 4 * (u(rng) + 1));
        cam.target = {u(rng), u(rng), u(rng) * 0.5};
        cam.fovDegrees = 30 + 20 * (u(rng) + 1);
        ViewRefineOptions opt;
        opt.frontDepth = 3;
        opt.silhouetteDepth = 6;
        const Mesh out = subdivideForView(input, cam, opt, "torus");
        INFO("trial " << trial);
        CHECK(checkTopology(out).closedManifoldOriented());
        CHECK(countComponents(out) == 1);
    }
}
