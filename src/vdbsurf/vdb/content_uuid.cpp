#include "vdbsurf/vdb/content_uuid.h"

#include "vdbsurf/core/error.h"

#include <array>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <vector>

namespace vdbsurf {

namespace {

// OpenVDB's header: magic (8 bytes), file version, library major and minor (4 each), the grid
// offsets flag (1), then the UUID as 36 ASCII characters from format 218 on.
constexpr std::int64_t kMagic = 0x56444220;
constexpr std::uint32_t kAsciiUuid = 218;
constexpr std::size_t kUuidOffset = 21, kUuidLength = 36;

// Two independent 64-bit lanes over 8-byte words (a multiply–xorshift mix per word): fast
// enough for files of gigabytes straight after they were written, and the same on every run.
class ContentHash {
public:
    void add(const unsigned char* p, std::size_t n) {
        std::size_t i = 0;
        for (; mFill == 0 && i + 8 <= n; i += 8) { // whole words, little-endian as below
            std::uint64_t w = 0;
            for (int k = 0; k < 8; ++k) w |= std::uint64_t(p[i + std::size_t(k)]) << (8 * k);
            mWord = w;
            mFill = 8;
            flush();
        }
        for (; i < n; ++i) {
            mWord |= std::uint64_t(p[i]) << (8 * mFill);
            if (++mFill == 8) flush();
        }
    }
    std::array<std::uint64_t, 2> finish() {
        mWord |= std::uint64_t(0x80) << (8 * mFill); // the length's tail, so "ab" ≠ "ab\0"
        flush();
        return {mix(mA ^ mBytes), mix(mB + mBytes * 0x9e3779b97f4a7c15ull)};
    }

private:
    static std::uint64_t mix(std::uint64_t x) {
        x ^= x >> 33;
        x *= 0xff51afd7ed558ccdull;
        x ^= x >> 33;
        x *= 0xc4ceb9fe1a85ec53ull;
        return x ^ (x >> 33);
    }
    void flush() {
        mA = mix(mA ^ mWord) * 0x9e3779b97f4a7c15ull;
        mB = mix(mB + mWord * 0xd6e8feb86659fd93ull) ^ (mB >> 29);
        mBytes += mFill;
        mWord = 0;
        mFill = 0;
    }
    std::uint64_t mA = 0x243f6a8885a308d3ull, mB = 0x13198a2e03707344ull, mWord = 0, mBytes = 0;
    unsigned mFill = 0;
};

} // namespace

void stampContentUuid(const std::string& path) {
    std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
    if (!f) throw Error(path, "cannot be opened to set its identifier");
    std::array<unsigned char, kUuidOffset + kUuidLength> header{};
    f.read(reinterpret_cast<char*>(header.data()), std::streamsize(header.size()));
    std::int64_t magic;
    std::uint32_t version;
    std::memcpy(&magic, header.data(), 8);
    std::memcpy(&version, header.data() + 8, 4);
    if (!f || magic != kMagic || version < kAsciiUuid)
        throw Error(path, "is not a .vdb file with a text identifier (format 218 or later)");

    ContentHash hash;
    hash.add(header.data(), kUuidOffset);
    std::vector<unsigned char> buffer(1 << 20);
    while (f) {
        f.read(reinterpret_cast<char*>(buffer.data()), std::streamsize(buffer.size()));
        hash.add(buffer.data(), std::size_t(f.gcount()));
    }
    const std::array<std::uint64_t, 2> h = hash.finish();
    // RFC 9562: version 8 (custom) in the 13th hex digit, variant 10 in the 17th.
    unsigned char bytes[16];
    for (int i = 0; i < 8; ++i) {
        bytes[i] = static_cast<unsigned char>(h[0] >> (56 - 8 * i));
        bytes[8 + i] = static_cast<unsigned char>(h[1] >> (56 - 8 * i));
    }
    bytes[6] = static_cast<unsigned char>((bytes[6] & 0x0f) | 0x80);
    bytes[8] = static_cast<unsigned char>((bytes[8] & 0x3f) | 0x80);
    char text[kUuidLength + 1];
    std::snprintf(text, sizeof text, "%02x%02x%02x%02x-%02x%02x-%02x%02x-%02x%02x-%02x%02x%02x%02x%02x%02x", bytes[0], bytes[1],
                  bytes[2], bytes[3], bytes[4], bytes[5], bytes[6], bytes[7], bytes[8], bytes[9], bytes[10], bytes[11], bytes[12],
                  bytes[13], bytes[14], bytes[15]);
    f.clear();
    f.seekp(std::streamoff(kUuidOffset));
    f.write(text, std::streamsize(kUuidLength));
    f.flush();
    if (!f) throw Error(path, "cannot be written: its identifier could not be set");
}

} // namespace vdbsurf
