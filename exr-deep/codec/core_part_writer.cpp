#include "mcstat/exr-deep/codec/detail/core_part_writer.h"

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

#include "mcstat/core/parallel.h"
#include "mcstat/core/untrusted_text.h"
#include "mcstat/exr-deep/codec/detail/core_io.h"
#include "mcstat/exr-deep/codec/detail/deflate_codec.h"
#include "mcstat/exr-deep/codec/detail/fd_stream.h"
#include "mcstat/exr-deep/codec/detail/scratch_pool.h"
#include "mcstat/exr-deep/codec/temp_file.h"

namespace mcstat::detail {

namespace {

/// One encoding thread's state, reused from chunk to chunk: the ZIP encoder and the pipeline's
/// buffers (handed out by its allocation hooks).
struct Worker : PipelineWorker {
    ZipEncoder zip;
    std::vector<uint8_t> table, data;  ///< a deep chunk's sample counts and samples, unpacked
};

struct WriteIo {
    int fd = -1;
    std::mutex mutex;
    std::string error;  ///< the first write error
    /// Early writeback: the bytes below `kicked` were handed to the kernel's writeback as they
    /// arrived, so the commit's fsync waits only for the rest. Writes come one at a time
    /// (encodeAll's lock, or the calling thread).
    uint64_t kicked = 0;
};

/// Starts the writeback of what `io` holds beyond its last start once that is at least 1 MiB
/// (file writes end at `end`); advisory: the durability is still the commit's fsync.
void startWriteback(WriteIo& io, uint64_t end) {
#if defined(__linux__)
    constexpr uint64_t kStep = uint64_t(1) << 20;
    if (end < io.kicked + kStep) return;
    (void)::sync_file_range(io.fd, off_t(io.kicked), off_t(end - io.kicked), SYNC_FILE_RANGE_WRITE);
    io.kicked = end;
#else
    (void)io;
    (void)end;
#endif
}

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
    startWriteback(io, offset + done);
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
    const bool deep = h.type() == Imf::DEEPSCANLINE;
    exr_result_t rv = exr_add_part(ctxt, h.name().c_str(),
                                   deep ? EXR_STORAGE_DEEP_SCANLINE : EXR_STORAGE_SCANLINE, &idx);
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
            problem = fmt::format("part '{}': attribute '{}' of type {}", printable(h.name()),
                                  printable(a.name()), printable(type));
            return false;
        }
    }
    if (rv != EXR_ERR_SUCCESS) {
        problem =
            fmt::format("part '{}': {}", printable(h.name()), exr_get_default_error_message(rv));
        return false;
    }
    return true;
}

struct SpillChunk {
    uint64_t offset = 0;
    uint64_t size = 0;
    uint64_t tableBytes = 0;  ///< deep: the packed sample counts, first of the `size` bytes
    uint64_t unpacked = 0;    ///< deep: the samples' unpacked bytes
};

struct PartState {
    std::string name;
    exr_compression_t compression = EXR_COMPRESSION_NONE;
    bool deep = false;
    int lines = 1;  ///< rows per chunk
    int32_t chunks = 0;
    std::vector<std::string> channels;  ///< in the file's order
    std::vector<size_t> channelBytes;   ///< bytes of one value of each
    /// Staged rows of a flat part: slice s, row r at (s * lines + r) * width * 4 bytes, values
    /// packed by their size.
    std::unique_ptr<uint8_t[]> stage;
    size_t stageBytes = 0;
    int staged = 0;                      ///< rows in the stage (they start on a chunk boundary)
    std::vector<SpillChunk> spill;       ///< by chunk index
    exr_context_t copySource = nullptr;  ///< a deep part's chunks copied from this file
    std::string copyPath;
};

/// One chunk to encode: part `part`, first row `row` (0-based), `rows` rows, from the write's
/// rows (row `srcRow` of the write) or from the part's stage. A deep chunk's `out` is its packed
/// sample counts (`tableBytes`) followed by its packed samples (`unpacked` bytes unpacked).
struct Task {
    int part = 0;
    int row = 0;
    int rows = 0;
    bool staged = false;
    int srcRow = 0;
    std::vector<uint8_t> out;
    uint64_t tableBytes = 0;
    uint64_t unpacked = 0;
    std::string problem;
};

