// OpenSubdiv Far's Catmull-Clark (scheme CATMARK, edge-only boundary interpolation) as the
// independent reference for √2-subdivision, in tests and in bench_subdiv. Not part of the
// library: vdbsurf refines with its own √2 scheme; this only checks and times it.
#pragma once
#include "vdbsurf/mesh/mesh.h"

#include <vector>

namespace vdbsurf::reference {

struct CatmarkResult {
    std::vector<Vec3d> positions;  // last level's vertices, in Far's order
    std::vector<std::uint32_t> offsets{0}, indices; // last level's faces (all quads)
};

// `levels` uniform Catmull-Clark levels: topology by TopologyRefiner::RefineUniform, positions
// by PrimvarRefiner::Interpolate in double precision.
CatmarkResult catmullClark(const Mesh& mesh, int levels);

} // namespace vdbsurf::reference
