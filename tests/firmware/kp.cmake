# Tests of the KP kernel family: KP operators, RKP density, DCC law.
piezo_add_cmocka_test(test_kp SOURCES test_kp.c LIBS piezo_core GOLDEN kp)
piezo_add_cmocka_test(test_rkp SOURCES test_rkp.c LIBS piezo_core GOLDEN rkp)
piezo_add_cmocka_test(test_dcc SOURCES test_dcc.c LIBS piezo_core GOLDEN dcc)
