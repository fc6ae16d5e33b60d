#include "flat_part_writer.h"

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfChromaticitiesAttribute.h>
#include <OpenEXR/ImfFloatAttribute.h>
#include <OpenEXR/ImfIntAttribute.h>
#include <OpenEXR/ImfPartType.h>
#include <OpenEXR/ImfStringAttribute.h>
#include <OpenEXR/ImfStringVectorAttribute.h>
#include <OpenEXR/openexr.h>
#include <errno.h>
#include <fcntl.h>
#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <climits>
#include <condition_variable>
#include <cstring>
#include <functional>
#include <mutex>
#include <new>
#include <unordered_map>

#include "deflate_codec.h"
#include "fd_stream.h"
#include "mcstat/core/parallel.h"
#include "mcstat/temp_file.h"
#include "worker_pool.h"

namespace mcstat::detail {

namespace {

/// One encoding thread's state, reused from chunk to chunk: the ZIP encoder and the pipeline's
/// buffers (handed out by its allocation hooks).
struct Worker {
    ZipEncoder zip{4};
    TranscodeBuffers transcode;
    std::string message;  ///< OpenEXR's first error message of the current chunk
};

thread_local Worker* tWorker = nullptr;

void* workerAlloc(exr_transcoding_pipeline_buffer_id_t id, size_t n) {
    if (tWorker == nullptr) return nullptr;
    try {
        return tWorker->transcode.get(int(id), n);
    } catch (const std::bad_alloc&) {
        return nullptr;
    }
}

void workerFree(exr_transcoding_pipeline_buffer_id_t, void*) {}

void coreError(exr_const_context_t, exr_result_t code, const char* msg) {
    if (tWorker != nullptr && tWorker->message.empty())
        tWorker->message = msg != nullptr ? msg : exr_get_default_error_message(code);
}

struct WriteIo {
    int fd = -1;
    std::mutex mutex;
    std::string error;  ///< the first write error
};

int64_t coreWrite(exr_const_context_t, void* user, const void* buffer, uint64_t sz, uint64_t offset,
                  exr_stream_error_func_ptr_t) {
    auto& io = *static_cast<WriteIo*>(user);
    const char* p = static_cast<const char*>(buffer);
    uint64_t done = 0;
    while (done < sz) {
        const ssize_t w = ::pwrite(io.fd, p + done, size_t(sz - done), off_t(offset + done));
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) {
            const std::string what = w < 0 ? std::strerror(errno) : "nothing written";
            std::lock_guard<std::mutex> lock(io.mutex);
            if (io.error.empty()) io.error = what;
            return -1;
        }
        done += uint64_t(w);
    }
    return int64_t(done);
}

/// Attributes the part's structure sets (exr_add_part, exr_initialize_required_attr,
/// exr_add_channel, exr_write_header).
bool structural(const char* name) {
    static const char* const kNames[] = {
        "channels",          "compression", "dataWindow",       "displayWindow",
        "lineOrder",         "name",        "pixelAspectRatio", "screenWindowCenter",
        "screenWindowWidth", "type",        "chunkCount",       "tiles"};
    for (const char* n : kNames)
        if (std::strcmp(n, name) == 0) return true;
    return false;
}

bool hasNul(const std::string& s) { return s.find('\0') != std::string::npos; }

bool usesLongNames(const std::vector<Imf::Header>& headers) {
    constexpr size_t kShort = 31;
    for (const Imf::Header& h : headers) {
        for (auto a = h.begin(); a != h.end(); ++a)
            if (std::strlen(a.name()) > kShort || std::strlen(a.attribute().typeName()) > kShort)
                return true;
        for (auto c = h.channels().begin(); c != h.channels().end(); ++c)
            if (std::strlen(c.name()) > kShort) return true;
    }
    return false;
}

exr_attr_box2i_t boxOf(const Imath::Box2i& b) {
    exr_attr_box2i_t r{};
    r.min.x = b.min.x;
    r.min.y = b.min.y;
    r.max.x = b.max.x;
    r.max.y = b.max.y;
    return r;
}

/// Adds part `h` to `ctxt`; false with `problem`.
bool addPart(exr_context_t ctxt, const Imf::Header& h, std::string& problem) {
    int idx = -1;
    exr_result_t rv = exr_add_part(ctxt, h.name().c_str(), EXR_STORAGE_SCANLINE, &idx);
    const exr_attr_box2i_t disp = boxOf(h.displayWindow()), data = boxOf(h.dataWindow());
    exr_attr_v2f_t center{};
    center.x = h.screenWindowCenter().x;
    center.y = h.screenWindowCenter().y;
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_initialize_required_attr(ctxt, idx, &disp, &data, h.pixelAspectRatio(), &center,
                                          h.screenWindowWidth(), exr_lineorder_t(h.lineOrder()),
                                          exr_compression_t(h.compression()));
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_set_zip_compression_level(ctxt, idx, h.zipCompressionLevel());
    for (auto c = h.channels().begin(); rv == EXR_ERR_SUCCESS && c != h.channels().end(); ++c) {
        const Imf::Channel& ch = c.channel();
        rv = exr_add_channel(ctxt, idx, c.name(), exr_pixel_type_t(ch.type),
                             ch.pLinear ? EXR_PERCEPTUALLY_LINEAR : EXR_PERCEPTUALLY_LOGARITHMIC,
                             ch.xSampling, ch.ySampling);
    }
    for (auto a = h.begin(); rv == EXR_ERR_SUCCESS && a != h.end(); ++a) {
        if (structural(a.name())) continue;
        const std::string type = a.attribute().typeName();
        if (const auto* i = dynamic_cast<const Imf::IntAttribute*>(&a.attribute())) {
            rv = exr_attr_set_int(ctxt, idx, a.name(), i->value());
        } else if (const auto* f = dynamic_cast<const Imf::FloatAttribute*>(&a.attribute())) {
            rv = exr_attr_set_float(ctxt, idx, a.name(), f->value());
        } else if (const auto* s = dynamic_cast<const Imf::StringAttribute*>(&a.attribute())) {
            rv = exr_attr_set_string(ctxt, idx, a.name(), s->value().c_str());
        } else if (const auto* v =
                       dynamic_cast<const Imf::StringVectorAttribute*>(&a.attribute())) {
            std::vector<const char*> ptrs;
            for (const std::string& e : v->value()) ptrs.push_back(e.c_str());
            rv = exr_attr_set_string_vector(ctxt, idx, a.name(), int32_t(ptrs.size()),
                                            ptrs.empty() ? nullptr : ptrs.data());
        } else if (const auto* c =
                       dynamic_cast<const Imf::ChromaticitiesAttribute*>(&a.attribute())) {
            const Imf::Chromaticities& cv = c->value();
            exr_attr_chromaticities_t ch{};
            ch.red_x = cv.red.x, ch.red_y = cv.red.y, ch.green_x = cv.green.x;
            ch.green_y = cv.green.y, ch.blue_x = cv.blue.x, ch.blue_y = cv.blue.y;
            ch.white_x = cv.white.x, ch.white_y = cv.white.y;
            rv = exr_attr_set_chromaticities(ctxt, idx, a.name(), &ch);
        } else {
            problem = fmt::format("part '{}': attribute '{}' of type {}", h.name(), a.name(), type);
            return false;
        }
    }
    if (rv != EXR_ERR_SUCCESS) {
        problem = fmt::format("part '{}': {}", h.name(), exr_get_default_error_message(rv));
        return false;
    }
    return true;
}

struct SpillChunk {
    uint64_t offset = 0;
    uint64_t size = 0;
};

struct PartState {
    std::string name;
    exr_compression_t compression = EXR_COMPRESSION_NONE;
    int lines = 1;  ///< rows per chunk
    int32_t chunks = 0;
    std::unique_ptr<float[]> stage;  ///< staged rows: slice s, row r at (s * lines + r) * width
    size_t stageFloats = 0;
    int staged = 0;                 ///< rows in the stage (they start on a chunk boundary)
    std::vector<SpillChunk> spill;  ///< by chunk index
};

/// One chunk to encode: part `part`, first row `row` (0-based), `rows` rows, from the block's
/// slices (row `srcRow` of the block) or from the part's stage.
struct Task {
    int part = 0;
    int row = 0;
    int rows = 0;
    bool staged = false;
    int srcRow = 0;
    std::vector<uint8_t> out;
    std::string problem;
};

}  // namespace

