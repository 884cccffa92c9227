# Strict warnings for our own C code; the core gets the strictest set.
add_library(piezo_warnings INTERFACE)
target_compile_options(piezo_warnings INTERFACE
  -Wall -Wextra -Wpedantic -Werror -Wshadow -Wstrict-prototypes
  -Wmissing-prototypes -Wdouble-promotion -Wvla -Wcast-qual -Wundef)

add_library(piezo_core_warnings INTERFACE)
target_link_libraries(piezo_core_warnings INTERFACE piezo_warnings)
target_compile_options(piezo_core_warnings INTERFACE -Wconversion -Wsign-conversion)
