// How much memory the machine can still give this process, so that long builds stop with an
// error while they can: past it the kernel's out-of-memory killer ends the process without one.
#pragma once
#include <cstddef>
#include <optional>

namespace vdbsurf {

// The kernel's estimate of memory available without swapping (MemAvailable in /proc/meminfo);
// none where the system does not say.
std::optional<std::size_t> availableMemoryBytes();

// The bytes a long build may use: `limit` when it is given (> 0), else 80 % of the memory
// available now, leaving room for everything else; 0 where the system does not say (no limit).
double memoryBudgetBytes(double limit = 0);

} // namespace vdbsurf
