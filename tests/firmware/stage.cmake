# Tests of the SIL stage model (firmware/targets/sil/stage): every block
# against its analytic response, the parameter file reader, determinism.
if(TARGET piezo_stage)
  foreach(part blocks json run)
    piezo_add_cmocka_test(test_stage_${part}
      SOURCES ${CMAKE_CURRENT_LIST_DIR}/test_stage_${part}.c LIBS piezo_stage)
    target_compile_definitions(test_stage_${part} PRIVATE
      STAGE_DIR="${CMAKE_CURRENT_LIST_DIR}/../../firmware/targets/sil/stages"
      STAGE_TMP_DIR="${CMAKE_CURRENT_BINARY_DIR}")
  endforeach()
endif()
