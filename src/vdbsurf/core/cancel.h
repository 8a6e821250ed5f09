// Cooperative cancellation: long loops poll a flag that a signal handler or a caller sets, and
// unwind by throwing Cancelled, so output files (written through AtomicFile) are never left half done.
#pragma once
#include <atomic>

namespace vdbsurf {

class CancelToken {
public:
    void cancel() { mFlag.store(true, std::memory_order_relaxed); }
    bool cancelled() const { return mFlag.load(std::memory_order_relaxed); }
    // Throws Cancelled when cancelled; cheap enough to call once per work unit.
    void check() const;

private:
    std::atomic<bool> mFlag{false};
};

// The process-wide token that SIGINT and SIGTERM set once installSignalCancel() has run.
CancelToken& processCancelToken();
void installSignalCancel();

} // namespace vdbsurf
