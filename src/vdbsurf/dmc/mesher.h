// The meshing job as the command line, the benchmarks and the service run it: choose the lattice
// (spacing, where its nodes sit), the iso value, build the sparse lattice, run the mesher, and
// report what happened. Holds no algorithm of its own.
#pragma once
#include "vdbsurf/core/lattice_frame.h"
#include "vdbsurf/field/field.h"
#include "vdbsurf/mesh/mesh.h"

#include <cstdint>
#include <optional>
#include <string>

namespace vdbsurf {

class CancelToken;

enum class MeshMethod { MarchingCubes };

const char* methodName(MeshMethod m);

struct MeshRequest {
    std::optional<double> iso;       // default: Field::defaultIso()
    std::optional<double> voxelSize; // lattice spacing in world units; default: the field's own
    MeshMethod method = MeshMethod::MarchingCubes;
    bool triangulate = false;
    const CancelToken* cancel = nullptr;
};

struct MeshReport {
    double iso = 0;
    std::string isoReason;
    double voxelSize = 0;
    std::string voxelSizeReason;
    LatticeFrame frame;
    std::uint64_t upperNodesTested = 0, leafBlocksTested = 0, leafBlocksVisited = 0;
    std::uint64_t cellsExamined = 0, cellsActive = 0, cellsWithSurface = 0;
    double secondsLattice = 0, secondsMesh = 0;
    std::size_t vertices = 0, triangles = 0, quads = 0, otherPolygons = 0;
};

// Throws Error naming the input when the request cannot be met or the result would be empty.
Mesh meshField(const Field& field, const MeshRequest& request, MeshReport& report);

} // namespace vdbsurf