/// A write's rows of one part with what encoding them needs: each file channel's source (an index
/// into rows->slices or rows->deep) and, for a deep part, the index of each row's first sample.
struct Source {
    const PartRows* rows = nullptr;
    std::vector<size_t> channel;
    std::vector<uint64_t> rowStart;
};

/// Applies ZIP to `n` bytes at `in` into `out` (room for n), or copies them when ZIP would not
/// shrink them or there is no compression; returns the bytes stored.
size_t packBuffer(ZipEncoder* zip, const uint8_t* in, size_t n, uint8_t* out) {
    if (n == 0) return 0;
    const size_t got = zip != nullptr ? zip->apply(in, n, out, n) : 0;
    if (got != 0) return got;
    std::memcpy(out, in, n);
    return n;
}

}  // namespace

struct CorePartWriter::Impl {
    WriteIo io;
    exr_context_t ctxt = nullptr;
    std::string target;
    int threads = 1;
    int x0 = 0, y0 = 0, width = 0, height = 0;
    std::vector<PartState> parts;
    int nextRow = 0;
    bool direct = false;  ///< chunks go straight to the file (set by the first write)
    std::unique_ptr<TemporaryFile> spillFile;
    Fd spillFd;
    uint64_t spillSize = 0;
    detail::ScratchPool<Worker> pool;  ///< scratch of the threads encoding chunks
    Worker main;                       ///< the calling thread's, for the serial steps' messages

    ~Impl() {
        if (ctxt != nullptr) exr_finish(&ctxt);
        for (PartState& ps : parts)
            if (ps.copySource != nullptr) exr_finish(&ps.copySource);
    }
    bool encode(Task& t, const Source& src, Worker& w);
    bool encodeFlat(Task& t, const Source& src, Worker& w, const exr_chunk_info_t& ci);
    bool encodeDeep(Task& t, const Source& src, Worker& w);
    bool copyChunk(Task& t, Worker& w);
    /// Encodes `tasks` on `threads` threads; each chunk goes to `sink` in task order as soon as the
    /// ones before it are (false stops with Task::problem set) and is then released. False with
    /// the problem of the first failing task in task order.
    bool encodeAll(std::vector<Task>& tasks, const std::vector<Source>& src, std::string& problem,
                   const std::function<bool(Task&)>& sink);
    /// Writes the chunk of part `part` starting at file row `y` (`size` bytes at `bytes`; deep: the
    /// packed counts, `tableBytes` of them, then the samples, `unpacked` bytes unpacked).
    exr_result_t writeChunk(int part, int y, const uint8_t* bytes, uint64_t size,
                            uint64_t tableBytes, uint64_t unpacked) {
        if (!parts[size_t(part)].deep) return exr_write_scanline_chunk(ctxt, part, y, bytes, size);
        return exr_write_deep_scanline_chunk(ctxt, part, y, bytes + tableBytes, size - tableBytes,
                                             unpacked, bytes, tableBytes);
    }
    /// Writes chunk `t` (encoded) into the file; false with t.problem.
    bool toFile(Task& t);
    /// Appends chunk `t` to the spill file; false with t.problem.
    bool toSpill(Task& t);
    /// Opens the file part `p`'s chunks are copied from and checks it holds such a part.
    bool openCopySource(size_t p, const std::string& path, std::string& problem);
    /// Binds each part's rows of a write of `rows` rows to the file's channels (`src`, by part);
    /// opens the parts copied from another file. False with `problem`.
    bool bindSources(const std::vector<PartRows>& rows, int count, std::vector<Source>& src,
                     std::string& problem);
    /// Creates the spill file (chunks that cannot go to the file in its order yet). False with
    /// `problem`.
    bool openSpill(std::string& problem);
    /// Copies rows [from, to) of the write that starts at row r0 (`rows`, bound as `src`) into
    /// flat part p's stage, after the rows staged already.
    void stageRows(size_t p, const PartRows& rows, const Source& src, int r0, int from, int to);
    /// The chunks that rows [r0, r1) complete, in file order (`tasks`), staging the rows that
    /// complete a staged chunk; `leftover` gets each part's rows that start a chunk the write
    /// does not complete (to stage after the tasks are written).
    void planChunks(const std::vector<PartRows>& rows, const std::vector<Source>& src, int r0,
                    int r1, std::vector<Task>& tasks, std::vector<std::pair<int, int>>& leftover);
    /// A call from the caller's thread: OpenEXR's messages go to `main`.
    void enter() {
        main.message.clear();
        tPipelineWorker = &main;
    }
    std::string coreProblem(exr_result_t rv, const std::string& message) const {
        if (!io.error.empty()) return io.error;
        return coreMessage(rv, message);
    }
};

