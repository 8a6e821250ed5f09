// Grids whose transform rotates, mirrors or stretches their voxels are meshed in their own frame
// (Field::ownFrame): on their voxels, as if those were world's, and the mesh mapped to world.
#include "support/test_support.h"

#include "vdbsurf/dmc/lattice_deformation.h"
#include "vdbsurf/dmc/mesher.h"
#include "vdbsurf/field/grid_field.h"
#include "vdbsurf/lattice/lattice.h"
#include "vdbsurf/mesh/mesh_check.h"
#include "vdbsurf/quality/compare.h"
#include "vdbsurf/vdb/vdb_file.h"
#include "vdbsurf/vdb/volume_to_mesh_peer.h"

#include <catch2/catch.hpp>
#include <openvdb/openvdb.h>

#include <algorithm>
#include <cmath>
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
    return out;
}

Mesh meshGrid(const GridField& field, MeshMethod method, double spacing, MeshReport& report) {
    MeshRequest req;
    req.method = method;
    if (spacing > 0) req.voxelSize = spacing;
    return meshField(field, req, report);
}

} // namespace

TEST_CASE("a grid whose transform rotates, mirrors or stretches its voxels is meshed on them, then mapped to world") {
    initializeOpenVdb();
    const openvdb::FloatGrid::Ptr base = boxWithRod();
    const GridField baseField(base, "base");
    REQUIRE(baseField.ownFrame() == nullptr);
    for (const Case& c : transformedCases()) {
        INFO(c.name);
        const GridBaseCPtr grid = base->copyGridReplacingTransform(c.xform);
        const GridField field(grid, c.name);
        REQUIRE(field.ownFrame() != nullptr);
        CHECK(field.ownFrame()->toWorld.mirrors() == c.mirrors);
        // At the grid's voxel size (its own voxels the lattice) and at two voxels a cell.
        for (const double spacing : {0.0, 2 * kVoxel})
        for (const MeshMethod method : {MeshMethod::MarchingCubes, MeshMethod::Dmc}) {
            INFO(methodName(method) << " at spacing " << spacing);
            MeshReport baseReport, report;
            const Mesh aligned = meshGrid(baseField, method, spacing, baseReport);
            const Mesh m = meshGrid(field, method, spacing, report);
            REQUIRE(report.frameToWorld);
            if (method == MeshMethod::Dmc) {
                // The shape exercises both of DMC's steps (the rod is thin on the coarser lattice).
                if (spacing > 0) CHECK(report.thinNodesMoved > 0);
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
            const double det = field.ownFrame()->toWorld.determinant();
            CHECK(signedVolume(aligned) > 0);
            CHECK(signedVolume(m) == Approx(signedVolume(aligned) * std::fabs(det)).epsilon(1e-4));
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
    REQUIRE(mrep.frameToWorld);
    const PeerMesh same = volumeToMeshPeer(field.grid(), 0.0, &mrep.frame, &*mrep.frameToWorld);
    CHECK(!same.resampled);
    CHECK(same.mesh.points.size() == rep.rows[0].vertices);
    req.voxelSize = 2 * kVoxel;
    const CompareReport coarse = compareMeshers(field, req);
    CHECK(coarse.resampled);
}

TEST_CASE("the deformed lattice of a rotated grid (--lattice-out) turns with the grid and its offsets are world vectors") {
    initializeOpenVdb();
    test::TempDir dir;
    const openvdb::FloatGrid::Ptr base = boxWithRod();
    const Case c = transformedCases()[0];
    const GridField field(base->copyGridReplacingTransform(c.xform), c.name);
    const std::string path = dir.path("lattice.vdb");
    MeshRequest req;
    std::vector<std::pair<openvdb::Coord, Vec3d>> moved; // node, its moved position in world
    req.deformedLattice = [&](const Lattice& lattice, const LatticeDeformation& deformation, const AffineMap* toWorld) {
        REQUIRE(toWorld != nullptr);
        writeLatticeVdb(path, lattice, deformation, {}, toWorld);
        for (auto it = deformation.offsets->cbeginValueOn(); it; ++it) {
            const openvdb::Coord n = it.getCoord();
            const Vec3d p = lattice.frame.nodeWorld(Vec3i(n.x(), n.y(), n.z())) + Vec3d(it->x(), it->y(), it->z());
            moved.emplace_back(n, toWorld->apply(p));
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
