// Shared pieces of the vdbsurf command line: how messages look, how lists of numbers are parsed,
// and how a subcommand is run so that every failure ends in one line and a meaningful exit code.
#pragma once
#include "vdbsurf/core/vec3.h"

#include <CLI/CLI.hpp>
#include <chrono>
#include <nlohmann/json.hpp>

#include <functional>
#include <string>
#include <vector>

namespace vdbsurf::cli {

// Exit codes: 0 success, 1 bad input (Error), 2 bad usage (CLI11), 70 internal failure, 130 cancelled.
constexpr int kExitInput = 1;
constexpr int kExitInternal = 70;
constexpr int kExitCancelled = 130;

struct Globals {
    bool quiet = false;
};
Globals& globals();

// An informational line on stderr ("vdbsurf: ..."), unless --quiet.
void note(const std::string& text);

// "a,b,c" -> numbers; throws Error naming the option when the count or a number is wrong.
std::vector<double> parseNumbers(const std::string& option, const std::string& text, std::size_t count);
Box3 parseBox(const std::string& option, const std::string& text);

// Seconds elapsed since t, for the timings commands report.
using Clock = std::chrono::steady_clock;
inline double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

// Writes j (indented) to path atomically; throws Error naming path.
void writeJsonFile(const std::string& path, const nlohmann::json& j);

// Runs a subcommand body, mapping exceptions to messages and exit codes; `command` (the
// subcommand's name) names the job in an out-of-memory message and picks its hint.
int runGuarded(const std::function<void()>& body, const std::string& command);

// Subcommand registration; each returns the action to run when that subcommand was chosen.
using Action = std::function<void()>;
Action addInfoCommand(CLI::App& app);
Action addMeshCommand(CLI::App& app);
Action addCompareCommand(CLI::App& app);
Action addRasterizeCommand(CLI::App& app);
Action addEditCommand(CLI::App& app);
Action addSubdivideCommand(CLI::App& app);
Action addPatchesCommand(CLI::App& app);

} // namespace vdbsurf::cli
