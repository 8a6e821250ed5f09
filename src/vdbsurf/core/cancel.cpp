#include "vdbsurf/core/cancel.h"

#include "vdbsurf/core/error.h"

#include <csignal>

namespace vdbsurf {

void CancelToken::check() const {
    if (cancelled()) throw Cancelled();
}

CancelToken& processCancelToken() {
    static CancelToken token;
    return token;
}

namespace {
extern "C" void onSignal(int) { processCancelToken().cancel(); }
} // namespace

void installSignalCancel() {
    (void)processCancelToken(); // construct before any signal can arrive
    std::signal(SIGINT, onSignal);
    std::signal(SIGTERM, onSignal);
}

} // namespace vdbsurf
