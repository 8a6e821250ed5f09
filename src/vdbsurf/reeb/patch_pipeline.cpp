#include "vdbsurf/reeb/patch_pipeline.h"

#include "vdbsurf/core/cancel.h"

#include <chrono>

namespace vdbsurf::reeb {

namespace {
using Clock = std::chrono::steady_clock;
double lap(Clock::time_point& t) {
    const Clock::time_point now = Clock::now();
    const double s = std::chrono::duration<double>(now - t).count();
    t = now;
    return s;
}
} // namespace

PatchResult makePatches(const Mesh& mesh, const std::string& inputName, const PatchJob& job) {
    PatchResult r;
    const auto check = [&] {
        if (job.cancel) job.cancel->check();
    };
    Clock::time_point t = Clock::now();
    r.surface = buildClosedSurface(mesh, inputName);
    r.seconds.surface = lap(t);
    check();
    HeightFunction f = makeHeightFunction(r.surface, job.axis);
    requirePiecesSpanHeights(r.surface, f, inputName);
    const SimplifyReport simplified = simplifyExtrema(r.surface, f, job.persistence * r.surface.meanEdgeLength());
    r.seconds.height = lap(t);
    check();
    r.graph = buildReebGraph(r.surface, f);
    r.graph.simplified = simplified;
    r.seconds.reeb = lap(t);
    check();
    PatchOptions options;
    options.gridU = job.gridU;
    options.gridV = job.gridV;
    options.cancel = job.cancel;
    std::vector<RingGrid> grids = ringGrids(r.graph, options);
    r.seconds.grids = lap(t);
    r.patches = fitPatches(r.graph, std::move(grids), job.cancel);
    r.seconds.fit = lap(t);
    r.preview = tessellatePatches(r.graph, r.patches, job.previewDensity);
    r.seconds.tessellate = lap(t);
    check();
    if (job.measureError) r.error = fitError(r.surface, r.preview, job.cancel);
    r.seconds.error = lap(t);
    return r;
}

} // namespace vdbsurf::reeb
