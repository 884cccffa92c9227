/* In-memory NOR flash for storage tests: program clears bits only, erase sets
 * 0xFF, and a power cut can be scheduled after any number of operations (the
 * operation that hits it is done only partly: half its bytes). */
#ifndef NOR_FLASH_H
#define NOR_FLASH_H

#include <stdint.h>

#include "store.h"

typedef struct {
    uint8_t *mem;
    uint32_t size;
    long ops_left; /* < 0: no power cut scheduled */
    int dead;      /* power is gone: every further operation fails */
} nor_flash_t;

void nor_flash_init(nor_flash_t *f, uint8_t *mem, uint32_t size);
piezo_storage_t nor_flash_storage(nor_flash_t *f, uint32_t slot_bytes);

#endif
