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
