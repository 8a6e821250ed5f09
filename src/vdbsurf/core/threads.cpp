#include "vdbsurf/core/threads.h"

#include <tbb/global_control.h>
#include <tbb/info.h>

namespace vdbsurf {

struct ThreadLimit::Impl {
    tbb::global_control control;
    explicit Impl(int n) : control(tbb::global_control::max_allowed_parallelism, std::size_t(n)) {}
};

int ThreadLimit::hardwareThreads() { return tbb::info::default_concurrency(); }

// TBB's default arena never runs more workers than the hardware offers, whatever the limit, so
// a request beyond it is reported (threads()) as what actually runs.
ThreadLimit::ThreadLimit(int threads) : mThreads(threads > 0 && threads < hardwareThreads() ? threads : hardwareThreads()) {
    mImpl = std::make_unique<Impl>(mThreads);
}

ThreadLimit::~ThreadLimit() = default;

} // namespace vdbsurf
