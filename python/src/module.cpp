// The mcstat Python module (docs/python.md): `import mcstat` loads this extension, mcstat._mcstat,
// under the pure-Python layer python/mcstat/__init__.py. Built with pybind11 (Debian 12 packages
// pybind11 2.10; nanobind is not packaged there). This file only calls the binders of stats.cpp
// and operations.cpp; what those share is in shared.cpp.
#include "bindings.h"
#include "mcstat/version.h"

PYBIND11_MODULE(_mcstat, m) {
    using namespace mcstat::python;
    m.doc() = "mcstat's C++ library for Python: see the mcstat package and docs/python.md";
    m.attr("__version__") = MCSTAT_VERSION;  // the project's one version (mcstat/version.h)
    py::register_exception<Error>(m, "Error", PyExc_RuntimeError);
    bindStats(m);
    bindOperations(m);
}
