# Tests of the cross-coupling predictor (firmware/core/xcouple.c).
piezo_add_cmocka_test(test_xcouple SOURCES test_xcouple.c LIBS piezo_core GOLDEN xcouple)
