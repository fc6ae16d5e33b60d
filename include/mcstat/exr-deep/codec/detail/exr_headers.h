// Internal: OpenEXR headers read byte by byte, before any OpenEXR reader sizes anything by them:
// every attribute's size against the file's, and a string attribute rewritten in place. Used by
// the statistics file's header checks and by ingest for renderers' files.
#pragma once

#include <cstdint>
#include <functional>
#include <string>

namespace mcstat::detail {

/// OpenEXR's magic number, the first four bytes of every OpenEXR file.
inline constexpr unsigned char kExrMagic[4] = {0x76, 0x2f, 0x31, 0x01};

/// Largest channel list, string vector or other structured attribute value a reader accepts
/// (bytes).
inline constexpr uint32_t kMaxStructuredAttributeBytes = uint32_t(16) << 20;

/// A 32-bit little-endian value (OpenEXR's byte order for every number in a header).
inline uint32_t loadLe32(const unsigned char* p) {
    return uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16 | uint32_t(p[3]) << 24;
}

/// Each attribute as checkAttributeSizes walks them: the header's index, the attribute's name and
/// type, where its value starts and its size.
using AttributeVisitor = std::function<void(
    int header, const std::string& name, const std::string& type, uint64_t valueAt, uint32_t size)>;

/// Walks the attribute lists of every header of the OpenEXR file open as `fd` (`fileSize` bytes)
/// and checks each attribute's size against the bytes left in the file and, for the types
/// OpenEXR's C++ reader reads by their structure, against that structure; `visit` sees each.
/// False with "<path>: <problem>".
bool checkAttributeSizes(int fd, uint64_t fileSize, const std::string& path, std::string& err,
                         const AttributeVisitor& visit = {});
/// checkExrAttributeSizes (stats_file.h) over an open file.
bool checkExrAttributeSizes(int fd, uint64_t size, const std::string& path, std::string& err,
                            int64_t maxPixels = 0);
/// Overwrites, in every header of the OpenEXR file open as `fd` (read-write, `size` bytes), the
/// value of the string attribute `name` with `value` of the same length: a value known only once
/// the pixels are written (an ingest's RGB hashes in mcstat:seeds), put in place before the file
/// is renamed onto its target. OpenEXR 3.1's exr_start_inplace_header_update is not implemented.
/// False with "<path>: <problem>" when a header lacks it or holds it with another length.
bool replaceStringAttribute(int fd, uint64_t size, const std::string& path, const std::string& name,
                            const std::string& value, std::string& err);

}  // namespace mcstat::detail