CorePartWriter::CorePartWriter() = default;
CorePartWriter::~CorePartWriter() = default;

bool CorePartWriter::supports(const std::vector<Imf::Header>& headers, size_t maxPixelBytes) {
    // Deep chunks are packed here in the host's byte order, which must be the file's.
    if (__BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__) return false;
    if (headers.empty()) return false;
    const Imath::Box2i dw = headers[0].dataWindow();
    const int64_t width = int64_t(dw.max.x) - dw.min.x + 1;
    if (width < 1 || uint64_t(width) * maxPixelBytes > uint64_t(INT32_MAX) ||
        uint64_t(width) * sizeof(float) > uint64_t(INT32_MAX) || maxPixelBytes > size_t(INT32_MAX))
        return false;
    for (const Imf::Header& h : headers) {
        if (!h.hasType() || h.dataWindow() != dw || !h.hasName() || hasNul(h.name())) return false;
        const bool deep = h.type() == Imf::DEEPSCANLINE;
        if (!deep && h.type() != Imf::SCANLINEIMAGE) return false;
        const Imf::Compression c = h.compression();
        if (c != Imf::NO_COMPRESSION && c != Imf::ZIPS_COMPRESSION &&
            (deep || c != Imf::ZIP_COMPRESSION))
            return false;
        for (auto ch = h.channels().begin(); ch != h.channels().end(); ++ch) {
            const Imf::PixelType t = ch.channel().type;
            if ((t != Imf::FLOAT && t != Imf::UINT && (deep || t != Imf::HALF)) ||
                ch.channel().xSampling != 1 || ch.channel().ySampling != 1)
                return false;
        }
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

bool CorePartWriter::open(int fd, const std::string& target,
                          const std::vector<Imf::Header>& headers, int threads,
                          std::string& problem) {
    impl_.reset();
    if (!supports(headers, 0)) {
        problem = "the parts are not scan-line parts the Core writer takes";
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
    init.error_handler_fn = &pipelineError;
    init.user_data = &im->io;
    init.write_fn = &coreWrite;
    Worker& main = im->main;
    tPipelineWorker = &main;
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
        ps.deep = headers[p].type() == Imf::DEEPSCANLINE;
        int32_t lines = 0;
        const exr_attr_chlist_t* chlist = nullptr;
        ok = exr_get_compression(im->ctxt, int(p), &ps.compression) == EXR_ERR_SUCCESS &&
             exr_get_scanlines_per_chunk(im->ctxt, int(p), &lines) == EXR_ERR_SUCCESS &&
             exr_get_chunk_count(im->ctxt, int(p), &ps.chunks) == EXR_ERR_SUCCESS &&
             exr_get_channels(im->ctxt, int(p), &chlist) == EXR_ERR_SUCCESS && lines >= 1 &&
             ps.chunks >= 1 && chlist != nullptr && (!ps.deep || lines == 1);
        ps.lines = std::max(1, lines);
        ps.spill.resize(size_t(std::max(0, ps.chunks)));
        for (int c = 0; ok && c < chlist->num_channels; ++c) {
            ps.channels.emplace_back(chlist->entries[c].name.str);
            ps.channelBytes.push_back(chlist->entries[c].pixel_type == EXR_PIXEL_HALF ? 2 : 4);
        }
        if (!ok) problem = fmt::format("part '{}': no chunk layout", ps.name);
    }
    tPipelineWorker = nullptr;
    if (!ok) return false;
    impl_ = std::move(im);
    return true;
}

bool CorePartWriter::Impl::openCopySource(size_t p, const std::string& path, std::string& problem) {
    PartState& ps = parts[p];
    if (ps.copySource != nullptr) {
        if (path == ps.copyPath) return true;
        problem = fmt::format("part '{}': copied from two files", ps.name);
        return false;
    }
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.error_handler_fn = &pipelineError;
    exr_context_t src = nullptr;
    exr_result_t rv = exr_start_read(&src, path.c_str(), &init);
    int count = 0;
    exr_storage_t storage = EXR_STORAGE_LAST_TYPE;
    exr_compression_t comp = EXR_COMPRESSION_LAST_TYPE;
    exr_attr_box2i_t dw{};
    const exr_attr_chlist_t* chlist = nullptr;
    bool same = rv == EXR_ERR_SUCCESS && exr_get_count(src, &count) == EXR_ERR_SUCCESS &&
                count == 1 && exr_get_storage(src, 0, &storage) == EXR_ERR_SUCCESS &&
                storage == EXR_STORAGE_DEEP_SCANLINE &&
                exr_get_compression(src, 0, &comp) == EXR_ERR_SUCCESS && comp == ps.compression &&
                exr_get_data_window(src, 0, &dw) == EXR_ERR_SUCCESS && dw.min.x == x0 &&
                dw.min.y == y0 && dw.max.x == x0 + width - 1 && dw.max.y == y0 + height - 1 &&
                exr_get_channels(src, 0, &chlist) == EXR_ERR_SUCCESS && chlist != nullptr &&
                size_t(chlist->num_channels) == ps.channels.size();
    for (int c = 0; same && c < chlist->num_channels; ++c)
        same = ps.channels[size_t(c)] == chlist->entries[c].name.str &&
               ps.channelBytes[size_t(c)] == 4 && chlist->entries[c].pixel_type != EXR_PIXEL_HALF;
    if (!same) {
        problem = fmt::format(
            "part '{}': {} is not a deep part of its window, channels and compression{}", ps.name,
            path,
            rv != EXR_ERR_SUCCESS ? std::string(" (") + exr_get_default_error_message(rv) + ")"
                                  : std::string());
        if (src != nullptr) exr_finish(&src);
        return false;
    }
    ps.copySource = src;
    ps.copyPath = path;
    return true;
}

bool CorePartWriter::Impl::encode(Task& t, const Source& src, Worker& w) {
    const PartState& ps = parts[size_t(t.part)];
    w.message.clear();
    const int fileRow = y0 + t.row;
    if (ps.copySource != nullptr) return copyChunk(t, w);
    exr_chunk_info_t ci{};
    exr_result_t rv = exr_write_scanline_chunk_info(ctxt, t.part, fileRow, &ci);
    if (rv != EXR_ERR_SUCCESS) {
        t.problem = fmt::format("part '{}': the chunk of row {}: {}", ps.name, fileRow,
                                coreProblem(rv, w.message));
        return false;
    }
    if (ci.start_y != fileRow || ci.height != t.rows) {
        t.problem = fmt::format("part '{}': the chunk of row {} holds {} rows, expected {}",
                                ps.name, fileRow, ci.height, t.rows);
        return false;
    }
    return ps.deep ? encodeDeep(t, src, w) : encodeFlat(t, src, w, ci);
}

bool CorePartWriter::Impl::encodeFlat(Task& t, const Source& src, Worker& w,
                                      const exr_chunk_info_t& ci) {
    const PartState& ps = parts[size_t(t.part)];
    const int fileRow = y0 + t.row;
    exr_encode_pipeline_t enc{};  // EXR_ENCODE_PIPELINE_INITIALIZER: all zero
    exr_result_t rv = exr_encoding_initialize(ctxt, t.part, &ci, &enc);
    bool ok = rv == EXR_ERR_SUCCESS && enc.channel_count == int(src.channel.size());
    if (ok) {
        enc.alloc_fn = &pipelineAlloc;
        enc.free_fn = &pipelineFree;
        const size_t stageLine = size_t(width) * sizeof(float);
        for (int c = 0; ok && c < enc.channel_count; ++c) {
            exr_coding_channel_info_t& ch = enc.channels[c];
            // The pipeline's channels are the part's, in the file's order.
            ok = ch.channel_name != nullptr && ps.channels[size_t(c)] == ch.channel_name;
            const size_t s = src.channel[size_t(c)];
            const FloatSlice& sl = src.rows->slices[s];
            ch.user_data_type = ch.data_type;  // the slices hold the channel's own type
            ch.user_bytes_per_element = ch.bytes_per_element;
            if (t.staged) {
                ch.encode_from_ptr = ps.stage.get() + size_t(c) * size_t(ps.lines) * stageLine;
                ch.user_pixel_stride = int32_t(ch.bytes_per_element);
                ch.user_line_stride = int32_t(stageLine);
            } else {
                ch.encode_from_ptr =
                    reinterpret_cast<const uint8_t*>(sl.base + size_t(t.srcRow) * sl.lineStride);
                ch.user_pixel_stride = int32_t(sl.pixelStride);
                ch.user_line_stride = int32_t(sl.lineStride);
            }
        }
        if (ok) rv = exr_encoding_choose_default_routines(ctxt, t.part, &enc);
        if (ok && rv == EXR_ERR_SUCCESS && isZipCompression(ps.compression)) {
            enc.compress_fn = &zipCompressChunk;
            enc.encoding_user_data = &w.zip;
        }
        // Written by the caller in part and row order (exr_write_scanline_chunk checks it);
        // the default yield would refuse any chunk but the next one the file takes.
        enc.yield_until_ready_fn = nullptr;
        enc.write_fn = nullptr;
        if (ok && rv == EXR_ERR_SUCCESS) rv = exr_encoding_run(ctxt, t.part, &enc);
        if (ok && rv == EXR_ERR_SUCCESS) {
            const auto* b = static_cast<const uint8_t*>(enc.compressed_buffer);
            t.out.assign(b, b + enc.compressed_bytes);
        }
        ok = ok && rv == EXR_ERR_SUCCESS;
    }
    if (!ok && rv == EXR_ERR_SUCCESS)
        t.problem = fmt::format("part '{}': the encoder's channels are not the part's", ps.name);
    else if (!ok)
        t.problem = fmt::format("part '{}': the chunk of row {}: {}", ps.name, fileRow,
                                coreProblem(rv, w.message));
    if (enc.context != nullptr) exr_encoding_destroy(ctxt, &enc);
    return ok;
}

bool CorePartWriter::Impl::encodeDeep(Task& t, const Source& src, Worker& w) {
    // OpenEXR's deep scan-line chunk: the row's cumulative sample counts (int32), then for each
    // channel in the file's order every sample of the row, pixel after pixel.
    const PartState& ps = parts[size_t(t.part)];
    const size_t w0 = size_t(width);
    const uint32_t* counts = src.rows->counts + size_t(t.srcRow) * w0;
    w.table.resize(w0 * sizeof(int32_t));
    uint64_t total = 0;
    for (size_t x = 0; x < w0; ++x) {
        total += counts[x];
        if (total > uint64_t(INT32_MAX)) {
            t.problem = fmt::format("part '{}': row {} holds more than {} samples", ps.name,
                                    y0 + t.row, INT32_MAX);
            return false;
        }
        const int32_t cum = int32_t(total);
        std::memcpy(w.table.data() + x * sizeof(int32_t), &cum, sizeof cum);
    }
    uint64_t unpacked = 0;
    for (size_t b : ps.channelBytes) unpacked += total * b;
    w.data.resize(size_t(unpacked));
    uint8_t* dst = w.data.data();
    const uint64_t first = src.rowStart[size_t(t.srcRow)];
    for (size_t c = 0; c < ps.channels.size(); ++c) {
        const DeepChannelSource& d = src.rows->deep[src.channel[c]];
        const size_t eb = ps.channelBytes[c];
        if (!d.samePerPixel && d.sampleStride == eb) {
            if (total > 0) std::memcpy(dst, d.base + first * d.sampleStride, size_t(total) * eb);
            dst += total * eb;
        } else if (!d.samePerPixel) {
            const char* s = d.base + first * d.sampleStride;
            for (uint64_t k = 0; k < total; ++k, dst += eb, s += d.sampleStride)
                std::memcpy(dst, s, eb);
        } else {
            for (size_t x = 0; x < w0; ++x)
                for (uint32_t j = 0; j < counts[x]; ++j, dst += eb)
                    std::memcpy(dst, d.base + size_t(j) * d.sampleStride, eb);
        }
    }
    ZipEncoder* zip = isZipCompression(ps.compression) ? &w.zip : nullptr;
    t.out.resize(w.table.size() + size_t(unpacked));
    t.tableBytes = packBuffer(zip, w.table.data(), w.table.size(), t.out.data());
    const size_t dataBytes =
        packBuffer(zip, w.data.data(), size_t(unpacked), t.out.data() + t.tableBytes);
    t.out.resize(size_t(t.tableBytes) + dataBytes);
    t.unpacked = unpacked;
    return true;
}

bool CorePartWriter::Impl::copyChunk(Task& t, Worker& w) {
    const PartState& ps = parts[size_t(t.part)];
    const int fileRow = y0 + t.row;
    exr_chunk_info_t ci{};
    exr_result_t rv = exr_read_scanline_chunk_info(ps.copySource, 0, fileRow, &ci);
    if (rv == EXR_ERR_SUCCESS &&
        (ci.start_y != fileRow || ci.height != t.rows || ci.sample_count_table_size == 0 ||
         ci.sample_count_table_size > (uint64_t(1) << 40) ||
         ci.packed_size > (uint64_t(1) << 40))) {
        t.problem = fmt::format("part '{}': {}: the chunk of row {} is not one row of the part",
                                ps.name, ps.copyPath, fileRow);
        return false;
    }
    if (rv == EXR_ERR_SUCCESS) {
        t.out.resize(size_t(ci.sample_count_table_size + ci.packed_size));
        rv = exr_read_deep_chunk(ps.copySource, 0, &ci, t.out.data() + ci.sample_count_table_size,
                                 t.out.data());
    }
    if (rv != EXR_ERR_SUCCESS) {
        t.problem = fmt::format("part '{}': {}: the chunk of row {}: {}", ps.name, ps.copyPath,
                                fileRow, coreMessage(rv, w.message));
        return false;
    }
    t.tableBytes = ci.sample_count_table_size;
    t.unpacked = ci.unpacked_size;
    return true;
}

bool CorePartWriter::Impl::encodeAll(std::vector<Task>& tasks, const std::vector<Source>& src,
                                     std::string& problem, const std::function<bool(Task&)>& sink) {
    // Each thread claims the next task in order; `sink` takes the encoded chunks in task order as
    // soon as each one's predecessors are done, and a thread waits before encoding a task more
    // than `ahead` past the next one to sink (memory stays a few chunks). Claims are in order, so
    // the task the others wait for is always being encoded: no thread waits forever.
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
            {
                std::unique_lock<std::mutex> lock(m);
                cv.wait(lock, [&] { return i < nextSink + ahead || firstFailed.load() < n; });
                if (i > firstFailed.load()) continue;
            }
            Task& t = tasks[size_t(i)];
            Worker* w = nullptr;
            bool ok = false;
            try {
                w = pool.acquire();
                tPipelineWorker = w;
                ok = encode(t, src[size_t(t.part)], *w);
            } catch (const std::bad_alloc&) {
                t.problem = "out of memory while compressing";
            }
            tPipelineWorker = nullptr;
            if (w != nullptr) pool.release(w);
            if (!ok) fail(i);
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
        }
    });
    const int64_t failed = firstFailed.load();
    if (failed >= n) return true;
    problem = tasks[size_t(failed)].problem;
    return false;
}

