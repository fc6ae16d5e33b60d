// The image operations of imageops.h over a statistics image streamed by blocks of rows
// (StatsBlockSource): each block is decoded (in parallel by OpenEXR), run through the in-memory
// operation, and its rows copied into the result. Peak memory is one block (plus the neighbourhood
// operations' halo rows), not the file. Every output pixel is the in-memory operation's pixel: a
// block carries every row a pixel's window reaches, and each window is clipped to the file's data
// window exactly as in the whole image (tests/image/test_stream.cpp compares them bit for bit).
#include <OpenImageIO/imagebufalgo.h>

#include <algorithm>
#include <cstring>
#include <future>
#include <vector>

#include "mcstat/image/imageops.h"

namespace mcstat {

using OIIO::ImageBuf;
using OIIO::ImageSpec;
using OIIO::ROI;

namespace {

/// Runs `op(block, rows)` for consecutive blocks covering the rows of `roi` (absolute
/// coordinates, within the data window), where `rows` is the ROI of output rows the block
/// answers for and `block` holds them plus up to `halo` rows above and below (clipped to the
/// image). Each result image is copied into `dst`, which is sized on the first block from its
/// spec. Blocks start on multiples of the block height counted from the data window's top, a
/// multiple of the file's chunk height, so that no chunk is decoded twice apart from the halo.
template <class BlockOp>
bool forEachBlock(ImageBuf& dst, StatsBlockSource& reader, ROI roi, int halo, unsigned parts,
                  size_t budget, const char* what, BlockOp op) {
    const StatsHeader& h = reader.header();
    const ROI full = dataWindowROI(h);
    roi = prepareRoi(roi, full);
    roi.zbegin = 0, roi.zend = 1, roi.chbegin = 0, roi.chend = 10000;
    if (roi.width() <= 0 || roi.height() <= 0) {
        dst.errorfmt("{}: the region {} lies outside the data window {}", what, roi, full);
        return false;
    }
    // Half the budget per block: two blocks are in flight, the next one decoding on a helper
    // thread while this one is computed (the reader is used by one thread at a time).
    const int blockRows = std::max(1, reader.blockRows(parts, budget / 2));
    const int top = roi.ybegin - h.originY, bottom = roi.yend - h.originY;  // window rows
    std::vector<int> starts;
    for (int b0 = top - top % blockRows; b0 < bottom; b0 += blockRows) starts.push_back(b0);
    StatsImage blocks[2];
    std::string errs[2];
    const auto readBlock = [&](size_t i) {
        const int y0 = std::max(starts[i], top), y1 = std::min(starts[i] + blockRows, bottom);
        const int r0 = std::max(0, y0 - halo), r1 = std::min(h.height, y1 + halo);
        return reader.read(r0, r1 - r0, parts, blocks[i % 2], errs[i % 2]);
    };
    std::future<bool> next = std::async(std::launch::deferred, readBlock, size_t(0));
    for (size_t i = 0; i < starts.size(); ++i) {
        if (!next.get()) {
            dst.errorfmt("{}", errs[i % 2]);
            return false;
        }
        // Every return below waits for this read first (std::future of std::async).
        if (i + 1 < starts.size()) next = std::async(std::launch::async, readBlock, i + 1);
        const StatsImage& block = blocks[i % 2];
        const int y0 = std::max(starts[i], top), y1 = std::min(starts[i] + blockRows, bottom);
        ImageBuf part;
        const ROI rows(roi.xbegin, roi.xend, h.originY + y0, h.originY + y1);
        if (!op(part, block, rows)) {
            dst.errorfmt("{}", part.geterror());
            return false;
        }
        if (!dst.initialized()) {
            ImageSpec spec = part.spec();
            spec.y = roi.ybegin;
            spec.height = roi.height();
            const ROI disp = displayWindowROI(h);  // overscan: the render's display window
            spec.full_x = disp.xbegin;
            spec.full_y = disp.ybegin;
            spec.full_width = disp.width();
            spec.full_height = disp.height();
            dst.reset(spec, OIIO::InitializePixels::No);
        }
        const ImageSpec& ps = part.spec();
        if (ps.format != OIIO::TypeDesc::FLOAT || ps.nchannels != dst.nchannels() ||
            ps.width != roi.width() || ps.height != rows.height()) {
            dst.errorfmt("{}: a block's result has an unexpected shape", what);
            return false;
        }
        const size_t rowBytes = size_t(roi.width()) * size_t(ps.nchannels) * sizeof(float);
        std::memcpy(static_cast<char*>(dst.localpixels()) + size_t(y0 - top) * rowBytes,
                    part.localpixels(), rowBytes * size_t(rows.height()));
    }
    return true;
}

}  // namespace

std::vector<std::string> operationChannels(const Operation& op, const ParamValues& values,
                                           bool diagnostics, const StatsHeader* header) {
    if (op.input == InputKind::Samples) return {};
    if (op.input != InputKind::BufferMeans) {
        std::vector<std::string> names = {"R", "G", "B"};
        if (header)
            for (const std::string& n : aovOutputChannels(*header)) names.push_back(n);
        return names;
    }
    PixelKernel kernel = op.bindPixel(values, {0.0, 0.0, 0.0});
    bindConfidence(kernel, values);
    std::vector<std::string> names = estimatorChannels(kernel.mode, diagnostics);
    const StatsHeader none;  // without a header: the beauty's intervals only
    for (const std::string& n : intervalChannels(kernel, header ? *header : none))
        names.push_back(n);
    if (header)
        for (const std::string& n : aovOutputChannels(*header)) names.push_back(n);
    return names;
}

bool estimate(ImageBuf& dst, StatsBlockSource& src, const Operation& est, const PixelKernel& kernel,
              bool diagnostics, ROI roi, int nthreads) {
    dst.clear();
    if (!src.ready()) {
        dst.errorfmt("estimate {}: the source holds no image", est.name);
        return false;
    }
    // Per pixel: only the sub-buffers are decoded (the moments' count check needs part moments,
    // which `mcstat --check` reads; every count read here is still checked on its own).
    // With AOVs their part too: the estimator's weights apply to them pixel by pixel. A compact
    // file's intervals need part moments: the spread of its pixels that kept only their mean.
    const unsigned parts = kStatsPartBuffers | (src.header().aovs.empty() ? 0u : kStatsPartAovs) |
                           (kernel.ciLevel > 0.0 && src.header().compact ? kStatsPartMoments : 0u);
    const int halo = kernel.ciLevel > 0.0 && kernel.ciExpected ? kernel.ciPool : 0;
    return forEachBlock(dst, src, roi, halo, parts, kStreamBlockBytes, est.name.c_str(),
                        [&](ImageBuf& out, const StatsImage& block, ROI rows) {
                            return estimate(out, block, est, kernel, diagnostics, rows, nthreads);
                        });
}

ImageBuf estimate(StatsBlockSource& src, const Operation& est, const PixelKernel& kernel,
                  bool diagnostics, ROI roi, int nthreads) {
    ImageBuf dst;
    estimate(dst, src, est, kernel, diagnostics, roi, nthreads);
    return dst;
}

bool windowFilter(ImageBuf& dst, StatsBlockSource& src, const WindowKernel& kernel, ROI roi,
                  int nthreads) {
    dst.clear();
    if (!src.ready()) {
        dst.errorfmt("{}: the source holds no image", kernel.name);
        return false;
    }
    if (kernel.over != Neighbourhood::SubBuffers) {
        dst.errorfmt("{}: filters an image, not the sub-buffers of a statistics file", kernel.name);
        return false;
    }
    // Parameters out of range (a hand-built kernel's) fail here, before the first block is read.
    std::string err;
    if (kernel.check && !kernel.check(err)) {
        dst.errorfmt("{}: {}", kernel.name, err);
        return false;
    }
    // The halo re-decodes up to two chunks per block: a larger block keeps that small.
    const unsigned parts = kStatsPartBuffers | (src.header().aovs.empty() ? 0u : kStatsPartAovs);
    return forEachBlock(dst, src, roi, kernel.haloY(), parts, 4 * kStreamBlockBytes,
                        kernel.name.c_str(), [&](ImageBuf& out, const StatsImage& block, ROI rows) {
                            return windowFilter(out, block, kernel, rows, nthreads);
                        });
}

ImageBuf windowFilter(StatsBlockSource& src, const WindowKernel& kernel, ROI roi, int nthreads) {
    ImageBuf dst;
    windowFilter(dst, src, kernel, roi, nthreads);
    return dst;
}

}  // namespace mcstat
