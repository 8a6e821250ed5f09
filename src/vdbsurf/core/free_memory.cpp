#include "vdbsurf/core/free_memory.h"

#include <fstream>
#include <string>

namespace vdbsurf {

std::optional<std::size_t> availableMemoryBytes() {
    std::ifstream in("/proc/meminfo");
    std::string key, unit;
    std::size_t value = 0;
    while (in >> key >> value) {
        std::getline(in, unit);
        if (key == "MemAvailable:") return value * 1024; // the file counts kB (KiB)
    }
    return std::nullopt;
}

} // namespace vdbsurf
