# `cmake --install`: the mcstat and mcstat-render executables, mcstat-blender (a Python script) with
# its Cycles template, the OpenImageIO plugin, the libraries (static, or shared with
# -DBUILD_SHARED_LIBS=ON) with their public headers and LICENSE,
# an exported CMake package (find_package(mcstat CONFIG) giving mcstat::core, mcstat::filters,
# mcstat::exrdeep_codec, mcstat::exrdeep, mcstat::color, mcstat::image_spec, mcstat::image,
# mcstat::ingest, mcstat::compare, mcstat::compare_report, mcstat_EXECUTABLE and
# mcstat_add_render_test), mcstat.pc, the Python module (component python) and the built-in OCIO
# config as a file (component bin: share/mcstat/config.ocio, for oiiotool --colorconfig and $OCIO).
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

set(MCSTAT_INSTALL_CMAKEDIR "${CMAKE_INSTALL_LIBDIR}/cmake/mcstat"
    CACHE STRING "Where the CMake package files go (relative to the prefix)")
set(MCSTAT_INSTALL_PLUGINDIR "${CMAKE_INSTALL_LIBDIR}/OpenImageIO-plugins"
    CACHE STRING "Where mcstat.imageio.so goes; point OIIO_LIBRARY_PATH at it")

set(MCSTAT_INSTALL_DATADIR "${CMAKE_INSTALL_DATADIR}/mcstat"
    CACHE STRING "Where config.ocio (the built-in OCIO config) goes")
set(_mcstat_libs mcstat_core mcstat_filters mcstat_compact mcstat_exrdeep_codec mcstat_exrdeep mcstat_color mcstat_analysis mcstat_image_spec mcstat_image
                 mcstat_review mcstat_compare mcstat_compare_report mcstat_ingest)
foreach(_lib IN LISTS _mcstat_libs)
  string(REPLACE "mcstat_" "" _export_name "${_lib}")
  set_target_properties(${_lib} PROPERTIES EXPORT_NAME ${_export_name})
endforeach()

install(TARGETS ${_mcstat_libs}
  EXPORT mcstatTargets
  ARCHIVE DESTINATION "${CMAKE_INSTALL_LIBDIR}" COMPONENT dev
  LIBRARY DESTINATION "${CMAKE_INSTALL_LIBDIR}" COMPONENT dev)
install(FILES "${PROJECT_BINARY_DIR}/include/mcstat/version.h"
  DESTINATION "${CMAKE_INSTALL_INCLUDEDIR}/mcstat" COMPONENT dev)
install(FILES "${PROJECT_SOURCE_DIR}/LICENSE"
  DESTINATION "${CMAKE_INSTALL_DOCDIR}" COMPONENT dev)
# The public headers only (issue 51): every detail/ folder holds mcstat::detail, what the rooms
# share among themselves (the OpenEXR Core codec, the rank keys, the Boost.Math policy), and stays
# out, as OpenEXR keeps its internal_*.h and OIIO its *_pvt.h. No public header includes one
# (tests/architecture/check_arrows.sh); plugin.consumer (tests/plugin/consumer_test.cmake) finds no
# detail/ folder in the prefix and compiles every installed header with the pkg-config flags alone.
install(DIRECTORY "${PROJECT_SOURCE_DIR}/include/mcstat"
  DESTINATION "${CMAKE_INSTALL_INCLUDEDIR}" COMPONENT dev
  FILES_MATCHING PATTERN "*.h"
  PATTERN "detail" EXCLUDE)
install(TARGETS mcstat mcstat-render RUNTIME DESTINATION "${CMAKE_INSTALL_BINDIR}" COMPONENT bin)
install(FILES "${PROJECT_SOURCE_DIR}/color/config.ocio"
  DESTINATION "${MCSTAT_INSTALL_DATADIR}" COMPONENT bin)
# The Python module's own rules are in python/CMakeLists.txt (MCSTAT_INSTALL_PYTHONDIR).
if(TARGET mcstat_python)
  set(MCSTAT_CONFIG_PYTHONPATH "${MCSTAT_INSTALL_PYTHONDIR}")
  set(MCSTAT_CONFIG_PYTHON_EXECUTABLE "${MCSTAT_PYTHON_EXECUTABLE}")
else()
  set(MCSTAT_CONFIG_PYTHONPATH "")
  set(MCSTAT_CONFIG_PYTHON_EXECUTABLE "")
endif()

# A Python program of farm/ installed to bin, told where its data went: the line
# `MARK = None` becomes `MARK = "<DATADIR relative to bin>"` in the installed copy, which the
# program resolves against its own folder. Reconfigures when the program changes.
function(mcstat_install_program name mark datadir component)
  file(RELATIVE_PATH rel "/${CMAKE_INSTALL_BINDIR}" "/${datadir}")
  file(READ "${PROJECT_SOURCE_DIR}/farm/${name}" text)
  string(REPLACE "\n${mark} = None\n" "\n${mark} = \"${rel}\"\n" text "${text}")
  file(WRITE "${PROJECT_BINARY_DIR}/install/${name}" "${text}")
  set_property(DIRECTORY "${PROJECT_SOURCE_DIR}" APPEND PROPERTY CMAKE_CONFIGURE_DEPENDS
               "${PROJECT_SOURCE_DIR}/farm/${name}")
  install(PROGRAMS "${PROJECT_BINARY_DIR}/install/${name}"
    DESTINATION "${CMAKE_INSTALL_BINDIR}" COMPONENT ${component})
