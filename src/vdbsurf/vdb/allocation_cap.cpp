#include "vdbsurf/vdb/allocation_cap.h"

#include <cstdlib>
#include <new>

namespace vdbsurf {
namespace {
thread_local std::size_t tCap = 0; // 0: no cap
}

AllocationCap::AllocationCap(std::size_t maxBytes) : mPrevious(tCap) { tCap = maxBytes; }
AllocationCap::~AllocationCap() { tCap = mPrevious; }

namespace detail {
void* cappedAllocate(std::size_t n) {
    if (tCap != 0 && n > tCap) throw std::bad_alloc();
    void* p = std::malloc(n ? n : 1);
    if (!p) throw std::bad_alloc();
    return p;
}
} // namespace detail

} // namespace vdbsurf

// Replacements of the global allocation functions (C++ [replacement.functions]); they behave as
// the standard ones except under an AllocationCap. The aligned forms are left to the library.
void* operator new(std::size_t n) { return vdbsurf::detail::cappedAllocate(n); }
void* operator new[](std::size_t n) { return vdbsurf::detail::cappedAllocate(n); }
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
