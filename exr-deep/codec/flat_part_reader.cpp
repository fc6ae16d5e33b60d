#include "mcstat/exr-deep/codec/detail/flat_part_reader.h"

#include <OpenEXR/openexr.h>
#include <fmt/format.h>

#include <algorithm>
#include <atomic>
#include <climits>
#include <cstring>
#include <mutex>
#include <new>
#include <unordered_map>

#include "mcstat/core/parallel.h"
#include "mcstat/core/untrusted_text.h"
#include "mcstat/exr-deep/codec/detail/core_io.h"
#include "mcstat/exr-deep/codec/detail/deflate_codec.h"
#include "mcstat/exr-deep/codec/detail/fd_stream.h"
#include "mcstat/exr-deep/codec/detail/scratch_pool.h"

namespace mcstat::detail {

namespace {

/// One decoding thread's state, reused from chunk to chunk and read to read: the ZIP decoder,
/// the pipeline's buffers (handed out by the pipeline's allocation hooks) and the scratch rows
/// of a chunk that reaches outside the rows asked for.
struct Worker : PipelineWorker {
    ZipDecoder zip;
    std::unique_ptr<uint8_t[]> rows;
    size_t rowsSize = 0;

    uint8_t* rowScratch(size_t n) {
        if (rowsSize < n) {
            rows.reset();
            rowsSize = 0;
            rows.reset(new uint8_t[n]);
            rowsSize = n;
        }
        return rows.get();
    }
};

struct PartInfo {
    std::string name;
    bool scanline = false;
    bool sameWindow = false;
    exr_compression_t compression = EXR_COMPRESSION_LAST_TYPE;
    int linesPerChunk = 1;
};

/// One chunk to decode: part request `req`, its first row `y` (file coordinates).
struct Task {
    int req;
    int y;
    double cost;
};

/// A chunk as messages name it: "part 'NAME': the chunk of rows A..B" (made only for a message).
struct ChunkWhere {
    const PartInfo& info;
    int chunkY, chunkEnd;  ///< file rows, chunkEnd exclusive
    std::string operator()() const {
        return fmt::format("part '{}': the chunk of rows {}..{}", printable(info.name), chunkY,
                           chunkEnd - 1);
    }
};

/// Where a chunk's channels are decoded to. The pipeline's strides are int32: a chunk within the
/// rows asked for goes straight into the slices when theirs fit (`direct`), otherwise through
/// planar scratch rows (`scratch`, one plane of chunkRows rows per channel) and a copy.
struct ChunkPlan {
    bool direct = false;
    int blockY = 0;  ///< the file row of the first row asked for
    size_t rowBytes = 0, chunkRows = 0;
    uint8_t* scratch = nullptr;
    std::vector<const FloatSlice*> target;  ///< per channel of the chunk: its slice, or none
};

}  // namespace

struct FlatPartReader::Impl {
    CoreFile io;
    exr_context_t ctxt = nullptr;
    std::string path;
    int x0 = 0, y0 = 0, width = 0, height = 0;
    std::vector<PartInfo> parts;
    detail::ScratchPool<Worker> pool;  ///< scratch of the threads decoding chunks

    ~Impl() {
        if (ctxt != nullptr) exr_finish(&ctxt);
    }
    /// Decodes the chunk of part request `req` that starts at file row `chunkY` into the rows of
    /// its slices that [firstRow, firstRow + rows) (0-based) asks for, with worker `w`; anything
    /// but Ok with `problem`.
    Result decode(const PartSlices& req, const std::unordered_map<std::string, size_t>& byName,
                  int chunkY, int firstRow, int rows, Worker& w, std::string& problem);

