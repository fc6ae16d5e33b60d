# mcstat_target_warnings(target): the project's warning set; errors when MCSTAT_WERROR is on.
function(mcstat_target_warnings tgt)
  target_compile_options(${tgt} PRIVATE -Wall -Wextra -Wpedantic -Wshadow)
  if(MCSTAT_WERROR)
    target_compile_options(${tgt} PRIVATE -Werror)
  endif()
endfunction()

if(MCSTAT_SANITIZE)
  add_compile_options(-fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=undefined)
  add_link_options(-fsanitize=address,undefined)
  # clang links its sanitizer runtime statically by default, gcc its shared libasan: with clang,
  # every program takes the shared runtime (found through an rpath), so that the OIIO plugin and
  # the stock tools the tests preload it into share one runtime with mcstat's own programs. The
  # libFuzzer targets keep the static one (tests/fuzz: libFuzzer needs the runtime first).
  if(CMAKE_CXX_COMPILER_ID STREQUAL "Clang")
    execute_process(COMMAND ${CMAKE_CXX_COMPILER} -print-file-name=libclang_rt.asan-x86_64.so
                    OUTPUT_VARIABLE _mcstat_asan_rt OUTPUT_STRIP_TRAILING_WHITESPACE)
    get_filename_component(_mcstat_asan_dir "${_mcstat_asan_rt}" DIRECTORY)
    add_link_options(-shared-libsan "LINKER:-rpath,${_mcstat_asan_dir}")
  endif()
endif()

# MCSTAT_SANITIZER_TOOL_ENV: what a program we did not build (Debian's oiiotool, idiff, python3)
# needs in its environment to load our instrumented plugin or Python module: the sanitizer
# runtime preloaded (it must come first), and leak checking off (those programs' own allocations
# are not ours to judge; our programs are leak-checked by the rest of the suite). Empty without
# the sanitizers. A list of VAR=value, as CTest's ENVIRONMENT property takes it.
set(MCSTAT_SANITIZER_TOOL_ENV "")
if(MCSTAT_SANITIZE OR MCSTAT_FUZZ)
  if(CMAKE_CXX_COMPILER_ID STREQUAL "Clang")
    # clang's shared ASan runtime holds UBSan's handlers too.
    execute_process(COMMAND ${CMAKE_CXX_COMPILER} -print-file-name=libclang_rt.asan-x86_64.so
                    OUTPUT_VARIABLE _mcstat_preload OUTPUT_STRIP_TRAILING_WHITESPACE)
  else()
    execute_process(COMMAND ${CMAKE_CXX_COMPILER} -print-file-name=libasan.so
                    OUTPUT_VARIABLE _mcstat_asan OUTPUT_STRIP_TRAILING_WHITESPACE)
    execute_process(COMMAND ${CMAKE_CXX_COMPILER} -print-file-name=libubsan.so
                    OUTPUT_VARIABLE _mcstat_ubsan OUTPUT_STRIP_TRAILING_WHITESPACE)
    set(_mcstat_preload "${_mcstat_asan}:${_mcstat_ubsan}")
  endif()
  set(MCSTAT_SANITIZER_TOOL_ENV "LD_PRELOAD=${_mcstat_preload}" "ASAN_OPTIONS=detect_leaks=0")
endif()

# Fuzzing (tests/fuzz, scripts/fuzz.sh): everything is built with ASan+UBSan; only the fuzz targets
# link libFuzzer's main (-fsanitize=fuzzer). Coverage instrumentation (-fsanitize=fuzzer-no-link:
# an edge counter on every branch, a call on every comparison) goes where MCSTAT_FUZZ_COVERAGE
# says:
#  - input (the default): the code that turns untrusted bytes into data, which tests/fuzz/
#    CMakeLists.txt lists (the codec, exr-deep, ingest, the scene parser, ...). The operations the
#    targets then run on an accepted file run without feedback. The suite's sanitizer build is
#    this build (scripts/test.sh), and the instrumentation made its compute-bound code 4x slower
#    (RPF on a 48 x 48 dof render: 23.8 s with it, 6.1 s without; a 64-spp render 4.1 s, 3.2 s).
#  - all: every library, for long runs that also want guidance inside the operations
#    (scripts/fuzz.sh's own build-fuzz).
set(MCSTAT_FUZZ_COVERAGE "input" CACHE STRING
    "Code the fuzzers' coverage instrumentation covers: input (the readers) or all")
set_property(CACHE MCSTAT_FUZZ_COVERAGE PROPERTY STRINGS input all)
if(MCSTAT_FUZZ)
  if(NOT CMAKE_CXX_COMPILER_ID STREQUAL "Clang")
    message(FATAL_ERROR "MCSTAT_FUZZ needs clang (CXX=clang++): libFuzzer is part of clang")
  endif()
  if(NOT MCSTAT_FUZZ_COVERAGE MATCHES "^(input|all)$")
    message(FATAL_ERROR "MCSTAT_FUZZ_COVERAGE must be input or all, not '${MCSTAT_FUZZ_COVERAGE}'")
  endif()
  add_compile_options(-fsanitize=address,undefined -fno-omit-frame-pointer
                      -fno-sanitize-recover=undefined)
  if(MCSTAT_FUZZ_COVERAGE STREQUAL "all")
    add_compile_options(-fsanitize=fuzzer-no-link)
  endif()
  add_link_options(-fsanitize=address,undefined)
endif()
