// ScratchPool: per-thread scratch (an OpenEXR decode or encode pipeline's buffers) handed out to
// the tasks of a parallel loop, so that each task reuses a free worker's buffers instead of
// allocating its own; TranscodeBuffers, the buffers an OpenEXR Core pipeline asks its allocator
// for. The flat-part reader and writer share both.
#pragma once

#include <OpenEXR/openexr.h>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <vector>

namespace mcstat::detail {

template <class Worker>
class ScratchPool {
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

/// The buffers of one Core decode or encode pipeline, by the transcode buffer id its allocator is
/// called with, kept from one chunk to the next and grown when a chunk needs more.
struct TranscodeBuffers {
    static constexpr int kBuffers = int(EXR_TRANSCODE_BUFFER_SAMPLES) + 1;
    std::unique_ptr<uint8_t[]> buffers[kBuffers];
    size_t sizes[kBuffers] = {};

    /// Buffer `id` with at least `n` bytes (contents unspecified); null for an unknown id.
    void* get(int id, size_t n) {
        if (id < 0 || id >= kBuffers) return nullptr;
        if (sizes[id] < n) {
            buffers[id].reset();
            sizes[id] = 0;
            buffers[id].reset(new uint8_t[n]);
            sizes[id] = n;
        }
        return buffers[id].get();
    }
};

}  // namespace mcstat::detail
