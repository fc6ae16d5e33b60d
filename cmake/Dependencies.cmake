# Every dependency comes from Debian 12 packages; scripts/install-deps.sh installs them.
find_package(Threads REQUIRED)
find_package(OpenEXR 3 CONFIG REQUIRED)
find_package(Imath CONFIG REQUIRED)
find_package(OpenImageIO CONFIG REQUIRED)
# Debian's OpenImageIO target lists /usr/include/opencv4 (not installed with it): drop that directory,
# otherwise generation fails (checked on Debian 12).
foreach(_tgt OpenImageIO::OpenImageIO OpenImageIO::OpenImageIO_Util)
  if(TARGET ${_tgt})
    get_target_property(_inc ${_tgt} INTERFACE_INCLUDE_DIRECTORIES)
    if(_inc)
      list(FILTER _inc EXCLUDE REGEX "opencv4")
      set_target_properties(${_tgt} PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${_inc}")
    endif()
  endif()
endforeach()
# Debian 12 installs OpenColorIOConfig.cmake directly in /usr/share/cmake, from where it computes a
# wrong prefix ("/include"); its pkg-config file is right.
find_package(PkgConfig REQUIRED)
pkg_check_modules(OpenColorIO REQUIRED IMPORTED_TARGET OpenColorIO)
add_library(OpenColorIO::OpenColorIO ALIAS PkgConfig::OpenColorIO)
# libdeflate (libdeflate-dev 1.14 ships only a pkg-config file): the ZIP codec's inflate and
# deflate.
pkg_check_modules(libdeflate REQUIRED IMPORTED_TARGET libdeflate)
find_package(embree 3 CONFIG REQUIRED)
find_package(fmt CONFIG REQUIRED)
find_package(nlohmann_json CONFIG REQUIRED)
if(MCSTAT_BUILD_TESTS)
  find_package(GTest CONFIG REQUIRED)
endif()
if(MCSTAT_BUILD_BENCHMARKS)
  find_package(benchmark CONFIG REQUIRED)
endif()
