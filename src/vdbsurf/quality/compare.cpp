#include "vdbsurf/quality/compare.h"

#include "vdbsurf/core/cancel.h"
#include "vdbsurf/core/error.h"
#include "vdbsurf/dmc/mesher.h"
#include "vdbsurf/field/grid_field.h"
#include "vdbsurf/vdb/volume_to_mesh_peer.h"

#include <chrono>

namespace vdbsurf {

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

CompareRow describe(std::string method, const Mesh& mesh, double seconds, const GridField& field, double iso,
                    const std::vector<Vec3d>& surface, double h, const CancelToken* cancel) {
    CompareRow row;
    row.method = std::move(method);
    row.seconds = seconds;
    row.vertices = mesh.points.size();
    row.polygons = mesh.polygonCount();
    row.triangles = mesh.fannedTriangleCount();
    row.components = countComponents(mesh);
    row.topology = checkTopology(mesh);
    row.quality = measureSurfaceQuality(mesh, field, iso, surface, h, cancel);
    return row;
}

} // namespace

CompareReport compareMeshers(const GridField& field, const CompareRequest& request) {
    CompareReport report;
    report.gridVoxelSize = *field.naturalSpacing();

    // Our meshers first: meshField validates the iso value and spacing and names the frame.
    auto ours = [&](MeshMethod method, MeshReport& rep) {
        MeshRequest req;
        req.iso = request.iso;
        req.voxelSize = request.voxelSize;
        req.method = method;
        req.searchSteps = request.searchSteps;
        req.cancel = request.cancel;
        req.allowEmpty = true; // marching cubes losing a thin part entirely is what compare is for
        const auto t0 = Clock::now();
        Mesh m = meshField(field, req, rep);
        return std::make_pair(std::move(m), since(t0));
    };
    MeshReport mcReport, dmcReport;
    auto [mc, mcSeconds] = ours(MeshMethod::MarchingCubes, mcReport);
    auto [dmc, dmcSeconds] = ours(MeshMethod::Dmc, dmcReport);
    report.iso = mcReport.iso;
    report.isoReason = mcReport.isoReason;
    report.voxelSize = mcReport.voxelSize;
    const double h = report.voxelSize;

    // The input's own surface, the measure of every mesh: without one there is nothing to compare.
    const std::vector<Vec3d> surface = isoSurfaceSamples(field, report.iso, report.gridVoxelSize, request.cancel);
    report.surfaceSamples = surface.size();
    if (surface.empty()) {
        throw Error(field.describe(), "has no surface at iso " + messageNumber(report.iso) + " (" + valueRangeText(field) +
                                          "); choose another --iso");
    }

    const bool ownLattice = !request.voxelSize;
    PeerMesh peer = volumeToMeshPeer(field.grid(), report.iso, ownLattice ? nullptr : &mcReport.frame,
                                     mcReport.ownFrame);
    report.resampled = peer.resampled;
    if (request.cancel) request.cancel->check();

    CompareRow ref =
        describe("volumeToMesh", peer.mesh, peer.secondsResample + peer.secondsMesh, field, report.iso, surface, h, request.cancel);
    ref.secondsResample = peer.secondsResample;
    report.rows.push_back(std::move(ref));
    report.rows.push_back(describe("vdbsurf mc", mc, mcSeconds, field, report.iso, surface, h, request.cancel));
    report.rows.push_back(describe("vdbsurf dmc", dmc, dmcSeconds, field, report.iso, surface, h, request.cancel));
    return report;
}

} // namespace vdbsurf
