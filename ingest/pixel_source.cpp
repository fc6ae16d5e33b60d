// The pixels of an ingest (ingest.h), by blocks of rows: each render opened through OpenEXR's
// Core API or OIIO, its RGB as one sub-buffer, hashed and tallied; features and AOVs beside; the
// moments of the block. And one render's RGB by name (readRenderRGB).
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>
#include <OpenImageIO/strutil.h>
#include <fcntl.h>
#include <fmt/format.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <memory>
#include <set>

#include "ingest_plan.h"
#include "mcstat/color/color.h"
#include "mcstat/core/color_space.h"
#include "mcstat/core/parallel.h"
#include "mcstat/core/untrusted_text.h"
#include "mcstat/exr-deep/codec/detail/exr_headers.h"
#include "mcstat/exr-deep/codec/detail/fd_stream.h"
#include "mcstat/exr-deep/codec/detail/flat_part_reader.h"
#include "mcstat/image/spec/image_spec.h"
#include "mcstat/ingest/ingest.h"

namespace mcstat {

using namespace ingest_detail;
using OIIO::ImageInput;
using OIIO::ImageSpec;
using OIIO::TypeDesc;

namespace {

/// 64-bit FNV-1a over the bytes of `data`, continuing from `h`.
uint64_t fnv1a(uint64_t h, const void* data, size_t bytes) {
    const auto* p = static_cast<const unsigned char*>(data);
    for (size_t i = 0; i < bytes; ++i) {
        h ^= p[i];
        h *= 1099511628211ull;
    }
    return h;
}

/// Channels of one subimage that a file's read needs, read as one contiguous range per block.
struct SubimageRead {
    int subimage = 0;
    int chbegin = 0, chend = 0;  ///< range [chbegin, chend) of that subimage's channels
};

/// The (subimage, channel) of every channel index used, grouped into one range per subimage.
std::vector<SubimageRead> readsFor(const InputFile& f, const std::vector<int>& used) {
    std::vector<SubimageRead> reads;
    for (int i : used) {
        if (i < 0) continue;
        // Plain variables, not a structured binding: C++17 lambdas cannot capture those (clang).
        const int sub = f.where[size_t(i)].first, ch = f.where[size_t(i)].second;
        auto it = std::find_if(reads.begin(), reads.end(),
                               [&](const SubimageRead& r) { return r.subimage == sub; });
        if (it == reads.end()) {
            reads.push_back({sub, ch, ch + 1});
        } else {
            it->chbegin = std::min(it->chbegin, ch);
            it->chend = std::max(it->chend, ch + 1);
        }
    }
    return reads;
}

}  // namespace

bool readRenderRGB(const std::string& path, const std::string& layer, OIIO::ImageBuf& out,
                   BeautyChannels* found, std::string& err) {
    InputFile f;
    if (!openInput(path, ReadLimits().maxPixels, f, err)) return false;
    std::string problem;
    if (!findBeauty(f.names, layer, f.beauty, problem)) {
        err = path + ": " + problem;
        return false;
    }
    OIIO::ImageBuf buf(floatSpec(f.spec.roi(), {"R", "G", "B"}, f.spec.roi_full()));
    const ImageSpec& spec = buf.spec();
    std::vector<float> rows;
    const std::vector<int> used(f.beauty.index.begin(), f.beauty.index.end());
    const auto reads = readsFor(f, used);
    float* dst = static_cast<float*>(buf.localpixels());
    const int w = spec.width;
    for (const SubimageRead& r : reads) {
        const int nch = r.chend - r.chbegin;
        rows.resize(size_t(w) * size_t(spec.height) * size_t(nch));
        if (!f.in->read_scanlines(r.subimage, 0, spec.y, spec.y + spec.height, 0, r.chbegin,
                                  r.chend, TypeDesc::FLOAT, rows.data())) {
            err = fmt::format("{}: {}", path, libraryMessage(f.in->geterror()));
            return false;
        }
        for (int c = 0; c < 3; ++c) {
            const auto [sub, ch] = f.where[size_t(f.beauty.index[size_t(c)])];
            if (sub != r.subimage) continue;
            const size_t off = size_t(ch - r.chbegin);
            for (size_t p = 0; p < size_t(w) * size_t(spec.height); ++p)
                dst[p * 3 + size_t(c)] = rows[p * size_t(nch) + off];
        }
    }
    if (found) *found = f.beauty;
    out = std::move(buf);
    return true;
}

namespace {

/// Rows per chunk of a render as its compression stores them (OpenEXR: ZIPS, RLE and NONE 1, ZIP
/// and PXR24 16, PIZ, B44 and DWAA 32, DWAB 256; a tiled file its tile height): blocks of rows
/// that start on a multiple of it never decode a chunk twice.
int chunkRowsOf(const ImageSpec& spec) {
    if (spec.tile_height > 0) return spec.tile_height;
    const std::string c = OIIO::Strutil::lower(spec.get_string_attribute("compression"));
    using OIIO::Strutil::starts_with;
    if (starts_with(c, "zips") || starts_with(c, "rle") || starts_with(c, "none")) return 1;
    if (starts_with(c, "zip") || starts_with(c, "pxr24")) return 16;
    if (starts_with(c, "dwab")) return 256;
    if (starts_with(c, "piz") || starts_with(c, "b44") || starts_with(c, "dwaa")) return 32;
    return 16;
}

/// A render open for its pixels: through OpenEXR's Core API when it reads every channel used
/// (scan-line parts of the image's data window, FLOAT or HALF, ZIP and ZIPS inflated by libdeflate,
/// exr-deep/flat_part_reader.h), else through OIIO (tiled files, B44 and DWA, other formats).
/// MCSTAT_EXR_READER=cpp in the environment takes OIIO's reader always (tests compare the two).
struct OpenRender {
    detail::Fd fd;
    std::unique_ptr<detail::FlatPartReader> core;  ///< or
    std::unique_ptr<ImageInput> oiio;
};

/// Whether the environment asks for OIIO's reader (OpenEXR's C++ API) for renders.
bool oiioReaderForced() {
    const char* v = std::getenv("MCSTAT_EXR_READER");
    return v != nullptr && std::string(v) == "cpp";
}

/// Opens `f` through the Core API when it can read every channel of `used`; false leaves `r`
/// for OIIO (no error: OIIO's reader judges what the Core one does not take).
bool openCore(const InputFile& f, const std::vector<int>& used, OpenRender& r) {
    if (oiioReaderForced()) return false;
    detail::Fd fd(::open(f.path.c_str(), O_RDONLY | O_CLOEXEC));
    struct stat st {};
    if (fd.get() < 0 || ::fstat(fd.get(), &st) != 0 || !S_ISREG(st.st_mode)) return false;
    std::string problem;
    unsigned char magic[4] = {};
    if (detail::preadFull(fd.get(), magic, 4, 0) != 4 || magic[0] != 0x76 || magic[1] != 0x2f ||
        magic[2] != 0x31 || magic[3] != 0x01)
        return false;  // not OpenEXR
    auto core = std::make_unique<detail::FlatPartReader>();
    if (!detail::checkExrAttributeSizes(fd.get(), uint64_t(st.st_size), f.path, problem) ||
        !core->open(fd.get(), uint64_t(st.st_size), f.path, f.spec.x, f.spec.y, f.spec.width,
                    f.spec.height, problem))
        return false;
    for (int i : used)
        if (i >= 0 && !core->readsAsFloat(f.where[size_t(i)].first, f.rawNames[size_t(i)]))
            return false;
    r.fd = std::move(fd);
    r.core = std::move(core);
    return true;
}

/// Reopens `f` for the pixels of channels `used` into `r`, refusing it if it changed since its
/// header was read.
bool reopenInput(const InputFile& f, const std::vector<int>& used, OpenRender& r,
                 std::string& err) {
    if (openCore(f, used, r)) return true;
    r.oiio = openRender(f.path, ReadLimits().maxPixels, err);
    if (!r.oiio) return false;
    const ImageSpec& now = r.oiio->spec();
    if (now.x != f.spec.x || now.y != f.spec.y || now.width != f.spec.width ||
        now.height != f.spec.height || now.nchannels != f.spec.nchannels) {
        err = f.path + ": changed while being ingested";
        r.oiio.reset();
        return false;
    }
    return true;
}

/// The channels read from `f`: the beauty, and when asked the features and the AOVs (-1 for an
/// absent one).
std::vector<int> usedChannels(const InputFile& f, const std::vector<int>& aovIndex, bool features,
                              bool aovs) {
    std::vector<int> used(f.beauty.index.begin(), f.beauty.index.end());
    if (features) {
        for (int i : f.features.normal) used.push_back(i);
        for (int i : f.features.position) used.push_back(i);
        for (int i : f.features.albedo) used.push_back(i);
        used.push_back(f.features.depth);
    }
    if (aovs)
        for (int i : aovIndex) used.push_back(i);
    return used;
}

/// Rows [y0, y1) of one file's channels as read (one contiguous read per subimage, read r at
/// `base[r]`).
struct RowBlock {
    const InputFile& f;
    std::vector<SubimageRead> reads;
    std::vector<float> rows;
    std::vector<size_t> base;
    size_t pixels = 0;
};

/// Reads rows [y0, y1) (0-based) of channels `used` (grouped as b.reads) from `in` into b.rows,
/// pixel-interleaved per subimage as OIIO's read_scanlines gives them.
bool readBlock(OpenRender& in, const std::vector<int>& used, RowBlock& b, int y0, int y1, int W,
               std::string& err) {
    b.pixels = size_t(y1 - y0) * size_t(W);
    b.base.assign(b.reads.size(), 0);
    size_t total = 0;
    for (size_t r = 0; r < b.reads.size(); ++r) {
        b.base[r] = total;
        total += b.pixels * size_t(b.reads[r].chend - b.reads[r].chbegin);
    }
    b.rows.resize(total);
    if (in.core) {
        // Every channel used by name into its place of the same layout, once (a feature channel
        // is an AOV too).
        std::vector<detail::PartSlices> parts(b.reads.size());
        for (size_t r = 0; r < b.reads.size(); ++r) parts[r].part = b.reads[r].subimage;
        std::vector<int> once(used);
        std::sort(once.begin(), once.end());
        once.erase(std::unique(once.begin(), once.end()), once.end());
        for (int i : once) {
            if (i < 0) continue;
            const auto [sub, ch] = b.f.where[size_t(i)];
            for (size_t r = 0; r < b.reads.size(); ++r) {
                if (b.reads[r].subimage != sub) continue;
                const size_t nch = size_t(b.reads[r].chend - b.reads[r].chbegin);
                char* base = reinterpret_cast<char*>(b.rows.data() + b.base[r] +
                                                     size_t(ch - b.reads[r].chbegin));
                parts[r].slices.push_back({b.f.rawNames[size_t(i)], base, nch * sizeof(float),
                                           nch * sizeof(float) * size_t(W)});
            }
        }
        std::string problem;
        if (in.core->read(parts, y0, y1 - y0, 1, problem) != detail::FlatPartReader::Result::Ok) {
            err = fmt::format("{}: {}", b.f.path, problem);
            return false;
        }
        return true;
    }
    for (size_t r = 0; r < b.reads.size(); ++r)
        if (!in.oiio->read_scanlines(b.reads[r].subimage, 0, b.f.spec.y + y0, b.f.spec.y + y1, 0,
                                     b.reads[r].chbegin, b.reads[r].chend, TypeDesc::FLOAT,
                                     b.rows.data() + b.base[r])) {
            err = fmt::format("{}: {}", b.f.path, libraryMessage(in.oiio->geterror()));
            return false;
        }
    return true;
}

/// Where channel i lands in the block read of its subimage: `off` of block pixel 0 and `stride`
/// from one pixel to the next.
void locate(const RowBlock& b, int i, size_t& off, size_t& stride) {
    const auto [sub, ch] = b.f.where[size_t(i)];
    for (size_t r = 0; r < b.reads.size(); ++r)
        if (b.reads[r].subimage == sub) {
            stride = size_t(b.reads[r].chend - b.reads[r].chbegin);
            off = b.base[r] + size_t(ch - b.reads[r].chbegin);
        }
}

/// What one file's pixels showed over the rows hashed so far: the hash of its RGB (the same
/// render twice), its NaN/Inf.
struct FileTally {
    uint64_t hash = kFnvBasis;
    int64_t nonFinite = 0, nonFinitePixels = 0, nonFiniteAov = 0;
};

constexpr int kFeatureSlots = 10;  ///< N xyz, P xyz, albedo rgb, Z

}  // namespace

// ---- the pixels, by blocks of rows
// ----------------------------------------------------------------

struct IngestSource::Impl {
    std::shared_ptr<Ingest> plan;
    std::string name;
    int nthreads = 0;
    /// Files held open between reads (at most kKeepOpen files; more are opened per block).
    std::vector<std::unique_ptr<OpenRender>> open;
    std::vector<FileTally> tallies;
    int hashedRows = 0;  ///< rows [0, hashedRows) of every file hashed by this source
    int aovRows = 0;     ///< rows [0, aovRows) of every file's AOVs tallied by this source
    bool passDone = false;
    int64_t blocksDone = 0;
    std::vector<float> featureRaw;  ///< a block's features, [(j * pixels + q) * 10 + slot]
    std::vector<double> featureSum;

