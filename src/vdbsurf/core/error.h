// Errors a user can cause. Every one names the input it is about, so the command line can print
// one clear line and exit non-zero; everything else (std::exception) is an internal failure.
#pragma once
#include <sstream>
#include <stdexcept>
#include <string>

namespace vdbsurf {

class Error : public std::runtime_error {
public:
    // input: what the user gave (a file path, "--expr", "--voxel-size", a grid name ...).
    Error(std::string input, const std::string& message)
        : std::runtime_error(input.empty() ? message : input + ": " + message), mInput(std::move(input)), mMessage(message) {}
    const std::string& input() const { return mInput; }
    // What went wrong, without the input's name (what() is "input: message").
    const std::string& message() const { return mMessage; }

private:
    std::string mInput, mMessage;
};

// A number as error messages print it: 9 significant digits, enough to tell a value the user
// typed from its neighbours.
inline std::string messageNumber(double v) {
    std::ostringstream s;
    s.precision(9);
    s << v;
    return s.str();
}

// Thrown when the user interrupts long work (SIGINT/SIGTERM) or a caller cancels it.
class Cancelled : public std::runtime_error {
public:
    Cancelled() : std::runtime_error("cancelled") {}
};

} // namespace vdbsurf
