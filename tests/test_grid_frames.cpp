// Grids whose transform rotates, mirrors or stretches their voxels, or is a camera's frustum, are
// meshed in their own frame (Field::ownFrame): on their voxels, as if those were world's, and the
// mesh mapped to world.
#include "support/test_support.h"

#include "vdbsurf/core/error.h"
#include "vdbsurf/core/threads.h"
#include "vdbsurf/dmc/lattice_deformation.h"
#include "vdbsurf/dmc/mesher.h"
#include "vdbsurf/field/grid_field.h"
#include "vdbsurf/lattice/lattice.h"
#include "vdbsurf/mesh/mesh_check.h"
#include "vdbsurf/quality/compare.h"
#include "vdbsurf/vdb/vdb_file.h"
#include "vdbsurf/vdb/volume_to_mesh_peer.h"
#include "vdbsurf/vdb/voxel_transform.h"

#include <catch2/catch.hpp>
#include <openvdb/openvdb.h>
#include <openvdb/tools/SignedFloodFill.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <random>
#include <stdexcept>
#include <string>

using namespace vdbsurf;

namespace {

constexpr double kVoxel = 0.05;

// A box turned against the voxel axes (sharp edges and corners for DMC) with a rod 1.6 voxels
// across standing out of it (a thin part for the thin search on a lattice of two voxels), as a
// level set on an axis-aligned grid of voxel kVoxel.
openvdb::FloatGrid::Ptr boxWithRod() {
    const auto sdf = [](const Vec3d& p) {
        const double c = std::cos(0.5), s = std::sin(0.5), c2 = std::cos(0.3), s2 = std::sin(0.3);
        // Rotated about z by 0.5, then about x by 0.3.
        const Vec3d q(c * p.x + s * p.y, -s * p.x + c * p.y, p.z);
        const Vec3d r(q.x, c2 * q.y + s2 * q.z, -s2 * q.y + c2 * q.z);
        const Vec3d d(std::fabs(r.x) - 0.31, std::fabs(r.y) - 0.27, std::fabs(r.z) - 0.23);
        const Vec3d o(std::max(d.x, 0.0), std::max(d.y, 0.0), std::max(d.z, 0.0));
        const double box = length(o) + std::min(std::max(d.x, std::max(d.y, d.z)), 0.0);
        const Vec3d a = normalized(Vec3d(0.3, 0.2, 1.0));
        const double along = dot(p, a);
        const double rod = std::max(std::sqrt(std::max(dot(p, p) - along * along, 0.0)) - 0.8 * kVoxel, std::fabs(along - 0.35) - 0.3);
        return std::min(box, rod);
    };
    return openvdb::gridPtrCast<openvdb::FloatGrid>(test::makeLevelSetFromDistance(sdf, {{-0.8, -0.8, -0.8}, {0.8, 0.8, 0.8}}, kVoxel));
}

// Six times the signed volume the polygons enclose, each fanned from its centroid (which does not
// depend on where its loop starts): positive when they face outward.
double signedVolume(const Mesh& m) {
    double v = 0;
    for (std::size_t f = 0; f < m.polygonCount(); ++f) {
        const std::uint32_t first = m.offsets[f], end = m.offsets[f + 1];
        Vec3d centre;
        for (std::uint32_t i = first; i < end; ++i) centre += Vec3d(m.points[m.indices[i]]);
        centre *= 1.0 / double(end - first);
        for (std::uint32_t i = first; i < end; ++i) {
            const Vec3d b(m.points[m.indices[i]]), c(m.points[m.indices[i + 1 < end ? i + 1 : first]]);
            v += dot(centre, cross(b, c));
        }
    }
    return v;
}

struct Case {
    std::string name;
    openvdb::math::Transform::Ptr xform;
    bool mirrors;
};

std::vector<Case> transformedCases() {
    std::vector<Case> out;
    {
        auto xf = openvdb::math::Transform::createLinearTransform(kVoxel);
        xf->postRotate(0.7, openvdb::math::Z_AXIS);
        xf->postRotate(-0.4, openvdb::math::Y_AXIS);
        xf->postTranslate(openvdb::Vec3d(3.1, -2.2, 0.37));
        out.push_back({"rotated and moved", xf, false});
    }
    {
        openvdb::Mat4d m = openvdb::Mat4d::identity();
        m.preScale(openvdb::Vec3d(-kVoxel, kVoxel, kVoxel));
        m.setTranslation(openvdb::Vec3d(0.2, 0, -1));
        out.push_back({"mirrored", openvdb::math::Transform::createLinearTransform(m), true});
    }
    {
        openvdb::Mat4d m = openvdb::Mat4d::identity();
        m.preScale(openvdb::Vec3d(kVoxel, 1.5 * kVoxel, kVoxel));
        auto xf = openvdb::math::Transform::createLinearTransform(m);
        xf->postRotate(0.9, openvdb::math::X_AXIS);
        out.push_back({"stretched and rotated", xf, false});
    }
    for (const bool mirrored : {false, true}) {
        // A camera's frustum over the grid's voxels (index -20 .. 20 each way): voxels widen by
        // 1 / 0.6 from the near plane to the far one, turned and moved; mirrored by its second map.
        auto xf = openvdb::math::Transform::createFrustumTransform(openvdb::BBoxd(openvdb::Vec3d(-20), openvdb::Vec3d(20)), 0.6, 1.2, 0.07);
        if (mirrored) xf->postScale(openvdb::Vec3d(1, -1, 1));
        xf->postRotate(0.4, openvdb::math::Y_AXIS);
        xf->postTranslate(openvdb::Vec3d(0.3, 0.1, 2.0));
        out.push_back({mirrored ? "mirrored frustum" : "frustum", xf, mirrored});
    }
    return out;
}

// The frustum cases of transformedCases().
Case frustumCase(bool mirrored) {
    for (const Case& c : transformedCases())
        if (!c.xform->isLinear() && c.mirrors == mirrored) return c;
    throw std::logic_error("no frustum case");
}

Mesh meshGrid(const GridField& field, MeshMethod method, double spacing, MeshReport& report) {
    MeshRequest req;
    req.method = method;
    if (spacing > 0) req.voxelSize = spacing;
    return meshField(field, req, report);
}

} // namespace

