// Whole-file reads for the text and binary formats vdbsurf parses itself (OBJ, PLY).
#pragma once
#include <string>

namespace vdbsurf {

// The file's bytes; throws Error naming the path when it is missing, unreadable or a folder.
std::string readWholeFile(const std::string& path);

} // namespace vdbsurf
