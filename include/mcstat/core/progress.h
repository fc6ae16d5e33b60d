// The one progress line of every long operation (renders, ingest, --check, per-sample operations):
// "<label>  42.0%  elapsed 0:12  ETA 0:16" on stderr, redrawn in place at most ten times a second
// by a small reporter thread, and a final line when done. Quiet unless enabled, which callers set
// from onTerminal(): a log file or a pipe gets no carriage returns.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <string>
#include <thread>

namespace mcstat {

class Progress {
  public:
    /// `total` units of work; disabled, it costs one relaxed atomic add per advance().
    Progress(std::string label, int64_t total, bool enabled);
    ~Progress();  ///< finish()es
    Progress(const Progress&) = delete;
    Progress& operator=(const Progress&) = delete;

    /// Whether stderr is a terminal: where a progress line belongs.
    static bool onTerminal();

    void advance(int64_t n = 1) { done_.fetch_add(n, std::memory_order_relaxed); }
    /// Sets the work done as a fraction (0..1) of the total.
    void set(double fraction);
    /// set() as a callback, for functions that report a fraction (checkStatsFile, the per-sample
    /// operations); empty when disabled, so that they skip the reporting altogether.
    std::function<void(double)> fractionCallback();
    /// Stops the reporter and, if enabled, prints the final line and a newline.
    void finish();

  private:
    void draw(bool final);
    void run();

    std::string label_;
    int64_t total_;
    bool enabled_;
    std::atomic<int64_t> done_{0};
    std::chrono::steady_clock::time_point start_;
    std::mutex mutex_;
    std::condition_variable cv_;
    bool stop_ = false;
    std::thread thread_;
};

}  // namespace mcstat
