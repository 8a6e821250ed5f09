// A .vdb file's identifier derived from its contents. OpenVDB stamps every file it writes with a
// random UUID, so writing the same grids twice gives files that differ in those 36 bytes — a
// pipeline that caches by checksum, or a user who diffs two runs, sees a change where there is
// none. vdbsurf replaces it with a UUID hashed from the rest of the file: the same grids give the
// same file, different grids (almost surely) different identifiers, which is what OpenVDB uses
// the UUID for (telling files apart).
#pragma once
#include <string>

namespace vdbsurf {

// Rewrites the UUID in the header of the .vdb file at path (as OpenVDB 10 writes it: file
// format 218 or later) with a version-8 UUID from XXH3's 128-bit hash of every other byte. Throws
// Error naming the path when it is not such a file or cannot be rewritten.
void stampContentUuid(const std::string& path);

} // namespace vdbsurf
