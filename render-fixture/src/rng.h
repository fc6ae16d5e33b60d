// Random numbers: PCG32 (O'Neill 2014) seeded per sample through a SplitMix64 finaliser.
// Seeding every (seed, pixel, sample) triple independently is what makes renders bit-identical for
// any thread count and any scheduling: no generator state is ever shared or carried across samples.
#pragma once

#include <cstdint>

namespace mcstat::render {

/// SplitMix64's output function: a bijective 64-bit mixer with full avalanche, so nearby inputs
/// (consecutive pixels, consecutive samples) give unrelated outputs.
inline uint64_t mix64(uint64_t z) {
    z += 0x9e3779b97f4a7c15ULL;
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
}

class Pcg32 {
  public:
    /// pcg32_srandom_r: `stream` selects one of 2^63 independent sequences.
    Pcg32(uint64_t initState, uint64_t stream) : inc_((stream << 1u) | 1u) {
        next();
        state_ += initState;
        next();
    }

    uint32_t next() {
        const uint64_t old = state_;
        state_ = old * 6364136223846793005ULL + inc_;
        const auto xorshifted = static_cast<uint32_t>(((old >> 18u) ^ old) >> 27u);
        const auto rot = static_cast<uint32_t>(old >> 59u);
        return (xorshifted >> rot) | (xorshifted << ((32u - rot) & 31u));
    }

    /// Uniform in [0, 1): 32 random bits scaled by 2^-32, so never 1.
    double uniform() { return next() * 0x1p-32; }

  private:
    uint64_t state_ = 0;
    uint64_t inc_;
};

/// The generator of sample `sample` of pixel `pixel` in a render seeded with `seed`.
inline Pcg32 sampleRng(uint64_t seed, uint64_t pixel, uint64_t sample) {
    uint64_t h = mix64(seed);
    h = mix64(h ^ pixel);
    h = mix64(h ^ sample);
    return Pcg32(h, mix64(h ^ 0x5851f42d4c957f2dULL));
}

}  // namespace mcstat::render
