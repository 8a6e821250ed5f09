// Output files are written to a temporary name in the target folder and renamed over the real
// name on commit(), so a crash, an error or a cancel never leaves a half-written file behind.
#pragma once
#include <string>

namespace vdbsurf {

class AtomicFile {
public:
    explicit AtomicFile(std::string target);
    ~AtomicFile(); // removes the temporary file unless committed
    AtomicFile(const AtomicFile&) = delete;
    AtomicFile& operator=(const AtomicFile&) = delete;

    const std::string& tempPath() const { return mTemp; }
    const std::string& target() const { return mTarget; }
    // Renames the temporary file onto the target; throws Error naming the target on failure.
    void commit();

private:
    std::string mTarget, mTemp;
    bool mCommitted = false;
};

// Checks before any work is done that the target's folder exists and is writable, so a long
// meshing run does not fail at the end.
void checkWritableTarget(const std::string& target);

} // namespace vdbsurf