TEST_CASE("a grid whose transform rotates, mirrors, stretches its voxels or is a frustum is meshed on them, then mapped to world") {
    initializeOpenVdb();
    const openvdb::FloatGrid::Ptr base = boxWithRod();
    const GridField baseField(base, "base");
    REQUIRE(baseField.ownFrame() == nullptr);
    for (const Case& c : transformedCases()) {
        INFO(c.name);
        const GridBaseCPtr grid = base->copyGridReplacingTransform(c.xform);
        const GridField field(grid, c.name);
        REQUIRE(field.ownFrame() != nullptr);
        CHECK(field.ownFrame()->mirrors() == c.mirrors);
        CHECK((field.ownFrame()->curved != nullptr) == !c.xform->isLinear());
        // At the grid's voxel size (its own voxels the lattice) and at two voxels a cell (the
        // frame's voxels are the grid's smallest).
        for (const double voxels : {0, 2})
        for (const MeshMethod method : {MeshMethod::MarchingCubes, MeshMethod::Dmc}) {
            INFO(methodName(method) << " at " << voxels << " voxels a cell");
            MeshReport baseReport, report;
            const Mesh aligned = meshGrid(baseField, method, voxels * kVoxel, baseReport);
            const Mesh m = meshGrid(field, method, voxels * *field.naturalSpacing(), report);
            REQUIRE(report.ownFrame);
            if (method == MeshMethod::Dmc) {
                // The shape exercises both of DMC's steps (the rod is thin on the coarser lattice).
                if (voxels > 0) CHECK(report.thinNodesMoved > 0);
                CHECK(report.nodesOnEdges + report.nodesOnCorners > 0);
            }
            // The same mesh as on the axis-aligned grid (whose voxel centres are index * kVoxel),
            // each point where the grid's own transform puts it.
            REQUIRE(m.points.size() == aligned.points.size());
            REQUIRE(m.offsets == aligned.offsets);
            double worst = 0;
            for (std::size_t i = 0; i < m.points.size(); ++i) {
                const openvdb::Vec3d w = c.xform->indexToWorld(openvdb::Vec3d(aligned.points[i].x, aligned.points[i].y, aligned.points[i].z) / kVoxel);
                worst = std::max(worst, length(Vec3d(m.points[i]) - Vec3d(w.x(), w.y(), w.z())));
            }
            CHECK(worst < 1e-5);
            bool sameOrder = true, reversed = true;
            for (std::size_t f = 0; f < m.polygonCount(); ++f) {
                const auto b = m.indices.begin() + m.offsets[f], e = m.indices.begin() + m.offsets[f + 1];
                const auto ab = aligned.indices.begin() + aligned.offsets[f];
                sameOrder = sameOrder && std::equal(b, e, ab);
                reversed = reversed && std::equal(std::make_reverse_iterator(e), std::make_reverse_iterator(b), ab);
            }
            CHECK(sameOrder == !c.mirrors);
            CHECK(reversed == c.mirrors);
            // Closed, and facing out of the solid whatever the map's handedness.
            CHECK(checkTopology(m).closedManifoldOriented());
            CHECK(signedVolume(aligned) > 0);
            if (field.ownFrame()->curved) {
                CHECK(signedVolume(m) > 0);
            } else {
                const double det = field.ownFrame()->toWorld.determinant();
                CHECK(signedVolume(m) == Approx(signedVolume(aligned) * std::fabs(det)).epsilon(1e-4));
            }
        }
    }
}

