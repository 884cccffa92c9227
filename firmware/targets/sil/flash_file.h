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
    char why[192]; /* after a failed open: what was found, one line (empty if errno says it all) */
} piezo_flash_file_t;

/**
 * Opens a flash file of size bytes (two slots of size / 2), creating it erased
 * when it does not exist or is empty. An existing file is used only if it is a
 * flash image of this layout: exactly size bytes, and each slot's 16-byte
 * record either erased (0xFF) or starting with PIEZO_STORE_MAGIC. Anything
 * else is refused and left untouched (never truncated): a file of another
 * size or content ("not a flash image"), or a flash image cut short ("truncated
 * flash image", which would lose a table). Returns 0, or -1 with errno
 * (EINVAL for a refused file) and f->why saying what was found.
 */
int piezo_flash_file_open(piezo_flash_file_t *f, const char *path, uint32_t size);
/** The same for a store whose records start with another magic (the
 *  parameter store: PIEZO_PARAMS_MAGIC, param_store.h). */
int piezo_flash_file_open_magic(piezo_flash_file_t *f, const char *path, uint32_t size, uint32_t magic);
void piezo_flash_file_close(piezo_flash_file_t *f);
/** Storage callbacks over the file, two slots of slot_bytes. */
piezo_storage_t piezo_flash_file_storage(piezo_flash_file_t *f, uint32_t slot_bytes);

#endif /* PIEZO_FLASH_FILE_H */