struct FlatPartWriter::Impl {
    WriteIo io;
    exr_context_t ctxt = nullptr;
    std::string target;
    int threads = 1;
    int x0 = 0, y0 = 0, width = 0, height = 0;
    std::vector<PartState> parts;
    int nextRow = 0;
    bool direct = false;  ///< the whole image came in one write: chunks went to the file
    std::unique_ptr<TemporaryFile> spillFile;
    Fd spillFd;
    uint64_t spillSize = 0;
    detail::WorkerPool<Worker> pool;  ///< scratch of the threads encoding chunks
    Worker main;                      ///< the calling thread's, for the serial steps' messages

    ~Impl() {
        if (ctxt != nullptr) exr_finish(&ctxt);
    }
    bool encode(Task& t, const PartSlices* src, Worker& w);
    /// Encodes `tasks` on `threads` threads; false with the problem of the first failing one
    /// in task order. With `sink`, each chunk goes to it in task order (false stops with
    /// Task::problem set) and is then released.
    bool encodeAll(std::vector<Task>& tasks, const std::vector<PartSlices>& src,
                   std::string& problem, const std::function<bool(Task&)>& sink = nullptr);
    std::string coreProblem(exr_result_t rv, const std::string& message) const {
        if (!io.error.empty()) return io.error;
        return message.empty() ? std::string(exr_get_default_error_message(rv)) : message;
    }
};

