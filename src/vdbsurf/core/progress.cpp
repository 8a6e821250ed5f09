#include "vdbsurf/core/progress.h"

#include "vdbsurf/core/cancel.h"

#include <cstdio>
#include <exception>
#include <unistd.h>

namespace vdbsurf {

namespace {
constexpr std::int64_t kPrintIntervalNs = 200'000'000;
}

bool Progress::enabledForTerminal() { return ::isatty(STDERR_FILENO) == 1; }

Progress::Progress(std::string stage, std::uint64_t total, const CancelToken* cancel)
    : mStage(std::move(stage)), mTotal(total), mCancel(cancel), mStart(std::chrono::steady_clock::now()),
      mEnabled(enabledForTerminal()) {
    mNextPrintNs.store(kPrintIntervalNs);
}

Progress::~Progress() {
    // Only finish a line we started; work cut short (cancelled, an error) ends at what it reached.
    if (mEnabled && mNextPrintNs.load() < 0) print(std::uncaught_exceptions() == 0, true);
}

void Progress::advance(std::uint64_t units) {
    if (mCancel) mCancel->check();
    // Only a printed line reads the count: off a terminal, threads advancing leaf by leaf would
    // pass its cache line between cores for nothing.
    if (!mEnabled) return;
    mDone.fetch_add(units, std::memory_order_relaxed);
    const auto now = std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now() - mStart).count();
    std::int64_t next = mNextPrintNs.load(std::memory_order_relaxed);
    const std::int64_t due = next < 0 ? -next : next;
    if (now < due) return;
    // Negative marks "a line was printed"; whoever wins the exchange prints.
    if (mNextPrintNs.compare_exchange_strong(next, -(now + kPrintIntervalNs))) print(false, false);
}

void Progress::print(bool complete, bool endLine) {
    std::lock_guard<std::mutex> lock(mPrintMutex);
    const double frac = mTotal ? double(mDone.load()) / double(mTotal) : 1.0;
    std::fprintf(stderr, "\r%s: %5.1f%%%s", mStage.c_str(), 100.0 * (complete ? 1.0 : frac), endLine ? "\n" : "");
    std::fflush(stderr);
}

} // namespace vdbsurf
