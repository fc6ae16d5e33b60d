// WorkerPool: per-thread scratch (an OpenEXR decode or encode pipeline's buffers) handed out to
// the tasks of a parallel loop, so that each task reuses a free worker's buffers instead of
// allocating its own. The flat-part reader and writer share it.
#pragma once

#include <memory>
#include <mutex>
#include <vector>

namespace mcstat::detail {

template <class Worker>
class WorkerPool {
  public:
    /// A free worker, or a new one when every worker is in use; give it back with release().
    Worker* acquire() {
        std::lock_guard<std::mutex> lock(mutex_);
        if (idle_.empty()) {
            all_.push_back(std::make_unique<Worker>());
            return all_.back().get();
        }
        Worker* w = idle_.back();
        idle_.pop_back();
        return w;
    }
    void release(Worker* w) {
        std::lock_guard<std::mutex> lock(mutex_);
        idle_.push_back(w);
    }

  private:
    std::mutex mutex_;
    std::vector<std::unique_ptr<Worker>> all_;
    std::vector<Worker*> idle_;
};

}  // namespace mcstat::detail
