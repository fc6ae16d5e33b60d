#include "film.h"

#include <algorithm>
#include <limits>

namespace mcstat::render {

PixelAccumulator::PixelAccumulator(int M)
    : M_(M), bufSum_(size_t(M) * 3, 0.0), bufCount_(size_t(M), 0) {}

void PixelAccumulator::reset(int M) {
    bufSum_.resize(size_t(M) * 3);
    bufCount_.resize(size_t(M));
    M_ = M;
    reset();
}

void PixelAccumulator::reset() {
    std::fill(bufSum_.begin(), bufSum_.end(), 0.0);
    std::fill(bufCount_.begin(), bufCount_.end(), 0);
    n_ = 0;
    hits_ = 0;
    luma_ = RunningVariance();
    for (int c = 0; c < 3; ++c) mean_[c] = m2_[c] = sum_[c] = 0;
    normalSum_ = positionSum_ = albedoSum_ = Vec3();
    depthSum_ = 0;
}

bool PixelAccumulator::add(int64_t index, const PathSample& s) {
    if (!isFinite(s.L)) return false;
    addMoments(size_t(index % M_), s);
    return true;
}

bool PixelAccumulator::addLeastCount(const PathSample& s) {
    if (!isFinite(s.L)) return false;
    // min_element returns the first minimum: the lowest index on ties.
    addMoments(size_t(std::min_element(bufCount_.begin(), bufCount_.end()) - bufCount_.begin()), s);
    return true;
}

void PixelAccumulator::grow(int M) {
    if (M <= M_) return;
    bufSum_.resize(size_t(M) * 3, 0.0);
    bufCount_.resize(size_t(M), 0);
    M_ = M;
}

int64_t PixelAccumulator::maxBufferCount() const {
    return *std::max_element(bufCount_.begin(), bufCount_.end());
}

void PixelAccumulator::addMoments(size_t j, const PathSample& s) {
    ++bufCount_[j];
    ++n_;
    for (int c = 0; c < 3; ++c) {
        const double x = s.L[c];
        bufSum_[j * 3 + size_t(c)] += x;
        sum_[c] += x;
        // Welford: numerically stable even when the mean dwarfs the spread.
        const double delta = x - mean_[c];
        mean_[c] += delta / double(n_);
        m2_[c] += delta * (x - mean_[c]);
    }
    if (s.hit) {
        ++hits_;
        normalSum_ += s.normal;
        positionSum_ += s.position;
        albedoSum_ += s.albedo;
        depthSum_ += s.depth;
    }
    luma_.add(sigmaLuma(s.L));
}

void PixelAccumulator::store(StatsImage& img, size_t p) const {
    const size_t M = size_t(M_), k0 = img.bufferBegin(p);
    for (size_t j = 0; j < M; ++j) {
        const int64_t cnt = bufCount_[j];
        img.bufferCount[k0 + j] = float(cnt);
        for (size_t c = 0; c < 3; ++c)
            img.bufferMean[(k0 + j) * 3 + c] =
                cnt > 0 ? float(bufSum_[j * 3 + c] / double(cnt)) : 0.0f;
    }
    img.count[p] = float(n_);
    for (size_t c = 0; c < 3; ++c) {
        img.beauty[p * 3 + c] = n_ > 0 ? float(sum_[c] / double(n_)) : 0.0f;
        img.mean[p * 3 + c] = float(mean_[c]);
        img.variance[p * 3 + c] = n_ > 1 ? float(m2_[c] / double(n_ - 1)) : 0.0f;
    }
    const double invHits = hits_ > 0 ? 1.0 / double(hits_) : 0.0;
    const double invN = n_ > 0 ? 1.0 / double(n_) : 0.0;
    for (size_t c = 0; c < 3; ++c) {
        const int ci = int(c);
        img.normal[p * 3 + c] = float(normalSum_[ci] * invHits);
        img.position[p * 3 + c] = float(positionSum_[ci] * invHits);
        img.albedo[p * 3 + c] = float(albedoSum_[ci] * invN);
    }
    img.depth[p] = hits_ > 0 ? float(depthSum_ * invHits) : std::numeric_limits<float>::infinity();
    img.coverage[p] = float(double(hits_) * invN);
}

bool MeanAccumulator::add(const Vec3& L) {
    if (!isFinite(L)) return false;
    for (int c = 0; c < 3; ++c) sum[c] += L[c];
    ++n;
    return true;
}

void MeanAccumulator::store(float* rgb) const {
    for (int c = 0; c < 3; ++c) rgb[c] = n > 0 ? float(sum[c] / double(n)) : 0.0f;
}

}  // namespace mcstat::render
