// Progress line on stderr: percent, elapsed time and ETA, redrawn at most ten times a second by a
// small reporter thread. Disabled progress costs one relaxed atomic add per work item.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <thread>

namespace mcstat::render {

class Progress {
  public:
    Progress(int64_t total, bool enabled);
    ~Progress();  ///< finish()es
    Progress(const Progress&) = delete;
    Progress& operator=(const Progress&) = delete;

    void advance(int64_t n = 1) { done_.fetch_add(n, std::memory_order_relaxed); }
    /// Stops the reporter and, if enabled, prints the final line and a newline.
    void finish();

  private:
    void draw(bool final);
    void run();

    int64_t total_;
    bool enabled_;
    std::atomic<int64_t> done_{0};
    std::chrono::steady_clock::time_point start_;
    std::mutex mutex_;
    std::condition_variable cv_;
    bool stop_ = false;
    std::thread thread_;
};

}  // namespace mcstat::render