FlatPartWriter::FlatPartWriter() = default;
FlatPartWriter::~FlatPartWriter() = default;

bool FlatPartWriter::supports(const std::vector<Imf::Header>& headers, size_t maxPixelBytes) {
    if (headers.empty()) return false;
    const Imath::Box2i dw = headers[0].dataWindow();
    const int64_t width = int64_t(dw.max.x) - dw.min.x + 1;
    if (width < 1 || uint64_t(width) * maxPixelBytes > uint64_t(INT32_MAX) ||
        uint64_t(width) * sizeof(float) > uint64_t(INT32_MAX) || maxPixelBytes > size_t(INT32_MAX))
        return false;
    for (const Imf::Header& h : headers) {
        if (!h.hasType() || h.type() != Imf::SCANLINEIMAGE || h.dataWindow() != dw ||
            !h.hasName() || hasNul(h.name()))
            return false;
        if (h.compression() != Imf::NO_COMPRESSION && h.compression() != Imf::ZIPS_COMPRESSION &&
            h.compression() != Imf::ZIP_COMPRESSION)
            return false;
        for (auto c = h.channels().begin(); c != h.channels().end(); ++c)
            if (c.channel().type != Imf::FLOAT || c.channel().xSampling != 1 ||
                c.channel().ySampling != 1)
                return false;
        for (auto a = h.begin(); a != h.end(); ++a) {
            if (structural(a.name())) continue;
            const Imf::Attribute& at = a.attribute();
            if (const auto* s = dynamic_cast<const Imf::StringAttribute*>(&at)) {
                if (hasNul(s->value())) return false;
            } else if (const auto* v = dynamic_cast<const Imf::StringVectorAttribute*>(&at)) {
                for (const std::string& e : v->value())
                    if (hasNul(e)) return false;
            } else if (!dynamic_cast<const Imf::IntAttribute*>(&at) &&
                       !dynamic_cast<const Imf::FloatAttribute*>(&at) &&
                       !dynamic_cast<const Imf::ChromaticitiesAttribute*>(&at)) {
                return false;
            }
        }
    }
    return true;
}

