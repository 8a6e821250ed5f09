#include "vdbsurf/dmc/mesher.h"

#include "vdbsurf/core/cancel.h"
#include "vdbsurf/core/error.h"
#include "vdbsurf/dmc/lattice_surface.h"
#include "vdbsurf/lattice/lattice.h"

#include <cmath>
#include <sstream>

namespace vdbsurf {

const char* methodName(MeshMethod m) {
    switch (m) {
    case MeshMethod::MarchingCubes: return "mc";
    }
    return "?";
}

namespace {
std::string num(double v) {
    std::ostringstream s;
    s.precision(9);
    s << v;
    return s.str();
}
} // namespace

Mesh meshField(const Field& field, const MeshRequest& request, MeshReport& report) {
    if (request.iso) {
        if (!std::isfinite(*request.iso)) throw Error("--iso", "must be a finite number");
        report.iso = *request.iso;
        report.isoReason = "given";
    } else {
        report.iso = field.defaultIso();
        report.isoReason = field.inside() == Inside::Below ? "default for level sets and formulas" : "default for fog volumes";
    }
    if (request.voxelSize) {
        if (!(*request.voxelSize > 0) || !std::isfinite(*request.voxelSize))
            throw Error("--voxel-size", "must be a positive number of world units, not " + num(*request.voxelSize));
        report.voxelSize = *request.voxelSize;
        report.voxelSizeReason = "given";
    } else if (auto h = field.naturalSpacing()) {
        report.voxelSize = *h;
        report.voxelSizeReason = "the grid's voxel size";
    } else {
        throw Error("--voxel-size", "is required for " + field.describe());
    }
    report.frame = field.naturalFrame(report.voxelSize);

    const openvdb::CoordBBox range = latticeCellRange(field, report.frame);
    const Lattice lattice = buildLattice(field, report.frame, range, report.iso, CellTest::CornerSigns, request.cancel);
    report.upperNodesTested = lattice.stats.upperNodesTested;
    report.leafBlocksTested = lattice.stats.leafBlocksTested;
    report.leafBlocksVisited = lattice.stats.leafBlocksVisited;
    report.cellsExamined = lattice.stats.cellsExamined;
    report.cellsActive = lattice.stats.cellsActive;
    report.secondsLattice = lattice.stats.seconds;

    SurfaceOptions mc;
    mc.iso = report.iso;
    mc.triangulate = request.triangulate;
    mc.cancel = request.cancel;
    SurfaceStats mcStats;
    Mesh mesh = marchingCubes(field, lattice, mc, &mcStats);
    report.cellsWithSurface = mcStats.cellsWithSurface;
    report.secondsMesh = mcStats.seconds;

    if (mesh.empty()) {
        const Interval r = field.bounds(field.domain());
        throw Error(field.describe(), "has no surface at iso " + num(report.iso) + " on a lattice of spacing " +
                                          num(report.voxelSize) + " (values lie within " + num(r.lo) + " .. " + num(r.hi) +
                                          "); choose another --iso or a smaller --voxel-size");
    }
    report.vertices = mesh.points.size();
    report.triangles = mesh.countPolygonsOfSize(3);
    report.quads = mesh.countPolygonsOfSize(4);
    report.otherPolygons = mesh.polygonCount() - report.triangles - report.quads;
    return mesh;
}

} // namespace vdbsurf
