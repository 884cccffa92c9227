# Linux DAQ target (firmware/targets/linux-daq): the configuration reader, the
# comedi I/O against a link-time fake of comedilib's device calls
# (fake_comedi.c: the real libcomedi is linked for its pure conversion
# functions, every call that would touch a device is wrapped with
# -Wl,--wrap), the closed loop through the DAQ code path with the stage model
# behind the fake board, the pacing loop's statistics with a fake clock, and
# the executable's errors with no board present.
if(TARGET piezo_daq_io AND TARGET piezo_stage AND TARGET PkgConfig::COMEDILIB)
  set(piezo_daq_wrapped comedi_open comedi_close comedi_errno comedi_get_n_subdevices
      comedi_find_subdevice_by_type comedi_get_subdevice_type comedi_get_subdevice_flags
      comedi_get_n_channels comedi_get_n_ranges comedi_get_range comedi_get_maxdata
      comedi_do_insnlist comedi_data_read comedi_data_write
      comedi_get_default_calibration_path comedi_parse_calibration_file comedi_cleanup_calibration
      comedi_get_softcal_converter comedi_get_hardcal_converter)
  list(TRANSFORM piezo_daq_wrapped PREPEND "LINKER:--wrap=" OUTPUT_VARIABLE piezo_daq_wrap_opts)

  piezo_add_cmocka_test(test_daq_config SOURCES ${CMAKE_CURRENT_LIST_DIR}/test_daq_config.c LIBS piezo_daq_io)
  target_compile_definitions(test_daq_config PRIVATE DAQ_TMP_DIR="${CMAKE_CURRENT_BINARY_DIR}")

  piezo_add_cmocka_test(test_daq_io
    SOURCES ${CMAKE_CURRENT_LIST_DIR}/test_daq_io.c ${CMAKE_CURRENT_LIST_DIR}/fake_comedi.c
    LIBS piezo_daq_io piezo_stage PkgConfig::COMEDILIB m)
  target_link_options(test_daq_io PRIVATE ${piezo_daq_wrap_opts})

  if(TARGET piezo_target_common)
    piezo_add_cmocka_test(test_daq_pacer SOURCES ${CMAKE_CURRENT_LIST_DIR}/test_daq_pacer.c
      LIBS piezo_target_common)
  endif()

  # The closed loop uses the SIL target's tables (fixture sil_tables); its
  # export target is defined by the SIL part of the build, which CMake reads
  # after this file: register at the end of this directory.
  function(piezo_daq_closed_loop_test)
    if(NOT TARGET piezo_sil OR NOT TARGET fixture_sil_tables)
      message(STATUS "test_daq_closed_loop: needs the SIL target and its tables; not built")
      return()
    endif()
    piezo_add_cmocka_test(test_daq_closed_loop
      SOURCES ${CMAKE_CURRENT_LIST_DIR}/test_daq_closed_loop.c ${CMAKE_CURRENT_LIST_DIR}/fake_comedi.c
      LIBS piezo_daq_io piezo_sil PkgConfig::COMEDILIB m
      FIXTURES sil_tables)
    target_link_options(test_daq_closed_loop PRIVATE ${piezo_daq_wrap_opts})
    add_dependencies(test_daq_closed_loop fixture_sil_tables) # the export may live in another directory
    target_compile_definitions(test_daq_closed_loop PRIVATE
      STAGE_FILE="${PROJECT_SOURCE_DIR}/firmware/targets/sil/stages/default.json")
    set_tests_properties(test_daq_closed_loop PROPERTIES LABELS sil TIMEOUT 300)
  endfunction()
  cmake_language(DEFER CALL piezo_daq_closed_loop_test)

  # The executable with no board: a clear one-line error and exit status 1;
  # a broken configuration: file:line and exit status 2.
  if(TARGET daq_controller)
    set(cfg_dir ${CMAKE_CURRENT_BINARY_DIR}/daq)
    file(MAKE_DIRECTORY ${cfg_dir})
    file(WRITE ${cfg_dir}/missing_device.cfg
      "device = /nonexistent/comedi9\nflash = ${cfg_dir}/missing.flash\n[axis 0]\n"
      "ao.channel = 0\nao.range = 0\nai.channel = 0\nai.range = 0\n"
      "amplifier.gain = 15\nsensor.um_per_v = 1.2\n")
    file(WRITE ${cfg_dir}/bad_key.cfg
      "device = /nonexistent/comedi9\nflash = ${cfg_dir}/bad.flash\n[axis 0]\nao.chanel = 0\n")
    add_test(NAME daq_controller_missing_device
      COMMAND sh -c "\"$0\" --config \"$1\" --modbus-tcp 127.0.0.1:0 2>&1; echo \"status=$?\""
              $<TARGET_FILE:daq_controller> ${cfg_dir}/missing_device.cfg)
    set_tests_properties(daq_controller_missing_device PROPERTIES PASS_REGULAR_EXPRESSION
      "^daq-controller: cannot open comedi device /nonexistent/comedi9: No such file or directory[^\n]*\nstatus=1\n$")
    add_test(NAME daq_controller_bad_config
      COMMAND sh -c "\"$0\" --config \"$1\" --modbus-tcp 127.0.0.1:0 2>&1; echo \"status=$?\""
              $<TARGET_FILE:daq_controller> ${cfg_dir}/bad_key.cfg)
    set_tests_properties(daq_controller_bad_config PROPERTIES PASS_REGULAR_EXPRESSION
      "^daq-controller: [^\n]*/bad_key.cfg:4: unknown key 'ao.chanel'\nstatus=2\n$")

    # The command line (firmware/targets/common/cmdline.c): help, the errors
    # and their exit status, before the configuration is read.
    set(daq_usage "usage: daq-controller --config FILE --modbus-tcp HOST:PORT \\[--unlock-key HEX8\\]\n")
    piezo_add_cli_test(daq_controller_cli_help TARGET daq_controller ARGS -h
      EXPECT "^${daq_usage}status=0\n$")
    piezo_add_cli_test(daq_controller_cli_no_value TARGET daq_controller ARGS --config
      EXPECT "^daq-controller: --config needs a value\n${daq_usage}status=2\n$")
    piezo_add_cli_test(daq_controller_cli_unknown TARGET daq_controller
      ARGS --config ${cfg_dir}/missing_device.cfg --tcp 127.0.0.1:0
      EXPECT "^daq-controller: unknown option --tcp\n${daq_usage}status=2\n$")
    piezo_add_cli_test(daq_controller_cli_required TARGET daq_controller ARGS --modbus-tcp 127.0.0.1:0
      EXPECT "^daq-controller: --config FILE and --modbus-tcp HOST:PORT are required\n${daq_usage}status=2\n$")
    piezo_add_cli_test(daq_controller_cli_host_port TARGET daq_controller
      ARGS --config ${cfg_dir}/missing_device.cfg --modbus-tcp 5020
      EXPECT "^daq-controller: --modbus-tcp wants HOST:PORT, got 5020\nstatus=2\n$")
  endif()
endif()
