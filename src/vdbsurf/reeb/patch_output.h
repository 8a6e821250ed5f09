// What `vdbsurf patches` hands back: the patches as OBJ free-form surfaces, a welded
// tessellation of them for any viewer, the Reeb graph as JSON, and how far the patches lie
// from the input.
#pragma once
#include "vdbsurf/reeb/patch_fit.h"

#include <string>
#include <vector>

namespace vdbsurf::reeb {

// One mesh of all patches. Boundary rows take their vertices from the shared lobe curves (one
// vertex per lobe sample, saddle and pole), so neighbouring patches share vertices along their
// joins and the result is closed wherever the input was; `density` samples per knot span.
Mesh tessellatePatches(const ReebGraph& graph, const PatchSet& patches, int density = 4);

struct FitError {
    double rms = 0, max = 0;  // in units of the input's mean edge length
    double meanEdgeLength = 0;
};
// Distances of the surface's vertices to the tessellated patches.
FitError fitError(const ClosedSurface& surface, const Mesh& tessellation, const CancelToken* cancel = nullptr);

// OBJ free-form surfaces: `cstype bspline`, `deg 3 3`, one `surf` per unit (control points as
// `v`, u varying fastest), `parm u`, `parm v`, `end`. Written atomically; throws Error naming path.
void writePatchesObj(const std::string& path, const PatchSet& patches, const std::vector<std::string>& comments);

// The Reeb graph: axis, nodes (type, multiplicity, height, position, input vertex), arcs (ends,
// the input polygons of the unit, its area). Written atomically; throws Error naming path.
void writeReebJson(const std::string& path, const ReebGraph& graph, const ClosedSurface& surface);

} // namespace vdbsurf::reeb
