// Internal: what every user of OpenEXR's Core C API here shares (the flat and deep part readers,
// the part writer, the header checks): a file read through pread with its size known, the
// context's error handler that keeps OpenEXR's first message instead of printing it, and the
// plumbing that hands a decode or encode pipeline the buffers of the worker running it.
#pragma once

#include <OpenEXR/openexr.h>

#include <cstdint>
#include <string>

#include "mcstat/exr-deep/codec/detail/fd_stream.h"
#include "mcstat/exr-deep/codec/detail/scratch_pool.h"

namespace mcstat::detail {

/// An open file as a Core read context sees it (its user data): its descriptor, its size (what
/// every declared offset is checked against) and the context's first error message.
struct CoreFile {
    int fd = -1;
    int64_t size = 0;
    std::string firstError;
};

inline int64_t coreFileRead(exr_const_context_t, void* user, void* buffer, uint64_t sz,
                            uint64_t offset, exr_stream_error_func_ptr_t) {
    return preadFull(static_cast<CoreFile*>(user)->fd, buffer, sz, offset);
}

inline int64_t coreFileSize(exr_const_context_t, void* user) {
    return static_cast<CoreFile*>(user)->size;
}

/// The context's error handler for contexts whose user data is a CoreFile: its first message.
inline void coreFileError(exr_const_context_t ctxt, exr_result_t code, const char* msg) {
    void* user = nullptr;
    if (ctxt == nullptr || exr_get_user_data(ctxt, &user) != EXR_ERR_SUCCESS || user == nullptr)
        return;
    auto* file = static_cast<CoreFile*>(user);
    if (file->firstError.empty())
        file->firstError = msg != nullptr ? msg : exr_get_default_error_message(code);
}

/// A read context over `file` (which must outlive it): pread, the file's size, its first error.
inline exr_context_initializer_t coreFileReader(CoreFile& file) {
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.error_handler_fn = &coreFileError;
    init.user_data = &file;
    init.read_fn = &coreFileRead;
    init.size_fn = &coreFileSize;
    return init;
}

/// OpenEXR's message for `rv`, or the one the error handler kept (`captured`) when there is one.
inline std::string coreMessage(exr_result_t rv, const std::string& captured) {
    return captured.empty() ? std::string(exr_get_default_error_message(rv)) : captured;
}

/// What a thread decoding or encoding one chunk through a Core pipeline holds: the pipeline's
/// buffers (kept from chunk to chunk) and OpenEXR's first message about the chunk. The readers'
/// and the writer's workers derive from it.
struct PipelineWorker {
    TranscodeBuffers transcode;
    std::string message;
};

/// The worker of the chunk this thread transcodes: the pipeline's allocation hooks have no user
/// pointer, and a pipeline runs on the thread that set it up (set it for the chunk, then clear).
inline thread_local PipelineWorker* tPipelineWorker = nullptr;

/// The pipeline's alloc_fn: the running worker's buffer `id`; null (OpenEXR reports
/// EXR_ERR_OUT_OF_MEMORY) without a worker or memory.
inline void* pipelineAlloc(exr_transcoding_pipeline_buffer_id_t id, size_t n) {
    if (tPipelineWorker == nullptr) return nullptr;
    try {
        return tPipelineWorker->transcode.get(int(id), n);
    } catch (const std::bad_alloc&) {
        return nullptr;
    }
}

/// The pipeline's free_fn: nothing, the worker keeps its buffers.
inline void pipelineFree(exr_transcoding_pipeline_buffer_id_t, void*) {}

/// The error handler of contexts whose chunks are transcoded by workers: the first message about
/// the chunk the calling thread's worker transcodes.
inline void pipelineError(exr_const_context_t, exr_result_t code, const char* msg) {
    if (tPipelineWorker != nullptr && tPipelineWorker->message.empty())
        tPipelineWorker->message = msg != nullptr ? msg : exr_get_default_error_message(code);
}

}  // namespace mcstat::detail
