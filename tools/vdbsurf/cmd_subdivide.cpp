// vdbsurf subdivide: √2-subdivision of an OBJ/PLY mesh, uniform (--levels / --steps) or
// view-dependent (camera options without --levels/--steps), to .obj, .ply or a POV-Ray scene.
#include "cli_common.h"

#include "vdbsurf/core/atomic_file.h"
#include "vdbsurf/core/cancel.h"
#include "vdbsurf/core/progress.h"
#include "vdbsurf/core/error.h"
#include "vdbsurf/core/threads.h"
#include "vdbsurf/mesh/mesh_io.h"
#include "vdbsurf/subdiv/sqrt2_subdivision.h"
#include "vdbsurf/subdiv/view_refine.h"

#include <optional>
#include <sstream>

namespace vdbsurf::cli {

namespace {

struct SubdivideOptions {
    std::string input, output, stats;
    std::optional<int> levels, steps;
    std::string cameraPos, cameraTarget, cameraUp = "0,1,0", image = "640,480";
    double fov = 45;
    int frontDepth = 4, silhouetteDepth = 8;
    double stopPixels = 1.0;
    int threads = 0;
    bool mergePoints = false;
};

Vec3d parseVec(const std::string& option, const std::string& text) {
    const std::vector<double> v = parseNumbers(option, text, 3);
    return {v[0], v[1], v[2]};
}

void runSubdivide(const SubdivideOptions& o) {
    const auto t0 = Clock::now();
    if (o.threads < 0) throw Error("--threads", "must be 0 (all cores) or a positive number");
    const MeshFormat format = meshFormatOf(o.output);
    if (format != MeshFormat::Obj && format != MeshFormat::Ply && format != MeshFormat::Pov)
        throw Error(o.output, "unsupported output format; use .obj, .ply or .pov (a POV-Ray scene)");
    if (o.levels && o.steps) throw Error("--levels", "give --levels or --steps, not both");
    if (o.levels && (*o.levels < 0 || *o.levels > 8)) throw Error("--levels", "must be between 0 and 8");
    if (o.steps && (*o.steps < 0 || *o.steps > 16)) throw Error("--steps", "must be between 0 and 16");
    if (o.frontDepth < 0 || o.frontDepth > 16) throw Error("--front-depth", "must be between 0 and 16");
    if (o.silhouetteDepth < 0 || o.silhouetteDepth > 16) throw Error("--silhouette-depth", "must be between 0 and 16");
    if (!(o.stopPixels >= 0)) throw Error("--stop-pixels", "must not be negative");
    const bool haveCamera = !o.cameraPos.empty() || !o.cameraTarget.empty();
    if (haveCamera && (o.cameraPos.empty() || o.cameraTarget.empty()))
        throw Error(o.cameraPos.empty() ? "--camera-pos" : "--camera-target", "a camera needs both --camera-pos and --camera-target");
    std::optional<ViewCamera> camera;
    if (haveCamera) {
        ViewCamera c;
        c.position = parseVec("--camera-pos", o.cameraPos);
        c.target = parseVec("--camera-target", o.cameraTarget);
        c.up = parseVec("--camera-up", o.cameraUp);
        c.fovDegrees = o.fov;
        const std::vector<double> size = parseNumbers("--image", o.image, 2);
        if (size[0] != double(int(size[0])) || size[1] != double(int(size[1]))) throw Error("--image", "width and height must be whole pixels");
        c.width = int(size[0]);
        c.height = int(size[1]);
        validateCamera(c, "camera");
        camera = c;
    }
    checkWritableTarget(o.output);
    if (!o.stats.empty()) checkWritableTarget(o.stats);
    ThreadLimit threads(o.threads);

    Mesh input = readMesh(o.input);
    // A file that stores a point per corner, or per side of a texture seam, is open along every
    // seam: each side subdivides as a boundary, and the seams show as creases. Joined on request
    // (a seam may be a crease on purpose); else said when there are any.
    const std::size_t coincident = o.mergePoints ? mergeCoincidentPoints(input) : countCoincidentPoints(input);
    if (coincident)
        note(o.input + ": " + std::to_string(coincident) + " points lie exactly where an earlier one does" +
             (o.mergePoints ? "; merged (--merge-points)"
                            : " (a point per corner or per side of a seam): their polygons are not joined there, and each side is "
                              "refined as a boundary; --merge-points joins them"));
    const bool viewDependent = camera && !o.levels && !o.steps;
    const int steps = o.steps ? *o.steps : 2 * (o.levels ? *o.levels : 2);
    Mesh out;
    ViewRefineReport view;
    std::string how;
    std::size_t splitVertices = 0;
    const auto tRefine = Clock::now();
    if (viewDependent) {
        ViewRefineOptions vo;
        vo.frontDepth = o.frontDepth;
        vo.silhouetteDepth = o.silhouetteDepth;
        vo.stopPixels = o.stopPixels;
        vo.cancel = &processCancelToken();
        out = subdivideForView(input, *camera, vo, o.input, &view);
        how = "view-dependent: front depth " + std::to_string(o.frontDepth) + ", silhouette depth " + std::to_string(o.silhouetteDepth) +
              " sqrt2 steps";
        std::ostringstream s;
        s << view.initialFront << " front and " << view.initialSilhouette << " silhouette faces of " << view.inputFaces << " ("
          << view.outsideView << " outside the view); faces refined per step:";
        for (std::size_t n : view.refinedPerStep) s << " " << n;
        note(s.str());
        splitVertices = view.splitVertices;
    } else {
        Sqrt2Subdivider s(input, o.input);
        splitVertices = s.splitVertices();
        s.checkUniformSteps(steps);
        Progress progress("sqrt2 steps", std::uint64_t(steps), &processCancelToken());
        for (int i = 0; i < steps; ++i) {
            processCancelToken().check();
            s.step();
            progress.advance(); // (checks the token too)
        }
        out = s.mesh();
        how = "uniform: " + std::to_string(steps) + " sqrt2 steps" + (steps % 2 == 0 ? " (" + std::to_string(steps / 2) + " Catmull-Clark levels)" : "");
    }
    const double secondsRefine = since(tRefine);
    if (splitVertices)
        note(o.input + ": " + std::to_string(splitVertices) +
             " non-manifold vertices (separate fans of polygons meeting at a point) were split, one copy per fan");
    processCancelToken().check();
    writeMesh(o.output, out, {std::string("vdbsurf ") + VDBSURF_VERSION, "source: " + o.input, "subdivision: " + how},
              camera ? &*camera : nullptr);
    std::ostringstream summary;
    summary << "wrote " << o.output << ": " << out.points.size() << " vertices, " << out.polygonCount() << " polygons (" << how << "; "
            << input.polygonCount() << " input polygons; " << secondsRefine << " s)";
    note(summary.str());
    if (!o.stats.empty()) {
        nlohmann::json j{{"input", o.input},
                         {"output", o.output},
                         {"mode", viewDependent ? "view" : "uniform"},
                         {"input_polygons", input.polygonCount()},
                         {"output_vertices", out.points.size()},
                         {"output_polygons", out.polygonCount()},
                         {"threads", threads.threads()},
                         {"split_vertices", splitVertices},
                         {"coincident_points", coincident},
                         {"merged_points", o.mergePoints ? coincident : 0},
                         {"seconds", {{"refine", secondsRefine}, {"total", since(t0)}}}};
        if (viewDependent)
            j["view"] = {{"front_depth", o.frontDepth},         {"silhouette_depth", o.silhouetteDepth},
                         {"initial_front", view.initialFront}, {"initial_silhouette", view.initialSilhouette},
                         {"outside_view", view.outsideView},   {"refined_per_step", view.refinedPerStep}};
        else
            j["steps"] = steps;
        writeJsonFile(o.stats, j);
    }
}

} // namespace

Action addSubdivideCommand(CLI::App& app) {
    auto o = std::make_shared<SubdivideOptions>();
    CLI::App* sub = app.add_subcommand("subdivide", "Refine a polygon mesh by sqrt2-subdivision (two steps = one Catmull-Clark level)");
    sub->add_option("input", o->input, "Input .obj or .ply (triangles, quads, n-gons; manifold)")->required();
    sub->add_option("-o,--output", o->output, "Output .obj, .ply or .pov (a POV-Ray scene with the camera)")->required();
    sub->add_option("--levels", o->levels, "Catmull-Clark levels (2 sqrt2 steps each; default 2 without a camera)");
    sub->add_option("--steps", o->steps, "sqrt2 steps (odd numbers stop at a half level)");
    sub->add_option("--camera-pos", o->cameraPos, "Camera position X,Y,Z; with --camera-target and no --levels/--steps, refine for this view");
    sub->add_option("--camera-target", o->cameraTarget, "Point the camera looks at, X,Y,Z");
    sub->add_option("--camera-up", o->cameraUp, "Camera up vector X,Y,Z (default 0,1,0)");
    sub->add_option("--fov", o->fov, "Horizontal field of view in degrees (default 45)");
    sub->add_option("--image", o->image, "Image size W,H in pixels (default 640,480)");
    sub->add_option("--front-depth", o->frontDepth, "sqrt2 steps for front-facing faces (default 4)");
    sub->add_option("--silhouette-depth", o->silhouetteDepth, "sqrt2 steps for silhouette faces (default 8)");
    sub->add_option("--stop-pixels", o->stopPixels, "Stop refining a face smaller than this on screen (default 1 pixel)");
    sub->add_flag("--merge-points", o->mergePoints,
                  "Join points at exactly equal positions first (files that store a point per corner or per side of a seam)");
    sub->add_option("--threads", o->threads, "Worker threads (0: all cores)");
    sub->add_option("--stats", o->stats, "Write statistics as JSON to this file");
    return [o] { runSubdivide(*o); };
}

} // namespace vdbsurf::cli
