/*
 * flash_f4.h - the STM32F405's embedded flash as table storage (the A/B slots
 * of firmware/tables/store.h), following RM0090 section 3 ("Embedded Flash
 * memory interface"): unlock by the KEYR key sequence (3.5.1), sector erase
 * with SER, SNB and STRT (3.6.3), programming with PG and PSIZE = x32 (3.6.4,
 * supply 2.7-3.6 V), BSY polled before and after every operation, and the
 * error flags PGSERR, PGPERR, PGAERR, WRPERR, OPERR (3.7.5) checked and
 * cleared; CR locked again after each operation.
 *
 * Slots: sector 10 (A, 0x080C0000) and sector 11 (B, 0x080E0000), 128 KiB
 * each, far from the code (which starts at sector 0).
 *
 * Register and memory access goes through four functions
 * (piezo_f4_flash_rd/wr for the registers at 0x40023C00, piezo_f4_mem_rd8 and
 * piezo_f4_mem_wr32 for the flash array): flash_f4_mmio.c maps them onto the
 * chip; the host test (tests/firmware/test_flash_f4.c) onto a register-level
 * model. QEMU 7.2 models no flash interface (its 0x40023C00 reads 0 and the
 * flash is ROM): the PIL image stores tables in RAM behind the same
 * piezo_storage_t (piezo_ram_storage()).
 */
#ifndef PIEZO_FLASH_F4_H
#define PIEZO_FLASH_F4_H

#include <stdint.h>

#include "store.h"

/* RM0090 3.9: register offsets from 0x40023C00 */
#define PIEZO_FLASH_ACR 0x00u
#define PIEZO_FLASH_KEYR 0x04u
#define PIEZO_FLASH_OPTKEYR 0x08u
#define PIEZO_FLASH_SR 0x0Cu
#define PIEZO_FLASH_CR 0x10u
#define PIEZO_FLASH_OPTCR 0x14u

/* RM0090 3.5.1: the key sequence */
#define PIEZO_FLASH_KEY1 0x45670123u
#define PIEZO_FLASH_KEY2 0xCDEF89ABu

/* RM0090 3.9.4 FLASH_SR */
#define PIEZO_FLASH_SR_EOP (1u << 0)
#define PIEZO_FLASH_SR_OPERR (1u << 1)
#define PIEZO_FLASH_SR_WRPERR (1u << 4)
#define PIEZO_FLASH_SR_PGAERR (1u << 5)
#define PIEZO_FLASH_SR_PGPERR (1u << 6)
#define PIEZO_FLASH_SR_PGSERR (1u << 7)
#define PIEZO_FLASH_SR_BSY (1u << 16)
#define PIEZO_FLASH_SR_ERRORS (PIEZO_FLASH_SR_OPERR | PIEZO_FLASH_SR_WRPERR | PIEZO_FLASH_SR_PGAERR | \
                               PIEZO_FLASH_SR_PGPERR | PIEZO_FLASH_SR_PGSERR)

/* RM0090 3.9.5 FLASH_CR */
#define PIEZO_FLASH_CR_PG (1u << 0)
#define PIEZO_FLASH_CR_SER (1u << 1)
#define PIEZO_FLASH_CR_SNB_SHIFT 3u
#define PIEZO_FLASH_CR_SNB_MASK (0xFu << 3)
#define PIEZO_FLASH_CR_PSIZE_X32 (2u << 8)
#define PIEZO_FLASH_CR_PSIZE_MASK (3u << 8)
#define PIEZO_FLASH_CR_STRT (1u << 16)
#define PIEZO_FLASH_CR_LOCK (1u << 31)

#define PIEZO_FLASH_SLOT_A_SECTOR 10u
#define PIEZO_FLASH_SLOT_A_ADDR 0x080C0000u
#define PIEZO_FLASH_SLOT_BYTES (128u * 1024u)

/* The controller parameters (param_store.h): two slots of one sector each,
 * sectors 8 (0x08080000) and 9 (0x080A0000), 128 KiB each (RM0090 table 5);
 * a record uses the first PIEZO_PARAMS_SLOT_BYTES of its sector. The image
 * must end below 0x08080000 (link.ld asserts it). */
#define PIEZO_FLASH_PARAMS_A_SECTOR 8u
#define PIEZO_FLASH_PARAMS_A_ADDR 0x08080000u

/* BSY polls before an operation is reported failed (a sector erase takes up
 * to 2 s at x32, RM0090 / datasheet tERASE128KB; one poll is a few cycles). */
#ifndef PIEZO_FLASH_BSY_POLLS
#define PIEZO_FLASH_BSY_POLLS 400000000u
#endif

/* The access functions (flash_f4_mmio.c on the chip, a model in the test). */
uint32_t piezo_f4_flash_rd(uint32_t off);
void piezo_f4_flash_wr(uint32_t off, uint32_t value);
uint8_t piezo_f4_mem_rd8(uint32_t addr);
void piezo_f4_mem_wr32(uint32_t addr, uint32_t value);
/** While the flash is busy (an erase, programming): on = 1 lets only the
 *  tick interrupt in (BASEPRI above PIEZO_PRIO_TICK), on = 0 all again. The
 *  tick and this driver run from RAM (link.ld's .ramfunc); the UART's and
 *  USB's handlers run from the flash, and a fetch of theirs would stall the
 *  core until the operation ends, so they wait for it instead (a byte that
 *  arrives meanwhile overruns; the master waits for the command's answer). */
void piezo_f4_flash_hold(int on);

/** Erase a sector (8 and 9: parameters, 10 and 11: tables; never the code's). 0 or -1. */
int piezo_f4_flash_erase_sector(uint32_t sector);

/** Program n bytes at addr (word-aligned addr; a tail is padded with 0xFF,
 *  which leaves flash bits as they are). 0 or -1. */
int piezo_f4_flash_program(uint32_t addr, const uint8_t *data, uint32_t n);

/** The two slots on sectors 10 and 11 as table storage (store.h). */
piezo_storage_t piezo_f4_flash_storage(void);

/** The two slots on sectors 8 and 9 as parameter storage (param_store.h). */
piezo_storage_t piezo_f4_params_storage(void);

/** Table storage in RAM (QEMU, where the flash interface is not modelled):
 *  NOR semantics (program clears bits, erase sets 0xFF), lost at reset. */
piezo_storage_t piezo_ram_storage(uint8_t *mem, uint32_t slot_bytes);

/** The same over a caller-owned context (a second store beside the tables'). */
typedef struct {
    uint8_t *mem;
    uint32_t size;
} piezo_ram_store_t;
piezo_storage_t piezo_ram_storage_in(piezo_ram_store_t *r, uint8_t *mem, uint32_t slot_bytes);

#endif /* PIEZO_FLASH_F4_H */
