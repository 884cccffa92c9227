/* CRC-32 (IEEE 802.3, reflected, polynomial 0xEDB88320, init and final XOR
 * 0xFFFFFFFF): the same value as Python's zlib.crc32. Bitwise, no table: it
 * runs on table upload, never in the tick. */
#ifndef PIEZO_CRC32_H
#define PIEZO_CRC32_H

#include <stddef.h>
#include <stdint.h>

/** Continue a CRC over len bytes; start with crc = 0. */
uint32_t piezo_crc32(uint32_t crc, const uint8_t *data, size_t len);

#endif /* PIEZO_CRC32_H */