TEST_CASE("compare on a rotated grid measures what it measures on the same voxels unturned, volumeToMesh's lattice turned too") {
    initializeOpenVdb();
    const openvdb::FloatGrid::Ptr base = boxWithRod();
    const Case c = transformedCases()[0];
    const GridField field(base->copyGridReplacingTransform(c.xform), c.name), baseField(base, "base");
    CompareRequest req;
    const CompareReport rep = compareMeshers(field, req), baseRep = compareMeshers(baseField, req);
    REQUIRE(rep.rows.size() == 3);
    REQUIRE(baseRep.rows.size() == 3);
    CHECK(!rep.resampled);
    // Every mesher sees the same voxels whichever way the grid is turned (volumeToMesh works in
    // index space): the same quality. On a lattice of world axes vdbsurf's marching cubes came
    // out at F 0.992 and 0.0012 mean distance here, against 0.9995 and 0.00046 unturned.
    for (std::size_t r = 0; r < 3; ++r) {
        const SurfaceQuality &q = rep.rows[r].quality, &b = baseRep.rows[r].quality;
        INFO(rep.rows[r].method << ": F at H/4 " << q.fScoreQuarter << " (unturned " << b.fScoreQuarter << "), mean distance "
                                << q.meanDistance << " (" << b.meanDistance << ")");
        CHECK(rep.rows[r].vertices == baseRep.rows[r].vertices);
        CHECK(std::fabs(q.fScoreQuarter - b.fScoreQuarter) < 1e-3);
        CHECK(q.meanDistance == Approx(b.meanDistance).epsilon(0.02));
    }

    // Asked for the lattice vdbsurf used at the grid's own spacing (its voxels, turned with it),
    // volumeToMesh's peer knows it for the grid's own and does not resample; at twice the
    // spacing it resamples.
    MeshRequest mreq;
    mreq.method = MeshMethod::MarchingCubes;
    MeshReport mrep;
    meshField(field, mreq, mrep);
    REQUIRE(mrep.ownFrame);
    const PeerMesh same = volumeToMeshPeer(field.grid(), 0.0, &mrep.frame, mrep.ownFrame);
    CHECK(!same.resampled);
    CHECK(same.mesh.points.size() == rep.rows[0].vertices);
    req.voxelSize = 2 * kVoxel;
    const CompareReport coarse = compareMeshers(field, req);
    CHECK(coarse.resampled);
}

