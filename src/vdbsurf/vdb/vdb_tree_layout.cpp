#include "vdbsurf/vdb/vdb_tree_layout.h"

#include "vdbsurf/core/error.h"
#include "vdbsurf/vdb/vdb_file.h"

#include <openvdb/io/io.h>
#include <openvdb/math/Transform.h>

#include <algorithm>
#include <array>
#include <bitset>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <streambuf>
#include <vector>

namespace vdbsurf {

namespace {

// OpenVDB's io::Compression.h flags and per-node value-compression markers.
constexpr std::uint32_t kNodeMaskCompression = 222;
constexpr std::uint32_t kNewestKnown = 224; // OPENVDB_FILE_VERSION of OpenVDB 10: later layouts are not assumed
constexpr std::uint32_t kZip = 0x1, kActiveMask = 0x2, kBlosc = 0x4;
enum NodeValues : std::int8_t {
    kOneInactiveValue = 2, // NO_MASK_AND_ONE_INACTIVE_VAL
    kMaskNoValues = 3,     // MASK_AND_NO_INACTIVE_VALS
    kMaskOneValue = 4,     // MASK_AND_ONE_INACTIVE_VAL
    kMaskTwoValues = 5,    // MASK_AND_TWO_INACTIVE_VALS
    kAllValues = 6         // NO_MASK_AND_ALL_VALS
};

struct ValueBytes {
    std::size_t full = 0; // bytes of one value as the tree holds it
    std::size_t half = 0; // as a half-float grid stores it; 0: never stored as half (integers)
};

bool valueBytesOf(const std::string& treeType, ValueBytes& out) {
    static const struct {
        const char* type;
        ValueBytes bytes;
    } kTrees[] = {{"Tree_float_5_4_3", {4, 2}},  {"Tree_double_5_4_3", {8, 2}}, {"Tree_int32_5_4_3", {4, 0}},
                  {"Tree_int64_5_4_3", {8, 0}},  {"Tree_vec3s_5_4_3", {12, 6}}, {"Tree_vec3d_5_4_3", {24, 6}},
                  {"Tree_vec3i_5_4_3", {12, 0}}};
    for (const auto& t : kTrees)
        if (treeType == t.type) {
            out = t.bytes;
            return true;
        }
    return false;
}

// What was wrong, and where in the file.
struct Damage {
    std::string what;
    std::int64_t at;
};

// The grid's bytes, read with every length checked against their end.
class GridBytes {
public:
    GridBytes(std::vector<char> bytes, std::int64_t fileOffset) : mBytes(std::move(bytes)), mOffset(fileOffset) {}

    std::size_t remaining() const { return mBytes.size() - mPos; }
    std::int64_t filePosition() const { return mOffset + std::int64_t(mPos); }
    const char* current() const { return mBytes.data() + mPos; }

    void skip(std::uint64_t n, const char* what) {
        if (n > remaining())
            throw Damage{std::string(what) + " needs " + std::to_string(n) + " bytes, the grid has " +
                             std::to_string(remaining()) + " left",
                         filePosition()};
        mPos += std::size_t(n);
    }
    template <typename T>
    T read(const char* what) {
        const char* p = current();
        skip(sizeof(T), what);
        T v;
        std::memcpy(&v, p, sizeof(T));
        return v;
    }
    // The number of set bits of a node mask of `bits` bits.
    std::size_t maskCount(std::size_t bits, const char* what, std::vector<std::uint64_t>* words = nullptr) {
        const char* p = current();
        skip(bits / 8, what);
        std::size_t on = 0;
        for (std::size_t i = 0; i < bits / 64; ++i) {
            std::uint64_t w;
            std::memcpy(&w, p + 8 * i, 8);
            on += std::bitset<64>(w).count();
            if (words) words->push_back(w);
        }
        return on;
    }
    void string(const char* what) { skip(read<std::uint32_t>(what), what); }

private:
    std::vector<char> mBytes;
    std::int64_t mOffset;
    std::size_t mPos = 0;
};

// An istream over the bytes from the cursor on, for OpenVDB's own reader of transforms.
class ByteStream : public std::streambuf {
public:
    ByteStream(const char* begin, std::size_t size) {
        char* p = const_cast<char*>(begin);
        setg(p, p, p + size);
    }
    std::size_t consumed() const { return std::size_t(gptr() - eback()); }
};

class TreeWalk {
public:
    TreeWalk(GridBytes& in, std::uint32_t compression, const ValueBytes& value, bool half)
        : mIn(in), mCompression(compression), mValue(value), mHalf(half && value.half > 0) {}

    void topology() {
        mIn.skip(4, "the tree's buffer count");
        mIn.skip(mValue.full, "the background value");
        const auto tiles = mIn.read<std::uint32_t>("the root's tile count");
        const auto children = mIn.read<std::uint32_t>("the root's child count");
        mIn.skip(std::uint64_t(tiles) * (12 + mValue.full + 1), "the root's tiles");
        for (std::uint32_t i = 0; i < children; ++i) {
            RootChild c;
            for (int a = 0; a < 3; ++a) c.origin[a] = mIn.read<std::int32_t>("a root child's origin");
            c.firstLeaf = mLeafActive.size();
            internalNode(5);
            c.endLeaf = mLeafActive.size();
            mRootChildren.push_back(c);
        }
    }