bool FlatPartWriter::open(int fd, const std::string& target,
                          const std::vector<Imf::Header>& headers, int threads,
                          std::string& problem) {
    impl_.reset();
    if (!supports(headers, 0)) {
        problem = "the parts are not flat FLOAT parts the Core writer takes";
        return false;
    }
    auto im = std::make_unique<Impl>();
    im->io.fd = fd;
    im->target = target;
    im->threads = std::max(1, threads);
    const Imath::Box2i dw = headers[0].dataWindow();
    im->x0 = dw.min.x;
    im->y0 = dw.min.y;
    im->width = dw.max.x - dw.min.x + 1;
    im->height = dw.max.y - dw.min.y + 1;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.error_handler_fn = &coreError;
    init.user_data = &im->io;
    init.write_fn = &coreWrite;
    Worker& main = im->main;
    tWorker = &main;
    exr_result_t rv = exr_start_write(&im->ctxt, target.c_str(), EXR_WRITE_FILE_DIRECTLY, &init);
    // Names beyond 31 bytes need the long-names flag, which the C++ API sets exactly when an
    // attribute's name or type name or a channel's name is that long: the same here.
    if (rv == EXR_ERR_SUCCESS && usesLongNames(headers)) rv = exr_set_longname_support(im->ctxt, 1);
    bool ok = rv == EXR_ERR_SUCCESS;
    for (size_t p = 0; ok && p < headers.size(); ++p) ok = addPart(im->ctxt, headers[p], problem);
    if (ok) {
        rv = exr_write_header(im->ctxt);
        ok = rv == EXR_ERR_SUCCESS;
        if (!ok) problem = fmt::format("header: {}", im->coreProblem(rv, main.message));
    } else if (problem.empty()) {
        problem = fmt::format("header: {}", im->coreProblem(rv, main.message));
    }
    im->parts.resize(headers.size());
    for (size_t p = 0; ok && p < headers.size(); ++p) {
        PartState& ps = im->parts[p];
        ps.name = headers[p].name();
        int32_t lines = 0;
        ok = exr_get_compression(im->ctxt, int(p), &ps.compression) == EXR_ERR_SUCCESS &&
             exr_get_scanlines_per_chunk(im->ctxt, int(p), &lines) == EXR_ERR_SUCCESS &&
             exr_get_chunk_count(im->ctxt, int(p), &ps.chunks) == EXR_ERR_SUCCESS && lines >= 1 &&
             ps.chunks >= 1;
        ps.lines = std::max(1, lines);
        ps.spill.resize(size_t(std::max(0, ps.chunks)));
        if (!ok) problem = fmt::format("part '{}': no chunk layout", ps.name);
    }
    tWorker = nullptr;
    if (!ok) return false;
    impl_ = std::move(im);
    return true;
}

