#include "table_image.h"

#include <stddef.h>

#include "crc32.h"

uint16_t piezo_le16(const uint8_t *p)
{
    return (uint16_t)(p[0] | (p[1] << 8));
}

uint32_t piezo_le32(const uint8_t *p)
{
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}

int16_t piezo_section_i16(const piezo_section_t *s, uint32_t i)
{
    return (int16_t)piezo_le16(s->data + 2u * (size_t)i);
}

int32_t piezo_section_i32(const piezo_section_t *s, uint32_t i)
{
    return (int32_t)piezo_le32(s->data + 4u * (size_t)i);
}

const piezo_section_t *piezo_table_section(const piezo_table_info_t *info, uint16_t id)
{
    for (uint16_t i = 0; i < info->n_sections; i++) {
        if (info->section[i].id == id) {
            return &info->section[i];
        }
    }
    return NULL;
}

/* Walks the section chain; every byte of the payload must belong to a section. */
static uint16_t parse_sections(const uint8_t *p, uint32_t len, uint16_t n, piezo_table_info_t *info)
{
    uint32_t off = 0u;
    if (n > PIEZO_TABLE_MAX_SECTIONS) {
        return PIEZO_TABLE_REASON_BAD_SECTION;
    }
    for (uint16_t i = 0; i < n; i++) {
        uint32_t shift, bytes, padded;
        piezo_section_t *s = &info->section[i];
        if (len - off < 8u) {
            return PIEZO_TABLE_REASON_BAD_LENGTH;
        }
        s->id = piezo_le16(p + off);
        s->type = piezo_le16(p + off + 2u);
        s->count = piezo_le32(p + off + 4u);
        off += 8u;
        if (s->type == PIEZO_SECTION_TYPE_INT16) {
            shift = 1u;
        } else if (s->type == PIEZO_SECTION_TYPE_INT32) {
            shift = 2u;
        } else {
            return PIEZO_TABLE_REASON_BAD_SECTION;
        }
        if (s->count > ((len - off) >> shift)) {
            return PIEZO_TABLE_REASON_BAD_LENGTH;
        }
        bytes = s->count << shift;
        padded = (bytes + 3u) & ~3u;
        if (padded > len - off) {
            return PIEZO_TABLE_REASON_BAD_LENGTH;
        }
        for (uint32_t k = bytes; k < padded; k++) {
            if (p[off + k] != 0u) {
                return PIEZO_TABLE_REASON_BAD_SECTION;
            }
        }
        for (uint16_t j = 0; j < i; j++) {
            if (info->section[j].id == s->id) {
                return PIEZO_TABLE_REASON_BAD_SECTION;
            }
        }
        s->data = p + off;
        off += padded;
    }
    return off == len ? PIEZO_TABLE_REASON_OK : PIEZO_TABLE_REASON_BAD_LENGTH;
}

static const piezo_section_spec_t *spec_of(uint16_t id)
{
    for (uint32_t i = 0; i < PIEZO_SECTION_SPEC_N; i++) {
        if (piezo_section_specs[i].id == id) {
            return &piezo_section_specs[i];
        }
    }
    return NULL;
}

static int32_t element(const piezo_section_t *s, uint32_t i)
{
    return s->type == PIEZO_SECTION_TYPE_INT16 ? piezo_section_i16(s, i) : piezo_section_i32(s, i);
}

/* Every section against its specification (interface.toml): known for this
 * kind, its type, its field count, every element in range; then every section
 * the kind needs present. */
uint16_t piezo_table_check_specs(const piezo_table_info_t *info)
{
    uint32_t bit, any = 0u;
    if (info->kind >= 32u) {
        return PIEZO_TABLE_REASON_BAD_KIND;
    }
    bit = 1u << info->kind;
    for (uint32_t i = 0; i < PIEZO_SECTION_SPEC_N; i++) {
        any |= piezo_section_specs[i].kinds;
    }
    if ((any & bit) == 0u) {
        return PIEZO_TABLE_REASON_BAD_KIND;
    }
    for (uint16_t i = 0; i < info->n_sections; i++) {
        const piezo_section_t *s = &info->section[i];
        const piezo_section_spec_t *sp = spec_of(s->id);
        if (sp == NULL || (sp->kinds & bit) == 0u) {
            return PIEZO_TABLE_REASON_UNKNOWN_SECTION;
        }
        if (s->type != sp->type) {
            return PIEZO_TABLE_REASON_BAD_SECTION;
        }
        if (sp->n_fields != 0u && s->count != sp->n_fields) {
            return PIEZO_TABLE_REASON_BAD_LENGTH;
        }
        for (uint32_t k = 0; k < s->count; k++) {
            const piezo_range_t *r = sp->n_fields != 0u ? &piezo_section_fields[sp->first_field + k] : &sp->range;
            int32_t v = element(s, k);
            if (v < r->min || v > r->max) {
                return PIEZO_TABLE_REASON_OUT_OF_RANGE;
            }
        }
    }
    for (uint32_t i = 0; i < PIEZO_SECTION_SPEC_N; i++) {
        if ((piezo_section_specs[i].kinds & bit) != 0u && piezo_table_section(info, piezo_section_specs[i].id) == NULL) {
            return PIEZO_TABLE_REASON_MISSING_SECTION;
        }
    }
    return PIEZO_TABLE_REASON_OK;
}