bool CorePartWriter::Impl::toFile(Task& t) {
    // One at a time (encodeAll's lock), on any thread.
    PipelineWorker* const saved = tPipelineWorker;
    tPipelineWorker = &main;
    main.message.clear();
    const PartState& ps = parts[size_t(t.part)];
    const int y = y0 + t.row;
    const exr_result_t rv =
        writeChunk(t.part, y, t.out.data(), t.out.size(), t.tableBytes, t.unpacked);
    if (rv != EXR_ERR_SUCCESS)
        t.problem = fmt::format("part '{}': the chunk of row {}: {}", ps.name, y,
                                coreProblem(rv, main.message));
    tPipelineWorker = saved;
    return rv == EXR_ERR_SUCCESS;
}

bool CorePartWriter::Impl::toSpill(Task& t) {
    PartState& ps = parts[size_t(t.part)];
    const char* p = reinterpret_cast<const char*>(t.out.data());
    uint64_t done = 0;
    while (done < t.out.size()) {
        const ssize_t w =
            ::pwrite(spillFd.get(), p + done, t.out.size() - done, off_t(spillSize + done));
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) {
            t.problem = fmt::format("cannot write the spill file {} ({})", spillFile->path(),
                                    w < 0 ? std::strerror(errno) : "nothing written");
            return false;
        }
        done += uint64_t(w);
    }
    ps.spill[size_t(t.row / ps.lines)] = {spillSize, t.out.size(), t.tableBytes, t.unpacked};
    spillSize += t.out.size();
    return true;
}