    // Leaf buffers, in the order OpenVDB reads them: root children sorted by origin (its table is
    // a std::map), then each one's leaves in the order its topology listed them.
    void buffers() {
        std::stable_sort(mRootChildren.begin(), mRootChildren.end(),
                         [](const RootChild& a, const RootChild& b) { return a.origin < b.origin; });
        for (std::size_t i = 1; i < mRootChildren.size(); ++i)
            if (mRootChildren[i].origin == mRootChildren[i - 1].origin)
                throw Damage{"two root children share one origin", mIn.filePosition()};
        for (const RootChild& c : mRootChildren)
            for (std::size_t l = c.firstLeaf; l < c.endLeaf; ++l) {
                mIn.skip(64, "a leaf's value mask");
                values(512, mLeafActive[l], "a leaf's values");
            }
    }

private:
    struct RootChild {
        std::array<std::int32_t, 3> origin;
        std::size_t firstLeaf = 0, endLeaf = 0;
    };

    void internalNode(int log2Dim) {
        const std::size_t bits = std::size_t(1) << (3 * log2Dim);
        std::vector<std::uint64_t> childWords;
        childWords.reserve(bits / 64);
        mIn.maskCount(bits, "an internal node's child mask", &childWords);
        const std::size_t activeTiles = mIn.maskCount(bits, "an internal node's value mask");
        values(bits, activeTiles, "an internal node's values");
        for (const std::uint64_t w : childWords)
            for (std::size_t b = 0, n = std::bitset<64>(w).count(); b < n; ++b) {
                if (log2Dim > 4) internalNode(log2Dim - 1);
                else mLeafActive.push_back(mIn.maskCount(512, "a leaf's value mask"));
            }
    }

    // One node's values as io::readCompressedValues reads them, for a node of `count` values
    // of which `active` are active.
    void values(std::size_t count, std::size_t active, const char* what) {
        const auto marker = mIn.read<std::int8_t>(what);
        if (marker < 0 || marker > kAllValues)
            throw Damage{std::string(what) + " carry an unknown compression marker " + std::to_string(int(marker)),
                         mIn.filePosition() - 1};
        if (marker == kOneInactiveValue || marker == kMaskOneValue || marker == kMaskTwoValues)
            mIn.skip(mValue.full * (marker == kMaskTwoValues ? 2 : 1), what);
        if (marker == kMaskNoValues || marker == kMaskOneValue || marker == kMaskTwoValues) mIn.skip(count / 8, what);
        const std::size_t stored = (mCompression & kActiveMask) && marker != kAllValues ? active : count;
        if (mHalf && stored == 0) return; // a half-float chunk of no values is not written at all
        const std::uint64_t bytes = std::uint64_t(stored) * (mHalf ? mValue.half : mValue.full);
        if (!(mCompression & (kZip | kBlosc))) {
            mIn.skip(bytes, what);
            return;
        }
        const auto stated = mIn.read<std::int64_t>(what);
        if (stated > 0) {
            mIn.skip(std::uint64_t(stated), what);
        } else if (std::uint64_t(0) - std::uint64_t(stated) != bytes) {
            // The case OpenVDB checks only after it has copied the chunk into a buffer of `bytes`.
            throw Damage{std::string(what) + " are stored as " + std::to_string(std::uint64_t(0) - std::uint64_t(stated)) +
                             " uncompressed bytes where the node holds " + std::to_string(bytes),
                         mIn.filePosition() - 8};
        } else {
            mIn.skip(bytes, what);
        }
    }

    GridBytes& mIn;
    std::uint32_t mCompression;
    ValueBytes mValue;
    bool mHalf;
    std::vector<RootChild> mRootChildren;
    std::vector<std::uint16_t> mLeafActive; // active values of each leaf, in topology order
};

std::vector<char> readExtent(const std::string& path, std::int64_t begin, std::int64_t end) {
    std::ifstream in(path, std::ios::binary);
    std::vector<char> bytes(std::size_t(end - begin));
    in.seekg(begin);
    in.read(bytes.data(), std::streamsize(bytes.size()));
    if (!in) throw Error(path, "cannot be read");
    return bytes;
}

} // namespace

void checkGridTreeLayout(const std::string& path, const VdbLayout& layout, const VdbGridExtent& grid) {
    ValueBytes value;
    const bool knownLayout = layout.fileVersion >= kNodeMaskCompression && layout.fileVersion <= kNewestKnown;
    if (!layout.hasGridOffsets || !knownLayout || grid.instance || !valueBytesOf(grid.treeType, value))
        return;
    initializeOpenVdb(); // the transform reader needs OpenVDB's map registry
    GridBytes in(readExtent(path, grid.gridPos, grid.endPos), grid.gridPos);
    try {
        const auto compression = in.read<std::uint32_t>("the grid's compression flags");
        const auto metadataItems = in.read<std::uint32_t>("the grid's metadata");
        for (std::uint32_t i = 0; i < metadataItems; ++i) {
            in.string("the grid's metadata");
            in.string("the grid's metadata");
            in.string("the grid's metadata");
        }
        {
            ByteStream buffer(in.current(), in.remaining());
            std::istream is(&buffer);
            openvdb::io::setVersion(is, openvdb::VersionId(layout.libraryMajor, layout.libraryMinor), layout.fileVersion);
            try {
                openvdb::math::Transform().read(is);
            } catch (const std::exception& e) {
                throw Damage{std::string("its transform cannot be read: ") + e.what(), in.filePosition()};
            }
            if (!is) throw Damage{"its transform runs past the grid's end", in.filePosition()};
            in.skip(buffer.consumed(), "the grid's transform");
        }
        TreeWalk walk(in, compression, value, grid.halfFloat);
        walk.topology();
        walk.buffers();
    } catch (const Damage& d) {
        throw Error(path, "is damaged: grid " + gridLabel(grid.plainName()) + ", byte " + std::to_string(d.at) + ": " + d.what);
    }
}

} // namespace vdbsurf
