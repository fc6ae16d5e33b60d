// Internal: OpenEXR's ZIP and ZIPS chunk codec with libdeflate (inflate and deflate). A ZIP
// chunk (OpenEXR's "Technical Introduction", Data Compression) is the chunk's bytes split into even
// and odd bytes, each byte stored as its difference to the previous one plus 128, then deflated in
// the zlib format; ZIPS is the same over one scan line. OpenEXR 3.1 does this with zlib; libdeflate
// inflates the same bytes about 2.8x as fast. ZipDecoder undoes it into the chunk's unpacked bytes,
// as the Core API's decode pipeline wants them from its decompress_fn (zipDecompressChunk); the
// pipeline's unpack step then converts those to the caller's layout.
#pragma once

#include <OpenEXR/openexr.h>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

struct libdeflate_compressor;
struct libdeflate_decompressor;

namespace mcstat::detail {

/// Whether `c` is OpenEXR's ZIP codec (16 or 1 scan lines per chunk).
inline bool isZipCompression(exr_compression_t c) {
    return c == EXR_COMPRESSION_ZIP || c == EXR_COMPRESSION_ZIPS;
}

/// One thread's ZIP decoder: a libdeflate decompressor and the scratch buffer it inflates into,
/// both kept from one chunk to the next. Not thread-safe.
class ZipDecoder {
  public:
    ZipDecoder();
    ~ZipDecoder();
    ZipDecoder(const ZipDecoder&) = delete;
    ZipDecoder& operator=(const ZipDecoder&) = delete;

    /// Undoes OpenEXR's ZIP on one chunk: inflates `packed` (zlib format; bytes after the end of
    /// its stream are ignored, as zlib's uncompress does), which must give exactly `outSize`
    /// bytes, then undoes the predictor and interleaves the two halves into `out`. False with
    /// problem() saying why; throws std::bad_alloc when the scratch buffer cannot grow.
    bool undo(const void* packed, size_t packedSize, void* out, size_t outSize);
    /// Why the last undo() failed, in a phrase.
    const std::string& problem() const { return problem_; }

  private:
    libdeflate_decompressor* d_ = nullptr;
    std::unique_ptr<uint8_t[]> scratch_;
    size_t scratchSize_ = 0;
    std::string problem_;
};

/// The decompress_fn of a Core decode pipeline of a ZIP or ZIPS part whose decoding_user_data
/// is a ZipDecoder: what OpenEXR's own does for ZIP with libdeflate instead of zlib. A chunk whose
/// packed size equals its unpacked size is stored as it is (copied when the pipeline did not
/// alias the two buffers); any other chunk is undone with ZipDecoder::undo, and a chunk that
/// does not give exactly its unpacked size is EXR_ERR_CORRUPT_CHUNK (the decoder's problem()
/// says why). An empty packed chunk of a non-empty one is corrupt too.
exr_result_t zipDecompressChunk(exr_decode_pipeline_t* decode);

/// One thread's ZIP encoder: OpenEXR's byte split and predictor, then the zlib format from
/// libdeflate's level 4: 160 MB/s of CPU on a statistics file's sub-buffers against zlib's 150
/// (measured on 103 MB of a 21-seed ingest's part buffers, docs/benchmarks.md); its levels 1 to 6
/// give 151 to 169 MB/s for 58.4 to 58.1 % of the bytes, since float data whose low mantissa
/// bytes are noise leaves a deflater little to find. Its output is a
/// function of its input, so a file holds the same bytes on any thread count. ISA-L's igzip,
/// 5x as fast, is not used: its stream varied from one process to another (1 render in 20 to 200
/// wrote a chunk 1 byte shorter; docs/benchmarks.md). The streams are standard zlib that every
/// ZIP reader inflates. Not thread-safe.
class ZipEncoder {
  public:
    ZipEncoder();
    ~ZipEncoder();
    ZipEncoder(const ZipEncoder&) = delete;
    ZipEncoder& operator=(const ZipEncoder&) = delete;

    /// Applies OpenEXR's ZIP to the `n` bytes at `in`, into `out` (room for `capacity` bytes);
    /// returns the compressed size, or 0 when the result would not be smaller than `n` (the
    /// chunk is then stored as it is, which readers tell by its size). Throws std::bad_alloc
    /// when the scratch buffer cannot grow.
    size_t apply(const void* in, size_t n, void* out, size_t capacity);

  private:
    struct FreeCompressor {
        void operator()(libdeflate_compressor* c) const;
    };
    std::unique_ptr<libdeflate_compressor, FreeCompressor> c_;  ///< level 4
    std::unique_ptr<uint8_t[]> scratch_;
    size_t scratchSize_ = 0;
};

/// The compress_fn of a Core encode pipeline of a ZIP or ZIPS part whose encoding_user_data is a
/// ZipEncoder: the compressed buffer comes from the pipeline's alloc_fn, and a chunk ZIP would
/// not shrink is stored as it is (compressed_bytes == packed_bytes), as OpenEXR's writers do.
exr_result_t zipCompressChunk(exr_encode_pipeline_t* encode);

/// The steps before deflating, on their own (the inverse of interleaveZipHalves and
/// undoZipPredictor): the even bytes of `in` then its odd ones, each byte but the first stored
/// as its difference to the previous one plus 128, modulo 256.
void splitAndPredictZip(const uint8_t* in, uint8_t* out, size_t n);

/// The two steps after inflating, on their own (ZipDecoder::undo runs them; exposed for tests
/// and benchmarks). undoZipPredictor: byte i (i > 0) of `p` becomes the sum of bytes 0..i, each
/// but the first less 128, modulo 256. interleaveZipHalves: out[2k] = in[k] and out[2k + 1] =
/// in[(n + 1) / 2 + k].
void undoZipPredictor(uint8_t* p, size_t n);
void interleaveZipHalves(const uint8_t* in, uint8_t* out, size_t n);

}  // namespace mcstat::detail
