/* The firmware image's USB glue (firmware/targets/cortex-m4/src/usb_board.c)
 * against the fake OTG core (fake_otgfs.c) and a record of its writes to the
 * RCC, GPIOA and the NVIC: the init order RM0090 asks for (the port's clock
 * before its pins, PA11/PA12 in AF10, the core's clock before any core
 * register, the interrupt enabled only once the core is up), init with no
 * core at all (QEMU: every register 0) ends in bounded time without the
 * interrupt, and the interrupt's path (masked in the NVIC, the work done by
 * the background poll, unmasked after) including a bus reset that ends the
 * USB session. */
#include <string.h>

#include "piezo_test.h"
#include "fake_otgfs.h"
#include "test_modbus_regs.h"
#include "usb_board.h"
#include "usb_otgfs.h"

typedef struct {
    uint32_t addr, value;
    unsigned otg_accesses; /* fake core accesses before this write */
} bwrite_t;

static bwrite_t log_[64];
static unsigned n_log;
static uint32_t mem_addr[16], mem_val[16];
static unsigned n_mem;

static uint32_t *cell(uint32_t addr)
{
    for (unsigned i = 0; i < n_mem; i++) {
        if (mem_addr[i] == addr) {
            return &mem_val[i];
        }
    }
    assert_true(n_mem < 16u);
    mem_addr[n_mem] = addr;
    mem_val[n_mem] = 0u;
    return &mem_val[n_mem++];
}

uint32_t piezo_usb_board_rd(uint32_t addr)
{
    return *cell(addr);
}

void piezo_usb_board_wr(uint32_t addr, uint32_t value)
{
    assert_true(n_log < 64u);
    log_[n_log++] = (bwrite_t){addr, value, fotg.accesses};
    *cell(addr) = value;
}

void piezo_usb_board_wr8(uint32_t addr, uint8_t value)
{
    piezo_usb_board_wr(addr, value);
}

/* index of the first write to addr with (value & mask) == want, or -1 */
static int find(uint32_t addr, uint32_t mask, uint32_t want)
{
    for (unsigned i = 0; i < n_log; i++) {
        if (log_[i].addr == addr && (log_[i].value & mask) == want) {
            return (int)i;
        }
    }
    return -1;
}

#define IRQ_WORD (PIEZO_IRQ_OTG_FS / 32u)
#define IRQ_BIT (1u << (PIEZO_IRQ_OTG_FS % 32u))
#define REG(off) fotg.reg[(off) / 4u]

static tregs_t bank;
static piezo_mb_regs_t regs;
static unsigned usb_ends;

static void count_session(void *ctx, uint8_t id, uint8_t event)
{
    (void)ctx;
    if (id == PIEZO_MB_SESSION_USB && event == PIEZO_MB_SESSION_END) {
        usb_ends++;
    }
}

static int fresh(void **state)
{
    (void)state;
    fake_otg_reset();
    n_log = 0u;
    n_mem = 0u;
    usb_ends = 0u;
    regs = tregs_init(&bank);
    regs.session = count_session;
    return 0;
}

static void test_init_order_follows_the_reference_manual(void **state)
{
    (void)state;
    assert_int_equal(piezo_usb_init(&regs), 0);
    assert_int_equal(piezo_usb_state(), PIEZO_USB_RUNNING);
    int gpioa_clk = find(PIEZO_RCC_AHB1ENR, PIEZO_RCC_AHB1ENR_GPIOAEN, PIEZO_RCC_AHB1ENR_GPIOAEN);
    int moder = find(PIEZO_GPIOA_MODER, (3u << 22) | (3u << 24), (2u << 22) | (2u << 24));
    int afrh = find(PIEZO_GPIOA_AFRH, (0xFu << 12) | (0xFu << 16), (10u << 12) | (10u << 16));
    int speed = find(PIEZO_GPIOA_OSPEEDR, (3u << 22) | (3u << 24), (3u << 22) | (3u << 24));
    int otg_clk = find(PIEZO_RCC_AHB2ENR, PIEZO_RCC_AHB2ENR_OTGFSEN, PIEZO_RCC_AHB2ENR_OTGFSEN);
    int prio = find(PIEZO_NVIC_IPR8(PIEZO_IRQ_OTG_FS), 0xFFu, PIEZO_PRIO_USB);
    int enable = find(PIEZO_NVIC_ISER(IRQ_WORD), IRQ_BIT, IRQ_BIT);
    assert_true(gpioa_clk >= 0 && moder >= 0 && afrh >= 0 && speed >= 0 && otg_clk >= 0);
    assert_true(prio >= 0 && enable >= 0);
    /* the port's clock before its registers; the alternate function chosen
     * before the pin is switched to it (no glitch on another function) */
    assert_true(gpioa_clk < afrh && afrh < moder && gpioa_clk < speed);
    /* no core register before its clock; the interrupt after the core is up */
    assert_int_equal(log_[otg_clk].otg_accesses, 0);
    assert_true(log_[enable].otg_accesses > 0u);
    assert_true(prio < enable);
    assert_int_equal(log_[enable].otg_accesses, fotg.accesses); /* the core's init had ended */
    assert_true((REG(OTG_GAHBCFG) & 1u) != 0u);                 /* the core's own global mask */
    assert_int_equal(REG(OTG_DCTL) & 2u, 0u);                    /* connected */
    /* other pins of port A untouched */
    assert_int_equal(piezo_usb_board_rd(PIEZO_GPIOA_MODER) & ~((3u << 22) | (3u << 24)), 0u);
}