    static constexpr size_t kKeepOpen = 64;

    bool readFile(size_t j, int y0, int y1, int blockRow0, bool features, bool aovs,
                  StatsImage& block, std::string& err);
    bool finishPass(std::string& err);
    void finishAovPass();
    void moments(StatsImage& block, size_t q0, size_t q1, bool features);
};

IngestSource::IngestSource() : impl_(std::make_unique<Impl>()) {}
IngestSource::~IngestSource() = default;

bool IngestSource::init(const std::vector<std::string>& paths, const IngestOptions& opt,
                        std::string& err, int nthreads) {
    impl_ = std::make_unique<Impl>();
    auto plan = std::make_shared<Ingest>();
    plan->opt = opt;
    if (!checkRequest(paths, opt, err) || !readHeaders(paths, *plan, err)) return false;
    fillHeader(*plan);
    impl_->plan = std::move(plan);
    impl_->nthreads = nthreads;
    impl_->name = paths.size() == 1 ? paths[0]
                                    : fmt::format("ingest of {} renders ({}, ..., {})",
                                                  paths.size(), paths.front(), paths.back());
    impl_->tallies.assign(paths.size(), FileTally());
    return true;
}

std::unique_ptr<IngestSource> IngestSource::clone(int nthreads) const {
    auto c = std::make_unique<IngestSource>();
    c->impl_->plan = impl_->plan;
    c->impl_->name = impl_->name;
    c->impl_->nthreads = nthreads;
    if (impl_->plan) c->impl_->tallies.assign(impl_->plan->files.size(), FileTally());
    return c;
}

const StatsHeader& IngestSource::header() const {
    static const StatsHeader kNone;
    return impl_->plan ? impl_->plan->header : kNone;
}
const std::string& IngestSource::name() const { return impl_->name; }
const IngestReport& IngestSource::report() const {
    static const IngestReport kNone;
    return impl_->plan ? impl_->plan->report : kNone;
}
bool IngestSource::hashed() const { return impl_->plan && impl_->plan->hashed; }
int IngestSource::chunkRows() const {
    return impl_->plan ? chunkRowsOf(impl_->plan->first().spec) : 1;
}
int IngestSource::decodeThreads() const {
    return impl_->plan ? std::max(1, std::min(threadCount(impl_->nthreads), impl_->plan->buffers()))
                       : 1;
}
int IngestSource::blocksHeld() const {
    // The features of every file are held per block before they are summed (10 floats per
    // buffer, about as much as the sub-buffers' 4): counted as a second block.
    return impl_->plan && impl_->plan->first().features.present != 0 ? 2 : 1;
}

/// Reads rows [y0, y1) of file j into `block` (whose row 0 is image row blockRow0): its RGB as
/// sub-buffer j with the file's count, hashed and tallied over the rows not hashed yet; its
/// features into featureRaw; its AOVs into sub-buffer j's.
bool IngestSource::Impl::readFile(size_t j, int y0, int y1, int blockRow0, bool features, bool aovs,
                                  StatsImage& block, std::string& err) {
    const Ingest& s = *plan;
    const InputFile& f = s.files[j];
    std::unique_ptr<OpenRender> once;
    std::unique_ptr<OpenRender>& in = j < open.size() ? open[j] : once;
    // Opened for every channel a read may ask for, so that a kept file serves any parts.
    if (!in) {
        in = std::make_unique<OpenRender>();
        if (!reopenInput(f, usedChannels(f, s.aovIndex, true, true), *in, err)) {
            in.reset();
            return false;
        }
    }
    const int W = s.width();
    const std::vector<int> used = usedChannels(f, s.aovIndex, features, aovs);
    RowBlock b{f, readsFor(f, used), {}, {}, 0};
    if (!readBlock(*in, used, b, y0, y1, W, err)) return false;
    const size_t M = size_t(s.buffers()), A = s.aovs.size();
    const size_t q0 = size_t(y0 - blockRow0) * size_t(W);  // the rows' first pixel in `block`
    const float n = float(f.spp);
    FileTally& t = tallies[j];
    // RGB: stored, and hashed and tallied over the rows this source has not hashed yet (a
    // window filter reads a block's halo rows twice; a pass that skips rows hashes nothing more).
    size_t rgbOff[3], rgbStride[3];
    for (int c = 0; c < 3; ++c) locate(b, f.beauty.index[size_t(c)], rgbOff[c], rgbStride[c]);
    const size_t hashFrom =
        y0 <= hashedRows && hashedRows < y1 ? size_t(hashedRows - y0) * size_t(W) : b.pixels;
    for (size_t q = 0; q < b.pixels; ++q) {
        float rgb[3];
        for (int c = 0; c < 3; ++c) rgb[c] = b.rows[rgbOff[c] + q * rgbStride[c]];
        const size_t k = (q0 + q) * M + j;
        for (int c = 0; c < 3; ++c) block.bufferMean[k * 3 + size_t(c)] = rgb[c];
        block.bufferCount[k] = n;
        if (q < hashFrom) continue;
        bool finite = true;
        for (int c = 0; c < 3; ++c)
            if (!std::isfinite(rgb[c])) {
                ++t.nonFinite;
                finite = false;
            }
        t.nonFinitePixels += !finite;
        t.hash = fnv1a(t.hash, rgb, sizeof rgb);
    }
    if (features) {
        const auto take = [&](int i, size_t slot) {
            if (i < 0) return;
            size_t off = 0, stride = 1;
            locate(b, i, off, stride);
            float* raw = featureRaw.data() + (j * block.pixelCount() + q0) * kFeatureSlots;
            for (size_t q = 0; q < b.pixels; ++q)
                raw[q * kFeatureSlots + slot] = b.rows[off + q * stride];
        };
        for (size_t c = 0; c < 3; ++c) {
            take(f.features.normal[c], c);
            take(f.features.position[c], 3 + c);
            take(f.features.albedo[c], 6 + c);
        }
        take(f.features.depth, 9);
    }
    if (aovs) {
        const size_t tallyFrom =
            y0 <= aovRows && aovRows < y1 ? size_t(aovRows - y0) * size_t(W) : b.pixels;
        for (size_t a = 0; a < A; ++a) {
            size_t off = 0, stride = 1;
            locate(b, s.aovIndex[a], off, stride);
            for (size_t q = 0; q < b.pixels; ++q) {
                const float v = b.rows[off + q * stride];
                if (q >= tallyFrom) t.nonFiniteAov += !std::isfinite(v);
                block.aov[((q0 + q) * M + j) * A + a] = v;
            }
        }
    }
    if (j >= open.size()) in.reset();  // more files than are kept open: closed after each block
    return true;
}

/// Moments of block pixels [q0, q1) from the buffers, in double; features from featureRaw,
/// count-weighted over the files in their order; absent ones NaN.
void IngestSource::Impl::moments(StatsImage& img, size_t q0, size_t q1, bool features) {
    const Ingest& s = *plan;
    const size_t M = size_t(s.buffers()), npix = img.pixelCount();
    const unsigned present = features ? s.first().features.present : 0u;
    const double N = s.totalSpp;
    const float nan = std::numeric_limits<float>::quiet_NaN();
    for (size_t p = q0; p < q1; ++p) {
        img.count[p] = float(N);
        for (size_t c = 0; c < 3; ++c) {
            double sum = 0.0;
            for (size_t j = 0; j < M; ++j) {
                const size_t k = p * M + j;
                sum += double(img.bufferCount[k]) * double(img.bufferMean[k * 3 + c]);
            }
            const double mean = sum / N;
            img.mean[p * 3 + c] = float(mean);
            img.beauty[p * 3 + c] = float(mean);
            img.variance[p * 3 + c] = float(bufferVariance(img, p, c, mean));
        }
        img.coverage[p] = nan;
        if (present == 0) {
            for (size_t c = 0; c < 3; ++c)
                img.normal[p * 3 + c] = img.position[p * 3 + c] = img.albedo[p * 3 + c] = nan;
            img.depth[p] = nan;
            continue;
        }
        double fs[kFeatureSlots] = {};
        for (size_t j = 0; j < M; ++j) {
            const double n = double(s.files[j].spp);
            const float* raw = featureRaw.data() + (j * npix + p) * kFeatureSlots;
            for (int slot = 0; slot < kFeatureSlots; ++slot) fs[slot] += n * double(raw[slot]);
        }
        for (size_t c = 0; c < 3; ++c) {
            img.normal[p * 3 + c] = present & kFeatureNormal ? float(fs[c] / N) : nan;
            img.position[p * 3 + c] = present & kFeaturePosition ? float(fs[3 + c] / N) : nan;
            img.albedo[p * 3 + c] = present & kFeatureAlbedo ? float(fs[6 + c] / N) : nan;
        }
        img.depth[p] = present & kFeatureDepth ? float(fs[9] / N) : nan;
    }
}

/// After a pass over every row: refuses a second copy of a render, records the hashes (the
/// header's seeds) and the NaN/Inf warnings, once per set of renders; a later pass must find the
/// same hashes (a render that changed in between is refused).
bool IngestSource::Impl::finishPass(std::string& err) {
    Ingest& s = *plan;
    const size_t M = s.files.size();
    if (s.hashed) {
        for (size_t j = 0; j < M; ++j)
            if (tallies[j].hash != s.hashes[j]) {
                err = s.files[j].path + ": changed while being ingested";
                return false;
            }
        return true;
    }
    std::vector<uint64_t> hashes(M);
    for (size_t j = 0; j < M; ++j) {
        hashes[j] = tallies[j].hash;
        for (size_t i = 0; i < j; ++i)
            if (hashes[i] == hashes[j]) {
                err = fmt::format("{}: holds the same RGB pixels as {} (the same render twice?)",
                                  s.files[j].path, s.files[i].path);
                return false;
            }
    }
    std::vector<std::string> warnings;
    for (size_t j = 0; j < M; ++j) {
        const FileTally& t = tallies[j];
        if (t.nonFinite) {
            s.report.nonFiniteValues += t.nonFinite;
            warnings.push_back(fmt::format(
                "{}: {} non-finite RGB values (NaN/Inf) in {} pixels: the stored mean (part "
                "beauty) there is non-finite; --mean and the robust estimators leave that "
                "sub-buffer out",
                s.files[j].path, t.nonFinite, t.nonFinitePixels));
        }
    }
    s.hashes = std::move(hashes);
    s.header.seeds = seedsText(&s.hashes, s.files);
    s.hashed = true;
    for (const std::string& w : warnings) s.warnOfPixels(w);
    return true;
}

/// After a pass over every row's AOVs, the first of any source (a pass that read RGB only, such as
/// --info's, settles the hashes but not these): the AOVs' NaN/Inf warnings, once per set of
/// renders.
void IngestSource::Impl::finishAovPass() {
    Ingest& s = *plan;
    if (s.aovsTallied) return;
    s.aovsTallied = true;
    for (size_t j = 0; j < s.files.size(); ++j) {
        const FileTally& t = tallies[j];
        if (!t.nonFiniteAov) continue;
        s.report.nonFiniteAovValues += t.nonFiniteAov;
        s.warnOfPixels(fmt::format(
            "{}: {} non-finite AOV values (NaN/Inf): each is left out of its channel alone, the "
            "other sub-buffers' weights renormalised (docs/aovs.md)",
            s.files[j].path, t.nonFiniteAov));
    }
}

bool IngestSource::read(int firstRow, int rows, unsigned parts, StatsImage& block,
                        std::string& err) {
    Impl& im = *impl_;
    if (!im.plan) {
        err = "ingest: no renders to read from";
        return false;
    }
    const Ingest& s = *im.plan;
    const int W = s.width(), H = s.height();
    if (rows < 1 || firstRow < 0 || firstRow > H - rows || (parts & ~kStatsAllParts)) {
        err = fmt::format("{}: cannot read rows {}..{} of parts {:#x} (the image has {} rows)",
                          im.name, firstRow, int64_t(firstRow) + rows - 1, parts, H);
        return false;
    }
    if (im.open.empty() && s.files.size() <= Impl::kKeepOpen) im.open.resize(s.files.size());
    // The RGB of every file is read whatever `parts` asks: the beauty and the moments are its
    // mean and variance. Features and AOVs are read only when asked.
    const bool features = (parts & kStatsPartFeatures) && s.first().features.present != 0;
    const bool aovs = (parts & kStatsPartAovs) && !s.aovs.empty();
    const size_t M = size_t(s.buffers()), A = s.aovs.size();
    StatsImage& img = block;
    img.header = s.header;
    img.header.height = rows;
    img.header.originY = s.header.originY + firstRow;
    const size_t npix = size_t(rows) * size_t(W);
    try {
        img.beauty.resize(npix * 3);
        img.bufferMean.resize(npix * M * 3);
        img.bufferCount.resize(npix * M);
        img.bufferOffset.clear();
        img.count.resize(npix);
        img.mean.resize(npix * 3);
        img.variance.resize(npix * 3);
        img.normal.resize(npix * 3);
        img.position.resize(npix * 3);
        img.albedo.resize(npix * 3);
        img.depth.resize(npix);
        img.coverage.resize(npix);
        img.aov.resize(aovs ? npix * M * A : 0);
        im.featureRaw.resize(features ? npix * M * kFeatureSlots : 0);
    } catch (const std::exception& e) {
        err = fmt::format("{}: cannot allocate rows {}..{} ({}x{}, M = {}): {}", im.name, firstRow,
                          firstRow + rows - 1, W, rows, M, e.what());
        return false;
    }
    // Rows in steps of opt.rowsPerBlock: each step reads every file (in parallel, one file per
    // task), so a whole-image read holds one step of each file's channels at a time.
    const int step = std::max(1, s.opt.rowsPerBlock);
    const int64_t stepsPerPass = (H + step - 1) / step;
    std::vector<std::string> errs(M);
    for (int y0 = firstRow; y0 < firstRow + rows; y0 += step) {
        const int y1 = std::min(firstRow + rows, y0 + step);
        parallelFor(0, int64_t(M), 1, im.nthreads, [&](int64_t b, int64_t e) {
            for (int64_t j = b; j < e; ++j)
                if (errs[size_t(j)].empty())
                    im.readFile(size_t(j), y0, y1, firstRow, features, aovs, img, errs[size_t(j)]);
        });
        for (const std::string& e : errs)  // the first file's error, whatever the thread count
            if (!e.empty()) {
                err = e;
                return false;
            }
        if (y0 <= im.hashedRows && im.hashedRows < y1) im.hashedRows = y1;
        if (aovs && y0 <= im.aovRows && im.aovRows < y1) im.aovRows = y1;
        ++im.blocksDone;
        if (s.opt.progress) s.opt.progress(std::min(im.blocksDone, stepsPerPass), stepsPerPass);
    }
    parallelFor(0, int64_t(rows), 0, im.nthreads, [&](int64_t b, int64_t e) {
        im.moments(img, size_t(b) * size_t(W), size_t(e) * size_t(W), features);
    });
    if (im.hashedRows == H && !im.passDone) {
        im.passDone = true;
        if (!im.finishPass(err)) return false;
        img.header.seeds = s.header.seeds;  // final now
    }
    if (im.aovRows == H && !s.aovs.empty()) im.finishAovPass();
    // The arrays of the parts not asked for are empty, as a file reader leaves them.
    if (!(parts & kStatsPartBeauty)) img.beauty.clear();
    if (!(parts & kStatsPartBuffers)) img.bufferMean.clear(), img.bufferCount.clear();
    if (!(parts & kStatsPartMoments)) img.count.clear(), img.mean.clear(), img.variance.clear();
    if (!features && !(parts & kStatsPartFeatures)) {
        img.normal.clear(), img.position.clear(), img.albedo.clear(), img.depth.clear();
        img.coverage.clear();
    }
    return true;
}

}  // namespace mcstat
