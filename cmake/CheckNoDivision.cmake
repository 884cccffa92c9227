# Fails when the core library contains an integer or floating-point division
# instruction (x86-64 host build). Run by CTest as core_has_no_division.
execute_process(COMMAND ${OBJDUMP} -d --no-show-raw-insn ${LIB}
                OUTPUT_VARIABLE dis RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "objdump failed on ${LIB}")
endif()
string(REGEX MATCHALL "\t(i?div[a-z]*|divs[sd]|divp[sd]|vdiv[a-z]*)[ \t][^\n]*" hits "${dis}")
if(hits)
  message(FATAL_ERROR "division in the core:\n${hits}")
endif()
string(REGEX MATCHALL "<[a-z_]+>:" syms "${dis}")
list(LENGTH syms nsyms)
message(STATUS "no division instruction in ${nsyms} functions of the core")
