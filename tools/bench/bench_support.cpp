#include "bench_support.h"

#include "vdbsurf/core/atomic_file.h"
#include "vdbsurf/core/threads.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <malloc.h>
#include <sstream>

namespace vdbsurf::bench {

namespace {

double statusKiB(const char* key) {
    std::ifstream in("/proc/self/status");
    std::string line;
    const std::size_t n = std::strlen(key);
    while (std::getline(in, line))
        if (line.compare(0, n, key) == 0) return std::atof(line.c_str() + n);
    return 0;
}

} // namespace

Measure measure(const std::function<void()>& fn) {
    malloc_trim(0);
    const double base = statusKiB("VmRSS:");
    { std::ofstream("/proc/self/clear_refs") << "5"; } // reset the high-water mark to the current RSS
    const auto t0 = std::chrono::steady_clock::now();
    fn();
    Measure m;
    m.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    m.peakMiB = std::max(0.0, statusKiB("VmHWM:") - base) / 1024.0;
    return m;
}

double median(std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
}

Measure measureMedian(int repeat, const std::function<void()>& fn) {
    std::vector<double> times;
    double peak = 0;
    for (int i = 0; i < std::max(1, repeat); ++i) {
        const Measure m = measure(fn);
        times.push_back(m.seconds);
        peak = std::max(peak, m.peakMiB);
    }
    return {median(times), peak};
}

Interleaved measureInterleaved(int repeat, const std::vector<std::function<void()>>& fns) {
    Interleaved out;
    out.medians.resize(fns.size());
    out.seconds.resize(fns.size());
    for (int round = 0; round < std::max(1, repeat); ++round)
        for (std::size_t f = 0; f < fns.size(); ++f) {
            const Measure m = measure(fns[f]);
            out.seconds[f].push_back(m.seconds);
            out.medians[f].peakMiB = std::max(out.medians[f].peakMiB, m.peakMiB);
        }
    for (std::size_t f = 0; f < fns.size(); ++f) out.medians[f].seconds = median(out.seconds[f]);
    return out;
}

std::function<void()> withThreads(int threads, std::function<void()> fn) {
    return [threads, fn = std::move(fn)] {
        ThreadLimit limit(threads);
        fn();
    };
}

double Interleaved::medianRatio(std::size_t a, std::size_t b) const {
    std::vector<double> ratios;
    for (std::size_t r = 0; r < seconds[a].size(); ++r) ratios.push_back(seconds[a][r] / seconds[b][r]);
    return median(ratios);
}

std::string sharedData(const std::string& relative) {
    const std::filesystem::path p = std::filesystem::path(VDBSURF_SOURCE_DIR) / ".." / "shared" / "data" / relative;
    return std::filesystem::exists(p) ? p.lexically_normal().string() : std::string();
}

void Table::add(const std::vector<std::string>& row, nlohmann::json record) {
    mRows.push_back(row);
    mRecords.push_back(std::move(record));
}

void Table::print() const {
    std::vector<std::size_t> w(mColumns.size());
    for (std::size_t c = 0; c < mColumns.size(); ++c) {
        w[c] = mColumns[c].size();
        for (const auto& r : mRows) w[c] = std::max(w[c], c < r.size() ? r[c].size() : 0);
    }
    auto line = [&](const std::vector<std::string>& r) {
        for (std::size_t c = 0; c < mColumns.size(); ++c) {
            const std::string cell = c < r.size() ? r[c] : "";
            std::cout << (c ? "  " : "") << (c == 0 ? std::left : std::right) << std::setw(int(w[c])) << cell;
        }
        std::cout << "\n";
    };
    line(mColumns);
    std::vector<std::string> rule;
    for (std::size_t c = 0; c < mColumns.size(); ++c) rule.push_back(std::string(w[c], '-'));
    line(rule);
    for (const auto& r : mRows) line(r);
    std::cout << std::flush;
}

void Table::writeJson(const std::string& path, const std::string& name, const nlohmann::json& meta) const {
    AtomicFile out(path);
    {
        std::ofstream f(out.tempPath());
        f << nlohmann::json{{"benchmark", name}, {"meta", meta}, {"rows", mRecords}}.dump(2) << "\n";
    }
    out.commit();
}

std::string fixed(double v, int digits) {
    std::ostringstream s;
    s << std::fixed << std::setprecision(digits) << v;
    return s.str();
}

} // namespace vdbsurf::bench
