// Internal: rows of the flat (scan-line) parts of an OpenEXR file decoded through OpenEXR's Core
// API ("OpenEXRCore" in OpenEXR's documentation: exr_read_scanline_chunk_info, then a decode
// pipeline per chunk), the chunks of one read on several threads (parallelFor). ZIP and ZIPS
// chunks are inflated by libdeflate (deflate_codec.h), every other compression by OpenEXR's own
// routines; the pipeline's unpack step writes each chunk's floats straight into the caller's
// arrays, and a chunk that holds rows outside those asked for goes through a scratch copy. The
// file is read with pread on a descriptor the caller keeps open (the file the header check judged).
#pragma once

#include <OpenEXR/openexr.h>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace mcstat::detail {

/// Where one channel goes, as float: element (x, y) of the rows read (both from 0) at
/// base + y * lineStride + x * pixelStride bytes.
struct FloatSlice {
    std::string name;
    char* base = nullptr;
    size_t pixelStride = 0;
    size_t lineStride = 0;
};

/// The channels to read of one flat part.
struct PartSlices {
    int part = 0;
    std::vector<FloatSlice> slices;
};

class FlatPartReader {
  public:
    FlatPartReader();
    ~FlatPartReader();
    FlatPartReader(const FlatPartReader&) = delete;
    FlatPartReader& operator=(const FlatPartReader&) = delete;

    /// Opens OpenEXR's Core reader on `fd` (`size` bytes, headers already checked; the chunk
    /// table is taken as written, not reconstructed). `x0`, `y0`, `width`, `height`: the data
    /// window every part read must have. False with a one-line `problem` (no path).
    bool open(int fd, uint64_t size, const std::string& path, int x0, int y0, int width, int height,
              std::string& problem);
    bool isOpen() const;
    /// Whether read() decodes part `part`: a scan-line part whose compression's Core routines
    /// give the C++ API's pixels (NONE, RLE, ZIPS, ZIP, PIZ, PXR24; B44, B44A, DWAA and DWAB stay
    /// with the caller's C++ API read).
    bool handles(int part) const;
    /// Whether read() takes channel `channel` of part `part`: a part handles() takes, a FLOAT or
    /// HALF channel (HALF converted to float by the pipeline), sampled at every pixel.
    bool readsAsFloat(int part, const std::string& channel) const;

    enum class Result { Ok, Corrupt, OutOfMemory };
    /// Reads rows [firstRow, firstRow + rows) of the data window (0-based) of every part of
    /// `parts` into its slices, each chunk a task of parallelFor on `threads` threads. Each slice
    /// must name a channel readsAsFloat() takes and every part must be one handles() takes (else
    /// Corrupt: "file changed while reading"). On failure `problem` (one line, no path) is that of
    /// the first failing chunk in the reader's fixed order, whatever the thread count.
    Result read(const std::vector<PartSlices>& parts, int firstRow, int rows, int threads,
                std::string& problem);

    /// What open() was given and made, for a reader of the file's other parts (DeepPartReader):
    /// the Core context (null before a successful open), the descriptor, its size, the window.
    exr_const_context_t context() const;
    int fd() const;
    uint64_t size() const;
    int x0() const;
    int y0() const;
    int width() const;
    int height() const;

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace mcstat::detail
