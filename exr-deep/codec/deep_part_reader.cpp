#include "mcstat/exr-deep/codec/detail/deep_part_reader.h"

#include <fmt/format.h>

#include <algorithm>
#include <atomic>
#include <cstring>
#include <new>

#include "mcstat/core/parallel.h"
#include "mcstat/core/untrusted_text.h"
#include "mcstat/exr-deep/codec/detail/deflate_codec.h"
#include "mcstat/exr-deep/codec/detail/fd_stream.h"
#include "mcstat/exr-deep/codec/detail/scratch_pool.h"

namespace mcstat::detail {

namespace {

/// One decoding thread's buffers, reused from line to line and read to read.
struct DeepWorker {
    ZipDecoder zip;
    std::vector<uint8_t> packed, unpacked;
};

struct DeepChannel {
    std::string name;
    size_t bytes = 4;  ///< per sample
};

/// Runs `decode(row)` for rows [0, rows) on `threads` threads with a worker each; the failure
/// reported is the first failing row's, whatever the thread count.
template <class Decode>
FlatPartReader::Result forEachLine(int rows, int threads, ScratchPool<DeepWorker>& pool,
                                   std::string& problem, Decode decode) {
    using Result = FlatPartReader::Result;
    std::vector<std::string> problems(static_cast<size_t>(rows));
    std::vector<Result> results(static_cast<size_t>(rows), Result::Ok);
    std::atomic<int64_t> firstFailed{rows};
    parallelFor(0, rows, 4, threads, [&](int64_t b, int64_t e) {
        DeepWorker* w = nullptr;
        try {
            w = pool.acquire();
        } catch (const std::bad_alloc&) {
            results[size_t(b)] = Result::OutOfMemory;
            problems[size_t(b)] = "out of memory while decoding";
            e = b;
            int64_t cur = firstFailed.load();
            while (b < cur && !firstFailed.compare_exchange_weak(cur, b)) {
            }
        }
        for (int64_t r = b; r < e; ++r) {
            if (r > firstFailed.load()) break;  // a line before it failed: its report stands
            Result res = Result::Ok;
            try {
                res = decode(int(r), *w, problems[size_t(r)]);
            } catch (const std::bad_alloc&) {
                res = Result::OutOfMemory;
                problems[size_t(r)] = "out of memory while decoding";
            }
            results[size_t(r)] = res;
            if (res != Result::Ok) {
                int64_t cur = firstFailed.load();
                while (r < cur && !firstFailed.compare_exchange_weak(cur, r)) {
                }
                break;
            }
        }
        if (w != nullptr) pool.release(w);
    });
    const int64_t failed = firstFailed.load();
    if (failed >= rows) return Result::Ok;
    problem = problems[size_t(failed)];
    return results[size_t(failed)];
}

}  // namespace

struct DeepPartReader::Impl {
    const FlatPartReader* flat = nullptr;
    exr_const_context_t ctxt = nullptr;
    int part = 0;
    std::string name;
    exr_compression_t compression = EXR_COMPRESSION_LAST_TYPE;
    bool oneLine = false, allFloat = false;
    std::vector<DeepChannel> channels;  ///< in the part's (sorted) order
    size_t bytesPerSample = 0;
    ScratchPool<DeepWorker> pool;

