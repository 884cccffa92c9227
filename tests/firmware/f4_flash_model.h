/*
 * f4_flash_model.h - a register-level model of the STM32F405 flash interface
 * (RM0090 section 3) for the driver's host test: KEYR's key sequence and the
 * CR lock, SER/SNB/STRT erase, PG programming with PSIZE, BSY for a number of
 * SR reads, EOP and the error flags (rc_w1), and the rules whose breach the
 * chip flags: a CR write while locked, programming without PG or with
 * another PSIZE (PGSERR, PGPERR), an unaligned word (PGAERR), a wrong key
 * (CR locked until reset), an operation started while BSY. Sectors 10 and 11
 * (tables: index 0, 1) are modelled over their first F4_MODEL_BYTES, sectors
 * 8 and 9 (parameters: index 2, 3) over their first F4_MODEL_PARAM_BYTES (a
 * parameter record is one slot of a few hundred bytes; the rest reads 0xFF).
 * The sizes keep the test image inside the chip's RAM under QEMU.
 */
#ifndef F4_FLASH_MODEL_H
#define F4_FLASH_MODEL_H

#include <stdint.h>

#define F4_MODEL_BYTES (20u * 1024u)
#define F4_MODEL_PARAM_BYTES 1024u

typedef struct {
    uint32_t sr, cr;
    int key_state;          /* 0: none, 1: KEY1 seen */
    int locked_until_reset; /* a wrong key */
    uint32_t busy_reads;    /* SR reads left with BSY set */
    uint32_t busy_len;      /* BSY length of each operation, in SR reads */
    int stuck_busy;         /* BSY never clears */
    uint32_t inject_sr;     /* error flags the next operation raises */
    /* rule breaches the chip would flag or hang on */
    uint32_t writes_while_locked, ops_while_busy, wrong_keys, key_writes;
    uint32_t erases[4], words_programmed;
    uint8_t mem[2][F4_MODEL_BYTES];        /* sectors 10, 11 */
    uint8_t pmem[2][F4_MODEL_PARAM_BYTES]; /* sectors 8, 9 */
} f4_flash_model_t;

extern f4_flash_model_t f4_model;
/* piezo_f4_flash_hold(): its depth (0 when balanced), and the polls that found
 * BSY set while not held (reset by the test) */
extern int f4_model_hold_depth;
extern unsigned f4_model_busy_polls_unheld;

/** Reset: CR locked, SR clear, all four sectors erased (0xFF). */
void f4_model_reset(uint32_t busy_len);

#endif /* F4_FLASH_MODEL_H */
