# Closed-loop compensation on the default SIL stage (test_sil_closed_loop).
# Its header comes from the fixture generator piezoctl.fixtures.sil_tables, which
# calibrates the C stage model from Python at build time: the export needs the
# stage's shared library built first and named in PIEZOCTL_STAGE_LIB. The
# export target is defined in firmware/targets/sil/CMakeLists.txt (with a
# plain, unsanitized copy of the library in sanitizer builds); the same
# DEPENDS and ENV are given here.
if(TARGET piezo_sil AND TARGET piezo_stage_shared)
  if(TARGET piezo_stage_plain)
    set(sil_stage_lib piezo_stage_plain)
  else()
    set(sil_stage_lib piezo_stage_shared)
  endif()
  piezo_add_cmocka_test(test_sil_closed_loop
    SOURCES ${CMAKE_CURRENT_LIST_DIR}/test_sil_closed_loop.c
    LIBS piezo_sil m
    FIXTURES sil_tables
    DEPENDS ${sil_stage_lib}
    ENV PIEZOCTL_STAGE_LIB=$<TARGET_FILE:${sil_stage_lib}>)
  # the header's rule lives in the SIL target's directory: order the builds
  add_dependencies(test_sil_closed_loop fixture_sil_tables)
  target_compile_definitions(test_sil_closed_loop PRIVATE
    STAGE_FILE="${CMAKE_CURRENT_LIST_DIR}/../../firmware/targets/sil/stages/default.json")
  set_tests_properties(test_sil_closed_loop PROPERTIES LABELS sil TIMEOUT 300)
endif()

# sil-stage's command line (firmware/targets/common/cmdline.c): help, the
# errors and their exit status, before anything is opened.
if(TARGET sil_stage)
  set(sil_usage "usage: sil-stage --modbus-tcp HOST:PORT [^\n]*\n[^\n]*--rtu-baud BAUD[^\n]*\n")
  piezo_add_cli_test(sil_stage_cli_help TARGET sil_stage ARGS --help
    EXPECT "^${sil_usage}status=0\n$")
  piezo_add_cli_test(sil_stage_cli_no_value TARGET sil_stage ARGS --seed 3 --modbus-tcp
    EXPECT "^sil-stage: --modbus-tcp needs a value\n${sil_usage}status=2\n$")
  piezo_add_cli_test(sil_stage_cli_unknown TARGET sil_stage ARGS --modbus-tcp 127.0.0.1:0 --port 5020
    EXPECT "^sil-stage: unknown option --port\n${sil_usage}status=2\n$")
  piezo_add_cli_test(sil_stage_cli_required TARGET sil_stage ARGS --stage --help
    EXPECT "^sil-stage: --modbus-tcp HOST:PORT is required\n${sil_usage}status=2\n$")
  piezo_add_cli_test(sil_stage_cli_host_port TARGET sil_stage ARGS --modbus-tcp localhost
    EXPECT "^sil-stage: --modbus-tcp wants HOST:PORT, got localhost\nstatus=2\n$")
  piezo_add_cli_test(sil_stage_cli_bad_port TARGET sil_stage ARGS --modbus-tcp 127.0.0.1:65536
    EXPECT "^sil-stage: bad port in 127.0.0.1:65536\nstatus=2\n$")
endif()

# The commit's checks on the calibrated SIL tables (issue 13): the absurd
# images, ranges, sections, the kernel sweep and its time, stage and axis,
# sessions, backoff and lockout.
if(TARGET piezo_sil AND TARGET piezo_stage_shared)
  piezo_add_cmocka_test(test_commit_checks
    SOURCES ${CMAKE_CURRENT_LIST_DIR}/test_commit_checks.c
    LIBS piezo_control
    FIXTURES sil_tables
    DEPENDS ${sil_stage_lib}
    ENV PIEZOCTL_STAGE_LIB=$<TARGET_FILE:${sil_stage_lib}>)
  add_dependencies(test_commit_checks fixture_sil_tables)
endif()