TEST_CASE("the deformed lattice of a rotated or frustum grid (--lattice-out) follows the grid and its offsets are world vectors") {
    initializeOpenVdb();
    test::TempDir dir;
    const openvdb::FloatGrid::Ptr base = boxWithRod();
    for (const Case& c : {transformedCases()[0], frustumCase(true)}) {
        INFO(c.name);
        const GridField field(base->copyGridReplacingTransform(c.xform), c.name);
        const std::string path = dir.path(c.mirrors ? "frustum_lattice.vdb" : "lattice.vdb");
        MeshRequest req;
        std::vector<std::pair<openvdb::Coord, Vec3d>> moved; // node, its moved position in world
        req.deformedLattice = [&](const Lattice& lattice, const LatticeDeformation& deformation, const OwnFrame* own) {
            REQUIRE(own != nullptr);
            writeLatticeVdb(path, lattice, deformation, {}, own);
            for (auto it = deformation.offsets->cbeginValueOn(); it; ++it) {
                const openvdb::Coord n = it.getCoord();
                const Vec3d p = lattice.frame.nodeWorld(Vec3i(n.x(), n.y(), n.z())) + Vec3d(it->x(), it->y(), it->z());
                moved.emplace_back(n, own->apply(p));
            }
        };
        MeshReport rep;
        meshField(field, req, rep);
        REQUIRE(!moved.empty());
        openvdb::io::File file(path);
        file.open();
        const auto offsets = openvdb::gridPtrCast<openvdb::Vec3SGrid>(file.readGrid("offsets"));
        file.close();
        REQUIRE(offsets);
        // At the grid's voxel size the lattice's nodes are the grid's voxels.
        for (const openvdb::Coord& ijk : {openvdb::Coord(0, 0, 0), openvdb::Coord(3, -2, 5), openvdb::Coord(-7, 4, 1)}) {
            const openvdb::Vec3d a = offsets->transform().indexToWorld(ijk), b = c.xform->indexToWorld(ijk);
            CHECK((a - b).length() < 1e-9);
        }
        // A moved node: its voxel's centre plus its offset is where the mesher moved it, in world.
        double worst = 0;
        for (const auto& [n, world] : moved) {
            const openvdb::Vec3d p = offsets->transform().indexToWorld(n) + openvdb::Vec3d(offsets->tree().getValue(n));
            worst = std::max(worst, length(Vec3d(p.x(), p.y(), p.z()) - world));
        }
        CHECK(worst < 1e-6);
    }
}

namespace {

// A sphere's signed distance in world, sampled at every voxel of a frustum grid's index box
// (-20 .. 20): the sphere sits in the middle of the frustum, 0.3 of its near plane's width across.
struct FrustumSphere {
    openvdb::FloatGrid::Ptr grid;
    Vec3d centre;
    double radius = 0;
};

FrustumSphere frustumSphere(const openvdb::math::Transform::Ptr& xform) {
    FrustumSphere s;
    const openvdb::Vec3d c = xform->indexToWorld(openvdb::Vec3d(0, 0, 0));
    s.centre = Vec3d(c.x(), c.y(), c.z());
    s.radius = 0.3 * (xform->indexToWorld(openvdb::Vec3d(20, 0, -20)) - xform->indexToWorld(openvdb::Vec3d(-20, 0, -20))).length();
    s.grid = openvdb::FloatGrid::create(float(s.radius));
    s.grid->setTransform(xform);
    s.grid->setGridClass(openvdb::GRID_LEVEL_SET);
    auto acc = s.grid->getAccessor();
    for (int i = -20; i <= 20; ++i)
        for (int j = -20; j <= 20; ++j)
            for (int k = -20; k <= 20; ++k) {
                const openvdb::Vec3d w = xform->indexToWorld(openvdb::Coord(i, j, k));
                acc.setValue(openvdb::Coord(i, j, k), float(length(Vec3d(w.x(), w.y(), w.z()) - s.centre) - s.radius));
            }
    return s;
}

// Runs `check` on the sphere of frustumSphere() in each frustum case, mirrored and not.
void forEachFrustumSphere(const std::function<void(const Case&, const FrustumSphere&, const GridField&)>& check) {
    initializeOpenVdb();
    for (const bool mirrored : {false, true}) {
        const Case c = frustumCase(mirrored);
        INFO(c.name);
        const FrustumSphere s = frustumSphere(c.xform);
        const GridField field(s.grid, c.name);
        check(c, s, field);
    }
}

} // namespace

