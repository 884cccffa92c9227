# cmocka tests registered through CTest. add_test() with a target name runs it
# through CMAKE_CROSSCOMPILING_EMULATOR when cross-building, so the same tests
# can run under QEMU.
find_package(PkgConfig REQUIRED)

# piezo_add_cmocka_test(NAME SOURCES src... [LIBS lib...] [GOLDEN kernel...]
#                       [FIXTURES name...] [DEPENDS target...] [ENV VAR=value...])
# GOLDEN kernel: generate golden/<kernel>_vectors.h from the host golden model
# (python -m piezoctl.golden.export <kernel>) and put it on the include path.
# FIXTURES name: the same for fixtures/<name>_vectors.h from a fixture generator
# (python -m piezoctl.fixtures.export <name>: SIL tables, test images).
# DEPENDS: targets the export needs built first (e.g. a library it loads);
# ENV: environment of the export command (may use generator expressions).
function(piezo_add_cmocka_test name)
  cmake_parse_arguments(T "" "" "SOURCES;LIBS;GOLDEN;FIXTURES;DEPENDS;ENV" ${ARGN})
  if(CMAKE_CROSSCOMPILING)
    # A library that is neither a target of this build nor the toolchain's
    # own (PIEZO_TARGET_SYSTEM_LIBS) is host-only: skip the test, visibly.
    # So is a test the target lists in PIEZO_TARGET_SKIP_<name> (the reason).
    set(skip "${PIEZO_TARGET_SKIP_${name}}")
    foreach(lib IN LISTS T_LIBS)
      if(NOT TARGET ${lib} AND NOT lib IN_LIST PIEZO_TARGET_SYSTEM_LIBS)
        set(skip "needs the host-only library ${lib}")
      endif()
    endforeach()
    if(skip)
      message(STATUS "${name}: skipped on ${PIEZO_TARGET}: ${skip}")
      add_test(NAME ${name} COMMAND ${name})
      set_tests_properties(${name} PROPERTIES DISABLED TRUE)
      return()
    endif()
  endif()
  add_executable(${name} ${T_SOURCES})
  target_link_libraries(${name} PRIVATE piezo_warnings ${T_LIBS} piezo_cmocka)
  foreach(kernel IN LISTS T_GOLDEN)
    piezo_golden_header(${kernel} header DEPENDS ${T_DEPENDS} ENV ${T_ENV})
    target_sources(${name} PRIVATE ${header})
  endforeach()
  foreach(fixture IN LISTS T_FIXTURES)
    piezo_fixture_header(${fixture} header DEPENDS ${T_DEPENDS} ENV ${T_ENV})
    target_sources(${name} PRIVATE ${header})
  endforeach()
  target_include_directories(${name} PRIVATE ${CMAKE_BINARY_DIR}/golden ${CMAKE_BINARY_DIR}/fixtures)
  add_test(NAME ${name} COMMAND ${name})
  set_tests_properties(${name} PROPERTIES ENVIRONMENT "CMOCKA_MESSAGE_OUTPUT=stdout")
  if(COMMAND piezo_target_test_image)
    piezo_target_test_image(${name}) # cross builds: startup, linker script, QEMU
  endif()
endfunction()

# piezo_golden_header(kernel outvar [DEPENDS file...] [ENV VAR=value...])
# golden/<kernel>_vectors.h from the bit-exact twin piezoctl.golden.<kernel>;
# target golden_<kernel>.
function(piezo_golden_header kernel outvar)
  _piezo_host_header(golden ${kernel} out "Golden vectors for ${kernel} from the host golden model" ${ARGN})
  set(${outvar} ${out} PARENT_SCOPE)
endfunction()

# piezo_fixture_header(name outvar [DEPENDS file...] [ENV VAR=value...])
# fixtures/<name>_vectors.h from the fixture generator piezoctl.fixtures.<name>
# (tables designed for the SIL stage, test images); target fixture_<name>.
function(piezo_fixture_header name outvar)
  _piezo_host_header(fixtures ${name} out "Test fixture ${name} from piezoctl.fixtures" ${ARGN})
  set(${outvar} ${out} PARENT_SCOPE)
endfunction()

# python -m piezoctl.<package>.export <name> -o ${CMAKE_BINARY_DIR}/<package>/<name>_vectors.h,
# once per build tree (target golden_<name> or fixture_<name>).
function(_piezo_host_header package name outvar comment)
  cmake_parse_arguments(G "" "" "DEPENDS;ENV" ${ARGN})
  set(out ${CMAKE_BINARY_DIR}/${package}/${name}_vectors.h)
  if(package STREQUAL "golden")
    set(tgt golden_${name})
  else()
    set(tgt fixture_${name})
  endif()
  if(NOT TARGET ${tgt})
    file(GLOB_RECURSE host_sources CONFIGURE_DEPENDS
         ${PROJECT_SOURCE_DIR}/host/piezoctl/*.py)
    add_custom_command(
      OUTPUT ${out}
      COMMAND ${CMAKE_COMMAND} -E make_directory ${CMAKE_BINARY_DIR}/${package}
      COMMAND ${CMAKE_COMMAND} -E env ${G_ENV} ${PIEZOCTL_PYTHON} -m piezoctl.${package}.export ${name} -o ${out}
      DEPENDS ${host_sources} ${G_DEPENDS}
      COMMENT "${comment}"
      VERBATIM)
    add_custom_target(${tgt} DEPENDS ${out})
  endif()
  set(${outvar} ${out} PARENT_SCOPE)
endfunction()

# piezo_add_cli_test(NAME TARGET executable [ARGS arg...] EXPECT regex)
# Runs a host executable of this build with ARGS: its stdout and stderr, then
# a line "status=N" (its exit status), must match EXPECT.
function(piezo_add_cli_test name)
  cmake_parse_arguments(C "" "TARGET;EXPECT" "ARGS" ${ARGN})
  add_test(NAME ${name}
    COMMAND sh -c "\"$0\" \"$@\" 2>&1; echo \"status=$?\"" $<TARGET_FILE:${C_TARGET}> ${C_ARGS})
  set_tests_properties(${name} PROPERTIES PASS_REGULAR_EXPRESSION "${C_EXPECT}")
endfunction()
