// A per-thread cap on the size of single allocations, in force while a file's structure is read.
// OpenVDB trusts the lengths it reads; on a truncated or damaged file a length read past the end
// is garbage, and a multi-gigabyte buffer would be allocated (and filled) before any check. No
// structure read from a file can be larger than the file, so allocations beyond the cap are
// refused with std::bad_alloc, which the reader reports as a damaged file.
#pragma once
#include <cstddef>

namespace vdbsurf {

class AllocationCap {
public:
    explicit AllocationCap(std::size_t maxBytes);
    ~AllocationCap();
    AllocationCap(const AllocationCap&) = delete;
    AllocationCap& operator=(const AllocationCap&) = delete;

private:
    std::size_t mPrevious;
};

} // namespace vdbsurf