static void test_without_a_core_init_gives_up_and_leaves_the_interrupt_off(void **state)
{
    (void)state;
    fotg.absent = 1; /* QEMU 7.2: no OTG model, every register 0 */
    assert_int_equal(piezo_usb_init(&regs), -1);
    assert_int_equal(piezo_usb_state(), PIEZO_USB_ABSENT);
    assert_int_equal(find(PIEZO_NVIC_ISER(IRQ_WORD), IRQ_BIT, IRQ_BIT), -1);
    assert_true(fotg.accesses <= 100001u); /* one bounded wait, then it gave up */
    /* a stray interrupt does not make the poll touch the missing core */
    OTG_FS_IRQHandler();
    unsigned before = fotg.accesses;
    assert_int_equal(piezo_usb_poll(), 0);
    assert_int_equal(fotg.accesses, before);
}

static void setup_request(uint8_t bm, uint8_t req, uint16_t value, uint16_t length)
{
    const uint8_t s[8] = {bm, req, (uint8_t)value, (uint8_t)(value >> 8), 0, 0, (uint8_t)length,
                          (uint8_t)(length >> 8)};
    fake_otg_rx(0u, OTG_RXSTS_SETUP_DATA, s, 8u);
    fake_otg_rx(0u, OTG_RXSTS_SETUP_DONE, NULL, 0u);
}

/* The interrupt only masks its line; the poll does the work and unmasks it. */
static void interrupt_then_poll(void)
{
    unsigned before = fotg.accesses, n0 = n_log;
    OTG_FS_IRQHandler();
    assert_int_equal(fotg.accesses, before); /* no core access in the handler */
    assert_int_equal(n_log, n0 + 1u);
    assert_int_equal(log_[n0].addr, PIEZO_NVIC_ICER(IRQ_WORD));
    assert_int_equal(log_[n0].value, IRQ_BIT);
    assert_int_equal(piezo_usb_poll(), 1);
    assert_int_equal(log_[n_log - 1u].addr, PIEZO_NVIC_ISER(IRQ_WORD));
    assert_int_equal(log_[n_log - 1u].value, IRQ_BIT);
    assert_int_equal(piezo_usb_poll(), 0); /* nothing pending: nothing done */
}

static void test_interrupt_path_enumerates_and_serves_the_register_map(void **state)
{
    (void)state;
    assert_int_equal(piezo_usb_init(&regs), 0);
    REG(OTG_GINTSTS) = OTG_GINT_USBRST;
    interrupt_then_poll();
    unsigned ends_after_reset = usb_ends;
    assert_true(ends_after_reset >= 1u);

    setup_request(0x80, 6, 0x0100, 64); /* GET_DESCRIPTOR device */
    interrupt_then_poll();
    assert_memory_equal(fotg.tx[0], piezo_usbd_device_desc, 18);
    setup_request(0x00, 5, 9, 0); /* SET_ADDRESS 9 */
    interrupt_then_poll();
    setup_request(0x00, 9, 1, 0); /* SET_CONFIGURATION 1: a new session */
    interrupt_then_poll();
    assert_int_equal(piezo_usb_dev.configuration, 1);
    assert_int_equal(usb_ends, ends_after_reset + 1u);

    fotg.tx_len[1] = 0u;
    const uint8_t req[] = {0xA5, 7, 5, 0, 0x04, 0x00, 0x00, 0x00, 0x01}; /* FC 4, one register */
    fake_otg_rx(1u, OTG_RXSTS_OUT_DATA, req, sizeof req);
    fake_otg_rx(1u, OTG_RXSTS_OUT_DONE, NULL, 0u);
    interrupt_then_poll();
    assert_int_equal(fotg.tx[1][0], 0xA5);
    assert_int_equal((fotg.tx[1][6] << 8) | fotg.tx[1][7], tregs_input_value(0));

    /* a bus reset (replug, re-enumeration) ends the session again */
    REG(OTG_GINTSTS) = OTG_GINT_USBRST;
    interrupt_then_poll();
    assert_int_equal(usb_ends, ends_after_reset + 2u);
    assert_int_equal(piezo_usb_dev.configuration, 0);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup(test_init_order_follows_the_reference_manual, fresh),
        cmocka_unit_test_setup(test_without_a_core_init_gives_up_and_leaves_the_interrupt_off, fresh),
        cmocka_unit_test_setup(test_interrupt_path_enumerates_and_serves_the_register_map, fresh),
    };
    return cmocka_run_group_tests_name("usb_board", tests, NULL, NULL);
}
