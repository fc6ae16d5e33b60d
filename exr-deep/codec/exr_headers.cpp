// OpenEXR headers read byte by byte, before any OpenEXR reader sizes anything by them
// (exr_headers.h).
#include "mcstat/exr-deep/codec/detail/exr_headers.h"

#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <map>
#include <vector>

#include "mcstat/core/untrusted_text.h"
#include "mcstat/exr-deep/codec/detail/fd_stream.h"

namespace mcstat::detail {

namespace {

/// Whether the value of an attribute of `type` (at `at`, `size` bytes) is exactly `size` bytes by
/// its own structure. OpenEXR's C++ reader reads the types it knows by their structure and not by
/// the size field (a channel list until its empty name, a box as 16 bytes), so a value whose
/// structure disagrees with its size makes it read the following bytes out of step, as names,
/// types and sizes nobody checked (fuzzing found a 1.5 GB string that way). Unknown types are
/// read by their size (opaque) and need no check.
bool valueMatchesSize(int fd, const std::string& type, uint64_t at, uint32_t size,
                      std::string& why) {
    static const std::map<std::string, uint32_t> kFixed = {{"box2i", 16},
                                                           {"box2f", 16},
                                                           {"v2i", 8},
                                                           {"v2f", 8},
                                                           {"v2d", 16},
                                                           {"v3i", 12},
                                                           {"v3f", 12},
                                                           {"v3d", 24},
                                                           {"int", 4},
                                                           {"float", 4},
                                                           {"double", 8},
                                                           {"compression", 1},
                                                           {"lineOrder", 1},
                                                           {"envmap", 1},
                                                           {"deepImageState", 1},
                                                           {"tiledesc", 9},
                                                           {"rational", 8},
                                                           {"timecode", 8},
                                                           {"keycode", 28},
                                                           {"chromaticities", 32},
                                                           {"m33f", 36},
                                                           {"m44f", 64},
                                                           {"m33d", 72},
                                                           {"m44d", 128}};
    if (const auto it = kFixed.find(type); it != kFixed.end()) {
        if (size == it->second) return true;
        why = fmt::format("{} bytes where the type has {}", size, it->second);
        return false;
    }
    if (type == "floatvector") {
        if (size % 4 == 0) return true;
        why = fmt::format("{} bytes, not a whole number of floats", size);
        return false;
    }
    const bool chlist = type == "chlist", strings = type == "stringvector";
    const bool preview = type == "preview";
    if (!chlist && !strings && !preview) return true;
    constexpr uint32_t kMaxStructured = kMaxStructuredAttributeBytes;
    if (size > kMaxStructured) {
        why = fmt::format("{} bytes, more than this reader reads of such a value", size);
        return false;
    }
    std::vector<unsigned char> v(size);
    if (size > 0 && preadFull(fd, v.data(), size, at) != int64_t(size)) {
        why = "cut short";
        return false;
    }
    auto le32 = [&v](size_t i) { return loadLe32(&v[i]); };
    if (preview) {
        const uint64_t need =
            size >= 8 ? 8 + uint64_t(le32(0)) * uint64_t(le32(4)) * 4 : uint64_t(8);
        if (size >= 8 && need == size) return true;
        why = fmt::format("{} bytes where its width and height need {}", size, need);
        return false;
    }
    size_t i = 0;
    if (strings) {  // int32 length, then the characters, repeated
        while (i < size) {
            if (size - i < 4 || le32(i) > size - i - 4) {
                why = fmt::format("a string at byte {} of {} runs past the value", i, size);
                return false;
            }
            i += 4 + le32(i);
        }
        return true;
    }
    // chlist: name NUL, 16 bytes (type, pLinear and reserved, xSampling, ySampling), repeated,
    // then an empty name: the last byte. A pixel type other than OpenEXR's three makes OIIO 2.4's
    // reader abort (an assertion, found by fuzzing ingest), a sampling below 1 divides by zero:
    // both refused here, before any reader sees them.
    while (i < size && v[i] != 0) {
        const auto* end = static_cast<const unsigned char*>(std::memchr(&v[i], 0, size - i));
        if (end == nullptr || size_t(end - &v[i]) > 255 || size_t(end - v.data()) + 1 + 16 > size) {
            why = fmt::format("a channel at byte {} of {} runs past the value", i, size);
            return false;
        }
        const size_t fields = size_t(end - v.data()) + 1;  // the channel's 16 bytes
        const auto pixelType = int32_t(le32(fields));
        const auto xs = int32_t(le32(fields + 8)), ys = int32_t(le32(fields + 12));
        if (pixelType < 0 || pixelType > 2) {
            why = fmt::format(
                "a channel at byte {} has pixel type {} (OpenEXR's are 0 uint, 1 half, "
                "2 float)",
                i, pixelType);
            return false;
        }
        if (xs < 1 || ys < 1) {
            why = fmt::format("a channel at byte {} has sampling {} x {} (at least 1 x 1)", i, xs,
                              ys);
            return false;
        }
        i = fields + 16;
    }
    if (i + 1 == size) return true;
    why = fmt::format("the channel list ends at byte {} of {}", i + 1, size);
    return false;
}

}  // namespace

/// Walks the attribute lists of every header (OpenEXR's layout: name NUL, type NUL, int32 size,
/// value; a NUL ends a header, another ends the headers of a multi-part file) and checks each
/// size against the bytes left in the file. OpenEXR's C++ reader allocates a string or an
/// opaque attribute of the size its header claims before reading it (1.8 GB for a 10 KB file
/// found by fuzzing, tests/fuzz/regressions), and the Core API accepts such a header, so this
/// runs before either sees the file.
bool checkAttributeSizes(int fd, uint64_t fileSize, const std::string& path, std::string& err,
                         const AttributeVisitor& visit) {
    // Long names are at most 255 bytes (OpenEXR's limit): a name, a type and a size fit in this.
    constexpr size_t kMaxNameLen = 255, kMaxAttributes = 100000;
    unsigned char version[4] = {};
    if (preadFull(fd, version, 4, 4) != 4) {
        err = path + ": truncated or corrupt (no version field)";
        return false;
    }
    const bool multiPart = (version[1] & 0x10) != 0;  // bit 12 of the version field
    uint64_t pos = 8;
    size_t attributes = 0;
    int header = 0;
    auto fail = [&](const std::string& what) {
        err = fmt::format("{}: truncated or corrupt (header {}: {})", path, header, what);
        return false;
    };
    std::vector<char> buf(2 * (kMaxNameLen + 1) + 4);
    for (;;) {
        const int64_t got = preadFull(fd, buf.data(), buf.size(), pos);
        if (got <= 0) return fail(fmt::format("it ends at byte {}", pos));
        const size_t n = size_t(got);
        if (buf[0] == '\0') {  // end of this header
            ++pos;
            ++header;
            if (!multiPart) return true;
            if (n < 2) return fail(fmt::format("it ends at byte {}", pos));
            if (buf[1] == '\0') return true;  // end of the header list
            continue;
        }
        const char* nameEnd =
            static_cast<const char*>(std::memchr(buf.data(), 0, std::min(n, kMaxNameLen + 1)));
        if (nameEnd == nullptr)
            return fail(fmt::format("an attribute name at byte {} is longer than {} bytes or cut",
                                    pos, kMaxNameLen));
        const size_t nameLen = size_t(nameEnd - buf.data());
        const size_t typeAt = nameLen + 1;
        const char* typeEnd =
            typeAt < n ? static_cast<const char*>(std::memchr(
                             buf.data() + typeAt, 0, std::min(n - typeAt, kMaxNameLen + 1)))
                       : nullptr;
        const std::string name(buf.data(), nameLen);
        if (typeEnd == nullptr)
            return fail(fmt::format("attribute '{}' has no valid type name", printable(name)));
        const size_t sizeAt = size_t(typeEnd - buf.data()) + 1;
        if (sizeAt + 4 > n) return fail(fmt::format("attribute '{}' is cut", printable(name)));
        const auto valueSize =
            int32_t(loadLe32(reinterpret_cast<const unsigned char*>(buf.data() + sizeAt)));
        const uint64_t valueAt = pos + sizeAt + 4;
        if (valueSize < 0 || uint64_t(valueSize) > fileSize - std::min(fileSize, valueAt))
            return fail(fmt::format("attribute '{}' claims {} bytes; {} are left in the file's {}",
                                    printable(name), valueSize,
                                    fileSize - std::min(fileSize, valueAt), fileSize));
        const std::string type(buf.data() + typeAt, size_t(typeEnd - (buf.data() + typeAt)));
        std::string why;
        if (!valueMatchesSize(fd, type, valueAt, uint32_t(valueSize), why))
            return fail(fmt::format("attribute '{}' of type {}: {}", printable(name),
                                    printable(type), why));
        if (visit) visit(header, name, type, valueAt, uint32_t(valueSize));
        pos = valueAt + uint64_t(valueSize);
        if (++attributes > kMaxAttributes)
            return fail(fmt::format("more than {} attributes", kMaxAttributes));
    }
}

bool checkExrAttributeSizes(int fd, uint64_t size, const std::string& path, std::string& err,
                            int64_t maxPixels) {
    unsigned char magic[4] = {};
    if (size < 8 || preadFull(fd, magic, 4, 0) != 4 || std::memcmp(magic, kExrMagic, 4) != 0)
        return true;  // not OpenEXR: its own reader judges it
    // Every part's data window (box2i: xMin, yMin, xMax, yMax, little endian) against maxPixels.
    int64_t width = 0, height = 0;
    bool tooLarge = false;
    const bool walked =
        checkAttributeSizes(fd, size, path, err,
                            [&](int, const std::string& name, const std::string& type,
                                uint64_t valueAt, uint32_t bytes) {
                                if (maxPixels <= 0 || tooLarge || name != "dataWindow" ||
                                    type != "box2i" || bytes != 16)
                                    return;
                                unsigned char b[16] = {};
                                if (preadFull(fd, b, 16, valueAt) != 16)
                                    return;  // the walk has checked the size
                                int32_t v[4];
                                for (int i = 0; i < 4; ++i) v[i] = int32_t(loadLe32(b + 4 * i));
                                const int64_t w = int64_t(v[2]) - int64_t(v[0]) + 1,
                                              h = int64_t(v[3]) - int64_t(v[1]) + 1;
                                if (w <= 0 || h <= 0)
                                    return;  // an empty window: OpenEXR's reader says so
                                if (w > maxPixels / h) {
                                    tooLarge = true;
                                    width = w;
                                    height = h;
                                }
                            });
    if (!walked) return false;
    if (tooLarge) {
        err = fmt::format("{}: image {}x{} exceeds the limit of {} pixels", path, width, height,
                          maxPixels);
        return false;
    }
    return true;
}

bool replaceStringAttribute(int fd, uint64_t size, const std::string& path, const std::string& name,
                            const std::string& value, std::string& err) {
    std::vector<uint64_t> at;
    bool sizesAgree = true;
    const bool walked = checkAttributeSizes(
        fd, size, path, err,
        [&](int, const std::string& n, const std::string& type, uint64_t valueAt, uint32_t bytes) {
            if (n != name || type != "string") return;
            at.push_back(valueAt);
            sizesAgree = sizesAgree && bytes == value.size();
        });
    if (!walked) return false;
    if (at.empty() || !sizesAgree) {
        err = fmt::format("{}: {} string attribute '{}' of {} bytes to replace in place", path,
                          at.empty() ? "no" : "not every", name, value.size());
        return false;
    }
    for (uint64_t pos : at) {
        size_t done = 0;
        while (done < value.size()) {
            const ssize_t n =
                ::pwrite(fd, value.data() + done, value.size() - done, off_t(pos + done));
            if (n < 0 && errno == EINTR) continue;
            if (n <= 0) {
                err = fmt::format("{}: cannot write attribute '{}' ({})", path, name,
                                  n < 0 ? std::strerror(errno) : "nothing written");
                return false;
            }
            done += size_t(n);
        }
    }
    return true;
}

}  // namespace mcstat::detail
