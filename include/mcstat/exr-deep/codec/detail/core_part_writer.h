// Internal: the parts of a statistics file written through OpenEXR's Core API ("OpenEXRCore" in
// OpenEXR's documentation: exr_start_write, a part per header, then the chunks in order), ZIP and
// ZIPS chunks compressed by libdeflate (deflate_codec.h), the chunks of each write on several
// threads (parallelFor). The bytes are standard OpenEXR: any reader opens them.
// Flat scan-line parts (FLOAT, UINT and HALF channels) go through the Core's encode pipeline, its
// compress_fn replaced by ZipEncoder's. Deep scan-line parts (NONE or ZIPS, one row a chunk) are
// packed here, because OpenEXR 3.1's Core has no deep packing (its default_pack_deep returns
// EXR_ERR_INVALID_ARGUMENT): a chunk is the row's cumulative sample counts and then, channel after
// channel in the file's order, every sample of the row, each compressed as ZIP compresses (a
// buffer that would not shrink stored as it is), then handed to exr_write_deep_scanline_chunk. A
// deep part may also be copied chunk by chunk, packed bytes as they are, from a single-part deep
// file with the same channels and compression (the per-sample records a render streamed).
// OpenEXR 3.1's Core writer takes the parts one after the other, each in row order, while a
// streaming writer is handed every part's rows block by block. A write of the whole image at once,
// or any write of a single-part file, goes to the file in order; otherwise the compressed chunks go
// to a spill file next to the target (a TemporaryFile) until finish() copies them into the file in
// part order. Both give the same bytes. Rows that do not fill a chunk wait in a staging buffer for
// the next block.
#pragma once

#include <OpenEXR/ImfHeader.h>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "mcstat/exr-deep/codec/detail/flat_part_reader.h"

namespace mcstat::detail {

/// One channel of a deep part's rows. Without `samePerPixel`, the rows' samples are consecutive
/// (pixels in scanline order, each pixel's samples in order) and sample k is at
/// base + k * sampleStride; with it, sample j of every pixel is at base + j * sampleStride (a
/// channel that holds the sample's index, or a constant). Values in the channel's own type.
struct DeepChannelSource {
    std::string name;
    const char* base = nullptr;
    size_t sampleStride = 0;
    bool samePerPixel = false;
};

/// The rows of one part for CorePartWriter::write: exactly one of the three is set.
struct PartRows {
    /// A flat part: every channel, element (x, y) of the rows (both from 0) at
    /// base + y * lineStride + x * pixelStride, in the channel's own type (4 bytes for FLOAT and
    /// UINT, 2 for HALF).
    std::vector<FloatSlice> slices;
    /// A deep part: the samples of each pixel of the rows (scanline order) and every channel.
    const uint32_t* counts = nullptr;
    std::vector<DeepChannelSource> deep;
    /// A deep part copied from this single-part deep file (a complete image of the same window,
    /// channels and compression); the rows of the write say which of its chunks.
    std::string copyFrom;
};

class CorePartWriter {
  public:
    CorePartWriter();
    ~CorePartWriter();
    CorePartWriter(const CorePartWriter&) = delete;
    CorePartWriter& operator=(const CorePartWriter&) = delete;

    /// Whether the Core writer can express `headers`: scan-line parts with one data window, flat
    /// ones of FLOAT, UINT and HALF channels and compression NONE, ZIPS or ZIP, deep ones of
    /// FLOAT and UINT channels and compression NONE or ZIPS, all sampled 1 1, attributes of types
    /// int, float, string, string vector and chromaticities (strings without NUL bytes), and
    /// pipeline strides within int32 for `maxPixelBytes` bytes per pixel of the largest array a
    /// flat slice points into.
    static bool supports(const std::vector<Imf::Header>& headers, size_t maxPixelBytes);

    /// Starts writing the file open as `fd` (empty; `target` is the file it will become: the
    /// spill file goes next to it, and messages name it). `threads` encode the chunks. False with
    /// a one-line `problem` (no path).
    bool open(int fd, const std::string& target, const std::vector<Imf::Header>& headers,
              int threads, std::string& problem);
    /// The next `rows` rows of every part: parts[i] holds part i's (its data is only read). False
    /// with `problem`.
    bool write(const std::vector<PartRows>& parts, int rows, std::string& problem);
    /// After the last row: the spilled chunks in part order and the offset tables. False with
    /// `problem`.
    bool finish(std::string& problem);

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace mcstat::detail
