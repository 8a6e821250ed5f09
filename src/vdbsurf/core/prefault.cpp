#include "vdbsurf/core/prefault.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cstdint>
#include <sys/mman.h>
#include <unistd.h>

namespace vdbsurf {

namespace {

// Below this a batch saves less than the tasks cost.
constexpr std::size_t kLeastBytes = std::size_t(256) << 10;
// One task's share: enough pages for a batch to pay, small enough for both threads to share
// the mesher's arrays (1–6 MB).
constexpr std::size_t kChunkBytes = std::size_t(256) << 10;

} // namespace

void prefaultPages(void* begin, std::size_t bytes) {
#ifdef MADV_POPULATE_WRITE
    if (bytes < kLeastBytes) return;
    static const std::uintptr_t page = std::uintptr_t(sysconf(_SC_PAGESIZE));
    // Whole pages only: the partial pages at either end may hold other objects, and the first
    // touch maps them anyway.
    const std::uintptr_t first = (std::uintptr_t(begin) + page - 1) & ~(page - 1);
    const std::uintptr_t last = (std::uintptr_t(begin) + bytes) & ~(page - 1);
    if (last <= first) return;
    const std::size_t chunks = (last - first + kChunkBytes - 1) / kChunkBytes;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, chunks, 1), [&](const tbb::blocked_range<std::size_t>& r) {
        const std::uintptr_t b = first + r.begin() * kChunkBytes;
        const std::uintptr_t e = std::min<std::uintptr_t>(last, first + r.end() * kChunkBytes);
        // (A failure — EINVAL before Linux 5.14 — leaves the pages to their first touch.)
        madvise(reinterpret_cast<void*>(b), e - b, MADV_POPULATE_WRITE);
    });
#else
    (void)begin;
    (void)bytes;
#endif
}

} // namespace vdbsurf