bool CorePartWriter::Impl::bindSources(const std::vector<PartRows>& rows, int count,
                                       std::vector<Source>& src, std::string& problem) {
    // Each part's sources, by the file's channel order.
    for (size_t p = 0; p < rows.size(); ++p) {
        const PartRows& pr = rows[p];
        const PartState& ps = parts[p];
        src[p].rows = &pr;
        if (!pr.copyFrom.empty()) {
            if (!ps.deep) {
                problem = fmt::format("part '{}': only deep parts are copied", ps.name);
                return false;
            }
            if (!openCopySource(p, pr.copyFrom, problem)) return false;
            continue;
        }
        if (ps.deep != (pr.counts != nullptr)) {
            problem =
                fmt::format("part '{}': {} rows for a {} part", ps.name,
                            pr.counts != nullptr ? "deep" : "flat", ps.deep ? "deep" : "flat");
            return false;
        }
        for (const std::string& c : ps.channels) {
            size_t i = 0;
            if (ps.deep)
                while (i < pr.deep.size() && pr.deep[i].name != c) ++i;
            else
                while (i < pr.slices.size() && pr.slices[i].name != c) ++i;
            if (i == (ps.deep ? pr.deep.size() : pr.slices.size())) {
                problem = fmt::format("part '{}': no data for channel '{}'", ps.name, c);
                return false;
            }
            src[p].channel.push_back(i);
        }
        if (ps.deep) {
            src[p].rowStart.assign(size_t(count) + 1, 0);
            const size_t w = size_t(width);
            for (size_t r = 0; r < size_t(count); ++r) {
                uint64_t sum = 0;
                for (size_t x = 0; x < w; ++x) sum += pr.counts[r * w + x];
                src[p].rowStart[r + 1] = src[p].rowStart[r] + sum;
            }
        }
    }
    return true;
}

