# Tests of the cross-coupling predictor (firmware/core/xcouple.c).
piezo_add_cmocka_test(test_xcouple SOURCES test_xcouple.c LIBS piezo_core GOLDEN xcouple)

# Closed loop on the two-axis SIL stage with the coupling table the host
# identifies from the C stage model (piezoctl.fixtures.xcouple_sil, at build time;
# the export loads the stage's shared library, so DEPENDS and ENV as in sil.cmake).
if(TARGET piezo_sil AND TARGET piezo_stage_shared)
  if(TARGET piezo_stage_plain)
    set(xc_stage_lib piezo_stage_plain)
  else()
    set(xc_stage_lib piezo_stage_shared)
  endif()
  piezo_add_cmocka_test(test_xcouple_sil
    SOURCES ${CMAKE_CURRENT_LIST_DIR}/test_xcouple_sil.c
    LIBS piezo_sil m
    FIXTURES xcouple_sil
    DEPENDS ${xc_stage_lib}
    ENV PIEZOCTL_STAGE_LIB=$<TARGET_FILE:${xc_stage_lib}>)
  target_compile_definitions(test_xcouple_sil PRIVATE
    STAGE_FILE="${CMAKE_CURRENT_LIST_DIR}/../../firmware/targets/sil/stages/two_axis.json")
  set_tests_properties(test_xcouple_sil PROPERTIES LABELS sil TIMEOUT 300)
endif()
