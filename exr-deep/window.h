// Internal: the data window of a statistics file as OpenEXR addresses it, shared by the writer,
// the reader and the version-4 parts.
#pragma once

#include <Imath/ImathBox.h>

#include <cstddef>
#include <cstdint>

#include "mcstat/exr-deep/stats_file.h"

namespace mcstat::detail {

/// The data window of `h` as an OpenEXR box.
inline Imath::Box2i windowOf(const StatsHeader& h) {
    return Imath::Box2i(Imath::V2i(h.originX, h.originY),
                        Imath::V2i(h.originX + h.width - 1, h.originY + h.height - 1));
}

/// The display window of `h` as an OpenEXR box: header.display* when displayWidth > 0, else the
/// data window.
inline Imath::Box2i displayWindowOf(const StatsHeader& h) {
    if (h.displayWidth <= 0 || h.displayHeight <= 0) return windowOf(h);
    return Imath::Box2i(
        Imath::V2i(h.displayX, h.displayY),
        Imath::V2i(h.displayX + h.displayWidth - 1, h.displayY + h.displayHeight - 1));
}

/// `data` shifted so that element (x, y) of the data window, in rows firstRow.. of the window
/// (0-based), is at data + ((y - originY - firstRow) * width + x - originX) * xStride, as
/// OpenEXR's slices address it with yStride = xStride * width (integer arithmetic: no
/// out-of-range pointer is formed).
inline char* windowBase(const void* data, const StatsHeader& h, size_t xStride, int firstRow = 0) {
    const intptr_t shift =
        (intptr_t(h.originY + firstRow) * intptr_t(h.width) + intptr_t(h.originX)) *
        intptr_t(xStride);
    return reinterpret_cast<char*>(reinterpret_cast<intptr_t>(data) - shift);
}

}  // namespace mcstat::detail
