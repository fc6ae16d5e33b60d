# mcstat_add_render_test(NAME A B [OPTIONS key=value...] [REPORT_DIR dir] [LABELS label...]
#                        [MCSTAT executable])
#
# Registers the CTest test NAME that runs
#   mcstat --ingest A --ingest B --compare:name=NAME:junit=R/NAME.xml:json=R/NAME.json:html=R/NAME:<OPTIONS>
# and passes when the two renders are the same image up to their Monte Carlo noise (mcstat's exit
# status 0), fails when they differ (2) or an input is bad (1) (docs/compare.md, "Render tests in
# CMake"). A and B are globs of renders (one EXR per seed, quoted for mcstat to expand: 'new/seed_*.exr')
# or statistics files (*.mcstat, used as they are). OPTIONS are --compare's modifiers, e.g.
# reltol=0.01 level=0.01. Reports go to REPORT_DIR (default ${CMAKE_CURRENT_BINARY_DIR}/mcstat-reports):
# NAME.xml (JUnit, for the CI server), NAME.json and the page NAME/index.html, attached to the test
# when it fails (CDash). Paths must not contain ':' (the modifiers' separator). MCSTAT overrides
# the executable (default: mcstat_EXECUTABLE, set by find_package(mcstat)).
function(mcstat_add_render_test name a b)
  cmake_parse_arguments(PARSE_ARGV 3 _mrt "" "REPORT_DIR;MCSTAT" "OPTIONS;LABELS")
  if(_mrt_UNPARSED_ARGUMENTS)
    message(FATAL_ERROR "mcstat_add_render_test(${name}): unknown arguments ${_mrt_UNPARSED_ARGUMENTS}")
  endif()
  set(_exe "${_mrt_MCSTAT}")
  if(NOT _exe)
    set(_exe "${mcstat_EXECUTABLE}")
  endif()
  if(NOT _exe)
    message(FATAL_ERROR "mcstat_add_render_test(${name}): no mcstat executable (find_package(mcstat) or MCSTAT)")
  endif()
  set(_dir "${_mrt_REPORT_DIR}")
  if(NOT _dir)
    set(_dir "${CMAKE_CURRENT_BINARY_DIR}/mcstat-reports")
  endif()
  file(MAKE_DIRECTORY "${_dir}")
  set(_inputs)
  foreach(_side IN ITEMS "${a}" "${b}")
    if(_side MATCHES "\\.mcstat$" AND NOT _side MATCHES "[*?[]")
      list(APPEND _inputs "${_side}")
    else()
      list(APPEND _inputs --ingest "${_side}")
    endif()
  endforeach()
  set(_compare "--compare:name=${name}:junit=${_dir}/${name}.xml:json=${_dir}/${name}.json:html=${_dir}/${name}")
  foreach(_opt IN LISTS _mrt_OPTIONS)
    string(APPEND _compare ":${_opt}")
  endforeach()
  add_test(NAME "${name}" COMMAND "${_exe}" ${_inputs} "${_compare}")
  set_tests_properties("${name}" PROPERTIES
    ATTACHED_FILES_ON_FAIL "${_dir}/${name}.xml;${_dir}/${name}.json;${_dir}/${name}/index.html")
  if(_mrt_LABELS)
    set_tests_properties("${name}" PROPERTIES LABELS "${_mrt_LABELS}")
  endif()
endfunction()
