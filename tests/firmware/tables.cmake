# Table images: parser and A/B storage.
piezo_add_cmocka_test(test_table_image SOURCES test_table_image.c LIBS piezo_tables FIXTURES tables)
piezo_add_cmocka_test(test_store SOURCES test_store.c nor_flash.c LIBS piezo_tables FIXTURES tables)