bool CorePartWriter::Impl::openSpill(std::string& problem) {
    spillFile = std::make_unique<TemporaryFile>(target, ".spill");
    spillFd = Fd(::open(spillFile->path().c_str(), O_RDWR | O_CREAT | O_EXCL | O_CLOEXEC, 0600));
    if (spillFd.get() < 0) {
        problem = fmt::format("cannot create the spill file {} ({})", spillFile->path(),
                              std::strerror(errno));
        spillFile->remove();
        return false;
    }
    return true;
}

void CorePartWriter::Impl::stageRows(size_t p, const PartRows& rows, const Source& src, int r0,
                                     int from, int to) {
    PartState& ps = parts[p];
    const size_t w = size_t(width), line = w * sizeof(float);
    const std::vector<FloatSlice>& sl = rows.slices;
    const size_t need = ps.channels.size() * size_t(ps.lines) * line;
    if (ps.stageBytes < need) {
        ps.stage.reset();
        ps.stageBytes = 0;
        ps.stage.reset(new uint8_t[need]);
        ps.stageBytes = need;
    }
    for (size_t c = 0; c < ps.channels.size(); ++c) {
        const FloatSlice& s = sl[src.channel[c]];
        const size_t eb = ps.channelBytes[c];
        for (int r = from; r < to; ++r) {
            uint8_t* dst =
                ps.stage.get() + (c * size_t(ps.lines) + size_t(ps.staged + r - from)) * line;
            const char* row = s.base + size_t(r - r0) * s.lineStride;
            for (size_t x = 0; x < w; ++x) std::memcpy(dst + x * eb, row + x * s.pixelStride, eb);
        }
    }
    ps.staged += to - from;
}

