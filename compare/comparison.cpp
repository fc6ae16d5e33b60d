// The comparison engine's loop (comparison.h): the quantities to test, then both sides read by the
// same blocks of rows, aligned to the tiles, so a tile is always whole inside one block; a block's
// tiles are the parallel tasks (comparison_tile.cpp). The multiple-testing threshold needs every
// p-value, so they are kept (4 bytes per hypothesis) with the maps; the sub-buffers are not.
#include "comparison.h"

#include <fmt/format.h>
#include <fnmatch.h>

#include "mcstat/core/parallel.h"
#include "mcstat/core/untrusted_text.h"

namespace mcstat::detail {

bool Comparison::resolveQuantities(std::string& err) {
    if (opt_.rgb) {
        const char* names[3] = {"R", "G", "B"};
        for (int c = 0; c < 3; ++c) {
            Quantity q;
            q.kind = Quantity::Channel;
            q.channel = c;
            q.name = names[c];
            q.suffix = std::string(".") + names[c];
            q_.push_back(q);
        }
    } else {
        Quantity q;
        q.name = "luminance";
        q_.push_back(q);
    }
    if (opt_.aovs.empty()) return true;
    if (a_.ref) {
        err = "AOVs cannot be compared against a reference image (it has no sub-buffers)";
        return false;
    }
    const StatsHeader& ha = a_.src->header();
    const StatsHeader& hb = b_.src->header();
    for (const std::string& pattern : opt_.aovs) {
        bool matched = false;
        for (size_t i = 0; i < ha.aovs.size(); ++i) {
            const std::string& name = ha.aovs[i].name;
            if (fnmatch(pattern.c_str(), name.c_str(), 0) != 0) continue;
            matched = true;
            if (std::any_of(q_.begin(), q_.end(), [&](const Quantity& e) {
                    return e.kind == Quantity::Aov && e.name == name;
                }))
                continue;
            const int ib = hb.aovIndex(name);
            if (ib < 0) {
                err = fmt::format("{} has AOV '{}', {} has not", a_.src->name(), printable(name),
                                  b_.src->name());
                return false;
            }
            Quantity q;
            q.kind = Quantity::Aov;
            q.aovA = int(i);
            q.aovB = ib;
            q.name = name;
            q.suffix = "." + name;
            q_.push_back(q);
        }
        if (!matched) {
            std::vector<std::string> names;
            for (const AovChannel& c : ha.aovs) names.push_back(c.name);
            err = fmt::format("AOV '{}' matches none of {}'s AOV channels ({})", pattern,
                              a_.src->name(),
                              names.empty() ? std::string("it has none") : printableList(names));
            return false;
        }
    }
    return true;
}

bool Comparison::processBlock(int row0, int rows, std::string& err) {
    const bool aovs = std::any_of(q_.begin(), q_.end(),
                                  [](const Quantity& q) { return q.kind == Quantity::Aov; });
    // A compact file's spread (what its buffer-free pixels keep for the test) is in part moments.
    const auto partsOf = [&](const Side& s) {
        return kStatsPartBuffers | (aovs ? kStatsPartAovs : 0u) |
               (s.src->header().compact ? kStatsPartMoments : 0u);
    };
    if (b_.src && !b_.src->read(row0, rows, partsOf(b_), b_.block, err)) return false;
    if (a_.src && !a_.src->read(row0, rows, partsOf(a_), a_.block, err)) return false;
    const int ty0 = row0 / taskSide_;
    const int ty1 = (row0 + rows + taskSide_ - 1) / taskSide_;
    const int64_t tasks = int64_t(ty1 - ty0) * tilesX_;
    parallelFor(0, tasks, 1, opt_.nthreads, [&](int64_t begin, int64_t end) {
        for (int64_t i = begin; i < end; ++i) {
            Tally t;
            testTile(int(i % tilesX_), ty0 + int(i / tilesX_), row0, t);
            const std::lock_guard<std::mutex> lock(mutex_);
            tally_.pixelsTested += t.pixelsTested;
            tally_.nonFiniteOneSide += t.nonFiniteOneSide;
            tally_.nonFiniteBoth += t.nonFiniteBoth;
            tally_.constantEqual += t.constantEqual;
            tally_.fewBuffers += t.fewBuffers;
            tally_.tilesTested += t.tilesTested;
            tally_.allZero = tally_.allZero && t.allZero;
        }
    });
    return true;
}

namespace {

int gcdInt(int a, int b) { return b == 0 ? a : gcdInt(b, a % b); }

}  // namespace

bool Comparison::run(std::string& err) {
    if (!resolveQuantities(err)) return false;
    out_.quantities.clear();
    for (const Quantity& q : q_) out_.quantities.push_back(q.name);
    taskSide_ = out_.tile > 0 ? out_.tile : 16;
    tilesX_ = (out_.width + taskSide_ - 1) / taskSide_;
    tilesY_ = (out_.height + taskSide_ - 1) / taskSide_;
    P_ = size_t(out_.width) * size_t(out_.height);
    T_ = out_.tile > 0 ? size_t(tilesX_) * size_t(tilesY_) : 0;
    const size_t Q = q_.size();
    p_.assign(Q * P_, kNaNf);
    z_.assign(Q * P_, kNaNf);
    effect_.assign(Q * P_, kNaNf);
    aEst_.assign(Q * P_, kNaNf);
    pixelNonFinite_.assign(P_, 0);
    tileP_.assign(Q * T_, kNaNf);
    tileZ_.assign(Q * T_, kNaNf);
    tileEffect_.assign(Q * T_, kNaNf);
    tileA_.assign(Q * T_, kNaNf);
    se_.assign(Q * P_, kNaNf);
    df_.assign(Q * P_, kNaNf);
    tileSe_.assign(Q * T_, kNaNf);
    tileDf_.assign(Q * T_, kNaNf);
    if (opt_.keepMeans) {
        meanA_.assign(3 * P_, kNaNf);
        meanB_.assign(3 * P_, kNaNf);
    }

    // Blocks of rows: whole tiles, whole chunks of both files (no chunk decoded twice), about
    // 64 MB of decoded buffers per side.
    int align = taskSide_;
    for (StatsBlockSource* s : {a_.src, b_.src}) {
        if (!s) continue;
        const int c = std::max(1, s->chunkRows());
        align = align / gcdInt(align, c) * c;
    }
    int rows = 0;
    for (StatsBlockSource* s : {a_.src, b_.src})
        if (s) rows = std::max(rows, s->blockRows(kStatsPartBuffers));
    rows = std::max(align, (rows + align - 1) / align * align);
    for (int row0 = 0; row0 < out_.height; row0 += rows) {
        const int n = std::min(rows, out_.height - row0);
        if (!processBlock(row0, n, err)) return false;
        if (opt_.progress) opt_.progress(double(row0 + n) / out_.height);
    }
    finish();
    buildMaps();
    buildMeans();
    return true;
}

}  // namespace mcstat::detail
