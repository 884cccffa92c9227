# Tests of the KP kernel family: KP operators, RKP density, DCC law.
piezo_add_cmocka_test(test_kp SOURCES test_kp.c LIBS piezo_core GOLDEN kp)
