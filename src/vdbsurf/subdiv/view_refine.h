// View-dependent √2 refinement (seed 001 §4): faces inside the view volume that face the
// camera are refined to a front depth, faces on the silhouette to a deeper silhouette depth,
// and any face stops once it covers less than a pixel; everything else stays coarse. Transitions
// are the √2 scheme's own (kept edges, isosceles triangles), so the result has no cracks.
#pragma once
#include "vdbsurf/core/camera.h"
#include "vdbsurf/mesh/mesh.h"

#include <string>
#include <vector>

namespace vdbsurf {

class CancelToken;

struct ViewRefineOptions {
    int frontDepth = 4;       // √2 steps for front-facing faces (4 = two Catmull-Clark levels)
    int silhouetteDepth = 8;  // √2 steps for faces holding a silhouette vertex
    double stopPixels = 1.0;  // a face whose projection spans less than this stops refining
    const CancelToken* cancel = nullptr; // checked before each step (throws Cancelled)
};

struct ViewRefineReport {
    std::size_t inputFaces = 0, outputFaces = 0;
    std::size_t splitVertices = 0; // non-manifold input vertices split per fan
    std::size_t initialFront = 0, initialSilhouette = 0, outsideView = 0;
    std::vector<std::size_t> refinedPerStep; // faces refined by each √2 step
};

// Shows progress (one unit a step) on a terminal.
Mesh subdivideForView(const Mesh& mesh, const ViewCamera& camera, const ViewRefineOptions& options, const std::string& inputName,
                      ViewRefineReport* report = nullptr);

} // namespace vdbsurf
