// The ZIP chunk codec on its own (exr-deep/deflate_codec.h): every chunk is libdeflate's level-4
// stream, byte for byte (ISA-L's, which it replaced, varied between processes); every size
// round-trips through ZipDecoder; an encoder's output is a function of the chunk alone, whatever
// it compressed before.
#include <gtest/gtest.h>
#include <libdeflate.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <memory>
#include <random>
#include <vector>

#include "mcstat/exr-deep/codec/detail/deflate_codec.h"

namespace mcstat::detail {
namespace {

/// A deep chunk's sample-count table: `width` cumulative counts of `per` samples (int32, little
/// endian), the chunk that differed between processes.
std::vector<uint8_t> countTable(int width, int32_t per) {
    std::vector<uint8_t> v(size_t(width) * 4);
    for (int x = 0; x < width; ++x) {
        const int32_t cum = per * (x + 1);
        std::memcpy(&v[size_t(x) * 4], &cum, 4);
    }
    return v;
}

/// Floats of a noisy image: high bytes alike, low mantissa bytes noise.
std::vector<uint8_t> noisyFloats(size_t bytes, uint32_t seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<float> d(0.5f, 0.05f);
    std::vector<uint8_t> v(bytes);
    for (size_t i = 0; i + 4 <= bytes; i += 4) {
        const float f = d(rng);
        std::memcpy(&v[i], &f, 4);
    }
    for (size_t i = bytes & ~size_t(3); i < bytes; ++i) v[i] = uint8_t(rng());
    return v;
}

std::vector<uint8_t> encode(ZipEncoder& z, const std::vector<uint8_t>& in) {
    std::vector<uint8_t> out(in.size());
    const size_t got = z.apply(in.data(), in.size(), out.data(), out.size());
    out.resize(got);
    return out;
}

/// libdeflate's level 4 over the split and predicted bytes, in at most n - 1 bytes (empty when
/// it does not fit: the chunk is stored).
std::vector<uint8_t> libdeflateLevel4(const std::vector<uint8_t>& in) {
    std::vector<uint8_t> pred(in.size()), out(in.size());
    splitAndPredictZip(in.data(), pred.data(), in.size());
    std::unique_ptr<libdeflate_compressor, void (*)(libdeflate_compressor*)> c(
        libdeflate_alloc_compressor(4), libdeflate_free_compressor);
    const size_t got = in.size() < 2 ? 0
                                     : libdeflate_zlib_compress(c.get(), pred.data(), in.size(),
                                                                out.data(), in.size() - 1);
    out.resize(got);
    return out;
}

TEST(ZipCodec, EveryChunkIsLibdeflatesLevel4StreamByteForByte) {
    ZipEncoder z;
    const std::vector<std::vector<uint8_t>> chunks = {
        countTable(30, 80),  // 120 bytes, the table that differed
        countTable(1, 7),
        countTable(1023, 3),  // 4,092 bytes
        noisyFloats(1, 1),
        noisyFloats(2, 2),
        noisyFloats(1000, 3),
        noisyFloats(4095, 4),
        noisyFloats(4096, 5),
        noisyFloats(37580, 6),  // the size of a chunk whose ISA-L stream
                                // differed between processes
        noisyFloats(250000, 7),
        countTable(2000, 80),
    };
    for (const auto& c : chunks) {
        SCOPED_TRACE(c.size());
        EXPECT_EQ(encode(z, c), libdeflateLevel4(c));
    }
    // The count table shrinks; one byte cannot.
    EXPECT_FALSE(encode(z, chunks[0]).empty());
    EXPECT_TRUE(encode(z, chunks[3]).empty());
}

TEST(ZipCodec, EverySizeRoundTripsThroughTheDecoder) {
    ZipEncoder z;
    ZipDecoder d;
    for (size_t n : {size_t(120), size_t(4095), size_t(4096), size_t(4097), size_t(250000)}) {
        SCOPED_TRACE(n);
        std::vector<uint8_t> in = noisyFloats(n, uint32_t(n));
        for (size_t i = 0; i < n / 2; ++i) in[i] = uint8_t(i % 7);  // something to match
        const std::vector<uint8_t> packed = encode(z, in);
        ASSERT_FALSE(packed.empty());
        std::vector<uint8_t> back(n);
        ASSERT_TRUE(d.undo(packed.data(), packed.size(), back.data(), n)) << d.problem();
        EXPECT_EQ(back, in);
    }
}

TEST(ZipCodec, AnEncodersOutputDependsOnTheChunkAloneWhateverItCompressedBefore) {
    std::vector<std::vector<uint8_t>> chunks;
    for (uint32_t s = 0; s < 6; ++s) chunks.push_back(noisyFloats(size_t(300) << (2 * s), s));
    chunks.push_back(countTable(30, 80));
    chunks.push_back(countTable(2000, 80));
    std::vector<std::vector<uint8_t>> fresh;
    for (const auto& c : chunks) {
        ZipEncoder z;
        fresh.push_back(encode(z, c));
    }
    ZipEncoder reused;  // the chunks in both orders, twice
    for (int pass = 0; pass < 4; ++pass)
        for (size_t k = 0; k < chunks.size(); ++k) {
            const size_t i = pass % 2 == 0 ? k : chunks.size() - 1 - k;
            EXPECT_EQ(encode(reused, chunks[i]), fresh[i]) << "chunk " << i << ", pass " << pass;
        }
}

}  // namespace
}  // namespace mcstat::detail
