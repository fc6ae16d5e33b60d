// Internal: rows of a deep scan-line part (a statistics file's `vbuffers`, FORMAT.md "Version 2")
// decoded without OpenEXR's C++ deep reader: the chunk offsets and sizes come from the Core API
// (exr_read_scanline_chunk_info), the bytes are read with pread, ZIPS chunks are inflated by
// libdeflate (deflate_codec.h), and the chunks of one read are decoded on several threads. The C++
// reader inflates with zlib one line at a time on its own pool, at about a quarter of this speed
// per byte (docs/benchmarks.md, "Compact files").
//
// A deep scan-line chunk (OpenEXR's "OpenEXR File Layout", deep data) is: the sample count
// table, for each pixel of each line the number of samples of the line up to and including that
// pixel (int32, cumulative within the line); then the samples, channel by channel in the part's
// channel order, each channel's values of every sample of the line in pixel order. Both are
// compressed with the part's compression. This reader takes chunks of one line (NONE and ZIPS,
// what mcstat writes); any other compression stays with the caller's C++ API read (handles()).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "mcstat/exr-deep/codec/detail/flat_part_reader.h"

namespace mcstat::detail {

/// Where one FLOAT channel of the deep part goes: sample k of the rows read (k counted from the
/// first sample of the first row) at base[k * stride].
struct DeepSlice {
    std::string name;
    float* base = nullptr;
    size_t stride = 1;
};

class DeepPartReader {
  public:
    DeepPartReader();
    ~DeepPartReader();
    DeepPartReader(const DeepPartReader&) = delete;
    DeepPartReader& operator=(const DeepPartReader&) = delete;

    /// Takes part `part` of the file `flat` has open (its Core context and descriptor; `flat`
    /// must outlive this reader). False with a one-line `problem` when the part is not a deep
    /// scan-line part of the data window `flat` was opened with.
    bool open(const FlatPartReader& flat, int part, std::string& problem);
    /// Whether read() decodes the part: chunks of one line, NONE or ZIPS, every channel FLOAT.
    bool handles() const;

    using Result = FlatPartReader::Result;
    /// The sample counts of rows [firstRow, firstRow + rows) (0-based), one per pixel in scan-line
    /// order, into `counts` (resized). Each line's table is checked (non-decreasing, within its
    /// chunk's unpacked size); the caller checks the counts against its own limits.
    Result readCounts(int firstRow, int rows, int threads, std::vector<uint32_t>& counts,
                      std::string& problem);
    /// The samples of the same rows into `slices`, `counts` being what readCounts gave for them
    /// (each chunk's unpacked size must match its line's total, else Corrupt: the file changed).
    /// Channels of the part not named by a slice are skipped.
    Result readSamples(int firstRow, int rows, const std::vector<uint32_t>& counts,
                       const std::vector<DeepSlice>& slices, int threads, std::string& problem);

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace mcstat::detail