  private:
    /// The chunk at file row `chunkY` of part `part`: its chunk table entry into `ci`, checked
    /// against the part's window and compression (a damaged file's lies end here).
    Result chunkInfo(int part, int chunkY, const ChunkWhere& where, Worker& w, exr_chunk_info_t& ci,
                     std::string& problem) const;
    /// Points every channel of `dec` that a slice asks for at its destination (`plan`: the
    /// slices themselves or the scratch rows) as FLOAT; Corrupt when a channel changed since the
    /// header was read.
    Result bindChannels(const PartSlices& req,
                        const std::unordered_map<std::string, size_t>& byName,
                        const exr_chunk_info_t& ci, int chunkY, const ChunkWhere& where,
                        ChunkPlan& plan, exr_decode_pipeline_t& dec, std::string& problem) const;
    /// OpenEXR's decoding routines for `dec`, ZIP's replaced by the worker's own decoder, run.
    exr_result_t runPipeline(int part, const PartInfo& info, exr_decode_pipeline_t& dec,
                             Worker& w) const;
    /// The rows [from, to) of the chunk at `chunkY` from the scratch rows to their slices.
    void copyScratchRows(const ChunkPlan& plan, int chunkY, int from, int to) const;
};

FlatPartReader::FlatPartReader() = default;
FlatPartReader::~FlatPartReader() = default;

bool FlatPartReader::isOpen() const { return impl_ && impl_->ctxt != nullptr; }

bool FlatPartReader::open(int fd, uint64_t size, const std::string& path, int x0, int y0, int width,
                          int height, std::string& problem) {
    impl_.reset();
    auto im = std::make_unique<Impl>();
    im->io.fd = fd;
    im->io.size = int64_t(size);
    im->path = path;
    im->x0 = x0;
    im->y0 = y0;
    im->width = width;
    im->height = height;
    exr_context_initializer_t init = coreFileReader(im->io);
    init.error_handler_fn = &pipelineError;  // each chunk's message goes to its worker
    init.flags = EXR_CONTEXT_FLAG_DISABLE_CHUNK_RECONSTRUCTION;
    Worker opener;  // collects the open's first message
    tPipelineWorker = &opener;
    const exr_result_t rv = exr_start_read(&im->ctxt, path.c_str(), &init);
    tPipelineWorker = nullptr;
    if (rv != EXR_ERR_SUCCESS) {
        problem = fmt::format("header: {}", coreMessage(rv, opener.message));
        return false;
    }
    int count = 0;
    if (exr_get_count(im->ctxt, &count) != EXR_ERR_SUCCESS || count < 0) {
        problem = "header: cannot count the parts";
        return false;
    }
    im->parts.resize(size_t(count));
    for (int p = 0; p < count; ++p) {
        PartInfo& info = im->parts[size_t(p)];
        const char* name = nullptr;
        if (exr_get_name(im->ctxt, p, &name) == EXR_ERR_SUCCESS && name != nullptr)
            info.name = name;
        exr_storage_t storage = EXR_STORAGE_LAST_TYPE;
        exr_attr_box2i_t dw{};
        int32_t lines = 0;
        info.scanline = exr_get_storage(im->ctxt, p, &storage) == EXR_ERR_SUCCESS &&
                        storage == EXR_STORAGE_SCANLINE &&
                        exr_get_compression(im->ctxt, p, &info.compression) == EXR_ERR_SUCCESS &&
                        exr_get_scanlines_per_chunk(im->ctxt, p, &lines) == EXR_ERR_SUCCESS &&
                        lines >= 1;
        info.linesPerChunk = std::max(1, lines);
        info.sameWindow = exr_get_data_window(im->ctxt, p, &dw) == EXR_ERR_SUCCESS &&
                          dw.min.x == x0 && dw.min.y == y0 &&
                          int64_t(dw.max.x) - dw.min.x + 1 == width &&
                          int64_t(dw.max.y) - dw.min.y + 1 == height;
    }
    impl_ = std::move(im);
    return true;
}

exr_const_context_t FlatPartReader::context() const { return impl_ ? impl_->ctxt : nullptr; }
int FlatPartReader::fd() const { return impl_ ? impl_->io.fd : -1; }
uint64_t FlatPartReader::size() const { return impl_ ? uint64_t(impl_->io.size) : 0; }
int FlatPartReader::x0() const { return impl_ ? impl_->x0 : 0; }
int FlatPartReader::y0() const { return impl_ ? impl_->y0 : 0; }
int FlatPartReader::width() const { return impl_ ? impl_->width : 0; }
int FlatPartReader::height() const { return impl_ ? impl_->height : 0; }

bool FlatPartReader::handles(int part) const {
    if (!isOpen() || part < 0 || size_t(part) >= impl_->parts.size()) return false;
    const PartInfo& info = impl_->parts[size_t(part)];
    // The compressions whose Core routines were checked against the C++ API's pixels
    // (tests/exr-deep/test_core_read.cpp). OpenEXR 3.1's Core B44 and B44A scramble FLOAT
    // channels (the C++ API stores them as they are); DWAA and DWAB are lossy.
    bool checked = false;
    switch (info.compression) {
        case EXR_COMPRESSION_NONE:
        case EXR_COMPRESSION_RLE:
        case EXR_COMPRESSION_ZIPS:
        case EXR_COMPRESSION_ZIP:
        case EXR_COMPRESSION_PIZ:
        case EXR_COMPRESSION_PXR24:
            checked = true;
            break;
        default:
            break;
    }
    // A scratch row of one channel must be addressable by the pipeline's int32 line stride.
    return checked && info.scanline && info.sameWindow && impl_->width <= INT32_MAX / 4;
}

bool FlatPartReader::readsAsFloat(int part, const std::string& channel) const {
    if (!handles(part)) return false;
    const exr_attr_chlist_t* chlist = nullptr;
    if (exr_get_channels(impl_->ctxt, part, &chlist) != EXR_ERR_SUCCESS || chlist == nullptr)
        return false;
    for (int c = 0; c < chlist->num_channels; ++c) {
        const exr_attr_chlist_entry_t& e = chlist->entries[c];
        if (e.name.str == nullptr || channel != e.name.str) continue;
        return (e.pixel_type == EXR_PIXEL_FLOAT || e.pixel_type == EXR_PIXEL_HALF) &&
               e.x_sampling == 1 && e.y_sampling == 1;
    }
    return false;
}

FlatPartReader::Result FlatPartReader::Impl::chunkInfo(int part, int chunkY,
                                                       const ChunkWhere& where, Worker& w,
                                                       exr_chunk_info_t& ci,
                                                       std::string& problem) const {
    const PartInfo& info = parts[size_t(part)];
    w.message.clear();
    const exr_result_t rv = exr_read_scanline_chunk_info(ctxt, part, chunkY, &ci);
    if (rv != EXR_ERR_SUCCESS) {
        problem = fmt::format("{}: {}", where(), coreMessage(rv, w.message));
        return rv == EXR_ERR_OUT_OF_MEMORY ? Result::OutOfMemory : Result::Corrupt;
    }
    if (ci.start_y != chunkY || ci.height != where.chunkEnd - chunkY || ci.width != width ||
        ci.start_x != x0) {
        problem = fmt::format("{}: the chunk covers {}x{} pixels from ({}, {})", where(), ci.width,
                              ci.height, ci.start_x, ci.start_y);
        return Result::Corrupt;
    }
    if (info.compression == EXR_COMPRESSION_NONE && ci.packed_size != ci.unpacked_size) {
        problem = fmt::format("{}: uncompressed chunk of {} bytes, expected {}", where(),
                              ci.packed_size, ci.unpacked_size);
        return Result::Corrupt;
    }
    return Result::Ok;
}

FlatPartReader::Result FlatPartReader::Impl::bindChannels(
    const PartSlices& req, const std::unordered_map<std::string, size_t>& byName,
    const exr_chunk_info_t& ci, int chunkY, const ChunkWhere& where, ChunkPlan& plan,
    exr_decode_pipeline_t& dec, std::string& problem) const {
    size_t found = 0;
    for (size_t c = 0; c < plan.target.size(); ++c) {
        exr_coding_channel_info_t& ch = dec.channels[c];
        const auto it = byName.find(ch.channel_name != nullptr ? ch.channel_name : "");
        ch.decode_to_ptr = nullptr;
        if (it == byName.end()) continue;
        // HALF is converted to FLOAT by the pipeline's unpack step (a renderer's half AOVs).
        if ((ch.data_type != EXR_PIXEL_FLOAT && ch.data_type != EXR_PIXEL_HALF) ||
            ch.x_samples != 1 || ch.y_samples != 1 || ch.width != width || ch.height != ci.height) {
            problem = fmt::format("{}: channel '{}' changed while reading", where(),
                                  printable(ch.channel_name));
            return Result::Corrupt;
        }
        const FloatSlice& s = req.slices[it->second];
        plan.target[c] = &s;
        ++found;
        ch.user_data_type = EXR_PIXEL_FLOAT;
        ch.user_bytes_per_element = 4;
        if (plan.direct) {
            ch.decode_to_ptr =
                reinterpret_cast<uint8_t*>(s.base + size_t(chunkY - plan.blockY) * s.lineStride);
            ch.user_pixel_stride = int32_t(s.pixelStride);
            ch.user_line_stride = int32_t(s.lineStride);
        } else {
            ch.decode_to_ptr = plan.scratch + c * plan.chunkRows * plan.rowBytes;
            ch.user_pixel_stride = int32_t(sizeof(float));
            ch.user_line_stride = int32_t(plan.rowBytes);
        }
    }
    if (found != req.slices.size()) {
        problem = fmt::format("{}: the file changed while reading (channels)", where());
        return Result::Corrupt;
    }
    return Result::Ok;
}

exr_result_t FlatPartReader::Impl::runPipeline(int part, const PartInfo& info,
                                               exr_decode_pipeline_t& dec, Worker& w) const {
    exr_result_t rv = exr_decoding_choose_default_routines(ctxt, part, &dec);
    if (rv == EXR_ERR_SUCCESS && isZipCompression(info.compression) &&
        dec.decompress_fn != nullptr) {
        dec.decompress_fn = &zipDecompressChunk;
        dec.decoding_user_data = &w.zip;
    }
    if (rv == EXR_ERR_SUCCESS) rv = exr_decoding_run(ctxt, part, &dec);
    return rv;
}

void FlatPartReader::Impl::copyScratchRows(const ChunkPlan& plan, int chunkY, int from,
                                           int to) const {
    for (size_t c = 0; c < plan.target.size(); ++c) {
        const FloatSlice* s = plan.target[c];
        if (s == nullptr) continue;
        for (int y = from; y < to; ++y) {
            const uint8_t* src =
                plan.scratch + (c * plan.chunkRows + size_t(y - chunkY)) * plan.rowBytes;
            char* dst = s->base + size_t(y - plan.blockY) * s->lineStride;
            for (size_t x = 0; x < size_t(width); ++x)
                std::memcpy(dst + x * s->pixelStride, src + x * sizeof(float), sizeof(float));
        }
    }
}

FlatPartReader::Result FlatPartReader::Impl::decode(
    const PartSlices& req, const std::unordered_map<std::string, size_t>& byName, int chunkY,
    int firstRow, int rows, Worker& w, std::string& problem) {
    const PartInfo& info = parts[size_t(req.part)];
    const int part = req.part;
    const int chunkEnd = std::min(chunkY + info.linesPerChunk, y0 + height);  // exclusive
    const ChunkWhere where{info, chunkY, chunkEnd};
    exr_chunk_info_t ci{};
    if (const Result r = chunkInfo(part, chunkY, where, w, ci, problem); r != Result::Ok) return r;
    ChunkPlan plan;
    plan.blockY = y0 + firstRow;
    const int blockEnd = y0 + firstRow + rows;  // file rows
    plan.direct = chunkY >= plan.blockY && chunkEnd <= blockEnd;
    for (const FloatSlice& s : req.slices)
        plan.direct =
            plan.direct && s.pixelStride <= size_t(INT32_MAX) && s.lineStride <= size_t(INT32_MAX);

    // Everything that may throw before the pipeline exists (it owns allocations until destroyed).
    const exr_attr_chlist_t* chlist = nullptr;
    if (exr_get_channels(ctxt, part, &chlist) != EXR_ERR_SUCCESS || chlist == nullptr) {
        problem = fmt::format("{}: no channel list", where());
        return Result::Corrupt;
    }
    plan.rowBytes = size_t(width) * sizeof(float);
    plan.chunkRows = size_t(ci.height);
    plan.target.assign(size_t(std::max(0, chlist->num_channels)), nullptr);
    plan.scratch =
        plan.direct ? nullptr : w.rowScratch(plan.target.size() * plan.chunkRows * plan.rowBytes);

    exr_decode_pipeline_t dec{};  // EXR_DECODE_PIPELINE_INITIALIZER: all zero
    exr_result_t rv = exr_decoding_initialize(ctxt, part, &ci, &dec);
    Result result = Result::Ok;
    if (rv == EXR_ERR_SUCCESS &&
        size_t(std::max<int16_t>(0, dec.channel_count)) != plan.target.size()) {
        problem = fmt::format("{}: the file changed while reading (channels)", where());
        result = Result::Corrupt;
    }
    if (rv == EXR_ERR_SUCCESS && result == Result::Ok) {
        dec.alloc_fn = &pipelineAlloc;
        dec.free_fn = &pipelineFree;
        result = bindChannels(req, byName, ci, chunkY, where, plan, dec, problem);
        if (result == Result::Ok) rv = runPipeline(part, info, dec, w);
    }
    if (result == Result::Ok && rv != EXR_ERR_SUCCESS) {
        // The codec's own reason first, else OpenEXR's first message for this chunk.
        const bool zipFailed = isZipCompression(info.compression) && rv == EXR_ERR_CORRUPT_CHUNK &&
                               !w.zip.problem().empty();
        problem = fmt::format("{}: {}", where(),
                              zipFailed ? w.zip.problem() : coreMessage(rv, w.message));
        result = rv == EXR_ERR_OUT_OF_MEMORY ? Result::OutOfMemory : Result::Corrupt;
    }
    if (dec.context != nullptr) exr_decoding_destroy(ctxt, &dec);
    if (result != Result::Ok || plan.direct) return result;
    // Scratch rows to the slices: the rows of the chunk that were asked for.
    copyScratchRows(plan, chunkY, std::max(chunkY, plan.blockY), std::min(chunkEnd, blockEnd));
    return Result::Ok;
}

FlatPartReader::Result FlatPartReader::read(const std::vector<PartSlices>& parts, int firstRow,
                                            int rows, int threads, std::string& problem) {
    if (!isOpen() || rows < 1 || firstRow < 0 || firstRow > impl_->height - rows) {
        problem = "rows outside the image";
        return Result::Corrupt;
    }
    Impl& im = *impl_;
    std::vector<std::unordered_map<std::string, size_t>> byName(parts.size());
    std::vector<Task> tasks;
    for (size_t r = 0; r < parts.size(); ++r) {
        const PartSlices& req = parts[r];
        if (!handles(req.part)) {
            problem = fmt::format("part {}: the file changed while reading", req.part);
            return Result::Corrupt;
        }
        for (size_t i = 0; i < req.slices.size(); ++i) byName[r].emplace(req.slices[i].name, i);
        const int lines = im.parts[size_t(req.part)].linesPerChunk;
        const int64_t last = int64_t(im.y0) + firstRow + rows - 1;
        for (int64_t y = int64_t(im.y0) + (firstRow / lines) * int64_t(lines); y <= last;
             y += lines) {
            const int64_t n = std::min<int64_t>(lines, int64_t(im.y0) + im.height - y);
            tasks.push_back({int(r), int(y), double(req.slices.size()) * double(n)});
        }
    }
    // The largest chunks first (the longest tasks start early); a fixed order, so the failure
    // reported is the same whatever the thread count.
    std::stable_sort(tasks.begin(), tasks.end(),
                     [](const Task& a, const Task& b) { return a.cost > b.cost; });
    std::vector<std::string> problems(tasks.size());
    std::vector<Result> results(tasks.size(), Result::Ok);
    std::atomic<int64_t> firstFailed{int64_t(tasks.size())};
    parallelFor(0, int64_t(tasks.size()), 1, threads, [&](int64_t b, int64_t e) {
        for (int64_t t = b; t < e; ++t) {
            if (t > firstFailed.load()) continue;  // a chunk before it failed: its report stands
            const Task& task = tasks[size_t(t)];
            Worker* w = nullptr;
            Result res = Result::Ok;
            try {
                w = im.pool.acquire();
                tPipelineWorker = w;
                res = im.decode(parts[size_t(task.req)], byName[size_t(task.req)], task.y, firstRow,
                                rows, *w, problems[size_t(t)]);
            } catch (const std::bad_alloc&) {
                res = Result::OutOfMemory;
                problems[size_t(t)] = "out of memory while decoding";
            }
            tPipelineWorker = nullptr;
            if (w != nullptr) im.pool.release(w);
            results[size_t(t)] = res;
            if (res != Result::Ok) {
                int64_t cur = firstFailed.load();
                while (t < cur && !firstFailed.compare_exchange_weak(cur, t)) {
                }
            }
        }
    });
    const int64_t failed = firstFailed.load();
    if (failed >= int64_t(tasks.size())) return Result::Ok;
    problem = problems[size_t(failed)];
    return results[size_t(failed)];
}

}  // namespace mcstat::detail
