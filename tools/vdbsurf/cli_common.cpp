#include "cli_common.h"

#include "vdbsurf/core/atomic_file.h"
#include "vdbsurf/core/error.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <sstream>

namespace vdbsurf::cli {

Globals& globals() {
    static Globals g;
    return g;
}

void note(const std::string& text) {
    if (!globals().quiet) std::cerr << "vdbsurf: " << text << "\n";
}

void writeJsonFile(const std::string& path, const nlohmann::json& j) {
    AtomicFile target(path);
    {
        std::ofstream out(target.tempPath());
        out << j.dump(2) << "\n";
        out.close();
        if (!out) throw Error(path, "cannot write");
    }
    target.commit();
}

std::vector<double> parseNumbers(const std::string& option, const std::string& text, std::size_t count) {
    std::vector<double> out;
    std::stringstream ss(text);
    std::string item;
    while (std::getline(ss, item, ',')) {
        const char* b = item.c_str();
        char* e = nullptr;
        const double v = std::strtod(b, &e);
        while (e && *e == ' ') ++e;
        if (e == b || *e != '\0' || !std::isfinite(v)) throw Error(option, "'" + item + "' is not a number");
        out.push_back(v);
    }
    if (out.size() != count)
        throw Error(option, "expects " + std::to_string(count) + " comma-separated numbers, got " + std::to_string(out.size()));
    return out;
}

Box3 parseBox(const std::string& option, const std::string& text) {
    const auto v = parseNumbers(option, text, 6);
    return {{v[0], v[1], v[2]}, {v[3], v[4], v[5]}};
}

namespace {

// What the user can change when a command runs out of memory.
std::string outOfMemoryHint(const std::string& command) {
    if (command == "mesh" || command == "compare" || command == "rasterize" || command == "edit") return " (try a larger --voxel-size)";
    if (command == "subdivide") return " (try fewer --levels or --steps, or a smaller --silhouette-depth)";
    return "";
}

} // namespace

int runGuarded(const std::function<void()>& body, const std::string& command) {
    try {
        body();
        return 0;
    } catch (const Cancelled&) {
        std::cerr << "vdbsurf: cancelled; no output written\n";
        return kExitCancelled;
    } catch (const Error& e) {
        std::cerr << "vdbsurf: error: " << e.what() << "\n";
        return kExitInput;
    } catch (const std::bad_alloc&) {
        std::cerr << "vdbsurf: error: " << command << ": out of memory" << outOfMemoryHint(command) << "\n";
        return kExitInput;
    } catch (const std::exception& e) {
        std::cerr << "vdbsurf: internal error: " << e.what() << "\n";
        return kExitInternal;
    }
}

} // namespace vdbsurf::cli
