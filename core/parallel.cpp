// The parallel loop (include/mcstat/core/parallel.h), on OIIO's thread pool and parallel_for.
#include "mcstat/core/parallel.h"

#include <OpenImageIO/parallel.h>
#include <OpenImageIO/thread.h>

#include <algorithm>
#include <thread>

namespace mcstat {

int threadCount(int requested) {
    if (requested > 0) return requested;
    return std::max(1, int(std::thread::hardware_concurrency()));
}

void parallelFor(int64_t begin, int64_t end, int64_t chunk, int nthreads,
                 const std::function<void(int64_t, int64_t)>& task) {
    if (end <= begin) return;
    const int threads = int(std::min<int64_t>(threadCount(nthreads), end - begin));
    if (threads == 1) {
        task(begin, end);
        return;
    }
    if (chunk <= 0) chunk = (end - begin + threads - 1) / threads;
    // A private pool sized exactly: the caller plus threads - 1 workers, whatever OIIO's global
    // pool was set to, so that `nthreads` is what runs.
    OIIO::thread_pool pool(threads - 1);
    OIIO::parallel_for_chunked(
        begin, end, chunk, [&](int64_t b, int64_t e) { task(b, e); },
        OIIO::paropt(threads, OIIO::paropt::SplitDir::Y, 1).pool(&pool));
}

}  // namespace mcstat
