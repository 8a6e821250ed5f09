// Limits the worker threads of everything vdbsurf runs through TBB for the lifetime of the object.
#pragma once
#include <memory>

namespace vdbsurf {

class ThreadLimit {
public:
    // threads <= 0 means "all hardware threads"; more than the hardware has runs (and reports) as many as it has.
    explicit ThreadLimit(int threads);
    ~ThreadLimit();
    int threads() const { return mThreads; }
    static int hardwareThreads();

private:
    struct Impl;
    std::unique_ptr<Impl> mImpl;
    int mThreads;
};

} // namespace vdbsurf
