# (Named to sort after protocol.cmake: test_usb_dev links its test_modbus_regs.)
# Drivers of the Cortex-M4 target tested on the host (and as target images)
# against models of their peripherals: the STM32F405 flash interface.
set(PIEZO_CM4_DIR ${PROJECT_SOURCE_DIR}/firmware/targets/cortex-m4)
piezo_add_cmocka_test(test_flash_f4 SOURCES test_flash_f4.c f4_flash_model.c ${PIEZO_CM4_DIR}/src/flash_f4.c
                      LIBS piezo_tables FIXTURES tables)
if(TARGET test_flash_f4)
  target_include_directories(test_flash_f4 PRIVATE ${PIEZO_CM4_DIR}/include)
  # a few polls, not the chip's 2 s: the model's busy time is counted in polls
  target_compile_definitions(test_flash_f4 PRIVATE PIEZO_FLASH_BSY_POLLS=1000u)
endif()

# The reference design's converters (AD5791 DAC, AD7980 ADC) against a fake
# SPI peripheral with both parts on it.
piezo_add_cmocka_test(test_converters_spi SOURCES test_converters_spi.c fake_spi.c
                      ${PIEZO_CM4_DIR}/src/converters_spi.c)
if(TARGET test_converters_spi)
  target_include_directories(test_converters_spi PRIVATE ${PIEZO_CM4_DIR}/include)
endif()

# USB device layer (descriptors, chapter 9 requests, bulk endpoints with the
# usb_bulk framing): QEMU models no OTG, so the host drives it as a host would.
piezo_add_cmocka_test(test_usb_dev SOURCES test_usb_dev.c ${PIEZO_CM4_DIR}/src/usb_dev.c
                      LIBS piezo_protocol test_modbus_regs)
if(TARGET test_usb_dev)
  target_include_directories(test_usb_dev PRIVATE ${PIEZO_CM4_DIR}/include)
endif()

# The OTG FS driver's register sequences against a fake core (QEMU has no OTG).
piezo_add_cmocka_test(test_usb_otgfs SOURCES test_usb_otgfs.c fake_otgfs.c ${PIEZO_CM4_DIR}/src/usb_otgfs.c
                      ${PIEZO_CM4_DIR}/src/usb_dev.c LIBS piezo_protocol test_modbus_regs)
if(TARGET test_usb_otgfs)
  target_include_directories(test_usb_otgfs PRIVATE ${PIEZO_CM4_DIR}/include)
endif()

# The firmware image's USB glue (usb_board.c: clock, pins, interrupt, the
# background poll) against the fake core and a record of its RCC/GPIO/NVIC
# writes: the init order of RM0090, init without a core (QEMU), dispatch.
piezo_add_cmocka_test(test_usb_board SOURCES test_usb_board.c fake_otgfs.c ${PIEZO_CM4_DIR}/src/usb_board.c
                      ${PIEZO_CM4_DIR}/src/usb_otgfs.c ${PIEZO_CM4_DIR}/src/usb_dev.c
                      LIBS piezo_protocol test_modbus_regs)
if(TARGET test_usb_board)
  target_include_directories(test_usb_board PRIVATE ${PIEZO_CM4_DIR}/include)
endif()
