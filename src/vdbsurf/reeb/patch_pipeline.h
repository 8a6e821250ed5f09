// The `vdbsurf patches` job as the command line and the benchmark run it: closed surface,
// height function, Reeb graph and units, ring grids, patches, tessellation and fit error, each
// stage timed. Holds no algorithm of its own.
#pragma once
#include "vdbsurf/reeb/patch_output.h"

#include <array>
#include <string>
#include <utility>

namespace vdbsurf::reeb {

struct PatchJob {
    Vec3d axis{0, 0, 1};
    // Extremum-saddle pairs less than this many mean edge lengths apart in height are noise
    // and are removed before the graph is built (0 keeps every one).
    double persistence = 0.5;
    int gridU = 0, gridV = 0; // 0: from each unit
    int previewDensity = 4;   // tessellation samples per knot span
    bool measureError = true;
    const CancelToken* cancel = nullptr; // checked between stages and within the long ones (throws Cancelled)
};

struct PatchTimings {
    double surface = 0, height = 0, reeb = 0, grids = 0, fit = 0, tessellate = 0, error = 0;
    // In pipeline order, under the names the command line's stats and the benchmark report them by.
    std::array<std::pair<const char*, double>, 7> stages() const {
        return {{{"surface", surface}, {"height", height}, {"reeb", reeb}, {"grids", grids}, {"fit", fit}, {"tessellate", tessellate}, {"error", error}}};
    }
};

struct PatchResult {
    ClosedSurface surface;
    ReebGraph graph;
    PatchSet patches;
    Mesh preview;
    FitError error;
    PatchTimings seconds;
};

// Throws Error naming inputName for input the Reeb graph cannot take (open, non-manifold, a piece
// flat across the axis ...),
// Cancelled once job.cancel is set.
PatchResult makePatches(const Mesh& mesh, const std::string& inputName, const PatchJob& job);

} // namespace vdbsurf::reeb
