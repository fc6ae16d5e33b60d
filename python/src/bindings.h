// The mcstat Python module's C++ side (python/, docs/python.md): what the binding files share.
// Only numpy arrays, dicts, lists, str and numbers cross into Python; the statistics image itself
// stays behind an opaque handle whose arrays numpy views without a copy.
#pragma once

#include <OpenImageIO/imagebuf.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <map>
#include <memory>
#include <stdexcept>
#include <string>

#include "mcstat/exr-deep/stats_file.h"

namespace mcstat::python {

namespace py = pybind11;

/// Raised as mcstat.Error (a RuntimeError) with the library's one-line message.
struct Error : std::runtime_error {
    using std::runtime_error::runtime_error;
};

/// A statistics image held for Python (read, ingested or a block of rows): the arrays numpy shows
/// are views of its vectors, which live as long as the handle or any view.
struct NativeStats {
    std::shared_ptr<StatsImage> img;
    std::string name;  ///< what messages call it: the path, or "ingest(...)"
};

/// False with the message `mcstat` gives for a directory or a plain EXR image where a statistics
/// file is needed; true otherwise (the reader then names any other problem, as mcstat's does).
bool checkStatsPath(const std::string& path, std::string& err);
/// The header as a Python dict (docs/python.md lists the keys).
py::dict headerDict(const StatsHeader& h);
/// The luminance weights of working space `space`; `what` names the file in errors.
std::array<double, 3> lumaOf(const std::string& space, const std::string& what);
/// The pixels of `img` as a (height, width, channels) float32 array and its channel names.
py::tuple imageArrays(const OIIO::ImageBuf& img);

void bindStats(py::module_& m);
void bindOperations(py::module_& m);

}  // namespace mcstat::python
