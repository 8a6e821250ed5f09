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

double memoryBudgetBytes(double limit) {
    if (limit > 0) return limit;
    const std::optional<std::size_t> freeBytes = availableMemoryBytes();
    return freeBytes ? 0.8 * double(*freeBytes) : 0.0;
}

} // namespace vdbsurf
