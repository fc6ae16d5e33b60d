// StatsImage::allocate and validateStats: the in-memory invariants of a statistics image.
#include <fmt/format.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <new>

#include "mcstat/exr-deep/stats_file.h"
#include "stats_layout.h"

namespace mcstat {

namespace {

/// Largest count a float32 holds exactly with every smaller integer (FORMAT.md, "Counts").
constexpr double kMaxCount = 16777216.0;  // 2^24

bool checkHeader(const StatsHeader& h, std::string& problem) {
    if (h.formatVersion < 1 || h.formatVersion > kStatsFormatVersion) {
        problem = fmt::format("format version {} (this library writes and holds 1..{})",
                              h.formatVersion, kStatsFormatVersion);
        return false;
    }
    if (h.adaptiveM && h.formatVersion < kStatsFormatVersionAdaptive) {
        problem = fmt::format("adaptive M needs format version {} (header has {})",
                              kStatsFormatVersionAdaptive, h.formatVersion);
        return false;
    }
    if (h.width <= 0 || h.height <= 0) {
        problem = fmt::format("empty or negative size {}x{}", h.width, h.height);
        return false;
    }
    if (h.M < 1 || h.M > kMaxBuffers) {
        problem = fmt::format("M = {} out of range 1..{}", h.M, kMaxBuffers);
        return false;
    }
    if (h.spp < 0) {
        problem = fmt::format("negative spp {}", h.spp);
        return false;
    }
    if (!layout::knownAssignment(h.assignment, h.adaptiveM, problem, h.compact)) return false;
    if (h.compact && (!h.adaptiveM || h.compactRule.empty())) {
        problem = "a compact file has the adaptive layout and names its rule";
        return false;
    }
    if (!layout::knownVariance(h.variance, problem)) return false;
    if (h.features > kAllFeatures) {
        problem = fmt::format("feature bits {:#x} beyond the known features", h.features);
        return false;
    }
    if (!layout::checkAovFields(h, problem)) return false;
    if (h.formatVersion < requiredFormatVersion(h)) {
        const bool v5 = requiredFormatVersion(h) >= kStatsFormatVersionAovs;
        problem = fmt::format(
            "format version {} cannot hold this content (assignment '{}', variance '{}', "
            "features '{}'{}{}): it needs version {}",
            h.formatVersion, printable(h.assignment), printable(h.variance),
            featureListText(h.features), h.sources.empty() ? "" : ", sources",
            v5 ? fmt::format(", {} AOVs, beauty channels '{}', '{}', '{}'{}{}", h.aovs.size(),
                             printable(h.beautyNames[0]), printable(h.beautyNames[1]),
                             printable(h.beautyNames[2]),
                             h.beautyPart.empty() ? "" : ", a beauty part",
                             h.sourceMetadata.empty() ? "" : ", source metadata")
               : std::string(),
            requiredFormatVersion(h));
        return false;
    }
    // OpenEXR's dataWindow.max must stay representable.
    if (int64_t(h.originX) + h.width - 1 > std::numeric_limits<int>::max() ||
        int64_t(h.originY) + h.height - 1 > std::numeric_limits<int>::max()) {
        problem = "data window exceeds the int range";
        return false;
    }
    return true;
}

/// Why `v` is not a valid sample count, or nullptr.
const char* countProblem(float v) {
    if (!std::isfinite(v)) return std::isnan(v) ? "is NaN" : "is infinite";
    if (v < 0.f) return "is negative";
    if (v != std::floor(v)) return "is not an integer";
    if (double(v) > kMaxCount) return "exceeds 2^24";
    return nullptr;
}

}  // namespace

namespace {

/// Allocates the arrays of `img` (header set) for `buffers` sub-buffers in total; `offsets` moves
/// into img.bufferOffset. On failure `img` is untouched.
bool allocateArrays(StatsImage& img, size_t buffers, std::vector<uint64_t>&& offsets,
                    std::string& err) {
    const StatsHeader& header = img.header;
    const size_t pixels = size_t(header.width) * size_t(header.height);  // < 2^62
    const size_t maxFloats = std::numeric_limits<size_t>::max() / sizeof(float);
    const size_t perPixel = layout::floatsPerPixel(0);
    const size_t A = header.aovs.size();  // <= kMaxAovs (checkHeader)
    if (pixels > maxFloats / perPixel || buffers > (maxFloats - pixels * perPixel) / (4 + A)) {
        err =
            fmt::format("cannot allocate statistics image: {}x{} pixels with {} buffers overflows",
                        header.width, header.height, buffers);
        return false;
    }
    try {
        StatsImage t;
        t.header = header;
        t.beauty.assign(pixels * 3, 0.f);
        t.bufferMean.assign(buffers * 3, 0.f);
        t.bufferCount.assign(buffers, 0.f);
        t.count.assign(pixels, 0.f);
        if (layout::momentsOf(header) != layout::Moments::Slim) {
            t.mean.assign(pixels * 3, 0.f);
            t.variance.assign(pixels * 3, 0.f);
        }
        t.normal.assign(pixels * 3, 0.f);
        t.position.assign(pixels * 3, 0.f);
        t.albedo.assign(pixels * 3, 0.f);
        t.depth.assign(pixels, std::numeric_limits<float>::infinity());
        t.coverage.assign(pixels, 0.f);
        t.aov.assign(buffers * A, 0.f);
        if (header.compact) t.spread.assign(pixels * size_t(kSpreadFloats), 0.f);
        t.bufferOffset = std::move(offsets);
        img = std::move(t);
    } catch (const std::exception& e) {  // bad_alloc, length_error
        err = fmt::format("cannot allocate statistics image {}x{} with M = {}: {}", header.width,
                          header.height, header.M, e.what());
        return false;
    }
    return true;
}

}  // namespace

namespace detail {

bool resizeParts(StatsImage& img, unsigned parts, size_t buffers, std::vector<uint64_t>&& offsets,
                 std::string& err) {
    const StatsHeader& h = img.header;
    const size_t pixels = size_t(h.width) * size_t(h.height);  // a block: bounded by the file's
    // resize, not assign: a reused block keeps its storage, and every element of a part read is
    // overwritten by the decoder (the header check saw every channel).
    const auto fit = [](std::vector<float>& v, size_t n, bool keep) {
        if (keep)
            v.resize(n);
        else
            v.clear();
    };
    try {
        const bool beauty = parts & kStatsPartBeauty, buf = parts & kStatsPartBuffers;
        const bool mom = parts & kStatsPartMoments, feat = parts & kStatsPartFeatures;
        fit(img.beauty, pixels * 3, beauty);
        fit(img.bufferMean, buffers * 3, buf);
        fit(img.bufferCount, buffers, buf);
        img.bufferOffset = buf ? std::move(offsets) : std::vector<uint64_t>();
        fit(img.count, pixels, mom);
        const bool slim = layout::momentsOf(h) == layout::Moments::Slim;
        fit(img.mean, pixels * 3, mom && !slim);
        fit(img.variance, pixels * 3, mom && !slim);
        fit(img.normal, pixels * 3, feat);
        fit(img.position, pixels * 3, feat);
        fit(img.albedo, pixels * 3, feat);
        fit(img.depth, pixels, feat);
        fit(img.coverage, pixels, feat);
        // Part aovs (fixed M), or the AOV channels of the deep part (adaptive layout, read with
        // the buffers: `buffers` counts them).
        fit(img.aov, (h.adaptiveM ? buffers : pixels * size_t(h.M)) * h.aovs.size(),
            (parts & kStatsPartAovs) != 0);
        fit(img.spread, pixels * size_t(kSpreadFloats), mom && h.compact);
    } catch (const std::exception& e) {  // bad_alloc, length_error
        err = fmt::format("cannot allocate {} rows of {} pixels with {} buffers: {}", h.height,
                          h.width, buffers, e.what());
        return false;
    }
    return true;
}

}  // namespace detail

bool StatsImage::allocate(std::string& err) {
    std::string problem;
    if (!checkHeader(header, problem)) {
        err = "cannot allocate statistics image: " + problem;
        return false;
    }
    if (header.adaptiveM) {
        err = "cannot allocate statistics image: adaptive M needs allocateAdaptive";
        return false;
    }
    const size_t pixels = size_t(header.width) * size_t(header.height);  // < 2^62
    if (pixels > std::numeric_limits<size_t>::max() / size_t(kMaxBuffers)) {
        err = fmt::format("cannot allocate statistics image: {}x{} pixels with M = {} overflows",
                          header.width, header.height, header.M);
        return false;
    }
    return allocateArrays(*this, pixels * size_t(header.M), {}, err);
}

bool StatsImage::allocateAdaptive(const std::vector<uint32_t>& buffersPerPixel, std::string& err) {
    StatsHeader h = header;
    h.adaptiveM = true;
    std::string problem;
    if (!checkHeader(h, problem)) {
        err = "cannot allocate statistics image: " + problem;
        return false;
    }
    const size_t pixels = size_t(h.width) * size_t(h.height);
    if (buffersPerPixel.size() != pixels) {
        err = fmt::format("cannot allocate statistics image: {} buffer counts given for {} pixels",
                          buffersPerPixel.size(), pixels);
        return false;
    }
    std::vector<uint64_t> offsets;
    try {
        offsets.resize(pixels + 1);
    } catch (const std::exception& e) {
        err =
            fmt::format("cannot allocate statistics image {}x{}: {}", h.width, h.height, e.what());
        return false;
    }
    uint64_t total = 0;
    for (size_t p = 0; p < pixels; ++p) {
        const uint32_t m = buffersPerPixel[p];
        if (m < 1 || m > uint32_t(h.M)) {
            err = fmt::format(
                "cannot allocate statistics image: pixel ({}, {}) has {} buffers, outside 1..{}",
                h.originX + int64_t(p % size_t(h.width)), h.originY + int64_t(p / size_t(h.width)),
                m, h.M);
            return false;
        }
        offsets[p] = total;
        total += m;  // <= pixels * 999, no overflow
    }
    offsets[pixels] = total;
    StatsImage t;
    t.header = h;
    if (!allocateArrays(t, size_t(total), std::move(offsets), err)) return false;
    *this = std::move(t);
    return true;
}

bool StatsImage::checkBufferLayout(std::string& why) const {
    const StatsHeader& h = header;
    if (h.width <= 0 || h.height <= 0 || h.M < 1 || h.M > kMaxBuffers) {
        why = fmt::format("invalid size {}x{} or M = {}", h.width, h.height, h.M);
        return false;
    }
    const size_t pixels = pixelCount();
    size_t buffers = 0;
    if (!h.adaptiveM) {
        if (!bufferOffset.empty()) {
            why = fmt::format("fixed M but {} buffer offsets", bufferOffset.size());
            return false;
        }
        if (pixels > std::numeric_limits<size_t>::max() / size_t(kMaxBuffers)) {
            why = "size overflows";
            return false;
        }
        buffers = pixels * size_t(h.M);
    } else {
        if (bufferOffset.size() != pixels + 1 || bufferOffset[0] != 0) {
            why = fmt::format("adaptive M needs {} buffer offsets starting at 0, has {}",
                              pixels + 1, bufferOffset.size());
            return false;
        }
        for (size_t p = 0; p < pixels; ++p) {
            const uint64_t a = bufferOffset[p], b = bufferOffset[p + 1];
            // A compact file's pixel holds its M buffers or their mean alone.
            if (b <= a || b - a > uint64_t(h.M) ||
                (h.compact && b - a != 1 && b - a != uint64_t(h.M))) {
                why = fmt::format("pixel ({}, {}) has {} sub-buffers, {}",
                                  h.originX + int64_t(p % size_t(h.width)),
                                  h.originY + int64_t(p / size_t(h.width)),
                                  b >= a ? int64_t(b - a) : -int64_t(a - b),
                                  h.compact ? fmt::format("neither 1 nor M = {} (compact)", h.M)
                                            : fmt::format("outside 1..{}", h.M));
                return false;
            }
        }
        buffers = size_t(bufferOffset[pixels]);
    }
    if (bufferCount.size() != buffers || buffers > bufferMean.max_size() / 3 ||
        bufferMean.size() != buffers * 3) {
        why = fmt::format("sub-buffer arrays hold {} means and {} counts, expected {} buffers",
                          bufferMean.size(), bufferCount.size(), buffers);
        return false;
    }
    // Part aovs: empty (not read, or no AOVs) or one value per buffer and AOV.
    const size_t A = h.aovs.size();
    if (!aov.empty() && (A == 0 || buffers > aov.max_size() / A || aov.size() != buffers * A)) {
        why = fmt::format("AOV array holds {} values, expected {} buffers x {} AOVs", aov.size(),
                          buffers, A);
        return false;
    }
    return true;
}

bool validateStats(const StatsImage& img, const std::string& what, std::string& err) {
    return validateStats(img, kStatsAllParts, what, err);
}

bool validateStats(const StatsImage& img, unsigned parts, const std::string& what,
                   std::string& err) {
    const StatsHeader& h = img.header;
    std::string problem;
    if (!checkHeader(h, problem)) {
        err = what + ": " + problem;
        return false;
    }
    const size_t pixels = img.pixelCount();
    const bool buffers = (parts & kStatsPartBuffers) != 0,
               moments = (parts & kStatsPartMoments) != 0;
    if ((parts & kStatsPartAovs) && h.adaptiveM) {
        // The deep part's AOV channels: one value per buffer and AOV, read with the buffers.
        const size_t A = h.aovs.size();
        const size_t k =
            img.bufferOffset.size() == pixels + 1 ? size_t(img.bufferOffset[pixels]) : size_t(0);
        if (img.aov.size() != k * A) {
            err = fmt::format("{}: AOV array holds {} floats, expected {} buffers x {} AOVs", what,
                              img.aov.size(), k, A);
            return false;
        }
    } else if (parts & kStatsPartAovs) {
        const size_t A = h.aovs.size(), m = size_t(h.M);
        if (pixels > img.aov.max_size() / (m * A + 1) || img.aov.size() != pixels * m * A) {
            err = fmt::format(
                "{}: array of part '{}' holds {} floats, expected {} ({} pixels x M = {} x {} "
                "AOVs)",
                what, layout::kPartAovs, img.aov.size(), pixels * m * A, pixels, h.M, A);
            return false;
        }
    }
    for (int part = 0; part < layout::kPartCount; ++part) {
        if (!(parts & (1u << part))) continue;  // StatsParts bits follow the part order
        for (const layout::ChannelPlace& c :
             layout::partChannels(part, h.M, h.adaptiveM, layout::momentsOf(h))) {
            if (c.offset != 0) continue;  // one check per array
            const std::vector<float>& a = layout::arrayOf(img, c.array);
            if (pixels > a.max_size() / c.stride || a.size() != pixels * c.stride) {
                err = fmt::format(
                    "{}: array for channel '{}' of part '{}' holds {} floats, expected {}", what,
                    c.name, layout::kPartNames[part], a.size(), pixels * c.stride);
                return false;
            }
        }
    }
    if (std::string why; buffers && !img.checkBufferLayout(why)) {
        err = what + ": " + why;
        return false;
    }
    if (buffers && (parts & kStatsPartBeauty) && compactMeansInBeauty(h)) {
        // Version 8 stores the mean of a pixel with one buffer once, in part beauty.
        for (size_t p = 0; p < pixels; ++p) {
            const float* m = img.bufferMean.data() + 3 * img.bufferBegin(p);
            const float* b = img.beauty.data() + 3 * p;
            if (img.buffersOf(p) != 1 || std::memcmp(m, b, 3 * sizeof(float)) == 0) continue;
            err = fmt::format(
                "{}: pixel ({}, {}) keeps one buffer, whose mean ({}, {}, {}) a compact file of "
                "format {} stores in part '{}', but that part holds ({}, {}, {})",
                what, h.originX + int64_t(p % size_t(h.width)),
                h.originY + int64_t(p / size_t(h.width)), m[0], m[1], m[2], h.formatVersion,
                layout::kPartNames[layout::kBeauty], b[0], b[1], b[2]);
            return false;
        }
    }
    if (!buffers && !moments) return true;
    for (size_t p = 0; p < pixels; ++p) {
        const auto where = [&] {
            return fmt::format("pixel ({}, {})", h.originX + int64_t(p % size_t(h.width)),
                               h.originY + int64_t(p / size_t(h.width)));
        };
        double sum = 0.0;
        const size_t k0 = buffers ? img.bufferBegin(p) : 0;
        const size_t m = buffers ? size_t(img.buffersOf(p)) : 0;
        for (size_t j = 0; j < m; ++j) {
            const float c = img.bufferCount[k0 + j];
            if (const char* why = countProblem(c)) {
                err = fmt::format("{}: {}: buffer {} count {} ({})", what, where(), j, why, c);
                return false;
            }
            sum += double(c);
        }
        if (!moments) continue;
        const float n = img.count[p];
        if (const char* why = countProblem(n)) {
            err = fmt::format("{}: {}: moments count {} ({})", what, where(), why, n);
            return false;
        }
        if (buffers && sum != double(n)) {
            err = fmt::format("{}: {}: buffer counts sum to {} but the moments count is {}", what,
                              where(), sum, n);
            return false;
        }
    }
    return true;
}

}  // namespace mcstat
