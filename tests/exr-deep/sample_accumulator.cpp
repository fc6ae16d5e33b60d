#include "sample_accumulator.h"

#include <cmath>
#include <limits>
#include <stdexcept>

namespace mcstat::test {

namespace {
/// Uniform double in [0, 1) from 53 random bits (independent of the standard library's
/// distribution implementations).
double uniform(std::mt19937_64& rng) { return double(rng() >> 11) * 0x1.0p-53; }
}  // namespace

Sample makeSample(uint64_t seed, int pixel, int index) {
    std::mt19937_64 rng(seed * 0x9E3779B97F4A7C15ull ^ (uint64_t(pixel) << 20) ^ uint64_t(index));
    Sample s;
    const double firefly = uniform(rng) < 0.02 ? 100.0 : 1.0;
    for (double& c : s.rgb) c = 4.0 * uniform(rng) * firefly;
    s.hit = uniform(rng) < 0.75;
    if (s.hit) {
        double len = 0;
        do {
            for (double& c : s.normal) c = 2.0 * uniform(rng) - 1.0;
            len = std::sqrt(s.normal[0] * s.normal[0] + s.normal[1] * s.normal[1] +
                            s.normal[2] * s.normal[2]);
        } while (len < 1e-3 || len > 1.0);
        for (double& c : s.normal) c /= len;
        for (double& c : s.position) c = 20.0 * uniform(rng) - 10.0;
        for (double& c : s.albedo) c = uniform(rng);
        s.depth = 1.0 + 99.0 * uniform(rng);
    }
    return s;
}

SampleAccumulator::SampleAccumulator(int width, int height, int M, int originX, int originY)
    : width_(width), height_(height), M_(M), originX_(originX), originY_(originY) {
    const size_t n = size_t(width) * size_t(height);
    pixels_.resize(n);
    bufSum_.assign(n * size_t(M) * 3, 0.0);
    bufN_.assign(n * size_t(M), 0);
}

void SampleAccumulator::add(int x, int y, const Sample& s, int buffer) {
    if (x < 0 || y < 0 || x >= width_ || y >= height_ || buffer < 0 || buffer >= M_)
        throw std::out_of_range("SampleAccumulator::add");
    const size_t p = size_t(y) * size_t(width_) + size_t(x);
    Pixel& px = pixels_[p];
    ++px.n;
    for (int c = 0; c < 3; ++c) {  // Welford
        const double d = s.rgb[c] - px.mean[c];
        px.mean[c] += d / double(px.n);
        px.m2[c] += d * (s.rgb[c] - px.mean[c]);
    }
    const size_t k = p * size_t(M_) + size_t(buffer);
    ++bufN_[k];
    for (int c = 0; c < 3; ++c) bufSum_[k * 3 + c] += s.rgb[c];
    for (int c = 0; c < 3; ++c) px.sumAlbedo[c] += s.hit ? s.albedo[c] : 0.0;
    if (s.hit) {
        ++px.hits;
        for (int c = 0; c < 3; ++c) {
            px.sumN[c] += s.normal[c];
            px.sumP[c] += s.position[c];
        }
        px.sumZ += s.depth;
    }
}

void SampleAccumulator::addRoundRobin(int x, int y, const Sample& s) {
    const Pixel& px = pixels_.at(size_t(y) * size_t(width_) + size_t(x));
    add(x, y, s, int(px.n % M_));
}

StatsImage SampleAccumulator::finish(const StatsHeader& base) const {
    StatsImage img;
    img.header = base;
    img.header.width = width_;
    img.header.height = height_;
    img.header.M = M_;
    img.header.originX = originX_;
    img.header.originY = originY_;
    std::string err;
    if (!img.allocate(err)) throw std::runtime_error(err);
    const size_t m = size_t(M_);
    for (size_t p = 0; p < pixels_.size(); ++p) {
        const Pixel& px = pixels_[p];
        img.count[p] = float(px.n);
        for (size_t j = 0; j < m; ++j) {
            const size_t k = p * m + j;
            img.bufferCount[k] = float(bufN_[k]);
            for (size_t c = 0; c < 3; ++c)
                img.bufferMean[k * 3 + c] =
                    bufN_[k] ? float(bufSum_[k * 3 + c] / double(bufN_[k])) : 0.f;
        }
        for (size_t c = 0; c < 3; ++c) {
            const size_t i = p * 3 + c;
            img.mean[i] = float(px.mean[c]);
            img.beauty[i] = float(px.mean[c]);
            img.variance[i] = px.n > 1 ? float(px.m2[c] / double(px.n - 1)) : 0.f;
            img.albedo[i] = px.n ? float(px.sumAlbedo[c] / double(px.n)) : 0.f;
            img.normal[i] = px.hits ? float(px.sumN[c] / double(px.hits)) : 0.f;
            img.position[i] = px.hits ? float(px.sumP[c] / double(px.hits)) : 0.f;
        }
        img.depth[p] =
            px.hits ? float(px.sumZ / double(px.hits)) : std::numeric_limits<float>::infinity();
        img.coverage[p] = px.n ? float(double(px.hits) / double(px.n)) : 0.f;
    }
    return img;
}

}  // namespace mcstat::test
