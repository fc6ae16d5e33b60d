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

# Fuzzing (tests/fuzz, scripts/fuzz.sh): every library is compiled with libFuzzer's coverage
# instrumentation and ASan+UBSan; only the fuzz targets link libFuzzer's main (-fsanitize=fuzzer).
if(MCSTAT_FUZZ)
  if(NOT CMAKE_CXX_COMPILER_ID STREQUAL "Clang")
    message(FATAL_ERROR "MCSTAT_FUZZ needs clang (CXX=clang++): libFuzzer is part of clang")
  endif()
  add_compile_options(-fsanitize=fuzzer-no-link,address,undefined -fno-omit-frame-pointer
                      -fno-sanitize-recover=undefined)
  add_link_options(-fsanitize=address,undefined)
endif()
