// A large write buffer over a FILE*, writing an AtomicFile's temporary file; write errors
// (disk full) become an Error naming the target.
#pragma once
#include "vdbsurf/core/atomic_file.h"
#include "vdbsurf/core/error.h"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <memory>
#include <string>

namespace vdbsurf {

class BufferedFile {
public:
    explicit BufferedFile(const AtomicFile& target) : mPath(target.target()) {
        mFile = std::fopen(target.tempPath().c_str(), "wb");
        if (!mFile) throw Error(mPath, std::string("cannot write: ") + std::strerror(errno));
        mBuf.reset(new char[kSize]);
    }
    ~BufferedFile() {
        if (mFile) std::fclose(mFile);
    }
    void ensure(std::size_t n) {
        if (mUsed + n > kSize) flush();
    }
    char* cursor() { return mBuf.get() + mUsed; }
    void advance(std::size_t n) { mUsed += n; }
    void put(const char* s, std::size_t n) {
        if (n > kSize) {
            flush();
            if (std::fwrite(s, 1, n, mFile) != n) throw Error(mPath, "cannot write (disk full?)");
            return;
        }
        ensure(n);
        std::memcpy(cursor(), s, n);
        mUsed += n;
    }
    void put(const std::string& s) { put(s.data(), s.size()); }
    void close() {
        flush();
        const bool bad = std::ferror(mFile) != 0;
        const int rc = std::fclose(mFile);
        mFile = nullptr;
        if (bad || rc != 0) throw Error(mPath, "cannot write (disk full?)");
    }
    void flush() {
        if (mUsed && std::fwrite(mBuf.get(), 1, mUsed, mFile) != mUsed) throw Error(mPath, "cannot write (disk full?)");
        mUsed = 0;
    }

private:
    static constexpr std::size_t kSize = 1 << 20;
    std::string mPath;
    std::FILE* mFile = nullptr;
    std::unique_ptr<char[]> mBuf;
    std::size_t mUsed = 0;
};

} // namespace vdbsurf