bool FlatPartWriter::Impl::encode(Task& t, const PartSlices* src, Worker& w) {
    const PartState& ps = parts[size_t(t.part)];
    w.message.clear();
    const int fileRow = y0 + t.row;
    exr_chunk_info_t ci{};
    exr_result_t rv = exr_write_scanline_chunk_info(ctxt, t.part, fileRow, &ci);
    if (rv == EXR_ERR_SUCCESS && (ci.start_y != fileRow || ci.height != t.rows)) {
        t.problem = fmt::format("part '{}': the chunk of row {} holds {} rows, expected {}",
                                ps.name, fileRow, ci.height, t.rows);
        return false;
    }
    std::unordered_map<std::string, size_t> byName;
    for (size_t i = 0; i < src->slices.size(); ++i) byName.emplace(src->slices[i].name, i);
    exr_encode_pipeline_t enc{};  // EXR_ENCODE_PIPELINE_INITIALIZER: all zero
    if (rv == EXR_ERR_SUCCESS) rv = exr_encoding_initialize(ctxt, t.part, &ci, &enc);
    bool ok = rv == EXR_ERR_SUCCESS;
    if (ok) {
        enc.alloc_fn = &workerAlloc;
        enc.free_fn = &workerFree;
        const size_t rowFloats = size_t(width);
        for (int c = 0; ok && c < enc.channel_count; ++c) {
            exr_coding_channel_info_t& ch = enc.channels[c];
            const auto it = byName.find(ch.channel_name != nullptr ? ch.channel_name : "");
            if (it == byName.end()) {
                t.problem = fmt::format("part '{}': no data for channel '{}'", ps.name,
                                        ch.channel_name != nullptr ? ch.channel_name : "");
                ok = false;
                break;
            }
            const FloatSlice& s = src->slices[it->second];
            ch.user_data_type = EXR_PIXEL_FLOAT;
            ch.user_bytes_per_element = 4;
            if (t.staged) {
                ch.encode_from_ptr = reinterpret_cast<const uint8_t*>(
                    ps.stage.get() + it->second * size_t(ps.lines) * rowFloats);
                ch.user_pixel_stride = int32_t(sizeof(float));
                ch.user_line_stride = int32_t(rowFloats * sizeof(float));
            } else {
                ch.encode_from_ptr =
                    reinterpret_cast<const uint8_t*>(s.base + size_t(t.srcRow) * s.lineStride);
                ch.user_pixel_stride = int32_t(s.pixelStride);
                ch.user_line_stride = int32_t(s.lineStride);
            }
        }
        if (ok) {
            rv = exr_encoding_choose_default_routines(ctxt, t.part, &enc);
            if (rv == EXR_ERR_SUCCESS && isZipCompression(ps.compression)) {
                enc.compress_fn = &zipCompressChunk;
                enc.encoding_user_data = &w.zip;
            }
            // Written by the caller in part and row order (exr_write_scanline_chunk checks it);
            // the default yield would refuse any chunk but the next one the file takes.
            enc.yield_until_ready_fn = nullptr;
            enc.write_fn = nullptr;
            if (rv == EXR_ERR_SUCCESS) rv = exr_encoding_run(ctxt, t.part, &enc);
            if (rv == EXR_ERR_SUCCESS) {
                const auto* b = static_cast<const uint8_t*>(enc.compressed_buffer);
                t.out.assign(b, b + enc.compressed_bytes);
            }
            ok = rv == EXR_ERR_SUCCESS;
        }
    }
    if (!ok && t.problem.empty())
        t.problem = fmt::format("part '{}': the chunk of row {}: {}", ps.name, fileRow,
                                coreProblem(rv, w.message));
    if (enc.context != nullptr) exr_encoding_destroy(ctxt, &enc);
    return ok;
}

bool FlatPartWriter::Impl::encodeAll(std::vector<Task>& tasks, const std::vector<PartSlices>& src,
                                     std::string& problem, const std::function<bool(Task&)>& sink) {
    // Each thread claims the next task in order; `sink` (when given) takes the encoded chunks in
    // task order as soon as each one's predecessors are done, and a thread waits before encoding a
    // task more than `ahead` past the next one to sink (memory stays a few chunks). Claims are in
    // order, so the task the others wait for is always being encoded: no thread waits forever.
    const int64_t n = int64_t(tasks.size()), ahead = 4 * int64_t(threads);
    std::atomic<int64_t> claimed{0}, firstFailed{n};
    std::mutex m;
    std::condition_variable cv;
    int64_t nextSink = 0;
    std::vector<char> done(tasks.size(), 0);
    const auto fail = [&](int64_t i) {
        int64_t cur = firstFailed.load();
        while (i < cur && !firstFailed.compare_exchange_weak(cur, i)) {
        }
    };
    parallelFor(0, threads, 1, threads, [&](int64_t, int64_t) {
        for (int64_t i = claimed++; i < n; i = claimed++) {
            if (i > firstFailed.load()) continue;
            if (sink) {
                std::unique_lock<std::mutex> lock(m);
                cv.wait(lock, [&] { return i < nextSink + ahead || firstFailed.load() < n; });
                if (i > firstFailed.load()) continue;
            }
            Task& t = tasks[size_t(i)];
            Worker* w = nullptr;
            bool ok = false;
            try {
                w = pool.acquire();
                tWorker = w;
                ok = encode(t, &src[size_t(t.part)], *w);
            } catch (const std::bad_alloc&) {
                t.problem = "out of memory while compressing";
            }
            tWorker = nullptr;
            if (w != nullptr) pool.release(w);
            if (!ok) fail(i);
            if (sink) {
                std::lock_guard<std::mutex> lock(m);
                done[size_t(i)] = ok ? 1 : 0;
                while (nextSink < n && done[size_t(nextSink)] && nextSink < firstFailed.load()) {
                    Task& ready = tasks[size_t(nextSink)];
                    if (!sink(ready)) {
                        fail(nextSink);
                        break;
                    }
                    std::vector<uint8_t>().swap(ready.out);
                    ++nextSink;
                }
                cv.notify_all();
            } else if (!ok) {
                std::lock_guard<std::mutex> lock(m);
                cv.notify_all();
            }
        }
    });
    const int64_t failed = firstFailed.load();
    if (failed >= n) return true;
    problem = tasks[size_t(failed)].problem;
    return false;
}

