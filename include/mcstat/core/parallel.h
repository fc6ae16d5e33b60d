// The one parallel loop and the one reading of the core count. Every operation that runs on
// several threads (per-sample operations, the renderer, the codecs' thread pools) asks here how
// many threads a request means and, for its own loops, runs them through parallelFor: OIIO's
// parallel_for_chunked over a pool sized to exactly the threads asked for. Image loops over
// ImageBufs use OIIO's ImageBufAlgo::parallel_image directly, with the same thread counts.
#pragma once

#include <cstdint>
#include <functional>

namespace mcstat {

/// The threads a request means: `requested` when > 0, else every core (at least 1).
int threadCount(int requested);

/// task(b, e) over [begin, end) in chunks of `chunk` items (0: one chunk per thread), on
/// threadCount(nthreads) threads, the caller one of them; with one thread the caller runs
/// task(begin, end). Chunks are handed out as threads free up, so rows of very different cost
/// balance; a task must therefore not depend on which thread runs which chunk (results equal for
/// any thread count).
void parallelFor(int64_t begin, int64_t end, int64_t chunk, int nthreads,
                 const std::function<void(int64_t, int64_t)>& task);

}  // namespace mcstat