    /// The chunk of file row y0 + row, checked against the window and the file's size.
    Result chunk(int row, exr_chunk_info_t& ci, std::string& problem) const;
    /// Chunk bytes [offset, offset + n) into `buf`, inflated to `unpacked` bytes into `out`
    /// (or `buf` itself when stored as they are); the data, or null with `problem`.
    const uint8_t* bytes(uint64_t offset, uint64_t n, uint64_t unpacked, DeepWorker& w,
                         std::vector<uint8_t>& buf, std::vector<uint8_t>& out, const char* what,
                         std::string& problem) const;
    std::string where(int row) const {
        return fmt::format("part '{}': the chunk of row {}", printable(name), flat->y0() + row);
    }
};

DeepPartReader::DeepPartReader() = default;
DeepPartReader::~DeepPartReader() = default;

bool DeepPartReader::open(const FlatPartReader& flat, int part, std::string& problem) {
    impl_.reset();
    auto im = std::make_unique<Impl>();
    im->flat = &flat;
    im->ctxt = flat.context();
    im->part = part;
    if (im->ctxt == nullptr) {
        problem = "deep part reader: the file is not open";
        return false;
    }
    const char* name = nullptr;
    if (exr_get_name(im->ctxt, part, &name) == EXR_ERR_SUCCESS && name != nullptr) im->name = name;
    exr_storage_t storage = EXR_STORAGE_LAST_TYPE;
    exr_attr_box2i_t dw{};
    int32_t lines = 0;
    const exr_attr_chlist_t* chlist = nullptr;
    if (exr_get_storage(im->ctxt, part, &storage) != EXR_ERR_SUCCESS ||
        storage != EXR_STORAGE_DEEP_SCANLINE ||
        exr_get_compression(im->ctxt, part, &im->compression) != EXR_ERR_SUCCESS ||
        exr_get_scanlines_per_chunk(im->ctxt, part, &lines) != EXR_ERR_SUCCESS ||
        exr_get_data_window(im->ctxt, part, &dw) != EXR_ERR_SUCCESS ||
        exr_get_channels(im->ctxt, part, &chlist) != EXR_ERR_SUCCESS || chlist == nullptr) {
        problem = fmt::format("part {} is not a deep scan-line part", part);
        return false;
    }
    if (dw.min.x != flat.x0() || dw.min.y != flat.y0() ||
        int64_t(dw.max.x) - dw.min.x + 1 != flat.width() ||
        int64_t(dw.max.y) - dw.min.y + 1 != flat.height()) {
        problem = fmt::format("part '{}': the data window changed while reading", im->name);
        return false;
    }
    im->oneLine = lines == 1 && (im->compression == EXR_COMPRESSION_NONE ||
                                 im->compression == EXR_COMPRESSION_ZIPS);
    im->allFloat = true;
    for (int c = 0; c < chlist->num_channels; ++c) {
        const exr_attr_chlist_entry_t& e = chlist->entries[c];
        DeepChannel ch;
        ch.name = e.name.str != nullptr ? e.name.str : "";
        ch.bytes = e.pixel_type == EXR_PIXEL_HALF ? 2 : 4;
        im->allFloat = im->allFloat && e.pixel_type == EXR_PIXEL_FLOAT && e.x_sampling == 1 &&
                       e.y_sampling == 1;
        im->bytesPerSample += ch.bytes;
        im->channels.push_back(std::move(ch));
    }
    impl_ = std::move(im);
    return true;
}

bool DeepPartReader::handles() const {
    return impl_ && impl_->oneLine && impl_->allFloat && impl_->bytesPerSample > 0;
}

DeepPartReader::Result DeepPartReader::Impl::chunk(int row, exr_chunk_info_t& ci,
                                                   std::string& problem) const {
    const int y = flat->y0() + row;
    const exr_result_t rv = exr_read_scanline_chunk_info(ctxt, part, y, &ci);
    if (rv != EXR_ERR_SUCCESS) {
        problem = fmt::format("{}: {}", where(row), exr_get_default_error_message(rv));
        return rv == EXR_ERR_OUT_OF_MEMORY ? Result::OutOfMemory : Result::Corrupt;
    }
    if (ci.start_y != y || ci.height != 1 || ci.width != flat->width() ||
        ci.start_x != flat->x0()) {
        problem = fmt::format("{}: the chunk covers {}x{} pixels from ({}, {})", where(row),
                              ci.width, ci.height, ci.start_x, ci.start_y);
        return Result::Corrupt;
    }
    const uint64_t size = flat->size();
    if (ci.sample_count_data_offset > size || ci.sample_count_table_size > size ||
        ci.sample_count_data_offset + ci.sample_count_table_size > size || ci.data_offset > size ||
        ci.packed_size > size - ci.data_offset) {
        problem = fmt::format("{}: its {} + {} bytes reach past the end of the file ({} bytes)",
                              where(row), ci.sample_count_table_size, ci.packed_size, size);
        return Result::Corrupt;
    }
    return Result::Ok;
}

const uint8_t* DeepPartReader::Impl::bytes(uint64_t offset, uint64_t n, uint64_t unpacked,
                                           DeepWorker& w, std::vector<uint8_t>& buf,
                                           std::vector<uint8_t>& out, const char* what,
                                           std::string& problem) const {
    // A chunk is stored as it is when compressing would not shrink it (OpenEXR's writers), so
    // more packed bytes than unpacked ones is corrupt; this also bounds what is allocated here
    // by what the checked counts need.
    if (n > unpacked || (n == 0 && unpacked > 0) ||
        (compression == EXR_COMPRESSION_NONE && n != unpacked)) {
        problem = fmt::format("{} of {} bytes, expected {}{}", what, n,
                              compression == EXR_COMPRESSION_NONE ? "" : "at most ", unpacked);
        return nullptr;
    }
    if (buf.size() < n) buf.resize(size_t(n));
    if (n > 0 && preadFull(flat->fd(), buf.data(), n, offset) != int64_t(n)) {
        problem = fmt::format("{}: cannot read {} bytes at offset {}", what, n, offset);
        return nullptr;
    }
    if (n == unpacked) return buf.data();
    if (out.size() < unpacked) out.resize(size_t(unpacked));
    if (!w.zip.undo(buf.data(), size_t(n), out.data(), size_t(unpacked))) {
        problem = fmt::format("{}: {}", what, w.zip.problem());
        return nullptr;
    }
    return out.data();
}

DeepPartReader::Result DeepPartReader::readCounts(int firstRow, int rows, int threads,
                                                  std::vector<uint32_t>& counts,
                                                  std::string& problem) {
    if (!handles() || rows < 1 || firstRow < 0 || firstRow > impl_->flat->height() - rows) {
        problem = "deep part reader: rows outside the image";
        return Result::Corrupt;
    }
    Impl& im = *impl_;
    const size_t width = size_t(im.flat->width());
    counts.assign(width * size_t(rows), 0);
    return forEachLine(
        rows, threads, im.pool, problem, [&](int r, DeepWorker& w, std::string& why) {
            exr_chunk_info_t ci{};
            const int row = firstRow + r;
            if (Result res = im.chunk(row, ci, why); res != Result::Ok) return res;
            std::string what;
            const uint8_t* table = im.bytes(ci.sample_count_data_offset, ci.sample_count_table_size,
                                            width * sizeof(int32_t), w, w.packed, w.unpacked,
                                            "its sample count table", what);
            if (table == nullptr) {
                why = fmt::format("{}: {}", im.where(row), what);
                return Result::Corrupt;
            }
            // Cumulative counts within the line, little-endian int32.
            uint32_t* out = counts.data() + size_t(r) * width;
            int64_t prev = 0;
            for (size_t x = 0; x < width; ++x) {
                int32_t v;
                std::memcpy(&v, table + 4 * x, 4);
                if (v < prev) {
                    why = fmt::format(
                        "{}: its sample count table decreases at pixel {} ({} "
                        "after {})",
                        im.where(row), im.flat->x0() + int64_t(x), v, prev);
                    return Result::Corrupt;
                }
                out[x] = uint32_t(v - prev);
                prev = v;
            }
            if (ci.unpacked_size != uint64_t(prev) * im.bytesPerSample) {
                why = fmt::format("{}: {} samples of {} bytes need {} bytes, the chunk says {}",
                                  im.where(row), prev, im.bytesPerSample,
                                  uint64_t(prev) * im.bytesPerSample, ci.unpacked_size);
                return Result::Corrupt;
            }
            return Result::Ok;
        });
}

DeepPartReader::Result DeepPartReader::readSamples(int firstRow, int rows,
                                                   const std::vector<uint32_t>& counts,
                                                   const std::vector<DeepSlice>& slices,
                                                   int threads, std::string& problem) {
    const size_t width = impl_ ? size_t(impl_->flat->width()) : 0;
    if (!handles() || rows < 1 || firstRow < 0 || firstRow > impl_->flat->height() - rows ||
        counts.size() != width * size_t(rows)) {
        problem = "deep part reader: rows outside the image";
        return Result::Corrupt;
    }
    Impl& im = *impl_;
    // Each channel's slice (null: skipped) and the first sample of each line.
    std::vector<const DeepSlice*> target(im.channels.size(), nullptr);
    for (const DeepSlice& s : slices) {
        size_t c = 0;
        while (c < im.channels.size() && im.channels[c].name != s.name) ++c;
        if (c == im.channels.size()) {
            problem = fmt::format("part '{}': channel '{}' changed while reading",
                                  printable(im.name), printable(s.name));
            return Result::Corrupt;
        }
        target[c] = &s;
    }
    std::vector<uint64_t> lineStart(size_t(rows) + 1, 0);
    for (size_t r = 0; r < size_t(rows); ++r) {
        uint64_t n = 0;
        for (size_t x = 0; x < width; ++x) n += counts[r * width + x];
        lineStart[r + 1] = lineStart[r] + n;
    }
    return forEachLine(
        rows, threads, im.pool, problem, [&](int r, DeepWorker& w, std::string& why) {
            exr_chunk_info_t ci{};
            const int row = firstRow + r;
            if (Result res = im.chunk(row, ci, why); res != Result::Ok) return res;
            const uint64_t first = lineStart[size_t(r)];
            const uint64_t total = lineStart[size_t(r) + 1] - first;
            if (ci.unpacked_size != total * im.bytesPerSample) {
                why =
                    fmt::format("{}: the file changed while reading (its samples)", im.where(row));
                return Result::Corrupt;
            }
            if (total == 0) return Result::Ok;
            std::string what;
            const uint8_t* data = im.bytes(ci.data_offset, ci.packed_size, ci.unpacked_size, w,
                                           w.packed, w.unpacked, "its samples", what);
            if (data == nullptr) {
                why = fmt::format("{}: {}", im.where(row), what);
                return Result::Corrupt;
            }
            // Channel by channel, each holding every sample of the line.
            for (size_t c = 0; c < im.channels.size(); ++c) {
                const DeepSlice* s = target[c];
                if (s != nullptr) {
                    float* dst = s->base + first * s->stride;
                    for (uint64_t i = 0; i < total; ++i)
                        std::memcpy(dst + i * s->stride, data + 4 * i, 4);
                }
                data += total * im.channels[c].bytes;
            }
            return Result::Ok;
        });
}

}  // namespace mcstat::detail
