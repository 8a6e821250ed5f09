// Progress of long work on stderr, only when stderr is a terminal (pipelines and farm logs stay
// clean). Worker threads call advance(); printing is rate-limited and done by whichever thread
// crosses the next time step.
#pragma once
#include <atomic>
#include <chrono>
#include <cstdint>
#include <mutex>
#include <string>

namespace vdbsurf {

class CancelToken;

class Progress {
public:
    Progress(std::string stage, std::uint64_t total, const CancelToken* cancel = nullptr);
    ~Progress();
    Progress(const Progress&) = delete;
    Progress& operator=(const Progress&) = delete;

    // Adds done units; throws Cancelled if the token was cancelled.
    void advance(std::uint64_t units = 1);
    static bool enabledForTerminal();

private:
    void print(bool complete, bool endLine);

    std::string mStage;
    std::uint64_t mTotal;
    const CancelToken* mCancel;
    std::atomic<std::uint64_t> mDone{0};
    std::atomic<std::int64_t> mNextPrintNs{0};
    std::chrono::steady_clock::time_point mStart;
    std::mutex mPrintMutex;
    bool mEnabled;
};

} // namespace vdbsurf
