# ctest driver: installs the build tree into a fresh prefix, configures and builds the out-of-tree
# consumer project against it with find_package(mcstat CONFIG), runs it and checks its output;
# then compiles the same main.cpp with the flags of the installed mcstat.pc.
# Variables: BUILD_DIR (mcstat build tree), SOURCE_DIR (consumer sources), WORK_DIR (scratch),
# CXX (compiler), EXTRA_FLAGS (compile and link flags, e.g. sanitizers; may be empty), SHARED
# (the build's BUILD_SHARED_LIBS: the libraries are .so files, found at run time through the
# installed tools' RPATH, CMake's RPATH for the consumer, and -rpath for the pkg-config build).
foreach(_v BUILD_DIR SOURCE_DIR WORK_DIR CXX)
  if(NOT DEFINED ${_v})
    message(FATAL_ERROR "consumer_test.cmake: ${_v} is not set")
  endif()
endforeach()
set(_prefix "${WORK_DIR}/prefix")
set(_build "${WORK_DIR}/build")
file(REMOVE_RECURSE "${WORK_DIR}")
file(MAKE_DIRECTORY "${WORK_DIR}")

function(run_step what)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "${what} failed (${rc}):\n${out}\n${err}")
  endif()
  set(step_output "${out}" PARENT_SCOPE)
endfunction()

function(check_output what text)
  foreach(_line "G-MoN pixel 3.000000 3.000000 3.000000 kept 3" "G-MoN image 3.000000 3.000000 3.000000")
    string(FIND "${text}" "${_line}" _at)
    if(_at EQUAL -1)
      message(FATAL_ERROR "${what}: expected '${_line}' in the output, got:\n${text}")
    endif()
  endforeach()
endfunction()

if(SHARED)
  set(_lib lib/libmcstat_filters.so)
  set(_rpath "-Wl,-rpath,${_prefix}/lib")
else()
  set(_lib lib/libmcstat_filters.a)
  set(_rpath "")
endif()
run_step("cmake --install" "${CMAKE_COMMAND}" --install "${BUILD_DIR}" --prefix "${_prefix}")
foreach(_f lib/cmake/mcstat/mcstatConfig.cmake lib/pkgconfig/mcstat.pc
           lib/OpenImageIO-plugins/mcstat.imageio.so bin/mcstat bin/mcstat-render
           include/mcstat/filters/registry.h include/mcstat/version.h share/doc/mcstat/LICENSE
           ${_lib})
  if(NOT EXISTS "${_prefix}/${_f}")
    message(FATAL_ERROR "cmake --install did not install ${_f}")
  endif()
endforeach()

# 1. CMake package.
run_step("configure the consumer" "${CMAKE_COMMAND}" -S "${SOURCE_DIR}" -B "${_build}"
  "-DCMAKE_PREFIX_PATH=${_prefix}" -DCMAKE_BUILD_TYPE=Release
  "-DCMAKE_CXX_COMPILER=${CXX}" "-DCMAKE_CXX_FLAGS=${EXTRA_FLAGS}"
  "-DCMAKE_EXE_LINKER_FLAGS=${EXTRA_FLAGS}")
run_step("build the consumer" "${CMAKE_COMMAND}" --build "${_build}")
run_step("run the consumer" "${_build}/consumer")
check_output("consumer (CMake package)" "${step_output}")

# 2. pkg-config.
find_program(PKG_CONFIG pkg-config REQUIRED)
set(ENV{PKG_CONFIG_PATH} "${_prefix}/lib/pkgconfig")
run_step("pkg-config" "${PKG_CONFIG}" --cflags --libs mcstat)
string(STRIP "${step_output}" _pc_flags)
separate_arguments(_pc_flags UNIX_COMMAND "${_pc_flags}")
separate_arguments(_extra UNIX_COMMAND "${EXTRA_FLAGS}")
run_step("compile with pkg-config flags" "${CXX}" -std=c++17 ${_extra} "${SOURCE_DIR}/main.cpp"
  -o "${WORK_DIR}/consumer-pc" ${_pc_flags} ${_rpath})
run_step("run the pkg-config consumer" "${WORK_DIR}/consumer-pc")
check_output("consumer (pkg-config)" "${step_output}")

# 3. Only the public headers are installed (issue 51): no detail/ folder (mcstat::detail), and
# every installed header compiles in one translation unit with the pkg-config flags alone, so none
# includes a header the install left out.
file(GLOB_RECURSE _details LIST_DIRECTORIES true "${_prefix}/include/mcstat/*")
list(FILTER _details INCLUDE REGEX "/detail(/|$)")
if(_details)
  message(FATAL_ERROR "cmake --install installed private headers: ${_details}")
endif()
file(GLOB_RECURSE _headers RELATIVE "${_prefix}/include" "${_prefix}/include/mcstat/*.h")
list(LENGTH _headers _nheaders)
if(_nheaders LESS 40)
  message(FATAL_ERROR "cmake --install installed only ${_nheaders} headers: ${_headers}")
endif()
set(_all "${WORK_DIR}/all_headers.cpp")
file(WRITE "${_all}" "")
foreach(_h IN LISTS _headers)
  file(APPEND "${_all}" "#include \"${_h}\"\n")
endforeach()
run_step("compile every installed header" "${CXX}" -std=c++17 -fsyntax-only ${_extra} "${_all}"
  ${_pc_flags})

# 4. The installed tool runs from the prefix (with shared libraries: through its RPATH).
run_step("the installed mcstat" "${_prefix}/bin/mcstat" --version)
message(STATUS "consumer: CMake package and pkg-config builds print the expected G-MoN value")