TEST_CASE("a frustum grid answers in world space through its frustum: values, gradients, bounds and domain") {
    forEachFrustumSphere([](const Case& c, const FrustumSphere& s, const GridField& field) {
        REQUIRE(field.ownFrame() != nullptr);
        REQUIRE(field.ownFrame()->curved != nullptr);
        // The frame's voxel is the smallest: at the near plane (taper 0.6 widens them with depth).
        CHECK(*field.naturalSpacing() == Approx(c.xform->voxelSize(openvdb::Vec3d(-20, -20, -20)).x()).epsilon(1e-9));

        const Box3 domain = field.domain();
        double worstValue = 0;
        for (int i = -20; i <= 20; i += 5)
            for (int j = -20; j <= 20; j += 5)
                for (int k = -20; k <= 20; k += 5) {
                    const openvdb::Vec3d w = c.xform->indexToWorld(openvdb::Coord(i, j, k));
                    const Vec3d p(w.x(), w.y(), w.z());
                    CHECK(domain.contains(p));
                    worstValue = std::max(worstValue, std::fabs(field.value(p) - double(s.grid->tree().getValue(openvdb::Coord(i, j, k)))));
                }
        CHECK(worstValue < 1e-5);

        // Near the sphere the gradient is the distance's: the unit vector from its centre (it
        // was the frame's gradient, off by the frustum's scale, before it went through the map).
        std::mt19937 rng(7);
        std::uniform_real_distribution<double> unit(-1, 1);
        double worstGradient = 0;
        for (int n = 0; n < 200; ++n) {
            const Vec3d d = normalized(Vec3d(unit(rng), unit(rng), unit(rng)));
            const Vec3d p = s.centre + d * (s.radius * (1 + 0.1 * unit(rng)));
            Vec3d g;
            const double v = field.valueAndGradient(p, g);
            CHECK(v == field.value(p));
            CHECK(g == field.gradient(p));
            worstGradient = std::max(worstGradient, length(g - d));
        }
        CHECK(worstGradient < 0.1);

        // Bounds hold every value in random boxes, also boxes that reach behind the camera.
        const openvdb::Vec3d apex = c.xform->indexToWorld(openvdb::Vec3d(0, 0, -100)); // behind the apex (index depth -80)
        const Vec3d behind(apex.x(), apex.y(), apex.z());
        int outside = 0, reachingBehind = 0;
        for (int b = 0; b < 300; ++b) {
            const Vec3d from = b % 5 == 0 ? behind : s.centre;
            const Vec3d a = from + Vec3d(unit(rng), unit(rng), unit(rng)) * (2 * s.radius);
            const Vec3d e = Vec3d(std::fabs(unit(rng)), std::fabs(unit(rng)), std::fabs(unit(rng))) * (b % 3 == 0 ? 2 * s.radius : 0.2 * s.radius);
            const Box3 box{a, a + e};
            const Interval r = field.bounds(box);
            reachingBehind += r.lo == field.valueRange().lo && r.hi == field.valueRange().hi;
            for (int n = 0; n < 40; ++n) {
                const Vec3d p = box.min + Vec3d(e.x * (0.5 + 0.5 * unit(rng)), e.y * (0.5 + 0.5 * unit(rng)), e.z * (0.5 + 0.5 * unit(rng)));
                const double v = field.value(p);
                outside += !(v >= r.lo - 1e-6 && v <= r.hi + 1e-6);
            }
            for (int corner = 0; corner < 8; ++corner) {
                const double v = field.value(box.corner(corner));
                outside += !(v >= r.lo - 1e-6 && v <= r.hi + 1e-6);
            }
        }
        CHECK(outside == 0);
        CHECK(reachingBehind > 0);
        CHECK(reachingBehind < 300);
    });
}

