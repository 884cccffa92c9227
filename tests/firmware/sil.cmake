# Closed-loop compensation on the default SIL stage (test_sil_closed_loop):
# the golden module piezoctl.golden.sil_tables calibrates the C stage model
# from Python at build time, so its export needs the stage's shared library
# built first and pointed at through PIEZOCTL_STAGE_LIB.
#
# In a sanitizer build the library's objects carry ASan/UBSan, and Python can
# only load them with the sanitizer runtimes preloaded (LD_PRELOAD, which then
# instruments the whole interpreter and reports its allocations). The export
# uses a plain copy instead, built from the same sources with the sanitizers
# off: the same code, so the same samples, and the test itself still runs
# fully instrumented.
if(TARGET piezo_sil AND TARGET piezo_stage_shared)
  set(sil_stage_lib piezo_stage_shared)
  if(CMAKE_C_FLAGS MATCHES "-fsanitize=")
    get_target_property(sil_stage_src piezo_stage_obj SOURCES)
    get_target_property(sil_stage_dir piezo_stage_obj SOURCE_DIR)
    list(TRANSFORM sil_stage_src PREPEND ${sil_stage_dir}/)
    add_library(piezo_stage_plain SHARED ${sil_stage_src})
    target_compile_options(piezo_stage_plain PRIVATE -fno-sanitize=all)
    target_link_options(piezo_stage_plain PRIVATE -fno-sanitize=all)
    set_target_properties(piezo_stage_plain PROPERTIES OUTPUT_NAME piezo_stage_plain
      LIBRARY_OUTPUT_DIRECTORY ${CMAKE_CURRENT_BINARY_DIR})
    if(PIEZO_LIBM)
      target_link_libraries(piezo_stage_plain PRIVATE ${PIEZO_LIBM})
    endif()
    set(sil_stage_lib piezo_stage_plain)
  endif()
  piezo_add_cmocka_test(test_sil_closed_loop
    SOURCES ${CMAKE_CURRENT_LIST_DIR}/test_sil_closed_loop.c
    LIBS piezo_sil m
    GOLDEN sil_tables
    DEPENDS ${sil_stage_lib}
    ENV PIEZOCTL_STAGE_LIB=$<TARGET_FILE:${sil_stage_lib}>)
  target_compile_definitions(test_sil_closed_loop PRIVATE
    STAGE_FILE="${CMAKE_CURRENT_LIST_DIR}/../../firmware/targets/sil/stages/default.json")
  if(CMAKE_C_FLAGS MATCHES "-fsanitize=")
    target_compile_definitions(test_sil_closed_loop PRIVATE SIL_CL_SHORT=1)
  endif()
  set_tests_properties(test_sil_closed_loop PROPERTIES LABELS sil TIMEOUT 300)
endif()
