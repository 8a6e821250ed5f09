// What every benchmark shares: timing, peak-memory measurement, the shared data folder, and a
// result table printed to stdout and optionally written as JSON (--json FILE).
#pragma once
#include <nlohmann/json.hpp>

#include <functional>
#include <string>
#include <vector>

namespace vdbsurf::bench {

// Peak resident memory added while fn runs, in MiB (Linux: VmHWM reset via clear_refs), and
// its wall time in seconds.
struct Measure {
    double seconds = 0;
    double peakMiB = 0;
};
Measure measure(const std::function<void()>& fn);

// The middle value (the upper of the two middle ones for an even count); v must not be empty.
double median(std::vector<double> v);

// Runs fn `repeat` times; the median time and the largest peak.
Measure measureMedian(int repeat, const std::function<void()>& fn);

// Runs each of fns once a round for `repeat` rounds, so that the drift of a shared machine (its
// neighbours come and go within seconds) falls on every function alike, not on whichever ran
// in the slower stretch. Ratios are then taken round by round.
struct Interleaved {
    std::vector<Measure> medians;              // per function: median time, largest peak
    std::vector<std::vector<double>> seconds; // [function][round]
    // The median over rounds of seconds[a][r] / seconds[b][r].
    double medianRatio(std::size_t a, std::size_t b) const;
};
Interleaved measureInterleaved(int repeat, const std::vector<std::function<void()>>& fns);

// fn run under a ThreadLimit of `threads` (as one of measureInterleaved's functions).
std::function<void()> withThreads(int threads, std::function<void()> fn);

// ../shared/data/<relative> seen from the source tree, or "" when absent.
std::string sharedData(const std::string& relative);

class Table {
public:
    explicit Table(std::vector<std::string> columns) : mColumns(std::move(columns)) {}
    void add(const std::vector<std::string>& row, nlohmann::json record);
    void print() const;
    // Writes {"benchmark": name, "rows": [records...], "meta": meta} atomically.
    void writeJson(const std::string& path, const std::string& name, const nlohmann::json& meta) const;

private:
    std::vector<std::string> mColumns;
    std::vector<std::vector<std::string>> mRows;
    nlohmann::json mRecords = nlohmann::json::array();
};

std::string fixed(double v, int digits);

} // namespace vdbsurf::bench
