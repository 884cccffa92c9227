/*
 * table_image.h - parse a coefficient-table image without trusting it.
 *
 * Image (common/interface.toml, docs/tables.md): a little-endian header of
 * PIEZO_TABLE_HDR_BYTES, payload_len bytes of sections, then a CRC-32 over
 * everything before it. Each section: id (uint16), type (uint16: int16 or
 * int32), count (uint32), count elements, zero padding to a multiple of 4.
 *
 * piezo_table_check() is the one place that reads a header: it validates
 * lengths and the CRC first, then magic, layout version, interface CRC, the
 * section chain (every section inside the payload, known type, padding zero,
 * no duplicate id); piezo_table_check_specs() then checks every section
 * against its specification in
 * common/interface.toml (generated piezo_section_specs): a section id the kind
 * does not have (unknown_section), a section the kind needs and lacks
 * (missing_section), an element type or field count that differs
 * (bad_section, bad_length), an element outside its documented range
 * (out_of_range). It fills an info struct with the header fields the
 * controller needs (kind, version, the stage it was built for); everything
 * after it dispatches on that struct, never on the raw bytes. Nothing is
 * copied: sections point into the caller's buffer, read with explicit
 * little-endian loads (no alignment assumed).
 */
#ifndef PIEZO_TABLE_IMAGE_H
#define PIEZO_TABLE_IMAGE_H

#include <stdint.h>

#include "piezo_interface.h"

#define PIEZO_TABLE_MAX_SECTIONS 32u

typedef struct {
    uint16_t id;
    uint16_t type;          /* PIEZO_SECTION_TYPE_* */
    uint32_t count;         /* elements */
    const uint8_t *data;    /* first element, little-endian */
} piezo_section_t;

typedef struct {
    uint16_t kind;          /* PIEZO_TABLE_KIND_* */
    uint16_t axis;          /* axis the table was built for */
    int32_t drive_min_mv;   /* stage the table was built for: drive and */
    int32_t drive_max_mv;   /* position of q15 -32768 / +32768 */
    int32_t position_min_nm;
    int32_t position_max_nm;
    uint32_t table_version;
    uint32_t crc;           /* the image's CRC-32 (its last four bytes) */
    uint32_t total_len;     /* header + payload + CRC */
    uint16_t n_sections;
    piezo_section_t section[PIEZO_TABLE_MAX_SECTIONS];
} piezo_table_info_t;

uint16_t piezo_le16(const uint8_t *p);
uint32_t piezo_le32(const uint8_t *p);

/** Validate an image of len bytes; returns PIEZO_TABLE_REASON_OK or the reason. */
uint16_t piezo_table_check(const uint8_t *img, uint32_t len, piezo_table_info_t *info);

/** Every section of a checked image against its specification (see above):
 *  PIEZO_TABLE_REASON_OK, unknown_section, missing_section, bad_section,
 *  bad_length, out_of_range or bad_kind. The store keeps any image that
 *  passes piezo_table_check(); a commit needs both. */
uint16_t piezo_table_check_specs(const piezo_table_info_t *info);

/** The section with this id, or NULL. */
const piezo_section_t *piezo_table_section(const piezo_table_info_t *info, uint16_t id);

/** Element i of an int16 / int32 section (caller checked type and count). */
int16_t piezo_section_i16(const piezo_section_t *s, uint32_t i);
int32_t piezo_section_i32(const piezo_section_t *s, uint32_t i);

#endif /* PIEZO_TABLE_IMAGE_H */
