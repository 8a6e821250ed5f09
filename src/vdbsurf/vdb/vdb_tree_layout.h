// The byte layout of one grid's tree in a .vdb file (file versions 222–224): root tiles, node
// masks and each node's chunk of values, walked with every length checked against what the node
// holds and against the grid's extent in the file. OpenVDB 10 reads an uncompressed chunk into a
// buffer sized by the node *before* it compares the chunk's stated length with that size, so one
// damaged length overruns the heap: a crash, not an error. This walk turns such a file into an
// error before OpenVDB reads the grid.
#pragma once
#include "vdbsurf/vdb/vdb_layout.h"

#include <string>

namespace vdbsurf {

// Walks the tree of `grid` (one of `layout`'s grids in the file at `path`). Trees of float,
// double, int32, int64 and vec3 values with OpenVDB's 5-4-3 node sizes are walked; other trees
// (bool, mask, points, other node sizes), instances, files without grid offsets and file
// versions other than 222–224 (the layouts this walk knows) are left to OpenVDB. Throws Error
// naming the path and the grid when the bytes do not describe a tree.
void checkGridTreeLayout(const std::string& path, const VdbLayout& layout, const VdbGridExtent& grid);

} // namespace vdbsurf
