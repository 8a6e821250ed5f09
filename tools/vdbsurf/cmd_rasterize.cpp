// vdbsurf rasterize: a density scene (.json) to a sparse fog volume (.vdb, grid "density").
// vdbsurf edit: change, add or remove primitives of a rasterized scene, recomputing only the
// leaves they touch.
#include "cli_common.h"

#include "vdbsurf/core/atomic_file.h"
#include "vdbsurf/core/cancel.h"
#include "vdbsurf/core/error.h"
#include "vdbsurf/core/threads.h"
#include "vdbsurf/density/raster_file.h"
#include "vdbsurf/density/scene_json.h"
#include "vdbsurf/mesh/mesh_io.h"

#include <fstream>
#include <sstream>

namespace vdbsurf::cli {

namespace {

struct RasterizeOptions {
    std::string input, output;
    std::optional<double> voxelSize;
    bool surfaceOnly = false;
    int threads = 0;
};

struct EditOptions {
    std::string input, output, sceneOut;
    std::vector<std::string> set, add;
    std::vector<int> remove;
    int threads = 0;
};

std::string describe(const RasterStats& s) {
    std::ostringstream o;
    o << s.leavesEvaluated << " leaves evaluated (" << s.voxelsEvaluated << " voxels summed";
    // An edit corrects a voxel by the changed primitives alone where nothing else reaches it.
    if (s.voxelsUpdated) o << ", " << s.voxelsUpdated << " corrected by the changed primitives";
    o << "), " << s.leafTiles << " leaf tiles, " << s.nodeTiles << " 128^3 tiles, " << s.seconds << " s";
    return o.str();
}

void requireVdbOutput(const std::string& path) {
    if (meshFormatOf(path) != MeshFormat::Vdb) throw Error(path, "the output must be a .vdb file");
    checkWritableTarget(path);
}

// A raster kept only near the 0.5 surface keeps nothing where no density reaches 0.5 (weights
// too low to add up to it): an error naming the scene, before any file is written, rather than
// an empty grid. A full raster of such a scene holds its density, and says it has no surface.
void checkSurface(const DensityRaster& raster, bool surfaceOnly, const std::string& name) {
    const DensityScene& scene = raster.scene();
    if (surfaceOnly && raster.empty())
        throw Error(name, "has no surface: no density reaches 0.5 (" + valueRangeText(scene) +
                              "), so --surface-only keeps nothing; raise a weight, or rasterize without --surface-only for the density alone");
    if (!surfaceOnly && !(scene.bounds(scene.domain()).hi >= 0.5))
        note("no density reaches 0.5 (" + valueRangeText(scene) + "): the grid holds density but no surface");
}

void runRasterize(const RasterizeOptions& o) {
    if (o.threads < 0) throw Error("--threads", "must be 0 (all cores) or a positive number");
    requireVdbOutput(o.output);
    ThreadLimit threads(o.threads);
    const DensityScene scene = readSceneFile(o.input);
    const std::optional<double> h = o.voxelSize ? o.voxelSize : scene.voxelSize();
    if (!h) throw Error("--voxel-size", "is required (or give \"voxel_size\" in " + o.input + ")");
    RasterOptions ro;
    ro.voxelSize = *h;
    ro.surfaceOnly = o.surfaceOnly;
    ro.cancel = &processCancelToken();
    const DensityRaster raster(scene, ro);
    processCancelToken().check();
    checkSurface(raster, o.surfaceOnly, o.input);
    writeDensityVdb(o.output, raster, o.surfaceOnly, o.input);
    note("wrote " + o.output + ": grid 'density' (fog, surface at 0.5), voxel size " + messageNumber(*h) +
         (o.surfaceOnly ? ", values only near the surface" : "") + "; " + describe(raster.stats()));
}

void runEdit(const EditOptions& o) {
    if (o.threads < 0) throw Error("--threads", "must be 0 (all cores) or a positive number");
    if (o.set.empty() && o.add.empty() && o.remove.empty()) throw Error("edit", "give at least one --set, --add or --remove");
    requireVdbOutput(o.output);
    if (!o.sceneOut.empty()) checkWritableTarget(o.sceneOut);
    ThreadLimit threads(o.threads);
    const DensityFile file = readDensityVdb(o.input);
    const std::string source = o.input + ":density";
    const DensityScene before = parseSceneText(file.sceneJson, source);

    // Edits apply to the scene's JSON and are validated there, so they meet the same checks as
    // a scene file: --set first (by the numbers the scene had), then --remove, then --add.
    std::string json = file.sceneJson;
    for (const std::string& a : o.set) json = applySceneAssignment(json, a, source);
    std::vector<Primitive> prims = parseSceneText(json, source).primitives();
    // By the numbers the scene had: removed from the highest down, so each number still holds.
    std::vector<int> removed = o.remove;
    std::sort(removed.rbegin(), removed.rend());
    const std::size_t count = prims.size();
    for (std::size_t i = 0; i < removed.size(); ++i) {
        if (removed[i] < 0 || std::size_t(removed[i]) >= count)
            throw Error("--remove", "no primitive " + std::to_string(removed[i]) + " (the scene has " + std::to_string(count) +
                                        ", numbered from 0)");
        if (i > 0 && removed[i] == removed[i - 1]) throw Error("--remove", "primitive " + std::to_string(removed[i]) + " is given twice");
        prims.erase(prims.begin() + removed[i]);
    }
    // Each added primitive is checked alone (numbered as it will be), so it may subtract: a hole
    // carved into the raster. (Parsed as a scene of its own, it needed an "add" op.)
    for (const std::string& text : o.add) prims.push_back(parsePrimitiveText(text, prims.size(), "--add"));
    const std::string edited = source + ", edited"; // how the edited scene is named in its errors
    const DensityScene after(prims, edited, before.voxelSize());

    RasterOptions ro;
    ro.voxelSize = file.voxelSize;
    ro.surfaceOnly = file.surfaceOnly;
    ro.cancel = &processCancelToken();
    DensityRaster raster(before, ro, file.grid);
    const RasterStats& st = raster.update(after);
    processCancelToken().check();
    checkSurface(raster, file.surfaceOnly, edited);
    writeDensityVdb(o.output, raster, file.surfaceOnly, source);
    note("wrote " + o.output + ": " + std::to_string(st.leavesRecomputed) + " leaves recomputed; " + describe(st));
    if (!o.sceneOut.empty()) {
        AtomicFile target(o.sceneOut);
        {
            std::ofstream out(target.tempPath());
            out << sceneToJsonText(after.primitives(), after.voxelSize());
            out.close();
            if (!out) throw Error(o.sceneOut, "cannot write");
        }
        target.commit();
        note("wrote " + o.sceneOut);
    }
}

} // namespace

Action addRasterizeCommand(CLI::App& app) {
    auto o = std::make_shared<RasterizeOptions>();
    CLI::App* sub = app.add_subcommand("rasterize", "Rasterize a density scene (.json) sparsely into a fog volume (.vdb)");
    sub->add_option("input", o->input, "Scene .json file")->required();
    sub->add_option("-o,--output", o->output, "Output .vdb (grid 'density', fog, surface at 0.5)")->required();
    sub->add_option("--voxel-size", o->voxelSize, "Voxel size in world units (default: the scene's voxel_size)");
    sub->add_flag("--surface-only", o->surfaceOnly, "Compute values only where the 0.5 surface can be; fill the rest by side");
    sub->add_option("--threads", o->threads, "Worker threads (0: all cores)");
    return [o] { runRasterize(*o); };
}

Action addEditCommand(CLI::App& app) {
    auto o = std::make_shared<EditOptions>();
    CLI::App* sub = app.add_subcommand(
        "edit", "Change primitives of a rasterized scene (.vdb from rasterize), recomputing only the leaves they touch");
    sub->add_option("input", o->input, "A .vdb written by vdbsurf rasterize")->required();
    sub->add_option("-o,--output", o->output, "Output .vdb")->required();
    sub->add_option("--set", o->set,
                    "N.field=value, e.g. 0.center=1,0,0 or 1.op=subtract (repeatable; N as `vdbsurf info INPUT` numbers the primitives)");
    sub->add_option("--remove", o->remove, "Remove primitive N (repeatable)");
    sub->add_option("--add", o->add, "Add a primitive given as JSON, e.g. '{\"core\":\"box\",...}' (repeatable)");
    sub->add_option("--scene-out", o->sceneOut, "Also write the edited scene as .json");
    sub->add_option("--threads", o->threads, "Worker threads (0: all cores)");
    return [o] { runEdit(*o); };
}

} // namespace vdbsurf::cli