endfunction()

# mcstat-blender (farm/mcstat-blender, docs/ingest.md "Seeds"): renders a Blender scene once per
# seed through the farm's Cycles template, which goes with it with the caustic scene it renders
# when no .blend is given. The installed copy knows where they are relative to itself. Component
# `blender`: tests/aovs installs it alone.
set(MCSTAT_INSTALL_BLENDERDIR "${CMAKE_INSTALL_DATADIR}/mcstat/blender"
    CACHE STRING "Where mcstat-blender's Cycles template goes (relative to the prefix)")
mcstat_install_program(mcstat-blender INSTALLED_TEMPLATES "${MCSTAT_INSTALL_BLENDERDIR}" blender)
install(FILES "${PROJECT_SOURCE_DIR}/farm/templates/cycles_seed.py"
              "${PROJECT_SOURCE_DIR}/tests/aovs/cycles_caustic.py"
  DESTINATION "${MCSTAT_INSTALL_BLENDERDIR}" COMPONENT blender)
# mcstat-farm (docs/farm.md): the shot's jobs on Slurm. Installed beside mcstat and mcstat-render,
# which it runs; its templates go to share/mcstat/farm/templates, which {farm} names in a template.
set(MCSTAT_INSTALL_FARMDIR "${CMAKE_INSTALL_DATADIR}/mcstat/farm"
    CACHE STRING "Where mcstat-farm's templates go (relative to the prefix)")
mcstat_install_program(mcstat-farm INSTALLED_FARM_DATA "${MCSTAT_INSTALL_FARMDIR}" bin)
file(GLOB _mcstat_farm_templates CONFIGURE_DEPENDS "${PROJECT_SOURCE_DIR}/farm/templates/*.tmpl")
install(FILES ${_mcstat_farm_templates} "${PROJECT_SOURCE_DIR}/farm/templates/cycles_seed.py"
  DESTINATION "${MCSTAT_INSTALL_FARMDIR}/templates" COMPONENT bin)
if(TARGET mcstat_oiio_plugin)
  install(TARGETS mcstat_oiio_plugin
    LIBRARY DESTINATION "${MCSTAT_INSTALL_PLUGINDIR}" COMPONENT plugin)
endif()

install(EXPORT mcstatTargets
  NAMESPACE mcstat::
  FILE mcstatTargets.cmake
  DESTINATION "${MCSTAT_INSTALL_CMAKEDIR}" COMPONENT dev)
set(MCSTAT_INSTALL_EXECUTABLE "${CMAKE_INSTALL_BINDIR}/mcstat")
set(MCSTAT_INSTALL_OCIO_CONFIG "${MCSTAT_INSTALL_DATADIR}/config.ocio")
configure_package_config_file("${CMAKE_CURRENT_LIST_DIR}/mcstatConfig.cmake.in"
  "${PROJECT_BINARY_DIR}/mcstatConfig.cmake"
  INSTALL_DESTINATION "${MCSTAT_INSTALL_CMAKEDIR}"
  PATH_VARS MCSTAT_INSTALL_PLUGINDIR MCSTAT_INSTALL_EXECUTABLE MCSTAT_INSTALL_OCIO_CONFIG)
write_basic_package_version_file("${PROJECT_BINARY_DIR}/mcstatConfigVersion.cmake"
  VERSION "${PROJECT_VERSION}"
  COMPATIBILITY SameMinorVersion)
install(FILES "${PROJECT_BINARY_DIR}/mcstatConfig.cmake" "${PROJECT_BINARY_DIR}/mcstatConfigVersion.cmake"
              "${CMAKE_CURRENT_LIST_DIR}/mcstatRenderTest.cmake"
  DESTINATION "${MCSTAT_INSTALL_CMAKEDIR}" COMPONENT dev)

# pkg-config: the .pc file is written at install time so that `cmake --install --prefix P` gives P.
configure_file("${CMAKE_CURRENT_LIST_DIR}/mcstat.pc.in" "${PROJECT_BINARY_DIR}/mcstat.pc.in.configured"
  @ONLY)
install(CODE "
  set(_prefix \"\${CMAKE_INSTALL_PREFIX}\")
  file(READ \"${PROJECT_BINARY_DIR}/mcstat.pc.in.configured\" _pc)
  string(REPLACE \"%MCSTAT_PC_PREFIX%\" \"\${_prefix}\" _pc \"\${_pc}\")
  file(WRITE \"${PROJECT_BINARY_DIR}/mcstat.pc\" \"\${_pc}\")
" COMPONENT dev)
install(FILES "${PROJECT_BINARY_DIR}/mcstat.pc"
  DESTINATION "${CMAKE_INSTALL_LIBDIR}/pkgconfig" COMPONENT dev)
