# Modbus protocol layer (firmware/protocol): PDU server, RTU framer, MBAP,
# USB bulk framing; interop with libmodbus over a pseudo-terminal and TCP.
add_library(test_modbus_regs STATIC test_modbus_regs.c)
target_link_libraries(test_modbus_regs PUBLIC piezo_protocol PRIVATE piezo_warnings)
target_include_directories(test_modbus_regs PUBLIC ${CMAKE_CURRENT_SOURCE_DIR})

piezo_add_cmocka_test(test_modbus_pdu SOURCES test_modbus_pdu.c LIBS test_modbus_regs)
piezo_add_cmocka_test(test_modbus_rtu SOURCES test_modbus_rtu.c LIBS test_modbus_regs)
