# Prandtl-Ishlinskii family: CPI/UPI play operator bank, EUPI model, EUPI inverse.
piezo_add_cmocka_test(test_play SOURCES test_play.c LIBS piezo_core GOLDEN play)
piezo_add_cmocka_test(test_eupi SOURCES test_eupi.c LIBS piezo_core GOLDEN eupi)
piezo_add_cmocka_test(test_eupi_inv SOURCES test_eupi_inv.c LIBS piezo_core GOLDEN eupi_inv)
