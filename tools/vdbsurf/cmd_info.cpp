// vdbsurf info IN.vdb [--json]: what a file holds, grid by grid.
#include "cli_common.h"

#include "vdbsurf/vdb/vdb_file.h"

#include <nlohmann/json.hpp>

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

} // namespace

Action addInfoCommand(CLI::App& app) {
    struct Options {
        std::string input;
        bool json = false;
        bool verify = false;
    };
    auto opt = std::make_shared<Options>();
    CLI::App* sub = app.add_subcommand("info", "List the grids of a .vdb file: name, type, class, voxel size, active voxels, world bounds");
    sub->add_option("input", opt->input, "The .vdb file")->required();
    sub->add_flag("--json", opt->json, "Print JSON instead of a table");
    sub->add_flag("--verify", opt->verify, "Read every grid in full (slower), so damaged or truncated data is reported");
    return [opt] {
        const auto grids = summarizeVdbFile(opt->input, opt->verify);
        if (opt->json) {
            nlohmann::json out = nlohmann::json::array();
            for (const auto& g : grids) {
                nlohmann::json j{{"name", g.name}, {"type", g.valueType}, {"class", g.gridClass},
                                 {"voxel_size", {g.voxelSize.x, g.voxelSize.y, g.voxelSize.z}},
                                 {"active_voxels", g.activeVoxels}, {"meshable", g.scalar}};
                if (!g.empty)
                    j["world_bbox"] = {{g.worldBounds.min.x, g.worldBounds.min.y, g.worldBounds.min.z},
                                       {g.worldBounds.max.x, g.worldBounds.max.y, g.worldBounds.max.z}};
                else
                    j["world_bbox"] = nullptr;
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
    };
}

} // namespace vdbsurf::cli
