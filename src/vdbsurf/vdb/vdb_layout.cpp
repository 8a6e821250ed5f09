#include "vdbsurf/vdb/vdb_layout.h"

#include "vdbsurf/core/error.h"

#include <cstring>
#include <fstream>

namespace vdbsurf {

namespace {

// File format versions (OpenVDB's version.h) at which the header changed.
constexpr std::uint32_t kLibraryVersionStored = 211;
constexpr std::uint32_t kGridOffsetsFlag = 212;
constexpr std::uint32_t kGridInstancing = 216;
constexpr std::uint32_t kAsciiUuid = 218;
constexpr std::uint32_t kSelectiveCompression = 220;
constexpr std::uint32_t kNodeMaskCompression = 222;

class Reader {
public:
    Reader(const std::string& path) : mPath(path), mIn(path, std::ios::binary) {
        if (!mIn) throw Error(path, "cannot be read");
        mIn.seekg(0, std::ios::end);
        mSize = std::int64_t(mIn.tellg());
        mIn.seekg(0);
    }
    std::int64_t size() const { return mSize; }
    std::int64_t pos() { return std::int64_t(mIn.tellg()); }

    void need(std::int64_t bytes, const char* what) {
        if (bytes < 0 || pos() + bytes > mSize)
            throw Error(mPath, std::string("is truncated: it ends at byte ") + std::to_string(mSize) + " inside the " + what);
    }
    template <typename T>
    T read(const char* what) {
        need(std::int64_t(sizeof(T)), what);
        T v;
        mIn.read(reinterpret_cast<char*>(&v), sizeof(T));
        return v;
    }
    void skip(std::int64_t bytes, const char* what) {
        need(bytes, what);
        mIn.seekg(bytes, std::ios::cur);
    }
    std::string string(const char* what) {
        const std::uint32_t n = read<std::uint32_t>(what);
        need(n, what);
        std::string s(n, '\0');
        mIn.read(s.data(), n);
        return s;
    }
    void seek(std::int64_t p, const char* what) {
        if (p < 0 || p > mSize)
            throw Error(mPath, std::string("is truncated: the ") + what + " should start at byte " + std::to_string(p) +
                                   " but the file has " + std::to_string(mSize) + " bytes");
        mIn.seekg(p);
    }

private:
    std::string mPath;
    std::ifstream mIn;
    std::int64_t mSize = 0;
};

} // namespace

VdbLayout checkVdbLayout(const std::string& path) {
    Reader r(path);
    VdbLayout out;
    r.skip(8, "header"); // magic number, checked by the caller
    out.fileVersion = r.read<std::uint32_t>("header");
    if (out.fileVersion < kLibraryVersionStored) {
        r.skip(8, "header"); // old minor/patch numbers
    } else {
        out.libraryMajor = r.read<std::uint32_t>("header");
        out.libraryMinor = r.read<std::uint32_t>("header");
    }
    out.hasGridOffsets = true;
    if (out.fileVersion >= kGridOffsetsFlag) out.hasGridOffsets = r.read<char>("header") != 0;
    if (out.fileVersion >= kSelectiveCompression && out.fileVersion < kNodeMaskCompression) r.skip(1, "header");
    r.skip(out.fileVersion >= kAsciiUuid ? 36 : 16, "header");

    const std::uint32_t metaCount = r.read<std::uint32_t>("file metadata");
    for (std::uint32_t i = 0; i < metaCount; ++i) {
        r.string("file metadata");
        r.string("file metadata");
        r.skip(r.read<std::uint32_t>("file metadata"), "file metadata");
    }
    if (!out.hasGridOffsets) return out;

    const std::int32_t gridCount = r.read<std::int32_t>("grid list");
    if (gridCount < 0) throw Error(path, "is damaged: negative grid count");
    for (std::int32_t i = 0; i < gridCount; ++i) {
        VdbGridExtent g;
        g.name = r.string("grid descriptor");
        g.treeType = r.string("grid descriptor");
        const std::string half = "_HalfFloat"; // OpenVDB's suffix for grids saved as half floats
        if (g.treeType.size() > half.size() && g.treeType.compare(g.treeType.size() - half.size(), half.size(), half) == 0) {
            g.treeType.resize(g.treeType.size() - half.size());
            g.halfFloat = true;
        }
        if (out.fileVersion >= kGridInstancing) g.instance = !r.string("grid descriptor").empty(); // instance parent
        g.gridPos = r.read<std::int64_t>("grid descriptor");
        g.blockPos = r.read<std::int64_t>("grid descriptor");
        g.endPos = r.read<std::int64_t>("grid descriptor");
        if (g.endPos > r.size())
            throw Error(path, "is truncated: grid '" + g.name + "' needs " + std::to_string(g.endPos) + " bytes, the file has " +
                                  std::to_string(r.size()));
        if (g.gridPos < r.pos() || g.blockPos < g.gridPos || g.endPos < g.blockPos)
            throw Error(path, "is damaged: grid '" + g.name + "' has inconsistent offsets");
        out.grids.push_back(g);
        r.seek(g.endPos, "next grid descriptor");
    }
    return out;
}

} // namespace vdbsurf
