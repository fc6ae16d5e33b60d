# mcstat_precompile_headers(TARGET [IMAGES] [HEADERS header...]): a precompiled header of the
# target's own (same flags, so GCC and clang accept it for every file of the target).
# Parsing the standard library, fmt and OIIO's ImageBuf headers is a third to a half of many of
# our translation units' compile time. Measured on two clean GCC builds (CPU seconds of each
# target's files, the header's own compile included): mcstat_image 83 -> 61, mcstat_filters 37 ->
# 27, mcstat_exrdeep 29 -> 21, mcstat_compare 31 -> 25, the mcstat tool 54 -> 49; the whole build
# 319 s -> 295 s of wall time. Targets where it did not pay (ingest, the Python module, review,
# the renderer: a few files, each including different heavy headers) take none. IMAGES adds OIIO's
# ImageBuf and ImageBufAlgo headers (targets that link OpenImageIO::OpenImageIO).
# MCSTAT_PRECOMPILE=OFF turns them all off (e.g. to check that every file includes what it uses).
option(MCSTAT_PRECOMPILE "Precompiled headers for the larger libraries and tools" ON)
set(MCSTAT_PCH_STD <algorithm> <cmath> <cstring> <functional> <limits> <map> <memory> <string>
    <vector>)
function(mcstat_precompile_headers target)
  if(NOT MCSTAT_PRECOMPILE)
    return()
  endif()
  cmake_parse_arguments(P "IMAGES" "" "HEADERS" ${ARGN})
  # OIIO first: its headers define FMT_DEPRECATED_OSTREAM before they include fmt, which lets
  # fmt print OIIO's types (ROI) through operator<<; fmt included first would not.
  set(headers)
  if(P_IMAGES)
    list(APPEND headers <OpenImageIO/imagebuf.h> <OpenImageIO/imagebufalgo.h>)
  endif()
  list(APPEND headers ${P_HEADERS} ${MCSTAT_PCH_STD})
  target_precompile_headers(${target} PRIVATE ${headers})
  # A header GCC cannot use is otherwise skipped in silence (a slow build): a warning, an error
  # under MCSTAT_WERROR.
  target_compile_options(${target} PRIVATE -Winvalid-pch)
endfunction()
