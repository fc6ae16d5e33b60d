// What the binding files share (bindings.h): the statistics-path check, the luminance weights and
// an image as numpy arrays. The calls of the module point one way: module.cpp calls the binders of
// stats.cpp and operations.cpp, which call this file, which calls none of them.
#include "bindings.h"
#include "mcstat/color/color.h"

namespace mcstat::python {

bool checkStatsPath(const std::string& path, std::string& err) {
    FileContent c;
    if (!probeFileContent(path, c, err)) return false;
    switch (c.kind) {
        case FileContent::Directory:
            err = path + " is a directory";
            return false;
        case FileContent::PlainExr:
            err = path +
                  " is a plain EXR image, not a statistics file (no part 'buffers' or 'vbuffers'; "
                  "it has " +
                  c.partsText() + ")";
            return false;
        default:  // the reader's own message for a missing file, or one that is not OpenEXR
            return true;
    }
}

std::array<double, 3> lumaOf(const std::string& space, const std::string& what) {
    std::array<double, 3> luma{};
    std::string err, warn;
    if (!lumaCoefficients(space, luma, err, &warn)) throw Error(what + ": " + err);
    return luma;
}

py::tuple imageArrays(const OIIO::ImageBuf& img) {
    const OIIO::ImageSpec& spec = img.spec();
    py::array_t<float> a({spec.height, spec.width, spec.nchannels});
    {
        py::gil_scoped_release release;
        img.get_pixels(img.roi(), OIIO::TypeFloat, a.mutable_data());
    }
    return py::make_tuple(py::cast(spec.channelnames), a);
}

}  // namespace mcstat::python