TEST_CASE("a frustum grid's sphere comes out closed, facing out and on the sphere, and compare measures it in world") {
    forEachFrustumSphere([](const Case& c, const FrustumSphere& s, const GridField& field) {
        const double farVoxel = c.xform->voxelSize(openvdb::Vec3d(20, 20, 20)).length();
        for (const MeshMethod method : {MeshMethod::MarchingCubes, MeshMethod::Dmc}) {
            INFO(methodName(method));
            MeshReport rep, rep1;
            const Mesh m = meshGrid(field, method, 0, rep);
            CHECK(checkTopology(m).closedManifoldOriented());
            CHECK(signedVolume(m) > 0);
            double worst = 0;
            for (const Vec3f& p : m.points) worst = std::max(worst, std::fabs(length(Vec3d(p) - s.centre) - s.radius));
            CHECK(worst < 0.05 * farVoxel);
            ThreadLimit one(1);
            const Mesh m1 = meshGrid(field, method, 0, rep1);
            CHECK(m1.offsets == m.offsets);
            CHECK(m1.indices == m.indices);
            CHECK(std::equal(m1.points.begin(), m1.points.end(), m.points.begin(), m.points.end()));
        }
        CompareRequest req;
        const CompareReport own = compareMeshers(field, req);
        REQUIRE(own.rows.size() == 3);
        CHECK(!own.resampled);
        for (const CompareRow& row : own.rows) {
            INFO(row.method);
            CHECK(row.topology.closedManifoldOriented());
            CHECK(row.quality.coverageOne > 0.99);
            CHECK(row.quality.meanDistance < 0.1);
        }
        // At two voxels a cell volumeToMesh meshes the grid resampled onto the lattice vdbsurf
        // used, whose transform is a frustum too: node i where the frame's map puts it.
        req.voxelSize = 2 * *field.naturalSpacing();
        const CompareReport coarse = compareMeshers(field, req);
        CHECK(coarse.resampled);
        for (const CompareRow& row : coarse.rows) {
            INFO(row.method << " at two voxels");
            CHECK(row.topology.closedManifoldOriented());
            CHECK(row.quality.coverageOne > 0.99);
        }
        MeshReport rep;
        meshGrid(field, MeshMethod::MarchingCubes, *req.voxelSize, rep);
        REQUIRE(rep.ownFrame);
        const auto xform = latticeTransform(rep.frame, rep.ownFrame, "test");
        double worst = 0;
        for (const Vec3i& n : {Vec3i(0, 0, 0), Vec3i(3, -2, 5), Vec3i(-7, 4, 1), Vec3i(9, 9, -9)}) {
            const openvdb::Vec3d a = xform->indexToWorld(openvdb::Vec3d(n.x, n.y, n.z));
            worst = std::max(worst, length(Vec3d(a.x(), a.y(), a.z()) - rep.ownFrame->apply(rep.frame.nodeWorld(n))));
        }
        CHECK(worst < 1e-9);
    });
}

TEST_CASE("a frustum grid whose data reaches behind its camera is refused, naming the grid") {
    initializeOpenVdb();
    const Case c = frustumCase(false);
    FrustumSphere s = frustumSphere(c.xform);
    s.grid->tree().setValue(openvdb::Coord(0, 0, -100), 0.5f); // index depth -80 is the apex
    try {
        const GridField field(s.grid, "cam.vdb:density");
        FAIL("accepted");
    } catch (const Error& e) {
        const std::string what = e.what();
        INFO(what);
        CHECK(what.find("cam.vdb:density") != std::string::npos);
        CHECK(what.find("apex") != std::string::npos);
    }
}

