// Every chunk of a statistics file inside the file, and no chunk claiming more bytes than its
// compression can give (HeaderChecker::checkChunks, header_checker.h).
#include <algorithm>

#include "header_checker.h"

namespace mcstat::detail {

namespace {

/// The most bytes one packed byte of `c` can unpack to, plus slack for the codec's fixed
/// overhead; 0 when no simple bound holds (PIZ's Huffman runs, B44's and DWA's blocks), which
/// leaves those files to the ReadLimits alone. Deflate stores at most 258 bytes of a match in
/// 2 bits and a bit more, about 1032:1; PXR24 deflates 24 of every 32 bits of a float (x 4/3);
/// OpenEXR's RLE codes at most 128 equal bytes in 2 (64:1).
double maxUnpackRatio(exr_compression_t c) {
    switch (c) {
        case EXR_COMPRESSION_NONE:
            return 1.0;
        case EXR_COMPRESSION_RLE:
            return 64.0;
        case EXR_COMPRESSION_ZIPS:
        case EXR_COMPRESSION_ZIP:
            return 1040.0;
        case EXR_COMPRESSION_PXR24:
            return 1040.0 * 4.0 / 3.0;
        default:
            return 0.0;
    }
}

const char* compressionName(exr_compression_t c) {
    static const char* const kNames[] = {"NONE",  "RLE", "ZIPS", "ZIP",  "PIZ",
                                         "PXR24", "B44", "B44A", "DWAA", "DWAB"};
    return c >= 0 && c < EXR_COMPRESSION_LAST_TYPE ? kNames[c] : "unknown";
}

}  // namespace

bool HeaderChecker::checkChunks(uint64_t fileSize) {
    for (int part = 0; part < nparts_; ++part) {
        const std::string pn = printable(partName(part));
        exr_storage_t storage = EXR_STORAGE_LAST_TYPE;
        exr_attr_box2i_t dw{};
        int32_t lines = 0;
        if (exr_get_storage(c_, part, &storage) != EXR_ERR_SUCCESS ||
            exr_get_data_window(c_, part, &dw) != EXR_ERR_SUCCESS ||
            exr_get_scanlines_per_chunk(c_, part, &lines) != EXR_ERR_SUCCESS || lines < 1)
            return fail(fmt::format("truncated or corrupt (part '{}': no chunk layout)", pn));
        if (storage != EXR_STORAGE_SCANLINE && storage != EXR_STORAGE_DEEP_SCANLINE) continue;
        exr_compression_t comp = EXR_COMPRESSION_LAST_TYPE;
        if (exr_get_compression(c_, part, &comp) != EXR_ERR_SUCCESS)
            return fail(fmt::format("truncated or corrupt (part '{}': no compression)", pn));
        const double ratio = maxUnpackRatio(comp);
        // What a header claims is checked against what the file holds: a chunk cannot unpack to
        // more than its codec allows, so a small file cannot claim a large image (for ZIP, an
        // image at most about 1000 times the file's size reaches the allocations).
        auto tooDense = [&](uint64_t packed, uint64_t unpacked) {
            return ratio > 0.0 && packed != unpacked &&
                   double(unpacked) > ratio * double(packed) + 64.0;
        };
        const uint64_t width = uint64_t(int64_t(dw.max.x) - dw.min.x + 1);
        for (int64_t y = dw.min.y; y <= dw.max.y; y += lines) {
            exr_chunk_info_t ci{};
            const exr_result_t rv = exr_read_scanline_chunk_info(c_, part, int(y), &ci);
            uint64_t end = ci.data_offset + ci.packed_size;
            bool inside = rv == EXR_ERR_SUCCESS && ci.data_offset <= fileSize &&
                          ci.packed_size <= fileSize - ci.data_offset;
            if (inside && storage == EXR_STORAGE_DEEP_SCANLINE) {
                end = ci.sample_count_data_offset + ci.sample_count_table_size;
                inside = ci.sample_count_data_offset <= fileSize &&
                         ci.sample_count_table_size <= fileSize - ci.sample_count_data_offset;
            }
            if (!inside)
                return fail(fmt::format(
                    "truncated or corrupt (part '{}': the chunk of row {} {} the file's {} bytes)",
                    pn, y,
                    rv == EXR_ERR_SUCCESS ? fmt::format("ends at byte {}, beyond", end)
                                          : std::string("has no valid offset within"),
                    fileSize));
            const uint64_t rows = uint64_t(std::min<int64_t>(lines, int64_t(dw.max.y) - y + 1));
            const uint64_t countTable = width * rows * sizeof(int32_t);
            const bool countsTooDense = storage == EXR_STORAGE_DEEP_SCANLINE &&
                                        tooDense(ci.sample_count_table_size, countTable);
            if (tooDense(ci.packed_size, ci.unpacked_size) || countsTooDense)
                return fail(fmt::format(
                    "truncated or corrupt (part '{}': the chunk of row {} claims {} bytes from "
                    "{}, more than {} compression gives ({:.0f}:1))",
                    pn, y, countsTooDense ? countTable : ci.unpacked_size,
                    countsTooDense ? ci.sample_count_table_size : ci.packed_size,
                    compressionName(comp), ratio));
        }
    }
    return true;
}

}  // namespace mcstat::detail
