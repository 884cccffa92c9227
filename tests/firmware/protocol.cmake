# Modbus protocol layer (firmware/protocol): PDU server, RTU framer, MBAP,
# USB bulk framing; interop with libmodbus over a pseudo-terminal and TCP.
add_library(test_modbus_regs STATIC test_modbus_regs.c)
target_link_libraries(test_modbus_regs PUBLIC piezo_protocol PRIVATE piezo_warnings)
target_include_directories(test_modbus_regs PUBLIC ${CMAKE_CURRENT_SOURCE_DIR})

piezo_add_cmocka_test(test_modbus_pdu SOURCES test_modbus_pdu.c LIBS test_modbus_regs)
piezo_add_cmocka_test(test_modbus_rtu SOURCES test_modbus_rtu.c LIBS test_modbus_regs)
piezo_add_cmocka_test(test_modbus_usb SOURCES test_modbus_usb.c LIBS test_modbus_regs)
if(TARGET piezo_protocol_tcp)
  piezo_add_cmocka_test(test_modbus_tcp SOURCES test_modbus_tcp.c LIBS test_modbus_regs piezo_protocol_tcp)
endif()

# The framers' per-byte and per-request code must not divide: the same
# sources as piezo_protocol minus modbus_rtu_init.c (the set-up, which does).
if(NOT CMAKE_CROSSCOMPILING)
  set(proto_dir ${PROJECT_SOURCE_DIR}/firmware/protocol)
  add_library(protocol_nodiv_check STATIC ${proto_dir}/modbus_pdu.c ${proto_dir}/modbus_rtu.c
              ${proto_dir}/modbus_tcp.c ${proto_dir}/usb_bulk.c)
  target_include_directories(protocol_nodiv_check PRIVATE ${proto_dir})
  target_link_libraries(protocol_nodiv_check PRIVATE piezo_core_warnings)
  add_test(NAME protocol_has_no_division
           COMMAND ${CMAKE_COMMAND} -DOBJDUMP=${CMAKE_OBJDUMP}
                   -DLIB=$<TARGET_FILE:protocol_nodiv_check>
                   -P ${PROJECT_SOURCE_DIR}/cmake/CheckNoDivision.cmake)
endif()

# Interop with libmodbus's clients: the RTU framer behind a pseudo-terminal,
# the TCP server loop on 127.0.0.1 (test servers also used by the pytest
# interop tests with pymodbus, tests/host/test_rtu_interop.py). Host only.
if(NOT CMAKE_CROSSCOMPILING)
  add_executable(rtu_pty_server rtu_pty_server.c)
  target_link_libraries(rtu_pty_server PRIVATE piezo_warnings test_modbus_regs util)
endif()
if(TARGET piezo_protocol_tcp)
  add_executable(tcp_modbus_server tcp_modbus_server.c)
  target_link_libraries(tcp_modbus_server PRIVATE piezo_warnings test_modbus_regs piezo_protocol_tcp)
  add_executable(test_modbus_libmodbus test_modbus_libmodbus.c test_modbus_spawn.c)
  target_link_libraries(test_modbus_libmodbus PRIVATE piezo_warnings test_modbus_regs
                        piezo_protocol_tcp piezo_cmocka)
  add_test(NAME test_modbus_rtu_libmodbus
           COMMAND test_modbus_libmodbus rtu $<TARGET_FILE:rtu_pty_server>)
  add_test(NAME test_modbus_tcp_libmodbus
           COMMAND test_modbus_libmodbus tcp $<TARGET_FILE:tcp_modbus_server>)
  set_tests_properties(test_modbus_rtu_libmodbus test_modbus_tcp_libmodbus PROPERTIES
                       ENVIRONMENT "CMOCKA_MESSAGE_OUTPUT=stdout" TIMEOUT 60)
endif()
