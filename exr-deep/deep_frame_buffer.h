// Internal to exr-deep: the one set-up of an OpenEXR deep frame buffer over rows of a statistics
// file's data window, used by every deep part (adaptive M's "vbuffers", per-sample "records", an
// operation's per-pixel state "modes"). OpenEXR addresses a deep channel through an array of one
// pointer per pixel; the frame buffer keeps the arrays' addresses, and setting a new frame buffer
// forgets the sample counts read so far. So the order is always: build this, set its frameBuffer(),
// read the counts, allocate the samples, then point() every pixel and read (or point and write).
#pragma once

#include <OpenEXR/ImfDeepFrameBuffer.h>

#include <cstdint>
#include <string>
#include <vector>

#include "window.h"

namespace mcstat::detail {

class DeepFrameBufferSet {
  public:
    /// Rows [firstRow, firstRow + counts / width) of `h`'s data window (0-based rows of the
    /// window), sample counts in `counts` (one per pixel, scanline order; kept by address).
    DeepFrameBufferSet(const StatsHeader& h, uint32_t* counts, int firstRow = 0)
        : h_(h), firstRow_(firstRow) {
        fb_.insertSampleCountSlice(
            Imf::Slice(Imf::UINT, windowBase(counts, h, sizeof(uint32_t), firstRow),
                       sizeof(uint32_t), sizeof(uint32_t) * size_t(h.width)));
    }
    // The frame buffer holds the addresses of the pointer arrays: no copies.
    DeepFrameBufferSet(const DeepFrameBufferSet&) = delete;
    DeepFrameBufferSet& operator=(const DeepFrameBufferSet&) = delete;
    /// Adds FLOAT channel `name` for `pixels` pixels, consecutive samples `sampleStride` bytes
    /// apart; its pointers start null. Returns its index for point().
    size_t addChannel(const std::string& name, size_t pixels, size_t sampleStride) {
        ptr_.emplace_back(pixels, nullptr);  // moving the inner vectors keeps their storage
        const size_t xs = sizeof(char*);
        fb_.insert(name,
                   Imf::DeepSlice(Imf::FLOAT, windowBase(ptr_.back().data(), h_, xs, firstRow_), xs,
                                  xs * size_t(h_.width), sampleStride));
        return ptr_.size() - 1;
    }
    /// Channels 0..nc-1 of every pixel at its first record in `records` (nc floats per record,
    /// every pixel's records contiguous in scanline order, `counts` of them): the layout of
    /// records and of an operation's state. A pixel without records points nowhere.
    void pointContiguous(const float* records, const uint32_t* counts, size_t pixels, size_t nc) {
        size_t k = 0;
        for (size_t p = 0; p < pixels; ++p) {
            for (size_t c = 0; c < nc; ++c) point(c, p, counts[p] ? records + k * nc + c : nullptr);
            k += counts[p];
        }
    }
    /// Pixel p's first sample of channel c is at `at`.
    void point(size_t c, size_t p, const void* at) {
        ptr_[c][p] = static_cast<char*>(const_cast<void*>(at));
    }
    Imf::DeepFrameBuffer& frameBuffer() { return fb_; }

  private:
    const StatsHeader& h_;  ///< the caller's, which outlives this
    int firstRow_;
    std::vector<std::vector<char*>> ptr_;  ///< [channel][pixel]
    Imf::DeepFrameBuffer fb_;
};

}  // namespace mcstat::detail
