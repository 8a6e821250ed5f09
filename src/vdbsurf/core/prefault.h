// Fresh memory in parallel. The kernel maps a page of fresh memory on its first touch, a fault a
// page (~2 µs each on the machines measured); a std::vector grown by resize() takes every one of
// them on the calling thread as it value-initialises. The mesher's output arrays alone were
// ~1,400 faults (3.4 ms) on one thread while the other waited. Here the kernel maps a vector's new
// pages first, in batches and on all threads (MADV_POPULATE_WRITE, Linux 5.14); where it cannot
// (an older kernel, another system) nothing happens and the first touch faults as before.
#pragma once
#include <cstddef>
#include <vector>

namespace vdbsurf {

// Has the kernel map the whole pages of [begin, begin + bytes) writable, in parallel chunks.
// Only names memory, through the kernel: writes no object. Small ranges are left alone.
void prefaultPages(void* begin, std::size_t bytes);

// Room for n elements in v, the part past its size mapped in parallel.
template <typename T, typename A>
void reservePrefaulted(std::vector<T, A>& v, std::size_t n) {
    if (n > v.capacity()) v.reserve(n);
    if (n > v.size()) prefaultPages(v.data() + v.size(), (n - v.size()) * sizeof(T));
}

// v.resize(n) (or v.resize(n, value)) with the memory it grows into mapped first in parallel.
template <typename T, typename A>
void resizePrefaulted(std::vector<T, A>& v, std::size_t n) {
    reservePrefaulted(v, n);
    v.resize(n);
}
template <typename T, typename A>
void resizePrefaulted(std::vector<T, A>& v, std::size_t n, const T& value) {
    reservePrefaulted(v, n);
    v.resize(n, value);
}

// std::vector<T>(n, value), its memory mapped first in parallel.
template <typename T>
std::vector<T> prefaultedVector(std::size_t n, const T& value = T()) {
    std::vector<T> v;
    resizePrefaulted(v, n, value);
    return v;
}

} // namespace vdbsurf
