// The floor of reading a ZIP statistics file: the time to inflate its chunks' bytes with
// libdeflate on N threads, nothing else (no file reads: the chunks are loaded first), against
// zlib's uncompress on the same threads, and OpenEXR's whole ZIP undo (inflate, predictor,
// interleave) as mcstat's reader runs it.
//   bench_inflate FILE [THREADS=2] [PART...]   (parts by name; default every ZIP/ZIPS part)
// Prints per codec: the best of 5 runs, seconds and MB/s of inflated bytes.
#include <OpenEXR/openexr.h>
#include <libdeflate.h>
#include <zlib.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "mcstat/core/parallel.h"
#include "mcstat/exr-deep/codec/detail/deflate_codec.h"

namespace {

struct Chunk {
    std::vector<uint8_t> packed;
    size_t unpacked;
};

double seconds() {
    return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch())
        .count();
}

}  // namespace

int main(int argc, char** argv) {
    if (argc < 2) {
        std::fprintf(stderr, "usage: bench_inflate FILE [THREADS] [PART...]\n");
        return 2;
    }
    const int threads = argc > 2 ? std::atoi(argv[2]) : 2;
    std::vector<std::string> wanted(argv + std::min(argc, 3), argv + argc);
    exr_context_t ctxt = nullptr;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    if (exr_start_read(&ctxt, argv[1], &init) != EXR_ERR_SUCCESS) return 1;
    int parts = 0;
    exr_get_count(ctxt, &parts);
    std::vector<Chunk> chunks;
    size_t packedBytes = 0, unpackedBytes = 0;
    for (int p = 0; p < parts; ++p) {
        const char* name = nullptr;
        exr_get_name(ctxt, p, &name);
        exr_storage_t storage{};
        exr_compression_t comp{};
        exr_attr_box2i_t dw{};
        int32_t lines = 0;
        exr_get_storage(ctxt, p, &storage);
        exr_get_compression(ctxt, p, &comp);
        exr_get_data_window(ctxt, p, &dw);
        exr_get_scanlines_per_chunk(ctxt, p, &lines);
        if (storage != EXR_STORAGE_SCANLINE || !mcstat::detail::isZipCompression(comp)) continue;
        if (!wanted.empty() &&
            std::find(wanted.begin(), wanted.end(), std::string(name ? name : "")) == wanted.end())
            continue;
        for (int y = dw.min.y; y <= dw.max.y; y += lines) {
            exr_chunk_info_t ci{};
            if (exr_read_scanline_chunk_info(ctxt, p, y, &ci) != EXR_ERR_SUCCESS) return 1;
            Chunk c{std::vector<uint8_t>(ci.packed_size), size_t(ci.unpacked_size)};
            if (exr_read_chunk(ctxt, p, &ci, c.packed.data()) != EXR_ERR_SUCCESS) return 1;
            if (ci.packed_size == ci.unpacked_size) continue;  // stored, nothing to inflate
            packedBytes += c.packed.size();
            unpackedBytes += c.unpacked;
            chunks.push_back(std::move(c));
        }
    }
    exr_finish(&ctxt);
    std::printf("%zu ZIP chunks, %.1f MB packed, %.1f MB inflated, %d threads\n", chunks.size(),
                double(packedBytes) / 1e6, double(unpackedBytes) / 1e6, threads);

    size_t largest = 0;
    for (const Chunk& c : chunks) largest = std::max(largest, c.unpacked);
    const auto run = [&](const char* what, auto&& one) {
        double best = 1e30;
        for (int rep = 0; rep < 5; ++rep) {
            const double t0 = seconds();
            mcstat::parallelFor(0, int64_t(chunks.size()), 1, threads, [&](int64_t b, int64_t e) {
                std::unique_ptr<uint8_t[]> out(new uint8_t[largest]);
                for (int64_t i = b; i < e; ++i) one(chunks[size_t(i)], out.get());
            });
            best = std::min(best, seconds() - t0);
        }
        std::printf("%-34s %7.3f s  %7.0f MB/s\n", what, best, double(unpackedBytes) / best / 1e6);
    };
    run("libdeflate inflate (the floor)", [](const Chunk& c, uint8_t* out) {
        thread_local std::unique_ptr<libdeflate_decompressor, void (*)(libdeflate_decompressor*)> d(
            libdeflate_alloc_decompressor(), &libdeflate_free_decompressor);
        size_t got = 0;
        if (libdeflate_zlib_decompress(d.get(), c.packed.data(), c.packed.size(), out, c.unpacked,
                                       &got) != LIBDEFLATE_SUCCESS)
            std::abort();
    });
    run("zlib uncompress", [](const Chunk& c, uint8_t* out) {
        uLongf got = uLongf(c.unpacked);
        if (uncompress(out, &got, c.packed.data(), uLong(c.packed.size())) != Z_OK) std::abort();
    });
    run("libdeflate + predictor + interleave", [](const Chunk& c, uint8_t* out) {
        thread_local mcstat::detail::ZipDecoder zip;
        if (!zip.undo(c.packed.data(), c.packed.size(), out, c.unpacked)) std::abort();
    });
    return 0;
}