uint16_t piezo_table_check(const uint8_t *img, uint32_t len, piezo_table_info_t *info)
{
    uint32_t payload_len;
    if (img == NULL || info == NULL || len < PIEZO_TABLE_HDR_BYTES + 4u || len > PIEZO_TABLE_MAX_BYTES) {
        return PIEZO_TABLE_REASON_BAD_LENGTH;
    }
    if (piezo_le32(img + PIEZO_TABLE_HDR_MAGIC_OFFSET) != PIEZO_TABLE_MAGIC) {
        return PIEZO_TABLE_REASON_BAD_MAGIC;
    }
    payload_len = piezo_le32(img + PIEZO_TABLE_HDR_PAYLOAD_LEN_OFFSET);
    if (piezo_le16(img + PIEZO_TABLE_HDR_HEADER_BYTES_OFFSET) != PIEZO_TABLE_HDR_BYTES ||
        payload_len != len - PIEZO_TABLE_HDR_BYTES - 4u) {
        return PIEZO_TABLE_REASON_BAD_LENGTH;
    }
    /* the CRC first: a flipped bit anywhere is reported as what it is */
    info->crc = piezo_le32(img + len - 4u);
    if (piezo_crc32(0u, img, len - 4u) != info->crc) {
        return PIEZO_TABLE_REASON_BAD_CRC;
    }
    if (piezo_le16(img + PIEZO_TABLE_HDR_LAYOUT_VERSION_OFFSET) != PIEZO_LAYOUT_VERSION) {
        return PIEZO_TABLE_REASON_BAD_LAYOUT_VERSION;
    }
    if (piezo_le32(img + PIEZO_TABLE_HDR_INTERFACE_CRC_OFFSET) != PIEZO_INTERFACE_CRC32) {
        return PIEZO_TABLE_REASON_BAD_INTERFACE_CRC;
    }
    if (piezo_le16(img + PIEZO_TABLE_HDR_Q_SIGNAL_FRAC_OFFSET) != PIEZO_Q15_FRAC ||
        piezo_le16(img + PIEZO_TABLE_HDR_Q_COEF_FRAC_OFFSET) != PIEZO_Q24_FRAC) {
        return PIEZO_TABLE_REASON_BAD_LAYOUT_VERSION;
    }
    if (piezo_le16(img + PIEZO_TABLE_HDR_RESERVED_OFFSET) != 0u) {
        return PIEZO_TABLE_REASON_BAD_LAYOUT_VERSION;
    }
    info->kind = piezo_le16(img + PIEZO_TABLE_HDR_KIND_OFFSET);
    info->axis = piezo_le16(img + PIEZO_TABLE_HDR_AXIS_OFFSET);
    info->drive_min_mv = (int32_t)piezo_le32(img + PIEZO_TABLE_HDR_DRIVE_MIN_MV_OFFSET);
    info->drive_max_mv = (int32_t)piezo_le32(img + PIEZO_TABLE_HDR_DRIVE_MAX_MV_OFFSET);
    info->position_min_nm = (int32_t)piezo_le32(img + PIEZO_TABLE_HDR_POSITION_MIN_NM_OFFSET);
    info->position_max_nm = (int32_t)piezo_le32(img + PIEZO_TABLE_HDR_POSITION_MAX_NM_OFFSET);
    info->table_version = piezo_le32(img + PIEZO_TABLE_HDR_TABLE_VERSION_OFFSET);
    info->total_len = len;
    info->n_sections = piezo_le16(img + PIEZO_TABLE_HDR_N_SECTIONS_OFFSET);
    uint16_t r = parse_sections(img + PIEZO_TABLE_HDR_BYTES, payload_len, info->n_sections, info);
    return r;
}