TEST_CASE("a frustum or stretched grid whose smallest voxels are below what OpenVDB stores is meshed on its voxels all the same") {
    // The frame (index space scaled by the smallest voxel) needs a linear transform OpenVDB stores,
    // 1.44e-5 a side at least; a near plane close to the camera has voxels 8e-6 wide, a scan
    // 1e-5 x 1e-5 x 1e-4 (which OpenVDB stores: its determinant is what it checks).
    initializeOpenVdb();
    auto xf = openvdb::math::Transform::createFrustumTransform(openvdb::BBoxd(openvdb::Vec3d(-20), openvdb::Vec3d(20)), 0.5, 1.2, 40 * 8e-6);
    REQUIRE(xf->voxelSize(openvdb::Vec3d(0, 0, -20)).x() < smallestStorableVoxelSize());
    const FrustumSphere fs = frustumSphere(xf);
    openvdb::Mat4d scan = openvdb::Mat4d::identity();
    scan.preScale(openvdb::Vec3d(1e-5, 1e-5, 1e-4));
    FrustumSphere ss;
    ss.radius = 4e-4;
    ss.grid = openvdb::FloatGrid::create(float(3e-4));
    ss.grid->setTransform(openvdb::math::Transform::createLinearTransform(scan));
    ss.grid->setGridClass(openvdb::GRID_LEVEL_SET);
    {
        auto acc = ss.grid->getAccessor();
        for (int i = -50; i <= 50; ++i)
            for (int j = -50; j <= 50; ++j)
                for (int k = -6; k <= 6; ++k) {
                    const double d = length(Vec3d(i * 1e-5, j * 1e-5, k * 1e-4)) - ss.radius;
                    if (std::fabs(d) < 3e-4) acc.setValue(openvdb::Coord(i, j, k), float(d));
                }
        openvdb::tools::signedFloodFill(ss.grid->tree());
    }
    for (const auto& [s, largestVoxel] : {std::make_pair(fs, xf->voxelSize(openvdb::Vec3d(20, 20, 20)).length()), std::make_pair(ss, 1e-4)}) {
        const bool frustum = !s.grid->transform().isLinear();
        INFO((frustum ? "frustum" : "scan"));
        const GridField field(s.grid, "near.vdb");
        CHECK(*field.naturalSpacing() == smallestStorableVoxelSize());
        for (const MeshMethod method : {MeshMethod::MarchingCubes, MeshMethod::Dmc}) {
            INFO(methodName(method));
            MeshReport rep;
            const Mesh m = meshGrid(field, method, 0, rep);
            CHECK(rep.voxelSizeReason.find("below what OpenVDB stores") != std::string::npos);
            CHECK(checkTopology(m).closedManifoldOriented());
            CHECK(signedVolume(m) > 0);
            double worst = 0;
            for (const Vec3f& p : m.points) worst = std::max(worst, std::fabs(length(Vec3d(p) - s.centre) - s.radius));
            CHECK(worst < 0.05 * largestVoxel);
        }
    }
}

namespace {

// A level set of `sdf` (world units) on a grid whose transform is the affine map of these rows
// (times hmin) and translation, over the world box [-1, 1]^3, as random affine grids were made.
GridBasePtr affineLevelSet(const double rows[3][3], double hmin, const openvdb::Vec3d& translation,
                           const std::function<double(const openvdb::Vec3d&)>& sdf) {
    initializeOpenVdb();
    openvdb::Mat4d m = openvdb::Mat4d::identity();
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) m(i, j) = rows[i][j] * hmin;
    m.setTranslation(translation);
    const auto xf = openvdb::math::Transform::createLinearTransform(m);
    const double band = 3 * std::max({xf->voxelSize()[0], xf->voxelSize()[1], xf->voxelSize()[2]});
    auto grid = openvdb::FloatGrid::create(float(band));
    grid->setTransform(xf);
    grid->setGridClass(openvdb::GRID_LEVEL_SET);
    openvdb::CoordBBox box;
    for (int c = 0; c < 8; ++c) {
        const openvdb::Vec3d i = xf->worldToIndex(openvdb::Vec3d(c & 1 ? 1 : -1, c & 2 ? 1 : -1, c & 4 ? 1 : -1));
        box.expand(openvdb::Coord::floor(i));
        box.expand(openvdb::Coord::floor(i) + openvdb::Coord(1));
    }
    auto acc = grid->getAccessor();
    for (auto it = box.begin(); it; ++it) {
        const double d = sdf(xf->indexToWorld(*it));
        if (std::fabs(d) < band) acc.setValue(*it, float(d));
    }
    openvdb::tools::signedFloodFill(grid->tree());
    return grid;
}

} // namespace

