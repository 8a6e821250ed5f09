// The byte layout of a .vdb file (header, file metadata, grid descriptors), walked with every
// length checked against the file's size. OpenVDB trusts these lengths and, for uncompressed
// data, reads past the end of a truncated file without noticing; this walk is what turns a
// truncated file into an error before any grid is read.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

namespace vdbsurf {

struct VdbGridExtent {
    std::string name;     // the descriptor's unique name
    std::string treeType; // e.g. "Tree_float_5_4_3", without the half-float suffix
    bool halfFloat = false; // values stored as 16-bit floats
    bool instance = false;  // shares another grid's tree: no tree of its own in the file
    std::int64_t gridPos = 0, blockPos = 0, endPos = 0;

    // The grid's name: a unique name adds "\x1e<n>" to a name that repeats in the file.
    std::string plainName() const { return name.substr(0, name.find('\x1e')); }
};

struct VdbLayout {
    std::uint32_t fileVersion = 0;
    std::uint32_t libraryMajor = 0, libraryMinor = 0; // of the library that wrote it
    bool hasGridOffsets = false; // files written as streams carry no offsets: nothing to check
    std::vector<VdbGridExtent> grids;
};

// Throws Error naming the path when the file is truncated or its structure is inconsistent.
VdbLayout checkVdbLayout(const std::string& path);

} // namespace vdbsurf