void CorePartWriter::Impl::planChunks(const std::vector<PartRows>& rows,
                                      const std::vector<Source>& src, int r0, int r1,
                                      std::vector<Task>& tasks,
                                      std::vector<std::pair<int, int>>& leftover) {
    for (size_t p = 0; p < rows.size(); ++p) {
        PartState& ps = parts[p];
        int row = r0;
        if (ps.staged > 0) {  // complete the staged chunk first
            const int start = r0 - ps.staged;
            const int end = std::min(start + ps.lines, height);
            const int take = std::min(end, r1) - r0;
            stageRows(p, rows[p], src[p], r0, r0, r0 + take);
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
            const int end = std::min(row + ps.lines, height);
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
}

bool CorePartWriter::write(const std::vector<PartRows>& parts, int rows, std::string& problem) {
    if (!impl_ || rows < 1 || rows > impl_->height - impl_->nextRow ||
        parts.size() != impl_->parts.size()) {
        problem = "rows or parts that do not continue the image";
        return false;
    }
    Impl& im = *impl_;
    im.enter();
    const int r0 = im.nextRow, r1 = im.nextRow + rows;  // rows of this write, 0-based
    if (r0 == 0) im.direct = parts.size() == 1 || r1 == im.height;
    const auto fail = [&](std::string why) {
        problem = std::move(why);
        tPipelineWorker = nullptr;
        return false;
    };
    std::vector<Source> src(parts.size());
    if (!im.bindSources(parts, rows, src, problem)) return tPipelineWorker = nullptr, false;
    if (!im.direct && !im.spillFile && !im.openSpill(problem))
        return tPipelineWorker = nullptr, false;
    // The chunks this write completes, in file order when it is the whole image.
    std::vector<Task> tasks;
    std::vector<std::pair<int, int>> leftover(parts.size(), {r1, r1});
    try {
        im.planChunks(parts, src, r0, r1, tasks, leftover);
    } catch (const std::bad_alloc&) {
        return fail("out of memory while staging rows");
    }
    const auto sink = [&](Task& t) { return im.direct ? im.toFile(t) : im.toSpill(t); };
    if (!im.encodeAll(tasks, src, problem, sink)) return tPipelineWorker = nullptr, false;
    for (const Task& t : tasks)
        if (t.staged) im.parts[size_t(t.part)].staged = 0;
    try {
        for (size_t p = 0; p < parts.size(); ++p)
            if (leftover[p].first < leftover[p].second)
                im.stageRows(p, parts[p], src[p], r0, leftover[p].first, leftover[p].second);
    } catch (const std::bad_alloc&) {
        return fail("out of memory while staging rows");
    }
    im.nextRow = r1;
    tPipelineWorker = nullptr;
    return true;
}

bool CorePartWriter::finish(std::string& problem) {
    if (!impl_ || impl_->nextRow != impl_->height) {
        problem = "the image is not complete";
        return false;
    }
    Impl& im = *impl_;
    im.enter();
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
                    tPipelineWorker = nullptr;
                    return false;
                }
                const int y = im.y0 + int(c) * ps.lines;
                rv = im.writeChunk(int(p), y, buf.data(), sc.size, sc.tableBytes, sc.unpacked);
            }
        }
    }
    if (rv == EXR_ERR_SUCCESS) rv = exr_finish(&im.ctxt);
    tPipelineWorker = nullptr;
    if (rv != EXR_ERR_SUCCESS || !im.io.error.empty()) {
        problem = im.coreProblem(rv, im.main.message);
        return false;
    }
    im.spillFd.reset();
    im.spillFile.reset();  // removes the spill file
    return true;
}

}  // namespace mcstat::detail
