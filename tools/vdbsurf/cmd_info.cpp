// vdbsurf info IN.vdb|IN.obj|IN.ply|IN.json [--json]: what a file holds — a volume grid by grid
// (and, for a raster of a density scene, the scene's primitives as `edit` numbers them), a mesh by
// its counts and topology and whether subdivide and patches take it (and if not, why), a density
// scene by its primitives and extent.
#include "cli_common.h"

#include "vdbsurf/core/error.h"
#include "vdbsurf/density/scene.h"
#include "vdbsurf/density/scene_json.h"
#include "vdbsurf/mesh/mesh_check.h"
#include "vdbsurf/mesh/mesh_io.h"
#include "vdbsurf/reeb/closed_surface.h"
#include "vdbsurf/reeb/height_function.h"
#include "vdbsurf/reeb/patch_pipeline.h"
#include "vdbsurf/subdiv/sqrt2_subdivision.h"
#include "vdbsurf/vdb/vdb_file.h"

#include <nlohmann/json.hpp>

#include <array>
#include <iomanip>
#include <iostream>
#include <sstream>

namespace vdbsurf::cli {

namespace {

std::string vecText(const Vec3d& v) {
    std::ostringstream s;
    s << std::setprecision(6) << "(" << v.x << ", " << v.y << ", " << v.z << ")";
    return s.str();
}

std::string voxelText(const Vec3d& v) {
    std::ostringstream s;
    s << std::setprecision(6);
    if (v.x == v.y && v.y == v.z) s << v.x;
    else s << v.x << " x " << v.y << " x " << v.z;
    return s.str();
}

std::string numberText(double v) {
    std::ostringstream s;
    s << std::setprecision(6) << v;
    return s.str();
}

std::string coreSize(const Primitive& p) {
    switch (p.core) {
    case CoreShape::Ellipsoid: return "radii " + vecText(p.size);
    case CoreShape::Box: return "half extents " + vecText(p.size);
    case CoreShape::Capsule: return "half length " + numberText(p.size.x) + ", radius " + numberText(p.size.y);
    }
    return "?";
}

// The primitives as `edit --set N.field=value` numbers them, one row each.
void printPrimitives(const std::vector<Primitive>& prims) {
    std::vector<std::array<std::string, 9>> rows{{"#", "name", "core", "size", "center", "rotation", "falloff", "weight", "op"}};
    for (std::size_t i = 0; i < prims.size(); ++i) {
        const Primitive& p = prims[i];
        rows.push_back({std::to_string(i), p.name.empty() ? "-" : p.name, coreName(p.core), coreSize(p), vecText(p.center),
                        vecText(p.rotationDegrees), numberText(p.falloff), numberText(p.weight), p.op == DensityOp::Add ? "add" : "subtract"});
    }
    std::array<std::size_t, 9> width{};
    for (const auto& r : rows)
        for (std::size_t c = 0; c < r.size(); ++c) width[c] = std::max(width[c], r[c].size());
    for (const auto& r : rows) {
        std::cout << "  ";
        for (std::size_t c = 0; c + 1 < r.size(); ++c) std::cout << std::left << std::setw(int(width[c])) << r[c] << "  ";
        std::cout << r.back() << "\n";
    }
}

// The primitives in the scene file's own form, each with its number.
nlohmann::json primitivesJson(const std::vector<Primitive>& prims) {
    nlohmann::json list = nlohmann::json::parse(sceneToJsonText(prims, std::nullopt))["primitives"];
    for (std::size_t i = 0; i < list.size(); ++i) list[i]["index"] = i;
    return list;
}

void describeScene(const std::string& path, bool json) {
    const DensityScene scene = readSceneFile(path);
    const std::vector<Primitive>& prims = scene.primitives();
    std::size_t subtract = 0;
    for (const Primitive& p : prims) subtract += p.op == DensityOp::Subtract;
    const Box3 d = scene.domain();
    if (json) {
        nlohmann::json j{{"file", path},
                         {"kind", "density scene"},
                         {"primitives", primitivesJson(prims)},
                         {"influence_bbox", {{d.min.x, d.min.y, d.min.z}, {d.max.x, d.max.y, d.max.z}}},
                         {"voxel_size", scene.voxelSize() ? nlohmann::json(*scene.voxelSize()) : nlohmann::json(nullptr)}};
        std::cout << j.dump(2) << "\n";
        return;
    }
    std::cout << path << ": a density scene of " << prims.size() << (prims.size() == 1 ? " primitive" : " primitives") << " ("
              << prims.size() - subtract << " adding, " << subtract << " subtracting)\n";
    std::cout << "  influence bbox " << vecText(d.min) << " .. " << vecText(d.max) << "\n";
    if (scene.voxelSize()) std::cout << "  voxel size " << *scene.voxelSize() << " (the scene's own, for mesh and rasterize)\n";
    else std::cout << "  no voxel size of its own: mesh and rasterize need --voxel-size\n";
    printPrimitives(prims);
}

// Whether a job takes the mesh: "" if so, else the error it would stop with (without the file
// name, which the report already gives).
template <typename Job>
std::string refusal(Job&& job) {
    try {
        job();
        return "";
    } catch (const Error& e) {
        return e.message();
    }
}

void describeMesh(const std::string& path, bool json) {
    const Mesh mesh = readMesh(path);
    const MeshTopology t = checkTopology(mesh);
    const std::size_t triangles = mesh.countPolygonsOfSize(3), quads = mesh.countPolygonsOfSize(4);
    const std::size_t used = mesh.points.size() - t.unusedVertices, components = countComponents(mesh);
    const long euler = long(used) - long(t.edges) + long(mesh.polygonCount());
    const bool closed = t.closedManifoldOriented() && t.degeneratePolygons == 0;
    // A closed orientable surface of c pieces has Euler characteristic 2c - 2g.
    const long genus = closed ? (2 * long(components) - euler) / 2 : -1;
    const std::size_t coincident = countCoincidentPoints(mesh);
    const std::string subdivide = refusal([&] { Sqrt2Subdivider s(mesh, path); });
    reeb::ClosedSurface surface;
    // As `patches` runs by default: along its default axis.
    const std::string patches = refusal([&] {
        surface = reeb::buildClosedSurface(mesh, path);
        reeb::requirePiecesSpanHeights(surface, reeb::makeHeightFunction(surface, reeb::PatchJob().axis), path);
    });
    const Box3 b = mesh.bounds();
    if (json) {
        nlohmann::json j{{"file", path},
                         {"kind", "mesh"},
                         {"vertices", mesh.points.size()},
                         {"polygons", mesh.polygonCount()},
                         {"triangles", triangles},
                         {"quads", quads},
                         {"other_polygons", mesh.polygonCount() - triangles - quads},
                         {"bbox", {{b.min.x, b.min.y, b.min.z}, {b.max.x, b.max.y, b.max.z}}},
                         {"edges", t.edges},
                         {"boundary_edges", t.boundaryEdges},
                         {"non_manifold_edges", t.nonManifoldEdges},
                         {"inconsistent_edges", t.inconsistentEdges},
                         {"non_manifold_vertices", t.nonManifoldVertices},
                         {"folded_vertices", t.foldedVertices},
                         {"degenerate_polygons", t.degeneratePolygons},
                         {"unused_vertices", t.unusedVertices},
                         {"coincident_points", coincident},
                         {"components", components},
                         {"euler_characteristic", euler},
                         {"closed_manifold_oriented", closed},
                         {"genus", closed ? nlohmann::json(genus) : nlohmann::json(nullptr)},
                         {"subdivide", subdivide.empty() ? nlohmann::json(true) : nlohmann::json(subdivide)},
                         {"patches", patches.empty() ? nlohmann::json(true) : nlohmann::json(patches)},
                         {"patches_merged_points", surface.mergedPoints}};
        std::cout << j.dump(2) << "\n";
        return;
    }
    std::cout << path << ": a mesh of " << mesh.points.size() << " vertices and " << mesh.polygonCount() << " polygons (" << triangles
              << " triangles, " << quads << " quads, " << mesh.polygonCount() - triangles - quads << " larger)\n";
    std::cout << "  bbox " << vecText(b.min) << " .. " << vecText(b.max) << "\n";
    std::cout << "  " << t.edges << " edges: " << t.boundaryEdges << " on a boundary, " << t.nonManifoldEdges << " of three or more polygons, "
              << t.inconsistentEdges << " against the orientation\n";
    std::cout << "  " << t.nonManifoldVertices << " non-manifold vertices, " << t.foldedVertices << " folds, " << t.degeneratePolygons
              << " degenerate polygons, " << t.unusedVertices << " unused vertices, " << coincident
              << " points at an earlier point's position\n";
    std::cout << "  " << components << (components == 1 ? " piece" : " pieces") << ", Euler characteristic " << euler;
    if (closed) std::cout << "; closed, manifold and oriented, genus " << genus;
    std::cout << "\n";
    std::cout << "  subdivide: " << (subdivide.empty() ? "takes it" : "refuses it: " + subdivide) << "\n";
    std::cout << "  patches: "
              << (!patches.empty()           ? "refuses it: " + patches
                  : surface.mergedPoints > 0 ? "takes it with its " + std::to_string(surface.mergedPoints) + " coincident points merged"
                                             : "takes it")
              << "\n";
}

} // namespace

Action addInfoCommand(CLI::App& app) {
    struct Options {
        std::string input;
        bool json = false;
        bool verify = false;
    };
    auto opt = std::make_shared<Options>();
    CLI::App* sub = app.add_subcommand("info", "List the grids of a .vdb file (name, type, class, voxel size, active voxels, world "
                                               "bounds; a raster's scene), describe a mesh (counts, topology, what subdivide and "
                                               "patches make of it), or list a density scene's primitives");
    sub->add_option("input", opt->input, "The .vdb, .obj, .ply or scene .json file")->required();
    sub->add_flag("--json", opt->json, "Print JSON instead of a table");
    sub->add_flag("--verify", opt->verify, "Read every grid in full (slower), so damaged or truncated data is reported");
    return [opt] {
        const MeshFormat format = meshFormatOf(opt->input);
        if (format == MeshFormat::Obj || format == MeshFormat::Ply) {
            describeMesh(opt->input, opt->json);
            return;
        }
        if (opt->input.size() > 5 && opt->input.substr(opt->input.size() - 5) == ".json") {
            describeScene(opt->input, opt->json);
            return;
        }
        const auto grids = summarizeVdbFile(opt->input, opt->verify);
        // A raster's scene, as `edit` reads it (a file whose scene does not parse is reported so).
        auto sceneOf = [&](const GridSummary& g) {
            return parseSceneText(g.scene, opt->input + " (grid '" + g.name + "', its scene)").primitives();
        };
        if (opt->json) {
            nlohmann::json out = nlohmann::json::array();
            for (const auto& g : grids) {
                nlohmann::json j{{"name", g.name}, {"type", g.valueType}, {"class", g.gridClass},
                                 {"voxel_size", {g.voxelSize.x, g.voxelSize.y, g.voxelSize.z}},
                                 {"transform", g.frustum ? "frustum" : "linear"}, {"active_voxels", g.activeVoxels},
                                 {"meshable", g.scalar}};
                if (!g.empty)
                    j["world_bbox"] = {{g.worldBounds.min.x, g.worldBounds.min.y, g.worldBounds.min.z},
                                       {g.worldBounds.max.x, g.worldBounds.max.y, g.worldBounds.max.z}};
                else
                    j["world_bbox"] = nullptr;
                if (!g.scene.empty()) j["scene"] = {{"surface_only", g.surfaceOnly}, {"primitives", primitivesJson(sceneOf(g))}};
                out.push_back(j);
            }
            std::cout << nlohmann::json{{"file", opt->input}, {"grids", out}}.dump(2) << "\n";
            return;
        }
        std::cout << opt->input << ": " << grids.size() << (grids.size() == 1 ? " grid" : " grids") << "\n";
        std::size_t wName = 4, wType = 4, wClass = 5, wVoxel = 10;
        for (const auto& g : grids) {
            wName = std::max(wName, g.name.size());
            wType = std::max(wType, g.valueType.size());
            wClass = std::max(wClass, g.gridClass.size());
            wVoxel = std::max(wVoxel, voxelText(g.voxelSize).size());
        }
        std::cout << "  " << std::left << std::setw(int(wName)) << "name" << "  " << std::setw(int(wType)) << "type" << "  "
                  << std::setw(int(wClass)) << "class" << "  " << std::setw(int(wVoxel)) << "voxel size" << "  " << std::right
                  << std::setw(13) << "active voxels" << "  world bbox\n";
        for (const auto& g : grids) {
            std::cout << "  " << std::left << std::setw(int(wName)) << g.name << "  " << std::setw(int(wType)) << g.valueType
                      << "  " << std::setw(int(wClass)) << g.gridClass << "  " << std::setw(int(wVoxel)) << voxelText(g.voxelSize)
                      << "  " << std::right << std::setw(13) << g.activeVoxels << "  "
                      << (g.empty ? std::string("(empty)") : vecText(g.worldBounds.min) + " .. " + vecText(g.worldBounds.max))
                      << "\n";
        }
        for (const auto& g : grids)
            if (g.frustum)
                std::cout << "  " << g.name << ": a camera frustum's transform, its voxel size at the near plane's centre (voxels "
                          << "widen with depth)" << (g.scalar ? "; meshed on its voxels, the mesh mapped through the frustum" : "")
                          << "\n";
        for (const auto& g : grids) {
            if (g.scene.empty()) continue;
            const std::vector<Primitive> prims = sceneOf(g);
            std::cout << "  " << g.name << ": rasterized by vdbsurf (" << (g.surfaceOnly ? "surface only" : "full") << ") from a scene of "
                      << prims.size() << (prims.size() == 1 ? " primitive" : " primitives")
                      << "; `vdbsurf edit` changes them by these numbers (--set N.field=value, --remove N):\n";
            printPrimitives(prims);
        }
    };
}

} // namespace vdbsurf::cli
