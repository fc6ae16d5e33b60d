// Jung's 3D filters 3DWTMF, 3DWMF, 3DMF (thesis eq. 5.19-5.21, weights eq. 5.28, the merge of
// eq. 5.24) over the sub-buffers of a k x l window of pixels, and their registry entries
// (filter3d.h).
#include "mcstat/filters/window/filter3d.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

#include "mcstat/core/color_space.h"
#include "mcstat/exr-deep/stats_file.h"  // kMaxBuffers, for the overflow bound below
#include "mcstat/filters/window/detail/window_sort.h"
#include "mcstat/filters/window/window_kernel.h"

namespace mcstat {

using detail::normaliseWeights;
using detail::sortRanked;

// ---- 3D filters ---------------------------------------------------------------------------------

PixelBuffers FixedBufferGrid::at(int x, int y) const {
    const size_t p = size_t(y) * size_t(width) + size_t(x);
    return {bufferMean + p * size_t(M) * 3, bufferCount + p * size_t(M), M};
}

BufferView FixedBufferGrid::view() const {
    return {width, height, this, [](const void* ctx, int x, int y) {
                return static_cast<const FixedBufferGrid*>(ctx)->at(x, y);
            }};
}

namespace {

/// Number of rankings a pixel keeps: one by luminance, or one per channel.
int rankings(const SpatialParams& p) { return p.mode == EstimatorMode::Luminance ? 1 : 3; }

/// A rank key as an unsigned integer in the same order (as IEEE numbers: -0 equal to +0; keys are
/// never NaN), so that the merge compares integers, which compile to selects, not branches.
inline uint64_t orderedBits(double key) {
    key += 0.0;  // -0 -> +0
    uint64_t u;
    std::memcpy(&u, &key, sizeof u);
    return u ^ ((uint64_t(0) - (u >> 63)) | (uint64_t(1) << 63));  // negative: ~u, else set sign
}

// BufferVotes::PerSample: the copies of a window, sum over its pixels of w_q * sum_j n_j, fit an
// int64 for every window, centre weight and count the filters accept and up to 500,000 buffers per
// pixel, far more than a file can hold (the per-buffer form is far smaller: sum of w_q * M_q). In a
// validated file a pixel's counts sum to at most 2^24, so the copies stay below
// (10^6 + 255^2 - 1) * 2^24 < 1.8e13 < 2^53: exact as doubles too (spatialTrim, the weights r_i).
constexpr int64_t kMaxVotingBuffers = 500000;
static_assert(kMaxBuffers <= kMaxVotingBuffers);
static_assert((kMaxCentreWeight + int64_t(kMaxSpatialWindow) * kMaxSpatialWindow - 1) *
                      kMaxVotingBuffers * kMaxBufferVoteCount <=
                  std::numeric_limits<int64_t>::max(),
              "3D filter copy counts could overflow int64");

/// Whether a valid buffer's count can vote per sample: an integer in [1, kMaxBufferVoteCount].
inline bool votesPerSample(float n) {
    return n <= float(kMaxBufferVoteCount) && n == std::floor(n);
}

/// Eq. 5.24's per-pixel part, O(m log m): ranks the valid buffers of px (collectValidBuffers' rule;
/// with PerSample votes also an integral count up to kMaxBufferVoteCount) into order[r * px.M + i]
/// (ranking r, i < n) and, for luminance, key[i] (orderedBits); ties by buffer index, so each list
/// is the window's total order restricted to this pixel. Sets votes (RankedList::votes), returns n.
int rankPixel(const PixelBuffers& px, const SpatialParams& p, BufferVotes votes, int32_t* order,
              uint64_t* key, int& excluded, int64_t& voteSum, SpatialScratch& s) {
    int n = collectValidBuffers(px, s.valid, excluded);
    voteSum = n;
    if (votes == BufferVotes::PerSample) {
        voteSum = 0;
        int kept = 0;
        for (int i = 0; i < n; ++i) {
            const int j = s.valid[size_t(i)];
            if (!votesPerSample(px.count[j])) {
                ++excluded;
                continue;
            }
            voteSum += int64_t(px.count[j]);
            s.valid[size_t(kept++)] = j;
        }
        n = kept;
    }
    s.ranked.resize(size_t(n));
    for (int r = 0; r < rankings(p); ++r) {
        for (int i = 0; i < n; ++i) {
            const int j = s.valid[size_t(i)];
            const float* v = px.mean + 3 * size_t(j);
            // the keys of weightedTrimmedMean, computed the same way
            s.ranked[size_t(i)] = {
                p.mode == EstimatorMode::Luminance ? luminance(p.luma, v) : double(v[r]), j};
        }
        sortRanked(s);
        int32_t* o = order + size_t(r) * size_t(px.M);
        for (int i = 0; i < n; ++i) {
            o[i] = s.ranked[size_t(i)].second;
            if (key) key[i] = orderedBits(s.ranked[size_t(i)].first);
        }
    }
    return n;
}

/// Key of element i of list L in ranking r (the channel r per channel, the luminance otherwise).
template <bool kLum>
inline uint64_t listKey(const RankedList& L, int r, int i) {
    if constexpr (kLum) {
        return L.key[i];
    } else {
        return orderedBits(double(L.mean[3 * size_t(L.order[size_t(r)][i]) + size_t(r)]));
    }
}

/// The merge order of two list heads: ascending key, ties by list (window order). Keys are finite
/// (invalid buffers never enter a list, luma is finite), so every real key is below kEndKey, the
/// key of exhausted lists and padding leaves (whose list ids, >= the number of lists, also lose
/// ties).
constexpr uint64_t kEndKey = ~uint64_t(0);
inline bool mergesBefore(uint64_t ka, int la, uint64_t kb, int lb) {
    return bool(int(ka < kb) | (int(ka == kb) & int(la < lb)));
}

/// Eq. 5.24's window part, O(m n log n): a k-way merge of the window's n sorted lists with a
/// tournament (loser) tree, ceil(log2 n) comparisons per element. The merged order is the total
/// order of sortRanked over the window's elements (lists come in window order, each list is in
/// buffer order within a key), so the copies kept, their weights and the summation order are those
/// of trimmedAverage, bit for bit (kPerSample: over the elements (x_j, n_j, w_q n_j)). Walks only
/// up to duplicated rank hi. Returns the number of elements with a kept copy.
template <bool kLum, bool kPerSample>
int mergeTrimmed(const RankedList* lists, int nl, int r, int64_t lo, int64_t hi, int c0, int c1,
                 SpatialScratch& s, PixelEstimate& out) {
    int leaves = 1;
    while (leaves < nl) leaves *= 2;
    // Node i in [1, leaves) holds the loser of its match, node 0 the overall winner; built from
    // the winners of every subtree, node i's children being 2i and 2i + 1, leaf l at leaves + l.
    s.treeKey.resize(2 * size_t(leaves));
    s.treeList.resize(2 * size_t(leaves));
    s.cursor.assign(size_t(nl), 0);
    uint64_t* tk = s.treeKey.data();
    int* tl = s.treeList.data();
    for (int l = 0; l < leaves; ++l) {
        tk[leaves + l] = l < nl ? listKey<kLum>(lists[l], r, 0) : kEndKey;
        tl[leaves + l] = l < nl ? l : nl + l;
    }
    for (int i = leaves - 1; i >= 1; --i) {  // winners, bottom up
        const int w =
            mergesBefore(tk[2 * i], tl[2 * i], tk[2 * i + 1], tl[2 * i + 1]) ? 2 * i : 2 * i + 1;
        tk[i] = tk[w];
        tl[i] = tl[w];
    }
    const uint64_t winKey = tk[1];
    const int winList = tl[1];
    for (int i = 1; i < leaves; ++i) {  // losers, top down: the children still hold winners
        const int a = 2 * i, b = 2 * i + 1;
        const int lose = tl[a] == tl[i] ? b : a;
        tk[i] = tk[lose];
        tl[i] = tl[lose];
    }
    tk[0] = winKey;
    tl[0] = winList;
    double sum[3] = {0.0, 0.0, 0.0}, wsum = 0.0;
    int kept = 0;
    int64_t pos = 0;  // duplicated rank of the element's first copy
    for (;;) {
        const int l = tl[0];  // < nl: hi <= the number of copies, so no end marker wins
        const RankedList& L = lists[l];
        int& at = s.cursor[size_t(l)];
        size_t j = 0;
        int64_t copies = L.weight;  // w_q, or w_q n_j per sample
        if constexpr (kPerSample) {
            j = size_t(L.order[size_t(r)][at]);
            copies *= int64_t(L.count[j]);
        }
        const int64_t a = std::max(pos, lo), b = std::min(pos + copies, hi);
        pos += copies;
        if (b > a) {
            if constexpr (!kPerSample) j = size_t(L.order[size_t(r)][at]);
            // r_i n_i; per sample every copy is one sample: r_i
            const double w = double(b - a) * (kPerSample ? 1.0 : double(L.count[j]));
            wsum += w;
            for (int c = c0; c < c1; ++c) sum[c] += w * double(L.mean[3 * j + size_t(c)]);
            if (kLum && s.wantWeights) s.weights.push_back({l, int(j), w});
            ++kept;
        }
        if (pos >= hi) break;  // every later copy is trimmed
        // replay list l's next element from its leaf to the root
        uint64_t k = ++at < L.n ? listKey<kLum>(L, r, at) : kEndKey;
        int id = at < L.n ? l : nl + l;
        for (int i = (leaves + l) / 2; i > 0; i /= 2) {
            // the node keeps the loser and the winner goes on, with masks rather than branches:
            // which of the two wins is as unpredictable as the data
            const uint64_t nk = tk[i];
            const int nid = tl[i];
            const bool nodeWins = mergesBefore(nk, nid, k, id);
            const uint64_t km = uint64_t(0) - uint64_t(nodeWins);  // all ones or 0
            const int im = -int(nodeWins);
            tk[i] = (k & km) | (nk & ~km);
            tl[i] = (id & im) | (nid & ~im);
            k = (nk & km) | (k & ~km);
            id = (nid & im) | (id & ~im);
        }
        tk[0] = k;
        tl[0] = id;
    }
    for (int c = c0; c < c1; ++c) out.rgb[size_t(c)] = float(sum[c] / wsum);
    if (kLum && s.wantWeights) normaliseWeights(&s.weights, wsum);
    return kept;
}

/// The merges of one window in every ranking of p.mode.
template <bool kPerSample>
void mergeRankings(const SpatialParams& p, int64_t total, PixelEstimate& out, SpatialScratch& s) {
    const int nl = int(s.lists.size());
    const int64_t c = spatialTrim(p.alpha, total);
    if (p.mode == EstimatorMode::Luminance) {
        out.kept.fill(
            mergeTrimmed<true, kPerSample>(s.lists.data(), nl, 0, c, total - c, 0, 3, s, out));
        return;
    }
    for (int ch = 0; ch < 3; ++ch)
        out.kept[size_t(ch)] = mergeTrimmed<false, kPerSample>(s.lists.data(), nl, ch, c, total - c,
                                                               ch, ch + 1, s, out);
}

/// weightedTrimmedMean over the elements of s.lists (non-empty lists, in window order), each
/// buffer voting as `votes` says.
void mergeWindow(const SpatialParams& p, BufferVotes votes, PixelEstimate& out, SpatialScratch& s) {
    out.rgb = {0.f, 0.f, 0.f};
    out.gini = {0.f, 0.f, 0.f};
    out.kept = {0, 0, 0};
    s.weights.clear();
    if (s.lists.empty()) return;  // no valid element: black
    int64_t total = 0;            // s of eq. 5.6 / 5.19: every copy (bounded: see static_assert)
    for (const RankedList& L : s.lists) total += L.votes * L.weight;
    if (votes == BufferVotes::PerSample)
        mergeRankings<true>(p, total, out, s);
    else
        mergeRankings<false>(p, total, out, s);
}

/// The list of a pixel ranked by rankPixel into order (ranks rankings) and key.
RankedList rankedList(const PixelBuffers& px, int ranks, const int32_t* order, const uint64_t* key,
                      int n, int64_t weight, int64_t votes) {
    RankedList L;
    L.mean = px.mean;
    L.count = px.count;
    for (int r = 0; r < ranks; ++r) L.order[size_t(r)] = order + size_t(r) * size_t(px.M);
    L.key = key;
    L.n = n;
    L.weight = weight;
    L.votes = votes;
    return L;
}

}  // namespace

void filter3DPixel(const BufferView& v, int x, int y, const SpatialParams& p, PixelEstimate& out,
                   SpatialScratch& s) {
    const int rx = p.windowWidth / 2, ry = p.windowHeight / 2;
    const int x0 = std::max(0, x - rx), x1 = std::min(v.width - 1, x + rx);
    const int y0 = std::max(0, y - ry), y1 = std::min(v.height - 1, y + ry);
    const int ranks = rankings(p);
    const bool lum = p.mode == EstimatorMode::Luminance;
    size_t slots = 0;  // the window's buffers, valid or not
    for (int yy = y0; yy <= y1; ++yy)
        for (int xx = x0; xx <= x1; ++xx) slots += size_t(v.at(xx, yy).M);
    s.order.resize(slots * size_t(ranks));
    s.key.resize(lum ? slots : 0);
    s.lists.clear();
    s.source.clear();
    out.excluded = 0;
    size_t begin = 0;
    for (int yy = y0; yy <= y1; ++yy)
        for (int xx = x0; xx <= x1; ++xx) {
            const PixelBuffers px = v.at(xx, yy);  // this pixel's own M
            int32_t* order = s.order.data() + begin * size_t(ranks);
            uint64_t* key = lum ? s.key.data() + begin : nullptr;
            int excluded = 0;
            int64_t votes = 0;
            const int n = rankPixel(px, p, v.votes, order, key, excluded, votes, s);
            out.excluded += excluded;
            begin += size_t(px.M);
            // eq. 5.19 with eq. 5.28: every buffer of the centre pixel carries w_c
            const int64_t w = (xx == x && yy == y) ? p.centreWeight : int64_t(1);
            if (n > 0) s.lists.push_back(rankedList(px, ranks, order, key, n, w, votes));
            if (n > 0 && s.wantWeights) s.source.emplace_back(xx, yy);
        }
    mergeWindow(p, v.votes, out, s);
}

void filter3DImage(const BufferView& v, const SpatialParams& p, float* out) {
    RankedBufferGrid grid;
    grid.reset(v, p, 0, 0, v.width, v.height);
    SpatialScratch s;
    grid.sortRect(0, 0, v.width, v.height, s);
    PixelEstimate e;
    for (int y = 0; y < v.height; ++y)
        for (int x = 0; x < v.width; ++x) {
            grid.filterPixel(x, y, e, s);
            float* o = out + (size_t(y) * size_t(v.width) + size_t(x)) * 3;
            o[0] = e.rgb[0];
            o[1] = e.rgb[1];
            o[2] = e.rgb[2];
        }
}

// ---- RankedBufferGrid ---------------------------------------------------------------------------

void RankedBufferGrid::reset(const BufferView& v, const SpatialParams& p, int x0, int y0, int x1,
                             int y1) {
    view_ = v;
    params_ = p;
    x0_ = x0;
    y0_ = y0;
    width_ = std::max(0, x1 - x0);
    height_ = std::max(0, y1 - y0);
    pixels_.assign(size_t(width_) * size_t(height_), PixelRank{});
    uint64_t begin = 0;
    for (int y = 0; y < height_; ++y)
        for (int x = 0; x < width_; ++x) {
            pixels_[size_t(y) * size_t(width_) + size_t(x)].begin = begin;
            begin += uint64_t(v.at(x0 + x, y0 + y).M);
        }
    // The one extra array of eq. 5.24's scheme: the ranking of every buffer, as large as the
    // buffer means (12 bytes per buffer either way).
    order_.assign(size_t(begin) * size_t(rankings(p)), 0);
    key_.assign(p.mode == EstimatorMode::Luminance ? size_t(begin) : 0, 0);
}

void RankedBufferGrid::sortRect(int xa, int ya, int xb, int yb, SpatialScratch& s) {
    const int ranks = rankings(params_);
    const bool lum = params_.mode == EstimatorMode::Luminance;
    for (int y = ya; y < yb; ++y)
        for (int x = xa; x < xb; ++x) {
            PixelRank& pr = pixels_[size_t(y - y0_) * size_t(width_) + size_t(x - x0_)];
            int excluded = 0;
            pr.n = rankPixel(view_.at(x, y), params_, view_.votes,
                             order_.data() + pr.begin * size_t(ranks),
                             lum ? key_.data() + pr.begin : nullptr, excluded, pr.votes, s);
            pr.excluded = excluded;
        }
}

void RankedBufferGrid::filterPixel(int x, int y, PixelEstimate& out, SpatialScratch& s) const {
    const SpatialParams& p = params_;
    const int rx = p.windowWidth / 2, ry = p.windowHeight / 2;
    const int x0 = std::max(0, x - rx), x1 = std::min(view_.width - 1, x + rx);
    const int y0 = std::max(0, y - ry), y1 = std::min(view_.height - 1, y + ry);
    const int ranks = rankings(p);
    const bool lum = p.mode == EstimatorMode::Luminance;
    s.lists.clear();
    s.source.clear();
    out.excluded = 0;
    for (int yy = y0; yy <= y1; ++yy)
        for (int xx = x0; xx <= x1; ++xx) {
            const PixelRank& pr = pixels_[size_t(yy - y0_) * size_t(width_) + size_t(xx - x0_)];
            out.excluded += pr.excluded;
            if (pr.n == 0) continue;
            const int64_t w = (xx == x && yy == y) ? p.centreWeight : int64_t(1);
            s.lists.push_back(
                rankedList(view_.at(xx, yy), ranks, order_.data() + pr.begin * size_t(ranks),
                           lum ? key_.data() + pr.begin : nullptr, pr.n, w, pr.votes));
            if (s.wantWeights) s.source.emplace_back(xx, yy);
        }
    mergeWindow(p, view_.votes, out, s);
}

namespace {

WindowKernel bindBufferWindow(const ParamValues& values, const std::array<double, 3>& luma) {
    return windowKernel(Neighbourhood::SubBuffers, spatialParams(values, luma));
}

}  // namespace

Operation filter3dmfOperation() {
    return windowOperation("3dmf", "3DMF",
                           "3D median filter 3DMF(M x k x l) of the top statistics file: median of "
                           "every buffer mean in the window, one vote per buffer (eq. 5.21); "
                           "adaptive-M files: one vote per sample",
                           "Jung eq. 5.21", Neighbourhood::SubBuffers,
                           {windowSizeParam(), centreWeightParam("1", true),
                            breakdownParam("0.5", true), windowModeParam()},
                           &bindBufferWindow);
}

Operation filter3dwmfOperation() {
    return windowOperation("3dwmf", "3DWMF",
                           "3D weighted median filter 3DWMF(w, M x k x l): the centre pixel's "
                           "buffers weighted w (eq. 5.20, 5.28); adaptive-M files: one vote per "
                           "sample, w for the centre's",
                           "Jung eq. 5.20, 5.28", Neighbourhood::SubBuffers,
                           {windowSizeParam(), centreWeightParam("3", false),
                            breakdownParam("0.5", true), windowModeParam()},
                           &bindBufferWindow);
}

Operation filter3dwtmfOperation() {
    return windowOperation(
        "3dwtmf", "3DWTMF",
        "3D weighted trimmed mean filter 3DWTMF(alpha, w, M x k x l) (eq. 5.19); "
        "adaptive-M files: ranked and trimmed per sample",
        "Jung eq. 5.19", Neighbourhood::SubBuffers,
        {windowSizeParam(), centreWeightParam("3", false), breakdownParam("0.25", false),
         windowModeParam()},
        &bindBufferWindow);
}

}  // namespace mcstat
