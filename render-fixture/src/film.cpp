#include "film.h"

#include <algorithm>
#include <limits>

namespace mcstat::render {

bool PixelMoments::add(const PathSample& s) {
    if (!isFinite(s.L)) return false;
    ++n_;
    for (int c = 0; c < 3; ++c) {
        const double x = s.L[c];
        sum_[c] += x;
        rgb_[c].add(x);
    }
    if (s.hit) {
        ++hits_;
        normalSum_ += s.normal;
        positionSum_ += s.position;
        albedoSum_ += s.albedo;
        depthSum_ += s.depth;
    }
    luma_.add(sigmaLuma(s.L));
    return true;
}

void PixelMoments::store(StatsImage& img, size_t p) const {
    img.count[p] = float(n_);
    for (size_t c = 0; c < 3; ++c) {
        img.beauty[p * 3 + c] = n_ > 0 ? float(sum_[c] / double(n_)) : 0.0f;
        img.mean[p * 3 + c] = float(rgb_[c].mean);
        img.variance[p * 3 + c] = float(rgb_[c].variance());
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

void storeBuffer(StatsImage& img, size_t k, const double sum[3], int64_t count) {
    img.bufferCount[k] = float(count);
    for (size_t c = 0; c < 3; ++c)
        img.bufferMean[k * 3 + c] = count > 0 ? float(sum[c] / double(count)) : 0.0f;
}

void fixtureAovValues(const PathSample& s, double out[kFixtureAovFloats]) {
    out[0] = s.hit ? 1.0 : 0.0;
    for (int i = 0; i < kLightPathAovs; ++i)
        for (int c = 0; c < 3; ++c) out[1 + 3 * i + c] = s.lightPath[i][c];
}

PixelAccumulator::PixelAccumulator(int M, bool aovs)
    : M_(M), buffers_(size_t(M)), aovSums_(aovs ? size_t(M) * kFixtureAovFloats : 0) {}

void PixelAccumulator::reset(int M) {
    buffers_.resize(size_t(M));
    if (!aovSums_.empty()) aovSums_.resize(size_t(M) * kFixtureAovFloats);
    M_ = M;
    reset();
}

void PixelAccumulator::reset() {
    std::fill(buffers_.begin(), buffers_.end(), BufferSum());
    std::fill(aovSums_.begin(), aovSums_.end(), 0.0);
    moments_ = PixelMoments();
}

bool PixelAccumulator::add(int64_t index, const PathSample& s) {
    if (!moments_.add(s)) return false;  // a sample dropped from the beauty: from every AOV too
    const size_t j = size_t(index % M_);
    buffers_[j].add(s.L);
    if (!aovSums_.empty()) {
        double v[kFixtureAovFloats];
        fixtureAovValues(s, v);
        double* sum = &aovSums_[j * kFixtureAovFloats];
        for (int a = 0; a < kFixtureAovFloats; ++a) sum[a] += v[a];
    }
    return true;
}

void PixelAccumulator::store(StatsImage& img, size_t p) const {
    const size_t k0 = img.bufferBegin(p);
    for (size_t j = 0; j < size_t(M_); ++j) {
        const int64_t n = buffers_[j].count;
        storeBuffer(img, k0 + j, buffers_[j].sum, n);
        if (aovSums_.empty()) continue;
        float* out = &img.aov[(k0 + j) * kFixtureAovFloats];
        for (size_t a = 0; a < size_t(kFixtureAovFloats); ++a)
            out[a] = n > 0 ? float(aovSums_[j * kFixtureAovFloats + a] / double(n)) : 0.0f;
    }
    moments_.store(img, p);
}

bool GrowingPixel::add(const PathSample& s) {
    if (!moments_.add(s)) return false;
    if (!buffers_.empty())  // min_element returns the first minimum: the lowest index on ties
        std::min_element(buffers_.begin(), buffers_.end(),
                         [](const BufferSum& a, const BufferSum& b) { return a.count < b.count; })
            ->add(s.L);
    return true;
}

void GrowingPixel::grow(int M) {
    if (M <= buffers()) return;
    buffers_.reserve(size_t(M));  // exactly M: a doubling growth would waste per-pixel memory
    if (buffers_.empty()) {       // buffer 0 so far is the pixel's sum
        BufferSum b0;
        for (int c = 0; c < 3; ++c) b0.sum[c] = moments_.sum(c);
        b0.count = moments_.count();
        buffers_.push_back(b0);
    }
    buffers_.resize(size_t(M));
}

int64_t GrowingPixel::maxBufferCount() const {
    if (buffers_.empty()) return moments_.count();
    int64_t m = 0;
    for (const BufferSum& b : buffers_) m = std::max(m, b.count);
    return m;
}

void GrowingPixel::store(StatsImage& img, size_t p) const {
    const size_t k0 = img.bufferBegin(p);
    if (buffers_.empty()) {
        double sum[3];
        for (int c = 0; c < 3; ++c) sum[c] = moments_.sum(c);
        storeBuffer(img, k0, sum, moments_.count());
    } else {
        for (size_t j = 0; j < buffers_.size(); ++j)
            storeBuffer(img, k0 + j, buffers_[j].sum, buffers_[j].count);
    }
    moments_.store(img, p);
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
