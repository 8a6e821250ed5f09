#include "vdbsurf/core/read_file.h"

#include "vdbsurf/core/error.h"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>

namespace vdbsurf {

std::string readWholeFile(const std::string& path) {
    std::error_code ec;
    if (std::filesystem::is_directory(path, ec)) throw Error(path, "is a folder, not a file");
    std::FILE* f = std::fopen(path.c_str(), "rb");
    if (!f) throw Error(path, std::string("cannot open: ") + std::strerror(errno));
    std::string data;
    char buf[1 << 16];
    std::size_t n;
    while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) data.append(buf, n);
    const bool bad = std::ferror(f) != 0;
    std::fclose(f);
    if (bad) throw Error(path, "cannot read");
    return data;
}

} // namespace vdbsurf
