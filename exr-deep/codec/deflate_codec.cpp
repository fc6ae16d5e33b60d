#include "mcstat/exr-deep/codec/detail/deflate_codec.h"

#include <fmt/format.h>
#include <libdeflate.h>

#include <algorithm>
#include <climits>
#include <cstring>
#include <new>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace mcstat::detail {

void undoZipPredictor(uint8_t* p, size_t n) {
    if (n < 2) return;
    size_t i = 1;
    uint8_t prev = p[0];
#if defined(__SSE2__)
    // Sixteen bytes at a time: the prefix sums of the block by shifted adds, then the running
    // value before the block (`carry`, in every lane) added; the carry chain is one add per block.
    const __m128i bias = _mm_set1_epi8(char(-128));  // + (-128) mod 256: the stored + 128 undone
    __m128i carry = _mm_set1_epi8(char(prev));
    for (; n - i >= 16; i += 16) {
        __m128i d = _mm_add_epi8(_mm_loadu_si128(reinterpret_cast<const __m128i*>(p + i)), bias);
        d = _mm_add_epi8(d, _mm_slli_si128(d, 1));
        d = _mm_add_epi8(d, _mm_slli_si128(d, 2));
        d = _mm_add_epi8(d, _mm_slli_si128(d, 4));
        d = _mm_add_epi8(d, _mm_slli_si128(d, 8));
        // Byte 15 (the block's sum) in every lane: bytes doubled, word 7 to the high words, then
        // dword 3 everywhere.
        const __m128i sum =
            _mm_shuffle_epi32(_mm_shufflehi_epi16(_mm_unpackhi_epi8(d, d), 0xFF), 0xFF);
        _mm_storeu_si128(reinterpret_cast<__m128i*>(p + i), _mm_add_epi8(d, carry));
        carry = _mm_add_epi8(carry, sum);
    }
    prev = uint8_t(_mm_cvtsi128_si32(carry));
#endif
    for (; i < n; ++i) {
        prev = uint8_t(prev + p[i] - 128);
        p[i] = prev;
    }
}

void interleaveZipHalves(const uint8_t* in, uint8_t* out, size_t n) {
    const size_t pairs = n / 2;
    const uint8_t* a = in;
    const uint8_t* b = in + (n + 1) / 2;
    size_t k = 0;
#if defined(__SSE2__)
    for (; pairs - k >= 16; k += 16) {
        const __m128i va = _mm_loadu_si128(reinterpret_cast<const __m128i*>(a + k));
        const __m128i vb = _mm_loadu_si128(reinterpret_cast<const __m128i*>(b + k));
        _mm_storeu_si128(reinterpret_cast<__m128i*>(out + 2 * k), _mm_unpacklo_epi8(va, vb));
        _mm_storeu_si128(reinterpret_cast<__m128i*>(out + 2 * k + 16), _mm_unpackhi_epi8(va, vb));
    }
#endif
    for (; k < pairs; ++k) {
        out[2 * k] = a[k];
        out[2 * k + 1] = b[k];
    }
    if (n % 2 != 0) out[n - 1] = a[pairs];
}

void splitAndPredictZip(const uint8_t* in, uint8_t* out, size_t n) {
    if (n == 0) return;
    const size_t pairs = n / 2;
    uint8_t* a = out;
    uint8_t* b = out + (n + 1) / 2;
    size_t k = 0;
#if defined(__SSE2__)
    const __m128i low = _mm_set1_epi16(0x00ff);
    for (; pairs - k >= 16; k += 16) {
        const __m128i v0 = _mm_loadu_si128(reinterpret_cast<const __m128i*>(in + 2 * k));
        const __m128i v1 = _mm_loadu_si128(reinterpret_cast<const __m128i*>(in + 2 * k + 16));
        _mm_storeu_si128(reinterpret_cast<__m128i*>(a + k),
                         _mm_packus_epi16(_mm_and_si128(v0, low), _mm_and_si128(v1, low)));
        _mm_storeu_si128(reinterpret_cast<__m128i*>(b + k),
                         _mm_packus_epi16(_mm_srli_epi16(v0, 8), _mm_srli_epi16(v1, 8)));
    }
#endif
    for (; k < pairs; ++k) {
        a[k] = in[2 * k];
        b[k] = in[2 * k + 1];
    }
    if (n % 2 != 0) a[pairs] = in[n - 1];
    // Predictor, from the end so that each byte's predecessor is still the original.
    size_t i = n;  // bytes [i, n) are done
#if defined(__SSE2__)
    const __m128i bias = _mm_set1_epi8(char(-128));  // + 128 and - 128 are the same modulo 256
    for (; i >= 17; i -= 16) {
        const __m128i cur = _mm_loadu_si128(reinterpret_cast<const __m128i*>(out + i - 16));
        const __m128i prev = _mm_loadu_si128(reinterpret_cast<const __m128i*>(out + i - 17));
        _mm_storeu_si128(reinterpret_cast<__m128i*>(out + i - 16),
                         _mm_add_epi8(_mm_sub_epi8(cur, prev), bias));
    }
#endif
    for (; i > 1; --i) out[i - 1] = uint8_t(out[i - 1] - out[i - 2] + 128);
}

void ZipEncoder::FreeCompressor::operator()(libdeflate_compressor* c) const {
    libdeflate_free_compressor(c);
}

