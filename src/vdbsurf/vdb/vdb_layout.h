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
    std::string name;   // the descriptor's unique name
    std::int64_t gridPos = 0, blockPos = 0, endPos = 0;
};

struct VdbLayout {
    std::uint32_t fileVersion = 0;
    bool hasGridOffsets = false; // files written as streams carry no offsets: nothing to check
    std::vector<VdbGridExtent> grids;
};

// Throws Error naming the path when the file is truncated or its structure is inconsistent.
VdbLayout checkVdbLayout(const std::string& path);

} // namespace vdbsurf