bool FlatPartWriter::write(const std::vector<PartSlices>& parts, int rows, std::string& problem) {
    if (!impl_ || rows < 1 || rows > impl_->height - impl_->nextRow ||
        parts.size() != impl_->parts.size()) {
        problem = "rows or parts that do not continue the image";
        return false;
    }
    Impl& im = *impl_;
    Worker& main = im.main;
    main.message.clear();
    tWorker = &main;
    const int r0 = im.nextRow, r1 = im.nextRow + rows;  // rows of this write, 0-based
    if (r0 == 0 && r1 == im.height) {
        // The whole image: every part's chunks in file order, each written as soon as the ones
        // before it are.
        im.direct = true;
        std::vector<Task> tasks;
        for (size_t p = 0; p < parts.size(); ++p) {
            const PartState& ps = im.parts[p];
            for (int r = 0; r < im.height; r += ps.lines) {
                Task t;
                t.part = int(p);
                t.row = t.srcRow = r;
                t.rows = std::min(ps.lines, im.height - r);
                tasks.push_back(std::move(t));
            }
        }
        const auto toFile = [&](Task& t) {  // one at a time (encodeAll's lock), any thread
            Worker* const saved = tWorker;
            tWorker = &main;
            main.message.clear();
            const exr_result_t rv = exr_write_scanline_chunk(im.ctxt, t.part, im.y0 + t.row,
                                                             t.out.data(), t.out.size());
            if (rv != EXR_ERR_SUCCESS)
                t.problem =
                    fmt::format("part '{}': the chunk of row {}: {}", im.parts[size_t(t.part)].name,
                                im.y0 + t.row, im.coreProblem(rv, main.message));
            tWorker = saved;
            return rv == EXR_ERR_SUCCESS;
        };
        if (!im.encodeAll(tasks, parts, problem, toFile)) return tWorker = nullptr, false;
        im.nextRow = im.height;
        tWorker = nullptr;
        return true;
    }
    // A block of a streamed image: every chunk it completes, to the spill file.
    if (!im.spillFile) {
        im.spillFile = std::make_unique<TemporaryFile>(im.target, ".spill");
        im.spillFd =
            Fd(::open(im.spillFile->path().c_str(), O_RDWR | O_CREAT | O_EXCL | O_CLOEXEC, 0600));
        if (im.spillFd.get() < 0) {
            problem = fmt::format("cannot create the spill file {} ({})", im.spillFile->path(),
                                  std::strerror(errno));
            im.spillFile->remove();
            return tWorker = nullptr, false;
        }
    }
    const auto stageRows = [&](size_t p, int from, int to) {  // rows [from, to) of the write
        PartState& ps = im.parts[p];
        const size_t w = size_t(im.width);
        const std::vector<FloatSlice>& sl = parts[p].slices;
        const size_t need = sl.size() * size_t(ps.lines) * w;
        if (ps.stageFloats < need) {
            ps.stage.reset();
            ps.stageFloats = 0;
            ps.stage.reset(new float[need]);
            ps.stageFloats = need;
        }
        for (size_t s = 0; s < sl.size(); ++s)
            for (int r = from; r < to; ++r) {
                float* dst =
                    ps.stage.get() + (s * size_t(ps.lines) + size_t(ps.staged + r - from)) * w;
                const char* src = sl[s].base + size_t(r - r0) * sl[s].lineStride;
                for (size_t x = 0; x < w; ++x)
                    std::memcpy(dst + x, src + x * sl[s].pixelStride, sizeof(float));
            }
        ps.staged += to - from;
    };
    std::vector<Task> tasks;
    std::vector<std::pair<int, int>> leftover(parts.size(), {r1, r1});
    try {
        for (size_t p = 0; p < parts.size(); ++p) {
            PartState& ps = im.parts[p];
            int row = r0;
            if (ps.staged > 0) {  // complete the staged chunk first
                const int start = r0 - ps.staged;
                const int end = std::min(start + ps.lines, im.height);
                const int take = std::min(end, r1) - r0;
                stageRows(p, r0, r0 + take);
                row += take;
                if (start + ps.staged == end) {
                    Task t;
                    t.part = int(p);
                    t.row = start;
                    t.rows = end - start;
                    t.staged = true;
                    tasks.push_back(std::move(t));
                }
            }
            for (; row < r1; row += ps.lines) {
                const int end = std::min(row + ps.lines, im.height);
                if (end > r1) {
                    leftover[p] = {row, r1};
                    break;
                }
                Task t;
                t.part = int(p);
                t.row = row;
                t.rows = end - row;
                t.srcRow = row - r0;
                tasks.push_back(std::move(t));
            }
        }
    } catch (const std::bad_alloc&) {
        problem = "out of memory while staging rows";
        return tWorker = nullptr, false;
    }
    if (!im.encodeAll(tasks, parts, problem)) return tWorker = nullptr, false;
    for (const Task& t : tasks) {
        PartState& ps = im.parts[size_t(t.part)];
        if (t.staged) ps.staged = 0;
        const char* p = reinterpret_cast<const char*>(t.out.data());
        uint64_t done = 0;
        while (done < t.out.size()) {
            const ssize_t w = ::pwrite(im.spillFd.get(), p + done, t.out.size() - done,
                                       off_t(im.spillSize + done));
            if (w < 0 && errno == EINTR) continue;
            if (w <= 0) {
                problem = fmt::format("cannot write the spill file {} ({})", im.spillFile->path(),
                                      w < 0 ? std::strerror(errno) : "nothing written");
                return tWorker = nullptr, false;
            }
            done += uint64_t(w);
        }
        ps.spill[size_t(t.row / ps.lines)] = {im.spillSize, t.out.size()};
        im.spillSize += t.out.size();
    }
    try {
        for (size_t p = 0; p < parts.size(); ++p)
            if (leftover[p].first < leftover[p].second)
                stageRows(p, leftover[p].first, leftover[p].second);
    } catch (const std::bad_alloc&) {
        problem = "out of memory while staging rows";
        return tWorker = nullptr, false;
    }
    im.nextRow = r1;
    tWorker = nullptr;
    return true;
}