ZipEncoder::ZipEncoder() : c_(libdeflate_alloc_compressor(4)) {
    if (c_ == nullptr) throw std::bad_alloc();
}

ZipEncoder::~ZipEncoder() = default;

size_t ZipEncoder::apply(const void* in, size_t n, void* out, size_t capacity) {
    if (n < 2) return 0;  // a zlib stream has 6 bytes of header and checksum: stored
    if (scratchSize_ < n) {
        scratch_.reset();
        scratchSize_ = 0;
        scratch_.reset(new uint8_t[n]);
        scratchSize_ = n;
    }
    splitAndPredictZip(static_cast<const uint8_t*>(in), scratch_.get(), n);
    // One call over the whole chunk: the zlib header, the deflate stream, the Adler-32. Room for
    // one byte less than the input: a result that does not fit gives 0 and the chunk is stored,
    // since a chunk as large as its input would read as stored.
    return libdeflate_zlib_compress(c_.get(), scratch_.get(), n, out, std::min(capacity, n - 1));
}

exr_result_t zipCompressChunk(exr_encode_pipeline_t* encode) {
    if (encode == nullptr || encode->encoding_user_data == nullptr ||
        (encode->chunk.type != EXR_STORAGE_SCANLINE && encode->chunk.type != EXR_STORAGE_TILED) ||
        encode->alloc_fn == nullptr)
        return EXR_ERR_INVALID_ARGUMENT;
    auto& zip = *static_cast<ZipEncoder*>(encode->encoding_user_data);
    const size_t n = size_t(encode->packed_bytes);
    if (encode->compressed_buffer == nullptr || encode->compressed_alloc_size < n) {
        encode->compressed_buffer = encode->alloc_fn(EXR_TRANSCODE_BUFFER_COMPRESSED, n);
        encode->compressed_alloc_size = encode->compressed_buffer != nullptr ? n : 0;
        if (encode->compressed_buffer == nullptr) return EXR_ERR_OUT_OF_MEMORY;
    }
    try {
        const size_t got = zip.apply(encode->packed_buffer, n, encode->compressed_buffer,
                                     encode->compressed_alloc_size);
        if (got == 0) {
            std::memcpy(encode->compressed_buffer, encode->packed_buffer, n);
            encode->compressed_bytes = n;
        } else {
            encode->compressed_bytes = got;
        }
        return EXR_ERR_SUCCESS;
    } catch (const std::bad_alloc&) {
        return EXR_ERR_OUT_OF_MEMORY;
    }
}

ZipDecoder::ZipDecoder() : d_(libdeflate_alloc_decompressor()) {
    if (d_ == nullptr) throw std::bad_alloc();
}

ZipDecoder::~ZipDecoder() { libdeflate_free_decompressor(d_); }

bool ZipDecoder::undo(const void* packed, size_t packedSize, void* out, size_t outSize) {
    problem_.clear();
    if (scratchSize_ < outSize) {
        scratch_.reset();
        scratchSize_ = 0;
        scratch_.reset(new uint8_t[outSize]);
        scratchSize_ = outSize;
    }
    size_t used = 0, got = 0;
    const libdeflate_result r =
        libdeflate_zlib_decompress_ex(d_, packed, packedSize, scratch_.get(), outSize, &used, &got);
    if (r == LIBDEFLATE_INSUFFICIENT_SPACE) {
        problem_ = fmt::format("its {} bytes of ZIP data inflate to more than {} bytes", packedSize,
                               outSize);
        return false;
    }
    if (r != LIBDEFLATE_SUCCESS) {
        problem_ = fmt::format("its {} bytes of ZIP data do not inflate (corrupt zlib stream)",
                               packedSize);
        return false;
    }
    if (got != outSize) {
        problem_ = fmt::format("its {} bytes of ZIP data inflate to {} bytes, expected {}",
                               packedSize, got, outSize);
        return false;
    }
    undoZipPredictor(scratch_.get(), outSize);
    interleaveZipHalves(scratch_.get(), static_cast<uint8_t*>(out), outSize);
    return true;
}

exr_result_t zipDecompressChunk(exr_decode_pipeline_t* decode) {
    if (decode == nullptr || decode->decoding_user_data == nullptr ||
        (decode->chunk.type != EXR_STORAGE_SCANLINE && decode->chunk.type != EXR_STORAGE_TILED))
        return EXR_ERR_INVALID_ARGUMENT;
    auto& zip = *static_cast<ZipDecoder*>(decode->decoding_user_data);
    const uint64_t packed = decode->chunk.packed_size, unpacked = decode->chunk.unpacked_size;
    if (packed == unpacked) {  // stored as it is (OpenEXR's writers do so when ZIP would grow it)
        if (unpacked > 0 && decode->unpacked_buffer != decode->packed_buffer)
            std::memcpy(decode->unpacked_buffer, decode->packed_buffer, size_t(unpacked));
        return EXR_ERR_SUCCESS;
    }
    if (decode->packed_buffer == nullptr || decode->unpacked_buffer == nullptr)
        return EXR_ERR_INVALID_ARGUMENT;
    try {
        return zip.undo(decode->packed_buffer, size_t(packed), decode->unpacked_buffer,
                        size_t(unpacked))
                   ? EXR_ERR_SUCCESS
                   : EXR_ERR_CORRUPT_CHUNK;
    } catch (const std::bad_alloc&) {
        return EXR_ERR_OUT_OF_MEMORY;
    }
}

}  // namespace mcstat::detail
