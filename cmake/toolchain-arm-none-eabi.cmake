# Cross toolchain: Debian's arm-none-eabi-gcc for the Cortex-M4 target
# (firmware/targets/cortex-m4). Hard-float ABI with the FPv4-SP unit; the core
# itself uses no floating point (checked on the linked image).
set(CMAKE_SYSTEM_NAME Generic)
set(CMAKE_SYSTEM_PROCESSOR arm)

find_program(CMAKE_C_COMPILER arm-none-eabi-gcc REQUIRED)
find_program(CMAKE_AR arm-none-eabi-ar REQUIRED)
find_program(CMAKE_RANLIB arm-none-eabi-ranlib REQUIRED)
find_program(CMAKE_OBJCOPY arm-none-eabi-objcopy REQUIRED)
find_program(CMAKE_OBJDUMP arm-none-eabi-objdump REQUIRED)
find_program(CMAKE_NM arm-none-eabi-nm REQUIRED)
find_program(PIEZO_SIZE arm-none-eabi-size REQUIRED)

set(PIEZO_ARCH_FLAGS "-mcpu=cortex-m4 -mthumb -mfloat-abi=hard -mfpu=fpv4-sp-d16")
set(CMAKE_C_FLAGS_INIT "${PIEZO_ARCH_FLAGS} -ffunction-sections -fdata-sections")
# Our own startup code (no crt0): the target's Reset_Handler calls main().
set(CMAKE_EXE_LINKER_FLAGS_INIT "${PIEZO_ARCH_FLAGS} -nostartfiles -Wl,--gc-sections")
# No executable can run without a linker script and startup: try_compile builds
# static libraries only.
set(CMAKE_TRY_COMPILE_TARGET_TYPE STATIC_LIBRARY)

set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE ONLY)

# Which board support firmware/CMakeLists.txt adds (firmware/targets/<name>).
set(PIEZO_TARGET cortex-m4 CACHE STRING "firmware target directory")
# Libraries that are not CMake targets but exist on this toolchain (newlib).
set(PIEZO_TARGET_SYSTEM_LIBS m c)

# CTest runs every test image under QEMU (netduinoplus2: STM32F405, Cortex-M4)
# through this wrapper; add_test(NAME x COMMAND x) picks it up.
set(CMAKE_CROSSCOMPILING_EMULATOR
    ${CMAKE_CURRENT_LIST_DIR}/../firmware/targets/cortex-m4/qemu-run)
