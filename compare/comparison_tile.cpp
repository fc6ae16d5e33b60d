// The tests of one tile's pixels and of the tile (comparison.h): each pixel's quantities tested
// side against side (or against the reference image), their values summed into the tile, then
// the tile tested as a pixel is.
#include "comparison.h"

namespace mcstat::detail {

void Comparison::testTile(int tx, int ty, int row0, Tally& tally) {
    const int W = out_.width;
    const int x0 = tx * taskSide_, x1 = std::min(W, x0 + taskSide_);
    const int y0 = ty * taskSide_, y1 = std::min(out_.height, y0 + taskSide_);
    TileWork w;
    w.tiles = out_.tile > 0;
    // When a side's buffer indices do not line up across pixels (adaptive M, compact files), the
    // tile is summed from its pixels' means and their variances instead (PixelSums), on both
    // sides alike: the two tiles must estimate one quantity (a full side's trimmed tile against a
    // compact side's mean of per-pixel values would differ by the trimming's bias, which a tile's
    // small noise turns into false alarms).
    w.pixB = out_.adaptive;
    w.pixA = w.pixB && !a_.ref;
    // Otherwise tile sums per quantity and buffer: mean values and counts over the tile's pixels
    // (none for a reference side or a side summed per pixel).
    w.Ma = size_t(a_.ref || w.pixA ? 0 : out_.Ma);
    w.Mb = size_t(w.pixB ? 0 : out_.Mb);
    const size_t Q = q_.size();
    w.sumA.assign(Q * w.Ma, 0.0);
    w.cntA.assign(Q * w.Ma, 0.0);
    w.sumB.assign(Q * w.Mb, 0.0);
    w.cntB.assign(Q * w.Mb, 0.0);
    w.refSum.assign(Q, 0.0);
    w.refVarSum.assign(Q, 0.0);
    w.tileBad.assign(Q, 0);
    w.sumsA.resize(w.pixA ? Q : 0);
    w.sumsB.resize(w.pixB ? Q : 0);
    for (int y = y0; y < y1; ++y)
        for (int x = x0; x < x1; ++x) testPixelAt(x, y, row0, w, tally);
    if (!w.tiles) return;
    const size_t t = size_t(ty) * size_t(tilesX_) + size_t(tx);
    testTileSums(t, double(x1 - x0) * double(y1 - y0), w, tally);
}

void Comparison::testPixelAt(int x, int y, int row0, TileWork& w, Tally& tally) {
    const int W = out_.width;
    const size_t local = size_t(y - row0) * size_t(W) + size_t(x);
    const size_t pix = size_t(y) * size_t(W) + size_t(x);
    uint8_t nonFinite = 0;
    bool tested = false;
    if (opt_.keepMeans) {
        rgbMean(a_, local, x, y, &meanA_[pix * 3]);
        rgbMean(b_, local, x, y, &meanB_[pix * 3]);
    }
    for (size_t qi = 0; qi < q_.size(); ++qi) {
        const Quantity& q = q_[qi];
        SideSummary sa, sb;
        sb = sideSummary(b_, q, true, local, w.vb, w.cb);
        double nb = 0.0;
        for (double c : w.cb) nb += c > 0.0 ? c : 0.0;
        if (a_.ref) {
            sa = referenceSummary(q, x, y);
            if (a_.refVar.empty()) referenceNoise(sb, nb);
            if (w.tiles) {
                w.refSum[qi] += sa.estimate;
                w.refVarSum[qi] += sa.variance;
            }
        } else {
            sa = sideSummary(a_, q, false, local, w.va, w.ca);
        }
        if (w.tiles) addToTile(qi, local, sa, sb, nb, w);
        const size_t h = qi * P_ + pix;
        aEst_[h] = float(sa.estimate);
        if (!sa.finite || !sb.finite) {
            // NaN / Inf on one side only: the renderer changed (p = 0); on both: untested.
            const bool one = sa.finite != sb.finite;
            nonFinite = std::max<uint8_t>(nonFinite, one ? 1 : 2);
            p_[h] = one ? 0.f : kNaNf;
            z_[h] = kNaNf;
            effect_[h] = kNaNf;
            if (one) tally.allZero = false;
            continue;
        }
        const TwoSampleResult raw = testPixel(sa, sb, q, x, y, nb);
        const TwoSampleResult r = withoutRounding(sa, sb, raw);
        p_[h] = float(r.p);
        z_[h] = float(r.z);
        effect_[h] = float(r.difference);
        se_[h] = float(raw.se);
        df_[h] = float(raw.df);
        if (std::isnan(r.p)) continue;
        tested = true;
        if (raw.difference != 0.0) tally.allZero = false;
        if (r.se == 0.0 && r.difference == 0.0) ++tally.constantEqual;
    }
    if (nonFinite == 1) ++tally.nonFiniteOneSide;
    if (nonFinite == 2) ++tally.nonFiniteBoth;
    if (nonFinite == 1 || tested) ++tally.pixelsTested;
    if (nonFinite == 0 && !tested) ++tally.fewBuffers;
    pixelNonFinite_[pix] = nonFinite;
}

void Comparison::addToTile(size_t qi, size_t local, const SideSummary& sa, const SideSummary& sb,
                           double nb, TileWork& w) const {
    const Quantity& q = q_[qi];
    if (!sa.finite || !sb.finite) w.tileBad[qi] = 1;
    if (w.pixA) w.sumsA[qi].add(opt_.trimmed ? pixelMean(a_, q, local, w.va, w.ca) : sa, 0.0);
    if (w.pixB) w.sumsB[qi].add(opt_.trimmed ? pixelMean(b_, q, local, w.vb, w.cb) : sb, nb);
    const size_t Ma = w.Ma, Mb = w.Mb;
    for (size_t j = 0; j < Ma; ++j) {
        w.sumA[qi * Ma + j] += w.va[j];
        w.cntA[qi * Ma + j] += w.ca[j];
    }
    for (size_t j = 0; j < Mb; ++j) {
        w.sumB[qi * Mb + j] += w.vb[j];
        w.cntB[qi * Mb + j] += w.cb[j];
    }
}

void Comparison::testTileSums(size_t t, double n, TileWork& w, Tally& tally) {
    const size_t Ma = w.Ma, Mb = w.Mb;
    bool tested = false;
    for (size_t qi = 0; qi < q_.size(); ++qi) {
        const size_t h = qi * T_ + t;
        tileP_[h] = tileZ_[h] = tileEffect_[h] = tileA_[h] = kNaNf;
        if (w.tileBad[qi]) continue;
        // The tile's value in buffer j: the mean over its pixels of their buffer-j values, with the
        // mean count; buffers stay independent, so the tile is tested as a pixel is.
        for (size_t j = 0; j < Ma; ++j) {
            w.sumA[qi * Ma + j] /= n;
            w.cntA[qi * Ma + j] /= n;
        }
        for (size_t j = 0; j < Mb; ++j) {
            w.sumB[qi * Mb + j] /= n;
            w.cntB[qi * Mb + j] /= n;
        }
        w.vb.assign(w.sumB.begin() + long(qi * Mb), w.sumB.begin() + long((qi + 1) * Mb));
        w.cb.assign(w.cntB.begin() + long(qi * Mb), w.cntB.begin() + long((qi + 1) * Mb));
        SideSummary sb = w.pixB ? w.sumsB[qi].tile(n) : summarize(w.vb, w.cb), sa;
        if (w.pixB && sb.df <= 0.0) continue;  // a pixel without a variance: the tile untested
        if (a_.ref) {
            sa = exactSummary(w.refSum[qi] / n);
            if (!a_.refVar.empty()) {
                // The reference's pixels are independent: the tile mean's variance is the sum of
                // theirs over n^2.
                sa.variance = w.refVarSum[qi] / (n * n);
                sa.df = opt_.referenceSpp - 1.0;
            } else {
                double nb = 0.0;
                for (double c : w.cb) nb += c > 0.0 ? c : 0.0;
                referenceNoise(sb, w.pixB ? w.sumsB[qi].samples / n : nb);
            }
        } else if (w.pixA) {
            sa = w.sumsA[qi].tile(n);
            if (sa.df <= 0.0) continue;
        } else {
            w.va.assign(w.sumA.begin() + long(qi * Ma), w.sumA.begin() + long((qi + 1) * Ma));
            w.ca.assign(w.cntA.begin() + long(qi * Ma), w.cntA.begin() + long((qi + 1) * Ma));
            sa = summarize(w.va, w.ca);
        }
        const TwoSampleResult raw = welchTest(sa, sb, margin(sa.estimate, sb.estimate), opt_.test);
        const TwoSampleResult r = withoutRounding(sa, sb, raw);
        tileSe_[h] = float(raw.se);
        tileDf_[h] = float(raw.df);
        tileP_[h] = float(r.p);
        tileZ_[h] = float(r.z);
        tileEffect_[h] = float(r.difference);
        tileA_[h] = float(sa.estimate);
        if (!std::isnan(r.p)) tested = true;
    }
    if (tested) ++tally.tilesTested;
}

}  // namespace mcstat::detail
