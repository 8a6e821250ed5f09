// The comparison a user runs to decide whether to switch: one grid meshed at one spacing by
// OpenVDB's volumeToMesh, vdbsurf's marching cubes and vdbsurf's Deformed Marching Cubes, each
// timed and measured against the grid's own iso surface (surface_quality).
#pragma once
#include "vdbsurf/mesh/mesh_check.h"
#include "vdbsurf/quality/surface_quality.h"

#include <optional>
#include <string>
#include <vector>

namespace vdbsurf {

class CancelToken;
class GridField;

struct CompareRequest {
    std::optional<double> iso;       // default: the grid's (0 for level sets, 0.5 for fog)
    std::optional<double> voxelSize; // lattice spacing; default: the grid's voxel size
    int searchSteps = 5;
    const CancelToken* cancel = nullptr;
};

struct CompareRow {
    std::string method;        // "volumeToMesh", "vdbsurf mc", "vdbsurf dmc"
    double seconds = 0;        // meshing, resampling included for volumeToMesh
    double secondsResample = 0;
    std::size_t vertices = 0, polygons = 0, triangles = 0, components = 0;
    MeshTopology topology;
    SurfaceQuality quality;
};

struct CompareReport {
    double iso = 0, voxelSize = 0, gridVoxelSize = 0;
    std::string isoReason;
    bool resampled = false;    // volumeToMesh ran on a copy resampled to voxelSize
    std::size_t surfaceSamples = 0;
    std::vector<CompareRow> rows;
};

CompareReport compareMeshers(const GridField& field, const CompareRequest& request);

} // namespace vdbsurf
