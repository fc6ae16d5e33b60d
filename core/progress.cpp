// The progress line (include/mcstat/core/progress.h).
#include "mcstat/core/progress.h"

#include <unistd.h>

#include <algorithm>
#include <cstdio>

#include "mcstat/core/untrusted_text.h"

namespace mcstat {

namespace {

std::string formatDuration(double s) {
    const auto t = static_cast<long long>(s + 0.5);
    char buf[48];
    if (t >= 3600)
        std::snprintf(buf, sizeof buf, "%lld:%02lld:%02lld", t / 3600, (t / 60) % 60, t % 60);
    else
        std::snprintf(buf, sizeof buf, "%lld:%02lld", t / 60, t % 60);
    return buf;
}

}  // namespace

Progress::Progress(std::string label, int64_t total, bool enabled)
    : label_(oneLine(label)),  // a label may hold a file's name (core/untrusted_text.h)
      total_(total),
      enabled_(enabled),
      start_(std::chrono::steady_clock::now()) {
    if (enabled_) thread_ = std::thread([this] { run(); });
}

Progress::~Progress() { finish(); }

bool Progress::onTerminal() { return isatty(STDERR_FILENO) == 1; }

void Progress::set(double fraction) {
    const double f = std::clamp(fraction, 0.0, 1.0);
    done_.store(int64_t(f * double(total_)), std::memory_order_relaxed);
}

std::function<void(double)> Progress::fractionCallback() {
    if (!enabled_) return {};
    return [this](double f) { set(f); };
}

void Progress::finish() {
    if (!enabled_) return;
    {
        std::lock_guard<std::mutex> lock(mutex_);
        if (stop_) return;
        stop_ = true;
    }
    cv_.notify_all();
    thread_.join();
    draw(true);
}

void Progress::run() {
    std::unique_lock<std::mutex> lock(mutex_);
    while (!cv_.wait_for(lock, std::chrono::milliseconds(100), [this] { return stop_; }))
        draw(false);
}

void Progress::draw(bool final) {
    const double elapsed =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
    const int64_t done = final ? total_ : done_.load(std::memory_order_relaxed);
    const double frac = total_ > 0 ? double(done) / double(total_) : 1.0;
    std::string eta = "--:--";
    if (frac > 0) eta = formatDuration(elapsed * (1 - frac) / frac);
    // \r redraws in place; the trailing spaces wipe leftovers of a longer previous line.
    std::fprintf(stderr, "\r%s %5.1f%%  elapsed %s  ETA %s   %s", label_.c_str(), 100 * frac,
                 formatDuration(elapsed).c_str(), final ? "0:00" : eta.c_str(), final ? "\n" : "");
    std::fflush(stderr);
}

}  // namespace mcstat
