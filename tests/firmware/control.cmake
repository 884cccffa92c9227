# Control-loop building blocks: wave generator, recorder, PID + notch, limiter.
piezo_add_cmocka_test(test_wave SOURCES test_wave.c LIBS piezo_core m)
piezo_add_cmocka_test(test_recorder SOURCES test_recorder.c LIBS piezo_core)
piezo_add_cmocka_test(test_pid SOURCES test_pid.c LIBS piezo_core m)
# The dynamics-inverse FIR of the feedforward path, bit for bit against its golden model.
piezo_add_cmocka_test(test_fir SOURCES test_fir.c LIBS piezo_core GOLDEN fir)
# The controller: tick pipeline, table commit/rollback/persistence, safety.
piezo_add_cmocka_test(test_controller SOURCES test_controller.c nor_flash.c LIBS piezo_control FIXTURES ctl)
piezo_add_cmocka_test(test_regmap SOURCES test_regmap.c LIBS piezo_control FIXTURES ctl)
# Controller parameters in flash (A/B, CRC) through the register map; the servo switch.
piezo_add_cmocka_test(params_store SOURCES params_store.c nor_flash.c LIBS piezo_control)
# The wave's learned feedforward (iterative learning control's table).
piezo_add_cmocka_test(test_wave_ff SOURCES test_wave_ff.c LIBS piezo_control)
# The RKP kind through piezo_ff_process against the RKP and DCC kernels called directly.
piezo_add_cmocka_test(test_ff_rkp SOURCES test_ff_rkp.c LIBS piezo_control GOLDEN rkp)
