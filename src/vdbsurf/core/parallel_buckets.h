// Items grouped by bucket in parallel, by counting: one scan counts each bucket's items, the
// prefix sums place the buckets, a second scan fills them. No vector per bucket, and no serial
// pass over the items (the weld groups the corners at welded vertices so, twice).
#pragma once
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

namespace vdbsurf {

// Bucket b's items end up in items[first[b] .. first[b + 1]). `scan(put)` must call
// put(bucket, make) for every item, the same calls each time (it runs twice, in parallel as it
// likes); `make()` gives the item and is only called by the filling scan. The order of the items
// within a bucket depends on the threads: sort them where it matters.
template <typename Item, typename Scan>
void fillBuckets(std::size_t buckets, Scan&& scan, std::vector<std::uint32_t>& first, std::vector<Item>& items) {
    std::unique_ptr<std::atomic<std::uint32_t>[]> fill(new std::atomic<std::uint32_t>[buckets]);
    for (std::size_t b = 0; b < buckets; ++b) fill[b].store(0, std::memory_order_relaxed);
    scan([&](std::uint32_t bucket, auto&&) { fill[bucket].fetch_add(1, std::memory_order_relaxed); });
    first.assign(buckets + 1, 0);
    for (std::size_t b = 0; b < buckets; ++b) {
        first[b + 1] = first[b] + fill[b].load(std::memory_order_relaxed);
        fill[b].store(first[b], std::memory_order_relaxed);
    }
    items.resize(first.back());
    scan([&](std::uint32_t bucket, auto&& make) { items[fill[bucket].fetch_add(1, std::memory_order_relaxed)] = make(); });
}

} // namespace vdbsurf