TEST_CASE("a torus in a grid of sheared, unequal voxels keeps its one handle") {
    // Found among random affine grids: voxels 0.086 x 0.061 x 0.036, sheared and turned. Meshed at
    // 0.0994 (2.8 of its smallest voxel), the tube is two cells across one of the lattice's axes,
    // and bridging once joined two of its nodes that the lattice joins 7 steps round: a second
    // handle (marching cubes keeps one).
    const double rows[3][3] = {{0.52581654084267304, -1.9635254671647411, 1.2362350713192531},
                               {0.19331612429368988, 1.3124060505207882, 1.0554166093944328},
                               {-0.95599464837098569, -0.077928565008704959, 0.28284513614647699}};
    const GridField field(affineLevelSet(rows, 0.036009985115251199,
                                         openvdb::Vec3d(0.10988372153474872, -0.18662979502166982, -0.14708437574781349),
                                         [](const openvdb::Vec3d& p) {
                                             const double ring = std::sqrt(p.x() * p.x() + p.y() * p.y()) - 0.6;
                                             return std::sqrt(ring * ring + p.z() * p.z()) - 0.25;
                                         }),
                          "torus");
    for (const MeshMethod method : {MeshMethod::Dmc, MeshMethod::MarchingCubes}) {
        MeshReport report;
        const Mesh mesh = meshGrid(field, method, 0.099363, report);
        INFO((method == MeshMethod::Dmc ? "dmc" : "mc") << ": " << report.thinNodesMoved << " nodes moved");
        CHECK(checkTopology(mesh).closedManifoldOriented());
        CHECK(countComponents(mesh) == 1);
        CHECK(test::eulerCharacteristic(mesh) == 0);
    }
}

TEST_CASE("a box in a grid of sheared, unequal voxels has no bubble at its edges") {
    // Found among random affine grids, meshed on their own voxels: beside an edge of the box a
    // voxel inside by a sliver has no inside neighbour across a face, and marching cubes (and
    // volumeToMesh) leave it a bubble of its own; the grid's face joins it to its neighbour across
    // the face's diagonal, and so does DMC (lone_nodes.h).
    auto box = [](const openvdb::Vec3d& p) {
        const openvdb::Vec3d d(std::fabs(p.x()) - 0.5, std::fabs(p.y()) - 0.4, std::fabs(p.z()) - 0.3);
        const openvdb::Vec3d o(std::max(d.x(), 0.0), std::max(d.y(), 0.0), std::max(d.z(), 0.0));
        return o.length() + std::min(std::max({d.x(), d.y(), d.z()}), 0.0);
    };
    const double first[3][3] = {{1.2257725353259281, 0.75466887715228126, -0.38571447670083031},
                                {0.44243969710418474, -0.46980000625254809, -0.76389467111079068},
                                {-1.0775092773997934, 1.324221571052187, -0.83334303502972062}};
    const double second[3][3] = {{-0.34033343043959863, 1.5461834919811732, -0.57475078415387482},
                                 {1.7315188367600041, 0.36028222485259842, -1.148096992490552},
                                 {0.51433751499830638, 0.39597919425594502, 0.76069533874066775}};
    const GridBasePtr grids[2] = {
        affineLevelSet(first, 0.050952617627694728, openvdb::Vec3d(-0.25899154165740079, -0.11527236729770765, 0.038651707202225258), box),
        affineLevelSet(second, 0.029676295169860117, openvdb::Vec3d(0.19706479590050066, -0.098046144758099307, -0.11284946408188337), box)};
    for (const GridBasePtr& grid : grids) {
        const GridField field(grid, "box");
        MeshReport mcReport, report;
        CHECK(countComponents(meshGrid(field, MeshMethod::MarchingCubes, 0, mcReport)) == 2);
        const Mesh mesh = meshGrid(field, MeshMethod::Dmc, 0, report);
        CHECK(report.thinLoneJoined == 1);
        CHECK(checkTopology(mesh).closedManifoldOriented());
        CHECK(test::piecesWithoutHandles(mesh, 1));
    }
}
