/*
 * comm.c - Modbus RTU on USART1 (see comm.h).
 *
 * Time base. The framer wants the time at which each byte was completely
 * received, in microseconds. The receive interrupt stamps every byte with the
 * tick count (uart.c), and the framer gets tick x 100 us: the 3.5-character
 * silence that ends a frame (1750 us above 19200 baud [SL 2.5.1.1]) is 18
 * ticks, the 1.5-character gap that breaks one 8 (the framer's gap includes
 * the character time). A stamp is late by at most one tick (100 us), less
 * than either. Why ticks and no other timer: the tick is the one clock that
 * runs in every build, and under QEMU it is the emulated clock the guest sees
 * (docs/target-cortex-m4.md, "PIL: time under QEMU").
 *
 * Concurrency. The framer runs only here (bytes are taken from the ring
 * here), so rx and poll never overlap. The PDU server reads registers with
 * the tick running (status reads are single 32-bit loads, the recorder
 * window is a buffer the tick appends to). Writes change the controller's
 * state, which the tick uses: they run with interrupts masked, so a tick sees
 * a request whole or not at all (table commands excepted, below). Each write
 * starts right after a tick has ended, so it delays the next tick only if it takes longer than the rest of
 * the period (tick_time_max_ns would show it; tools/bench-target measures
 * it with every kind of write).
 */
#include "comm.h"

#include "board.h"
#include "control.h"
#include "piezo_interface.h"
#include "tick.h"
#include "uart.h"
#include "usb_board.h"

/* The unlock key this image is provisioned with (docs/protocol.md, "Sessions,
 * unlock and lockout"), set per image by CMakeLists.txt: the PIL image (a
 * simulated stage) has the development key, the board image the cache
 * variable PIEZO_FW_UNLOCK_KEY, or 0 (every unlock refused) without one. */
#ifndef PIEZO_COMM_UNLOCK_KEY
#error "PIEZO_COMM_UNLOCK_KEY: set by the image's target in CMakeLists.txt"
#endif

piezo_regmap_t piezo_comm_map;
piezo_rtu_t piezo_comm_rtu;
static piezo_mb_regs_t regs;
static piezo_mb_regs_t inner;
static uint8_t reply[PIEZO_RTU_ADU_MAX];

static uint8_t masked_write(void *ctx, uint16_t addr, uint16_t count, const uint16_t *values)
{
    uint8_t rc;
    if (addr == PIEZO_HOLDING_TABLE_COMMAND && count == 1u) {
        /* commit, rollback, clear: their long part (checking the image,
         * loading it into the spare coefficient set, persisting it) touches
         * nothing the tick reads; the swap is one byte the tick takes at its
         * start (controller.c, piezo_ctl_commit). So the tick keeps running. */
        return inner.write_holding(ctx, addr, count, values);
    }
    /* start right after a tick: a write shorter than the period minus the
     * tick's work (about 98 us) then never delays the next one */
    uint32_t t0 = piezo_tick_count();
    while (piezo_tick_count() == t0) {
    }
    piezo_irq_disable();
    rc = inner.write_holding(ctx, addr, count, values);
    piezo_irq_enable();
    return rc;
}

/* ns of 168 MHz cycles: x 1000 / 168 = x 5.952..., as (x * 6095) >> 10
 * (5.9521, 0.003 % high); no division. */
static uint32_t cycles_to_ns(uint32_t cycles)
{
    return (uint32_t)(((uint64_t)cycles * 6095u) >> 10);
}

int piezo_comm_init(void)
{
    piezo_regmap_init(&piezo_comm_map, &piezo_axis);
    piezo_comm_map.axis = 0u;
    piezo_comm_map.n_axes = 1u;
    piezo_comm_map.tick_hz = PIEZO_TICK_HZ;
    piezo_comm_map.drive_min_mv = piezo_control_range.drive_min_mv;
    piezo_comm_map.drive_max_mv = piezo_control_range.drive_max_mv;
    piezo_comm_map.position_min_nm = piezo_control_range.position_min_nm;
    piezo_comm_map.position_max_nm = piezo_control_range.position_max_nm;
    /* the stage and the key before a stored table is loaded (main.c attaches
     * the store after this): a stored table is checked against both */
    piezo_regmap_provision(&piezo_comm_map, (uint32_t)PIEZO_COMM_UNLOCK_KEY);
    inner = piezo_regmap_regs(&piezo_comm_map);
    regs = inner;
    regs.write_holding = masked_write;
    return piezo_rtu_init(&piezo_comm_rtu, (uint8_t)PIEZO_MODBUS_UNIT_ID, PIEZO_MODBUS_BAUD);
}

const piezo_mb_regs_t *piezo_comm_regs(void)
{
    return &regs;
}

int piezo_comm_poll(void)
{
    uint8_t b;
    uint32_t stamp;
    /* the USB link first (usb_board.c): its interrupt's work, a request
     * through the same register map and masked writes as the line's */
    int did = piezo_usb_poll();
    while (piezo_uart_get(&b, &stamp)) {
        piezo_rtu_rx_byte(&piezo_comm_rtu, b, stamp * PIEZO_COMM_US_PER_TICK);
        did = 1;
    }
    piezo_comm_map.tick_time_ns = cycles_to_ns(piezo_tick_time_cycles());
    piezo_comm_map.tick_time_max_ns = cycles_to_ns(piezo_tick_time_max_cycles());
    if (piezo_uart_tx_busy()) {
        return did; /* the answer to the previous request is still going out */
    }
    size_t n = piezo_rtu_poll(&piezo_comm_rtu, piezo_tick_count() * PIEZO_COMM_US_PER_TICK, &regs, reply,
                              sizeof reply);
    if (n > 0u) {
        (void)piezo_uart_send(reply, n);
        did = 1;
    }
    return did;
}
