// How much memory the machine can still give this process, so that long builds stop with an
// error while they can: past it the kernel's out-of-memory killer ends the process without one.
#pragma once
#include <cstddef>
#include <optional>

namespace vdbsurf {

// The kernel's estimate of memory available without swapping (MemAvailable in /proc/meminfo);
// none where the system does not say.
std::optional<std::size_t> availableMemoryBytes();

} // namespace vdbsurf
