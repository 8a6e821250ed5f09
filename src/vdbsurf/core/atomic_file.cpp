#include "vdbsurf/core/atomic_file.h"

#include "vdbsurf/core/error.h"

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <unistd.h>

namespace vdbsurf {

namespace fs = std::filesystem;

namespace {
std::string tempNameFor(const std::string& target) {
    static std::atomic<unsigned> counter{0};
    const fs::path p(target);
    const std::string name = "." + p.filename().string() + ".tmp-" + std::to_string(::getpid()) + "-" +
                             std::to_string(counter.fetch_add(1));
    return (p.parent_path() / name).string();
}
} // namespace

AtomicFile::AtomicFile(std::string target) : mTarget(std::move(target)), mTemp(tempNameFor(mTarget)) {}

AtomicFile::~AtomicFile() {
    if (!mCommitted) std::remove(mTemp.c_str());
}

void AtomicFile::commit() {
    if (std::rename(mTemp.c_str(), mTarget.c_str()) != 0) {
        const int err = errno;
        std::remove(mTemp.c_str());
        throw Error(mTarget, std::string("cannot write: ") + std::strerror(err));
    }
    mCommitted = true;
}

void checkWritableTarget(const std::string& target) {
    if (target.empty()) throw Error("-o", "no output file given");
    const fs::path p(target);
    if (p.filename().empty() || fs::is_directory(p)) throw Error(target, "output must be a file, not a folder");
    fs::path dir = p.parent_path();
    if (dir.empty()) dir = ".";
    std::error_code ec;
    if (!fs::is_directory(dir, ec)) throw Error(target, "folder '" + dir.string() + "' does not exist");
    if (::access(dir.c_str(), W_OK) != 0) throw Error(target, "folder '" + dir.string() + "' is not writable");
}

} // namespace vdbsurf
