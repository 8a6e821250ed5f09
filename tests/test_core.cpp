// core/prefault: a vector's fresh memory mapped in parallel before it is first touched.
#include "vdbsurf/core/prefault.h"
#include "vdbsurf/core/threads.h"

#include <catch2/catch.hpp>

#include <cerrno>
#include <cstdint>
#include <cstring>
#include <sys/mman.h>
#include <unistd.h>

using namespace vdbsurf;

namespace {

// How many of the pages of [p, p + bytes) are resident.
std::size_t residentPages(void* p, std::size_t bytes) {
    const std::size_t page = std::size_t(sysconf(_SC_PAGESIZE)), pages = (bytes + page - 1) / page;
    std::vector<unsigned char> in(pages);
    REQUIRE(mincore(p, bytes, in.data()) == 0);
    std::size_t count = 0;
    for (unsigned char c : in) count += c & 1u;
    return count;
}

} // namespace

TEST_CASE("prefaultPages maps the whole pages of a fresh range and writes nothing", "[core]") {
#ifndef MADV_POPULATE_WRITE
    WARN("skipped: this system has no MADV_POPULATE_WRITE");
#else
    const std::size_t page = std::size_t(sysconf(_SC_PAGESIZE)), pages = 300;
    void* region = mmap(nullptr, pages * page, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    REQUIRE(region != MAP_FAILED);
    char* bytes = static_cast<char*>(region);
    if (madvise(region, page, MADV_POPULATE_WRITE) != 0) {
        WARN("skipped: the kernel does not populate pages (errno " << errno << ")");
        munmap(region, pages * page);
        return;
    }
    REQUIRE(residentPages(region, pages * page) == 1);
    for (int threads : {1, 2}) {
        ThreadLimit limit(threads);
        // Fresh from page `at` on: the whole region on one thread, its upper half on two.
        // The range starts mid-page 1 and ends mid-page 298 (of 0..299): pages 2..297 are its
        // whole pages.
        const std::size_t at = threads == 1 ? 0 : 150;
        madvise(bytes + at * page, (pages - at) * page, MADV_DONTNEED); // fresh again
        std::memset(bytes + page + 100, 7, 10); // data the call must leave alone
        prefaultPages(bytes + page + 100, (pages - 3) * page);
        std::vector<unsigned char> in(pages);
        REQUIRE(mincore(region, pages * page, in.data()) == 0);
        for (std::size_t p = 2; p + 2 < pages; ++p) CHECK((in[p] & 1u) == 1u);
        CHECK((in[pages - 1] & 1u) == 0u); // past the range
        CHECK(bytes[page + 100] == 7);
        CHECK(bytes[page + 109] == 7);
        for (std::size_t p = 2; p + 2 < pages; ++p) CHECK(bytes[p * page] == 0);
    }
    // A range smaller than a batch is left to its first touch.
    madvise(region, pages * page, MADV_DONTNEED);
    prefaultPages(bytes, 16 * page);
    CHECK(residentPages(region, pages * page) == 0);
    munmap(region, pages * page);
#endif
}

TEST_CASE("resizePrefaulted grows a vector as resize does", "[core]") {
    std::vector<std::uint32_t> v = {5, 6, 7};
    resizePrefaulted(v, 500000);
    REQUIRE(v.size() == 500000);
    CHECK(v[0] == 5);
    CHECK(v[2] == 7);
    CHECK(v[3] == 0);
    CHECK(v.back() == 0);
    resizePrefaulted(v, 2, 9u); // shrinking keeps the front
    CHECK(v == std::vector<std::uint32_t>{5, 6});
    resizePrefaulted(v, 300000, 9u);
    CHECK(v[1] == 6);
    CHECK(v[2] == 9);
    CHECK(v.back() == 9);
    const std::vector<float> f = prefaultedVector(1000000, 2.5f);
    CHECK(f.size() == 1000000);
    CHECK(f.front() == 2.5f);
    CHECK(f.back() == 2.5f);
}
