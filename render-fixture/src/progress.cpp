#include "progress.h"

#include <fmt/format.h>

#include <cstdio>

namespace mcstat::render {

namespace {

std::string formatDuration(double s) {
    const auto t = static_cast<long long>(s + 0.5);
    if (t >= 3600) return fmt::format("{}:{:02}:{:02}", t / 3600, (t / 60) % 60, t % 60);
    return fmt::format("{}:{:02}", t / 60, t % 60);
}

}  // namespace

Progress::Progress(int64_t total, bool enabled)
    : total_(total), enabled_(enabled), start_(std::chrono::steady_clock::now()) {
    if (enabled_) thread_ = std::thread([this] { run(); });
}

Progress::~Progress() { finish(); }

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
    const int64_t done = done_.load(std::memory_order_relaxed);
    const double frac = total_ > 0 ? double(done) / double(total_) : 1.0;
    std::string eta = "--:--";
    if (frac > 0) eta = formatDuration(elapsed * (1 - frac) / frac);
    // \r redraws in place; the trailing spaces wipe leftovers of a longer previous line.
    std::string line = fmt::format("\rrendering {:5.1f}%  elapsed {}  ETA {}   ", 100 * frac,
                                   formatDuration(elapsed), final ? "0:00" : eta);
    if (final) line += "\n";
    std::fputs(line.c_str(), stderr);
    std::fflush(stderr);
}

}  // namespace mcstat::render
