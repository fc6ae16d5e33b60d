#include "stats_header_check.h"

#include <OpenEXR/openexr.h>
#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <functional>
#include <limits>
#include <map>
#include <vector>

#include "header_checker.h"
#include "mcstat/core/params.h"
#include "mcstat/core/untrusted_text.h"
#include "mcstat/exr-deep/codec/detail/core_io.h"
#include "mcstat/exr-deep/codec/detail/exr_headers.h"
#include "mcstat/exr-deep/codec/detail/fd_stream.h"
#include "stats_layout.h"

namespace mcstat::detail {

namespace {

/// exr_context_t closed on scope exit.
struct CoreContext {
    exr_context_t ctxt = nullptr;
    ~CoreContext() {
        if (ctxt != nullptr) exr_finish(&ctxt);
    }
};

/// Opens the headers of `io.fd` with OpenEXR's Core reader into `ctx` (the chunk table is not
/// reconstructed: the checks judge it). `io` must outlive `ctx`. False with a one-line `err`.
bool startCoreRead(CoreFile& io, CoreContext& ctx, const std::string& path, std::string& err) {
    exr_context_initializer_t init = coreFileReader(io);
    init.flags = EXR_CONTEXT_FLAG_DISABLE_CHUNK_RECONSTRUCTION;
    const exr_result_t rv = exr_start_read(&ctx.ctxt, path.c_str(), &init);
    if (rv == EXR_ERR_SUCCESS) return true;
    const std::string what = coreMessage(rv, io.firstError);
    err = fmt::format("{}: truncated or corrupt (header: {})", path, libraryMessage(what));
    return false;
}

}  // namespace

bool HeaderChecker::run(const ReadLimits& limits, StatsHeader& hdr) {
    if (exr_get_count(c_, &nparts_) != EXR_ERR_SUCCESS) return fail("cannot count the parts");
    if (!checkVersionFirst()) return false;
    adaptive_ = declaresAdaptive();
    names_ = layout::partNames(adaptive_);
    if (!checkParts() || !checkAttributes(hdr)) return false;

    const int maxM = std::min(limits.maxBuffers, kMaxBuffers);
    if (hdr.M < 1 || hdr.M > maxM)
        return fail(fmt::format("{} = {} out of range 1..{}", layout::kAttrM, hdr.M, maxM));

    exr_attr_box2i_t dw{};
    exr_get_data_window(c_, 0, &dw);
    const int64_t w = int64_t(dw.max.x) - dw.min.x + 1, h = int64_t(dw.max.y) - dw.min.y + 1;
    if (w <= 0 || h <= 0 || w > std::numeric_limits<int>::max() ||
        h > std::numeric_limits<int>::max())
        return fail(fmt::format("invalid data window {}", windowText(dw)));
    const int64_t pixels = w * h;  // both < 2^31
    if (pixels > limits.maxPixels)
        return fail(fmt::format("image size {}x{} ({} pixels) exceeds the limit of {} pixels", w, h,
                                pixels, limits.maxPixels));
    // Adaptive M: the least a pixel needs (one buffer and its offset); the sample counts are
    // checked against the limits once read, before the buffers are allocated. Fixed M: every
    // part, part aovs' M * A floats included. A reader holds what one read asks for (a block of
    // rows when streamed, every row when read whole: StatsFileReader::read checks that), so here
    // the limit only refuses an image whose single row cannot be read.
    const int64_t bytesPerPixel =
        hdr.adaptiveM ? int64_t(layout::floatsPerPixel(1, hdr.aovs.size(), layout::momentsOf(hdr)) *
                                    sizeof(float) +
                                sizeof(uint64_t))
                      : int64_t(layout::floatsPerPixel(hdr.M, hdr.aovs.size()) * sizeof(float));
    if (w > limits.maxBytes / bytesPerPixel)
        return fail(fmt::format(
            "a row of image {}x{} with {} = {}{} needs {}{} bytes, exceeding the limit of {} bytes",
            w, h, hdr.adaptiveM ? "adaptive M, M_max" : "M", hdr.M,
            hdr.aovs.empty() ? std::string() : fmt::format(" and {} AOVs", hdr.aovs.size()),
            hdr.adaptiveM ? "at least " : "", double(w) * double(bytesPerPixel), limits.maxBytes));
    for (int part = 0; part < layout::kPartCount; ++part)
        if (!checkChannels(part, hdr)) return false;
    if (hasAovs_ && !checkAovChannels(hdr)) return false;

    hdr.state = state_;
    hdr.hasRecords = hasRecords_;
    if ((hdr.hasState() || hasRecords_) && hdr.formatVersion < kStatsFormatVersionSamples)
        return fail("optional parts need format version 4");
    hdr.width = int(w);
    hdr.height = int(h);
    hdr.originX = dw.min.x;
    hdr.originY = dw.min.y;
    // The display window (the same in every part, checkParts): kept when it differs from the data
    // window, so that equal headers round-trip equal.
    exr_attr_box2i_t disp{};
    exr_get_display_window(c_, 0, &disp);
    hdr.displayX = hdr.displayY = hdr.displayWidth = hdr.displayHeight = 0;
    if (!sameBox(disp, dw)) {
        const int64_t dispW = int64_t(disp.max.x) - disp.min.x + 1,
                      dispH = int64_t(disp.max.y) - disp.min.y + 1;
        if (dispW <= 0 || dispH <= 0 || dispW > std::numeric_limits<int>::max() ||
            dispH > std::numeric_limits<int>::max())
            return fail(fmt::format("invalid display window {}", windowText(disp)));
        hdr.displayX = disp.min.x;
        hdr.displayY = disp.min.y;
        hdr.displayWidth = int(dispW);
        hdr.displayHeight = int(dispH);
    }
    return true;
}

bool readExrPartNames(int fd, uint64_t size, const std::string& path,
                      std::vector<std::string>& names, bool& newerStats, std::string& err) {
    if (!checkAttributeSizes(fd, size, path, err)) return false;
    CoreFile io{fd, int64_t(size), {}};
    CoreContext ctx;
    if (!startCoreRead(io, ctx, path, err)) return false;
    int n = 0;
    if (exr_get_count(ctx.ctxt, &n) != EXR_ERR_SUCCESS) {
        err = fmt::format("{}: truncated or corrupt (header: no part count)", path);
        return false;
    }
    HeaderChecker checker(ctx.ctxt, path);
    names.clear();
    newerStats = false;
    for (int part = 0; part < n; ++part) {
        names.push_back(checker.partName(part));
        const exr_attribute_t* v = checker.attr(part, layout::kAttrFormatVersion);
        if (v != nullptr && v->type == EXR_ATTR_INT && v->i > kStatsFormatVersion)
            newerStats = true;
    }
    return true;
}

bool checkStatsHeaders(int fd, uint64_t size, const std::string& path, const ReadLimits& limits,
                       StatsHeader& hdr, std::string& err) {
    unsigned char magic[4] = {};
    if (size == 0) {
        err = path + ": not an OpenEXR file (empty file)";
        return false;
    }
    const int64_t got = preadFull(fd, magic, 4, 0);
    if (got < 0) {
        err = fmt::format("{}: cannot read ({})", path, std::strerror(errno));
        return false;
    }
    if (got < 4 || std::memcmp(magic, kExrMagic, 4) != 0) {
        err = path + ": not an OpenEXR file";
        return false;
    }

    if (!checkAttributeSizes(fd, size, path, err)) return false;

    CoreFile io{fd, int64_t(size), {}};
    CoreContext ctx;
    if (!startCoreRead(io, ctx, path, err)) return false;
    HeaderChecker checker(ctx.ctxt, path);
    if (!checker.run(limits, hdr) || !checker.checkChunks(size)) {
        err = checker.err;
        return false;
    }
    return true;
}

}  // namespace mcstat::detail