// bench_subdiv: √2-subdivision against OpenSubdiv Far on the shared real meshes. Uniform: 2m √2
// steps against m Catmull-Clark levels (TopologyRefiner::RefineUniform + PrimvarRefiner), the
// same face count, in one run; both timed from the input mesh to refined positions and faces
// held in the library's own structure. View-dependent: faces and time against uniform
// refinement to the silhouette depth.
#include "bench_support.h"

#include "osd_catmark.h"
#include "vdbsurf/core/threads.h"
#include "vdbsurf/mesh/mesh_io.h"
#include "vdbsurf/subdiv/sqrt2_subdivision.h"
#include "vdbsurf/subdiv/view_refine.h"

#include <CLI/CLI.hpp>

#include <cmath>
#include <iostream>

using namespace vdbsurf;

int main(int argc, char** argv) {
    CLI::App app{"vdbsurf sqrt2-subdivision vs OpenSubdiv Far (Catmull-Clark), uniform and view-dependent"};
    int repeat = 3;
    bool quick = false;
    std::string json;
    std::vector<std::string> extra;
    int threads = 0;
    app.add_option("--repeat", repeat, "Runs per measurement (median time)");
    app.add_option("--threads", threads, "Threads for vdbsurf (0: all cores; OpenSubdiv Far refines serially)");
    app.add_flag("--quick", quick, "Fewer levels");
    app.add_option("--mesh", extra, "Further .obj/.ply meshes to include (repeatable)");
    app.add_option("--json", json, "Write the results as JSON");
    CLI11_PARSE(app, argc, argv);
    ThreadLimit limit(threads);

    std::vector<std::string> files;
    for (const char* f : {"mesh/spot.obj", "mesh/horse_quad.obj", "mesh/suzanne_mixed_open.obj", "mesh/bishop_quad_tri.obj"}) {
        const std::string path = bench::sharedData(f);
        if (path.empty()) std::cerr << "bench_subdiv: skipped " << f << ": ../shared/data is absent\n";
        else files.push_back(path);
    }
    files.insert(files.end(), extra.begin(), extra.end());
    if (files.empty()) {
        std::cerr << "bench_subdiv: no meshes (../shared/data absent and no --mesh given)\n";
        return 0;
    }

    bench::Table table({"mesh", "input faces", "method", "levels", "faces", "seconds", "vs OpenSubdiv"});
    for (const std::string& path : files) {
        const Mesh mesh = readMesh(path);
        const std::string name = path.substr(path.find_last_of('/') + 1);
        const int maxLevels = quick ? 2 : (mesh.polygonCount() > 100000 ? 2 : 4);
        for (int levels = 1; levels <= maxLevels; ++levels) {
            std::size_t osdFaces = 0, ourFaces = 0;
            // In turn, once a round; the ratio is the median of the rounds' (bench::Interleaved).
            const bench::Interleaved t = bench::measureInterleaved(
                repeat, {[&] { osdFaces = reference::catmullClark(mesh, levels).offsets.size() - 1; },
                         [&] {
                             Sqrt2Subdivider s(mesh, path);
                             for (int i = 0; i < 2 * levels; ++i) s.step();
                             ourFaces = s.faceCount();
                         }});
            const bench::Measure &osd = t.medians[0], &ours = t.medians[1];
            const double ratio = t.medianRatio(1, 0);
            table.add({name, std::to_string(mesh.polygonCount()), "OpenSubdiv Far", std::to_string(levels), std::to_string(osdFaces),
                       bench::fixed(osd.seconds, 4), "1"},
                      {{"mesh", name}, {"method", "osd"}, {"levels", levels}, {"faces", osdFaces}, {"seconds", osd.seconds}});
            table.add({name, std::to_string(mesh.polygonCount()), "vdbsurf sqrt2", std::to_string(levels), std::to_string(ourFaces),
                       bench::fixed(ours.seconds, 4), bench::fixed(ratio, 2)},
                      {{"mesh", name}, {"method", "sqrt2"}, {"levels", levels}, {"faces", ourFaces}, {"seconds", ours.seconds},
                       {"ratio_to_osd", ratio}});
        }
        // View-dependent: a camera in front of the mesh (framing it), against uniform refinement
        // to the silhouette depth.
        const ViewCamera camera = framingCamera(mesh.bounds());
        const ViewRefineOptions vo;
        std::size_t viewFaces = 0;
        const bench::Measure view = bench::measureMedian(repeat, [&] {
            viewFaces = subdivideForView(mesh, camera, vo, path).polygonCount();
        });
        // Uniform refinement to the silhouette depth grows the mesh 4x per level; beyond ~8 M faces
        // it only measures the machine's memory, so it is left out.
        const double uniformFaces = double(mesh.polygonCount()) * std::pow(4.0, vo.silhouetteDepth / 2);
        if (!quick && uniformFaces <= 8e6) {
            std::size_t uniformFaces = 0;
            const bench::Measure uniform = bench::measureMedian(1, [&] {
                Sqrt2Subdivider s(mesh, path);
                for (int i = 0; i < vo.silhouetteDepth; ++i) s.step();
                uniformFaces = s.faceCount();
            });
            table.add({name, std::to_string(mesh.polygonCount()), "sqrt2 uniform to silhouette depth", std::to_string(vo.silhouetteDepth / 2),
                       std::to_string(uniformFaces), bench::fixed(uniform.seconds, 4), "-"},
                      {{"mesh", name}, {"method", "sqrt2_uniform_silhouette_depth"}, {"steps", vo.silhouetteDepth}, {"faces", uniformFaces},
                       {"seconds", uniform.seconds}});
        }
        table.add({name, std::to_string(mesh.polygonCount()), "sqrt2 view-dependent (front 4, silhouette 8 steps)", "-",
                   std::to_string(viewFaces), bench::fixed(view.seconds, 4), "-"},
                  {{"mesh", name}, {"method", "sqrt2_view"}, {"front_depth", vo.frontDepth}, {"silhouette_depth", vo.silhouetteDepth},
                   {"faces", viewFaces}, {"seconds", view.seconds}});
    }
    std::cout << "bench_subdiv: vdbsurf on " << limit.threads() << " threads (OpenSubdiv Far serial), median of " << repeat
              << " rounds (the two in turn, once a round; ratios are the median of the rounds' ratios)\n";
    table.print();
    if (!json.empty()) table.writeJson(json, "bench_subdiv", {{"repeat", repeat}, {"threads", limit.threads()}});
    return 0;
}
