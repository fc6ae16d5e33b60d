// Internal: the flat (scan-line) parts of an OpenEXR file written through OpenEXR's Core API
// ("OpenEXRCore" in OpenEXR's documentation: exr_start_write, a part per header, then an encode
// pipeline per chunk), ZIP and ZIPS chunks compressed by libdeflate in the pipeline's compress_fn
// (deflate_codec.h), the chunks of each write on several threads (parallelFor). The bytes are
// standard OpenEXR: any reader opens them.
// OpenEXR 3.1's Core writer takes the parts one after the other, each in row order, while a
// streaming writer is handed every part's rows block by block. A write of the whole image at once
// goes to the file part by part; otherwise the compressed chunks go to a spill file next to the
// target (a TemporaryFile) until finish() copies them into the file in part order. Both give the
// same bytes. Rows that do not fill a chunk wait in a staging buffer for the next block.
#pragma once

#include <OpenEXR/ImfHeader.h>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "flat_part_reader.h"

namespace mcstat::detail {

class FlatPartWriter {
  public:
    FlatPartWriter();
    ~FlatPartWriter();
    FlatPartWriter(const FlatPartWriter&) = delete;
    FlatPartWriter& operator=(const FlatPartWriter&) = delete;

    /// Whether the Core writer can express `headers`: flat scan-line parts with one data window,
    /// FLOAT channels, compression NONE, ZIPS or ZIP, attributes of types int, float, string,
    /// string vector and chromaticities (strings without NUL bytes), and pipeline strides within
    /// int32 for `maxPixelBytes` bytes per pixel of the largest array a slice points into.
    static bool supports(const std::vector<Imf::Header>& headers, size_t maxPixelBytes);

    /// Starts writing the file open as `fd` (empty; `target` is the file it will become: the
    /// spill file goes next to it, and messages name it). `threads` encode the chunks. False with
    /// a one-line `problem` (no path).
    bool open(int fd, const std::string& target, const std::vector<Imf::Header>& headers,
              int threads, std::string& problem);
    /// The next `rows` rows of every part: parts[i] holds the slices of part i (every channel
    /// of the part; slices are only read). False with `problem`.
    bool write(const std::vector<PartSlices>& parts, int rows, std::string& problem);
    /// After the last row: the spilled chunks in part order and the offset tables. False with
    /// `problem`.
    bool finish(std::string& problem);

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace mcstat::detail
