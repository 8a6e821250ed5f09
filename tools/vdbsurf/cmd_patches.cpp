// vdbsurf patches: a closed mesh to bicubic B-spline patches laid out by its Reeb graph along an
// axis (seed 004), with the graph as JSON and a tessellated preview.
#include "cli_common.h"

#include "vdbsurf/core/atomic_file.h"
#include "vdbsurf/core/cancel.h"
#include "vdbsurf/core/error.h"
#include "vdbsurf/core/threads.h"
#include "vdbsurf/mesh/mesh_io.h"
#include "vdbsurf/reeb/patch_pipeline.h"

#include <algorithm>
#include <cmath>
#include <cctype>
#include <sstream>

namespace vdbsurf::cli {

namespace {

struct PatchesOptions {
    std::string input, output, reeb, preview, stats;
    std::string axis = "z", gridSize = "auto";
    double persistence = 0.5;
    int threads = 0;
};

Vec3d parseAxis(const std::string& text) {
    std::string t = text;
    std::transform(t.begin(), t.end(), t.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    if (t == "x") return {1, 0, 0};
    if (t == "y") return {0, 1, 0};
    if (t == "z") return {0, 0, 1};
    const std::vector<double> v = parseNumbers("--axis", text, 3);
    const Vec3d a{v[0], v[1], v[2]};
    if (!(maxAbsComponent(a) > 0)) throw Error("--axis", "the axis must be a non-zero direction");
    return a;
}

void runPatches(const PatchesOptions& o) {
    const auto t0 = Clock::now();
    if (o.threads < 0) throw Error("--threads", "must be 0 (all cores) or a positive number");
    if (meshFormatOf(o.output) != MeshFormat::Obj) throw Error(o.output, "patches are written as OBJ free-form surfaces; use .obj");
    if (!o.preview.empty()) {
        const MeshFormat f = meshFormatOf(o.preview);
        if (f != MeshFormat::Obj && f != MeshFormat::Ply && f != MeshFormat::Pov)
            throw Error(o.preview, "unsupported preview format; use .obj, .ply or .pov");
    }
    if (!(o.persistence >= 0)) throw Error("--persistence", "must not be negative");
    reeb::PatchJob job;
    job.axis = parseAxis(o.axis);
    job.persistence = o.persistence;
    if (o.gridSize != "auto") {
        const std::vector<double> g = parseNumbers("--grid-size", o.gridSize, 2);
        if (g[0] != double(int(g[0])) || g[1] != double(int(g[1])) || g[0] < 4 || g[1] < 3 || g[0] > 4096 || g[1] > 4096)
            throw Error("--grid-size", "give auto or U,V: whole numbers, U from 4 and V from 3 up to 4096");
        job.gridU = int(g[0]);
        job.gridV = int(g[1]);
    }
    for (const std::string* path : {&o.output, &o.reeb, &o.preview, &o.stats})
        if (!path->empty()) checkWritableTarget(*path);
    ThreadLimit threads(o.threads);

    const Mesh input = readMesh(o.input);
    job.cancel = &processCancelToken();
    const reeb::PatchResult r = reeb::makePatches(input, o.input, job);
    processCancelToken().check(); // (once the outputs are being written, they are all written)
    const reeb::ReebGraph& g = r.graph;
    const std::vector<std::string> comments{std::string("vdbsurf ") + VDBSURF_VERSION, "source: " + o.input,
                                            "patches: " + std::to_string(g.units.size()) + " bicubic B-spline patches along axis " +
                                                o.axis};
    reeb::writePatchesObj(o.output, r.patches, comments);
    if (!o.reeb.empty()) reeb::writeReebJson(o.reeb, g, r.surface);
    if (!o.preview.empty()) writeMesh(o.preview, r.preview, comments);

    if (r.surface.mergedPoints)
        note(std::to_string(r.surface.mergedPoints) + " points of " + o.input +
             " lie exactly where an earlier one does and were merged into it (a file that stores a point once per side of a " +
             "seam); merged, the surface is closed");
    std::ostringstream s;
    s << o.input << ": " << g.minima << " minima, " << g.maxima << " maxima, " << g.saddles << " saddles (Euler characteristic "
      << g.eulerCharacteristic << "); Reeb graph " << g.nodes.size() << " nodes, " << g.units.size() << " arcs, " << g.loops()
      << " loops";
    if (g.simplified.minimaRemoved + g.simplified.maximaRemoved)
        s << "; " << g.simplified.minimaRemoved + g.simplified.maximaRemoved << " extrema below the persistence of " << o.persistence
          << " mean edges removed";
    note(s.str());
    std::ostringstream w;
    w.precision(3);
    w << "wrote " << o.output << ": " << r.patches.patches.size() << " patches; fit error RMS " << r.error.rms << ", max "
      << r.error.max << " mean edge lengths (" << r.error.meanEdgeLength << ")";
    note(w.str());
    if (r.patches.sectionsWithSeveralLoops)
        note(std::to_string(r.patches.sectionsWithSeveralLoops) + " ring-grid sections met more than one contour loop in a unit " +
             "(noise below the persistence); the longest was used");
    if (r.patches.sectionsBlended)
        note(std::to_string(r.patches.sectionsBlended) + " ring-grid sections found no contour (flat or re-ordered parts of a unit) " +
             "and were blended from the sections beside them");
    if (!o.stats.empty()) {
        nlohmann::json units = nlohmann::json::array();
        for (std::size_t i = 0; i < g.units.size(); ++i) {
            const reeb::UnitPatch& p = r.patches.patches[i];
            units.push_back({{"grid", {p.grid.U, p.grid.V}}, {"control_points", {p.surface.nu, p.surface.nv}}, {"area", g.units[i].area}});
        }
        nlohmann::json seconds;
        for (const auto& [stage, s] : r.seconds.stages()) seconds[stage] = s;
        seconds["total"] = since(t0);
        writeJsonFile(o.stats, {{"input", o.input},
                                {"output", o.output},
                                {"input_polygons", input.polygonCount()},
                                {"triangles", r.surface.triangleCount()},
                                {"merged_points", r.surface.mergedPoints},
                                {"minima", g.minima},
                                {"maxima", g.maxima},
                                {"saddles", g.saddles},
                                {"nodes", g.nodes.size()},
                                {"arcs", g.units.size()},
                                {"loops", g.loops()},
                                {"euler_characteristic", g.eulerCharacteristic},
                                {"extrema_removed", g.simplified.minimaRemoved + g.simplified.maximaRemoved},
                                {"fit_error_rms", r.error.rms},
                                {"fit_error_max", r.error.max},
                                {"mean_edge_length", r.error.meanEdgeLength},
                                {"units", units},
                                {"threads", threads.threads()},
                                {"seconds", seconds}});
    }
}

} // namespace

Action addPatchesCommand(CLI::App& app) {
    auto o = std::make_shared<PatchesOptions>();
    CLI::App* sub = app.add_subcommand("patches", "Fit bicubic B-spline patches to a closed mesh, one per Reeb graph arc");
    sub->add_option("input", o->input, "Input .obj or .ply: a closed manifold mesh (triangles, quads, n-gons)")->required();
    sub->add_option("-o,--output", o->output, "Output .obj with the patches as free-form surfaces (cstype bspline)")->required();
    sub->add_option("--axis", o->axis, "Height axis: x, y, z (default) or a direction X,Y,Z");
    sub->add_option("--reeb", o->reeb, "Write the Reeb graph as JSON to this file");
    sub->add_option("--preview", o->preview, "Write a tessellation of the patches (.obj, .ply or .pov)");
    sub->add_option("--grid-size", o->gridSize, "Ring grid per unit: auto (default) or U,V");
    sub->add_option("--persistence", o->persistence,
                    "Remove extremum-saddle pairs closer than this many mean edge lengths in height (default 0.5; 0 keeps all)");
    sub->add_option("--threads", o->threads, "Worker threads (0: all cores)");
    sub->add_option("--stats", o->stats, "Write statistics and stage timings as JSON to this file");
    return [o] { runPatches(*o); };
}

} // namespace vdbsurf::cli