bool FlatPartWriter::finish(std::string& problem) {
    if (!impl_ || impl_->nextRow != impl_->height) {
        problem = "the image is not complete";
        return false;
    }
    Impl& im = *impl_;
    Worker& main = im.main;
    main.message.clear();
    tWorker = &main;
    exr_result_t rv = EXR_ERR_SUCCESS;
    if (!im.direct) {
        std::vector<uint8_t> buf;
        for (size_t p = 0; rv == EXR_ERR_SUCCESS && p < im.parts.size(); ++p) {
            const PartState& ps = im.parts[p];
            for (size_t c = 0; rv == EXR_ERR_SUCCESS && c < ps.spill.size(); ++c) {
                const SpillChunk& sc = ps.spill[c];
                buf.resize(size_t(sc.size));
                if (preadFull(im.spillFd.get(), buf.data(), sc.size, sc.offset) !=
                    int64_t(sc.size)) {
                    problem = fmt::format("cannot read the spill file {} ({})",
                                          im.spillFile->path(), std::strerror(errno));
                    tWorker = nullptr;
                    return false;
                }
                rv = exr_write_scanline_chunk(im.ctxt, int(p), im.y0 + int(c) * ps.lines,
                                              buf.data(), sc.size);
            }
        }
    }
    if (rv == EXR_ERR_SUCCESS) rv = exr_finish(&im.ctxt);
    tWorker = nullptr;
    if (rv != EXR_ERR_SUCCESS || !im.io.error.empty()) {
        problem = im.coreProblem(rv, main.message);
        return false;
    }
    im.spillFd.reset();
    im.spillFile.reset();  // removes the spill file
    return true;
}

}  // namespace mcstat::detail
