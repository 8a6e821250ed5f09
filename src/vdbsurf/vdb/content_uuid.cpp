#include "vdbsurf/vdb/content_uuid.h"

#include "vdbsurf/core/error.h"

#include <xxhash.h>

#include <array>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <memory>
#include <vector>

namespace vdbsurf {

namespace {

// OpenVDB's header: magic (8 bytes), file version, library major and minor (4 each), the grid
// offsets flag (1), then the UUID as 36 ASCII characters from format 218 on.
constexpr std::int64_t kMagic = 0x56444220;
constexpr std::uint32_t kAsciiUuid = 218;
constexpr std::size_t kUuidOffset = 21, kUuidLength = 36;

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

    // XXH3's 128-bit hash, streamed: files of gigabytes are hashed straight after they were
    // written, at memory speed, the same on every run and machine.
    const std::unique_ptr<XXH3_state_t, XXH_errorcode (*)(XXH3_state_t*)> state(XXH3_createState(), XXH3_freeState);
    if (!state || XXH3_128bits_reset(state.get()) != XXH_OK) throw Error(path, "cannot be hashed to set its identifier");
    XXH3_128bits_update(state.get(), header.data(), kUuidOffset);
    std::vector<unsigned char> buffer(1 << 20);
    while (f) {
        f.read(reinterpret_cast<char*>(buffer.data()), std::streamsize(buffer.size()));
        XXH3_128bits_update(state.get(), buffer.data(), std::size_t(f.gcount()));
    }
    const XXH128_hash_t digest = XXH3_128bits_digest(state.get());
    const std::array<std::uint64_t, 2> h = {digest.high64, digest.low64};
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
