// The block sources other than the file reader (MemoryStatsSource, MergedStatsSource), the block
// height rule, and the streaming copy of a source into a file (writeStatsFile over a source).
#include <fmt/format.h>

#include <algorithm>
#include <cstring>

#include "mcstat/exr-deep/stats_file.h"
#include "stats_layout.h"

namespace mcstat {

int StatsBlockSource::blockRows(unsigned parts, size_t budgetBytes) const {
    const StatsHeader& h = header();
    if (h.height < 1) return 1;
    size_t floats = 0;  // per pixel, over the parts read (adaptive M: at M_max, an upper bound)
    if (parts & kStatsPartBeauty) floats += 3;
    if (parts & kStatsPartBuffers) floats += 4 * size_t(h.M) + (h.adaptiveM ? 2 : 0);
    if (parts & kStatsPartMoments)
        floats += (layout::momentsOf(h) == layout::Moments::Slim ? 1 : 7) +
                  (h.compact ? size_t(kSpreadFloats) : 0);
    if (parts & kStatsPartFeatures) floats += 11;
    if (parts & kStatsPartAovs) floats += size_t(h.M) * h.aovs.size();
    const size_t rowBytes = std::max<size_t>(1, floats * sizeof(float) * size_t(h.width)) *
                            size_t(std::max(1, blocksHeld()));
    const size_t chunk = size_t(std::max(1, chunkRows()));
    const size_t chunks = size_t(std::max(1, decodeThreads()));
    const size_t rows = std::max<size_t>(chunks, budgetBytes / rowBytes / chunk) * chunk;
    return int(std::min<size_t>(rows, size_t(h.height)));
}

namespace {

/// Checks a block request against `h`; false with `err` naming `name`.
bool checkRange(const StatsHeader& h, const std::string& name, int firstRow, int rows,
                unsigned parts, std::string& err) {
    if (h.height < 1) {
        err = name + ": no image to read from";
        return false;
    }
    if (rows < 1 || firstRow < 0 || firstRow > h.height - rows || (parts & ~kStatsAllParts)) {
        err = fmt::format("{}: cannot read rows {}..{} of parts {:#x} (the image has {} rows)",
                          name, firstRow, int64_t(firstRow) + rows - 1, parts, h.height);
        return false;
    }
    return true;
}

}  // namespace

MemoryStatsSource::MemoryStatsSource(std::shared_ptr<const StatsImage> img, std::string name)
    : img_(std::move(img)), name_(std::move(name)) {}

bool MemoryStatsSource::read(int firstRow, int rows, unsigned parts, StatsImage& block,
                             std::string& err) {
    const StatsImage& img = *img_;
    if (!checkRange(img.header, name_, firstRow, rows, parts, err)) return false;
    parts = detail::partsToRead(img.header, parts);
    if (std::string why; !img.checkBufferLayout(why)) {
        err = name_ + ": " + why;
        return false;
    }
    block.header = img.header;
    block.header.height = rows;
    block.header.originY = img.header.originY + firstRow;
    const size_t w = size_t(img.header.width);
    const size_t p0 = size_t(firstRow) * w, np = size_t(rows) * w;
    const size_t k0 = img.bufferBegin(p0),
                 k1 = img.bufferBegin(p0 + np - 1) + size_t(img.buffersOf(p0 + np - 1));
    std::vector<uint64_t> offsets;
    if (img.header.adaptiveM && (parts & kStatsPartBuffers)) {
        offsets.resize(np + 1);
        for (size_t i = 0; i <= np; ++i) offsets[i] = img.bufferOffset[p0 + i] - k0;
    }
    if (!detail::resizeParts(block, parts, (parts & kStatsPartBuffers) ? k1 - k0 : 0,
                             std::move(offsets), err)) {
        err = name_ + ": " + err;
        return false;
    }
    // Every array of a part read: the same rows of the image's array.
    for (int part = 0; part < layout::kPartCount; ++part) {
        if (!(parts & (1u << part))) continue;
        for (const layout::ChannelPlace& c : layout::partChannels(
                 part, img.header.M, img.header.adaptiveM, layout::momentsOf(img.header))) {
            if (c.offset != 0) continue;  // one copy per array
            const std::vector<float>& src = layout::arrayOf(img, c.array);
            std::vector<float>& dst = layout::arrayOf(block, c.array);
            const size_t first = p0 * c.stride;
            std::copy(src.begin() + ptrdiff_t(first), src.begin() + ptrdiff_t(first + dst.size()),
                      dst.begin());
        }
    }
    if ((parts & kStatsPartAovs) && !block.aov.empty() && img.header.adaptiveM) {
        const size_t A = img.header.aovs.size();
        if (img.aov.size() != img.bufferCount.size() * A) {
            err = fmt::format("{}: AOV array holds {} values, expected {}", name_, img.aov.size(),
                              img.bufferCount.size() * A);
            return false;
        }
        std::copy(img.aov.begin() + ptrdiff_t(k0 * A), img.aov.begin() + ptrdiff_t(k1 * A),
                  block.aov.begin());
    } else if ((parts & kStatsPartAovs) && !block.aov.empty()) {  // fixed M: M * A per pixel
        const size_t per = size_t(img.header.M) * img.header.aovs.size();
        if (img.aov.size() != img.pixelCount() * per) {
            err = fmt::format("{}: AOV array holds {} values, expected {}", name_, img.aov.size(),
                              img.pixelCount() * per);
            return false;
        }
        std::copy(img.aov.begin() + ptrdiff_t(p0 * per),
                  img.aov.begin() + ptrdiff_t((p0 + np) * per), block.aov.begin());
    }
    if ((parts & kStatsPartBuffers) && img.header.adaptiveM) {
        std::copy(img.bufferMean.begin() + ptrdiff_t(k0 * 3),
                  img.bufferMean.begin() + ptrdiff_t(k1 * 3), block.bufferMean.begin());
        std::copy(img.bufferCount.begin() + ptrdiff_t(k0), img.bufferCount.begin() + ptrdiff_t(k1),
                  block.bufferCount.begin());
    }
    return validateStats(block, parts, name_, err);
}

bool MergedStatsSource::init(const std::vector<StatsBlockSource*>& inputs, std::string& err,
                             int nthreads) {
    inputs_.clear();
    header_ = StatsHeader();
    header_.width = header_.height = 0;
    std::vector<const StatsHeader*> headers;
    std::vector<std::string> names;
    for (StatsBlockSource* s : inputs) {
        if (s == nullptr || !s->ready()) {
            err = "cannot merge: an input holds no image";
            return false;
        }
        headers.push_back(&s->header());
        names.push_back(s->name());
    }
    StatsHeader h;
    if (!mergeHeaders(headers, h, err, inputs.size() > 2 ? names : std::vector<std::string>()))
        return false;
    inputs_ = inputs;
    header_ = std::move(h);
    nthreads_ = nthreads;
    blocks_.resize(inputs.size());
    name_ = "merge(" + names[0];
    for (size_t i = 1; i < names.size(); ++i) name_ += ", " + names[i];
    name_ += ")";
    return true;
}

bool MergedStatsSource::init(StatsBlockSource& a, StatsBlockSource& b, std::string& err) {
    return init(std::vector<StatsBlockSource*>{&a, &b}, err, 1);
}

int MergedStatsSource::chunkRows() const {
    int rows = 1;
    for (const StatsBlockSource* s : inputs_) rows = std::max(rows, s->chunkRows());
    return rows;
}

int MergedStatsSource::decodeThreads() const {
    int threads = 1;
    for (const StatsBlockSource* s : inputs_) threads = std::max(threads, s->decodeThreads());
    return threads;
}

int MergedStatsSource::blocksHeld() const {
    int blocks = 1;
    for (const StatsBlockSource* s : inputs_) blocks += s->blocksHeld();
    return blocks;
}

bool MergedStatsSource::read(int firstRow, int rows, unsigned parts, StatsImage& block,
                             std::string& err) {
    if (inputs_.empty()) {
        err = "merge: not initialised";
        return false;
    }
    if (!checkRange(header_, name_, firstRow, rows, parts, err)) return false;
    // The merge of any part needs the counts and coverage of the others: read everything.
    std::vector<const StatsImage*> in;
    for (size_t i = 0; i < inputs_.size(); ++i) {
        if (!inputs_[i]->read(firstRow, rows, kStatsAllParts, blocks_[i], err)) return false;
        in.push_back(&blocks_[i]);
    }
    StatsImage merged;
    if (!mergeStats(in, merged, err, nthreads_)) return false;
    // Per-pixel merging leaves the whole-image header fields (spp, seeds, ...) as mergeHeaders
    // made them; only the block's rows differ.
    merged.header = header_;
    merged.header.height = rows;
    merged.header.originY = header_.originY + firstRow;
    block = std::move(merged);
    return true;
}

bool writeStatsFile(const std::string& path, StatsBlockSource& src, std::string& err, int nthreads,
                    size_t budgetBytes) {
    if (!src.ready()) {
        err = path + ": nothing to write (" + src.name() + " holds no image)";
        return false;
    }
    const StatsHeader& h = src.header();
    StatsHeader out = h;
    if (out.hasState() || out.hasRecords) {  // the four parts only, in the lowest version for them
        out.state = StateOwner();
        out.hasRecords = false;
        out.formatVersion = requiredFormatVersion(out);
    }
    StatsFileWriter writer;
    if (!writer.open(path, out, err, nthreads)) return false;
    const int rows = src.blockRows(kStatsAllParts, budgetBytes);
    StatsImage block;
    for (int y = 0; y < h.height; y += rows) {
        if (!src.read(y, std::min(rows, h.height - y), kStatsAllParts, block, err)) {
            err = path + ": " + err;
            return false;
        }
        block.header.state = StateOwner();
        block.header.hasRecords = false;
        block.header.formatVersion = out.formatVersion;
        if (!writer.write(block, err)) return false;
    }
    // A source may know its seeds only once every row was read (an ingest's RGB hashes): the
    // last block's header carries them.
    if (block.header.seeds != out.seeds && !writer.replaceSeeds(block.header.seeds, err))
        return false;
    return writer.commit(err);
}

bool readAll(StatsBlockSource& src, StatsImage& img, std::string& err) {
    if (!src.ready()) {
        err = src.name() + ": holds no image";
        return false;
    }
    StatsImage t;
    if (!src.read(0, src.header().height, kStatsAllParts, t, err)) return false;
    if (!validateStats(t, src.name(), err)) return false;
    img = std::move(t);
    return true;
}

}  // namespace mcstat
