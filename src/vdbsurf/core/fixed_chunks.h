// Parallel loops over fixed chunks of [0, n): chunk c is [c * size, min(n, (c + 1) * size))
// whatever the number of threads, so results kept per chunk and joined in chunk order are the
// same with any thread count.
#pragma once
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cstddef>

namespace vdbsurf {

inline std::size_t fixedChunkCount(std::size_t n, std::size_t size) { return (n + size - 1) / size; }

// body(chunk, begin, end) for every chunk, in parallel.
template <typename Body>
void forEachFixedChunk(std::size_t n, std::size_t size, Body&& body) {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, fixedChunkCount(n, size), 1), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t c = r.begin(); c < r.end(); ++c) body(c, c * size, std::min(n, (c + 1) * size));
    });
}

} // namespace vdbsurf
