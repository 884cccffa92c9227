/*
 * flash_file.h - flash emulation for the SIL target: a file with NOR
 * semantics (erase sets 0xFF, programming can only clear bits), so table
 * persistence and its power-cut behaviour are the same as on a board. Every
 * operation is written through and synced, so a killed process leaves the
 * file as a board would be left by a power cut between two operations.
 */
#ifndef PIEZO_FLASH_FILE_H
#define PIEZO_FLASH_FILE_H

#include <stdint.h>

#include "store.h"

typedef struct {
    int fd;
    uint32_t size;
} piezo_flash_file_t;

/** Opens (creating, erased) a flash file of size bytes; returns 0 or -1 with errno. */
int piezo_flash_file_open(piezo_flash_file_t *f, const char *path, uint32_t size);
void piezo_flash_file_close(piezo_flash_file_t *f);
/** Storage callbacks over the file, two slots of slot_bytes. */
piezo_storage_t piezo_flash_file_storage(piezo_flash_file_t *f, uint32_t slot_bytes);

#endif /* PIEZO_FLASH_FILE_H */
