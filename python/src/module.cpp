// The mcstat Python module (docs/python.md): `import mcstat` loads this extension, mcstat._mcstat,
// under the pure-Python layer python/mcstat/__init__.py. Built with pybind11 (Debian 12 packages
// pybind11 2.10; nanobind is not packaged there).
#include <OpenImageIO/strutil.h>

#include "bindings.h"
#include "mcstat/color.h"
#include "mcstat/version.h"

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

PYBIND11_MODULE(_mcstat, m) {
    using namespace mcstat::python;
    m.doc() = "mcstat's C++ library for Python: see the mcstat package and docs/python.md";
    m.attr("__version__") = MCSTAT_VERSION;  // the project's one version (mcstat/version.h)
    py::register_exception<Error>(m, "Error", PyExc_RuntimeError);
    bindStats(m);
    bindOperations(m);
}
