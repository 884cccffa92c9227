/* Modbus RTU framer: see modbus_rtu.h. [SL x.y] = MODBUS over Serial Line
 * V1.02, [AP x.y] = MODBUS Application Protocol V1.1b3. */
#include "modbus_rtu.h"

uint16_t piezo_rtu_crc16_update(uint16_t crc, uint8_t byte)
{
    /* Bitwise CRC-16 [SL 6.2.2]: XOR the byte into the low byte, then eight
     * shifts right, XORing 0xA001 after each shift that drops a 1. */
    crc ^= byte;
    for (int i = 0; i < 8; i++) {
        uint16_t lsb = (uint16_t)(crc & 1u);
        crc = (uint16_t)(crc >> 1);
        if (lsb != 0u) {
            crc ^= 0xA001u;
        }
    }
    return crc;
}

uint16_t piezo_rtu_crc16(const uint8_t *data, size_t n)
{
    uint16_t crc = 0xFFFFu;
    for (size_t i = 0; i < n; i++) {
        crc = piezo_rtu_crc16_update(crc, data[i]);
    }
    return crc;
}

uint32_t piezo_rtu_t35_us(const piezo_rtu_t *r)
{
    return r->t35_us;
}

/* The frame in buf[rx] has ended: keep it when it is a valid frame addressed
 * to us (or a broadcast), else count why it is dropped. Starts a new frame. */
static void end_frame(piezo_rtu_t *r)
{
    uint16_t n = r->len[r->rx];
    r->stats.frames++;
    if (r->broken != 0u || n < PIEZO_RTU_ADU_MIN) {
        r->stats.malformed++;
    } else if (r->crc != 0u) {
        /* The CRC over a frame including its own CRC (low byte first) is 0. */
        r->stats.crc_errors++;
    } else if (r->buf[r->rx][0] != r->unit_id && r->buf[r->rx][0] != PIEZO_RTU_BROADCAST) {
        r->stats.not_for_us++;
    } else if (r->ready != 0u) {
        r->stats.overruns++;
    } else {
        r->ready = 1u;
        r->rx ^= 1u;
    }
    r->len[r->rx] = 0u;
    r->broken = 0u;
    r->crc = 0xFFFFu;
}

void piezo_rtu_rx_byte(piezo_rtu_t *r, uint8_t byte, uint32_t now_us)
{
    if (r->unit_id == 0u) {
        return;  /* not initialised */
    }
    uint16_t n = r->len[r->rx];
    if (n > 0u || r->broken != 0u) {
        uint32_t dt = now_us - r->last_us;  /* modulo 2^32: wrap-safe */
        if (dt >= r->gap35_us) {
            end_frame(r);   /* silence >= t3.5: this byte starts a new frame */
            n = 0u;
        } else if (dt > r->gap15_us) {
            r->broken = 1u; /* silence > t1.5 inside a frame [SL 2.5.1.1] */
        }
    }
    if (n == 0u && r->broken == 0u) {
        r->crc = 0xFFFFu;
    }
    r->last_us = now_us;
    if (n >= PIEZO_RTU_ADU_MAX) {
        r->broken = 1u;     /* longer than any RTU frame: drop it at its end */
        return;
    }
    r->buf[r->rx][n] = byte;
    r->len[r->rx] = (uint16_t)(n + 1u);
    r->crc = piezo_rtu_crc16_update(r->crc, byte);
}

void piezo_rtu_rx(piezo_rtu_t *r, const uint8_t *data, size_t n, uint32_t now_us)
{
    for (size_t i = 0; i < n; i++) {
        piezo_rtu_rx_byte(r, data[i], now_us);
    }
}

size_t piezo_rtu_poll(piezo_rtu_t *r, uint32_t now_us, const piezo_mb_regs_t *regs,
                      uint8_t *reply, size_t cap)
{
    if (r->unit_id == 0u) {
        return 0u;
    }
    /* A frame already waiting goes first; one ended by this silence waits
     * for the next poll. */
    if (r->ready == 0u && (r->len[r->rx] > 0u || r->broken != 0u) &&
        now_us - r->last_us >= r->t35_us) {
        end_frame(r);
    }
    if (r->ready == 0u) {
        /* the line's session ends once the master has been silent for the
         * idle time, not only when its next request comes: what it unlocked
         * and staged does not outlive it (another session may stage then) */
        if (r->in_session != 0u && regs != NULL && regs->session != NULL &&
            now_us - r->last_req_us >= PIEZO_MB_RTU_SESSION_IDLE_US) {
            regs->session(regs->ctx, PIEZO_MB_SESSION_RTU, PIEZO_MB_SESSION_END);
            r->in_session = 0u;
        }
        return 0u;
    }
    r->ready = 0u;
    const uint8_t *f = r->buf[r->rx ^ 1u];
    size_t pdu_len = (size_t)r->len[r->rx ^ 1u] - 3u;  /* minus address and CRC */
    if (regs != NULL && regs->session != NULL) {
        /* the line is one session; a master silent for the idle time starts a new one */
        if (r->in_session != 0u && now_us - r->last_req_us >= PIEZO_MB_RTU_SESSION_IDLE_US) {
            regs->session(regs->ctx, PIEZO_MB_SESSION_RTU, PIEZO_MB_SESSION_END);
        }
        regs->session(regs->ctx, PIEZO_MB_SESSION_RTU, PIEZO_MB_SESSION_BEGIN);
        r->in_session = 1u;
        r->last_req_us = now_us;
    }
    if (f[0] == PIEZO_RTU_BROADCAST) {
        if (piezo_mb_pdu_is_broadcast_write(f[1]) == 0) {
            r->stats.not_for_us++;
            return 0u;
        }
        /* Execute, never answer [SL 2.1]: the response goes to a scratch buffer. */
        uint8_t scratch[PIEZO_MB_PDU_MAX];
        (void)piezo_mb_pdu_process(regs, &f[1], pdu_len, scratch, sizeof scratch);
        r->stats.broadcasts++;
        return 0u;
    }
    if (reply == NULL || cap < PIEZO_RTU_ADU_MAX) {
        return 0u;
    }
    size_t n = piezo_mb_pdu_process(regs, &f[1], pdu_len, &reply[1], PIEZO_MB_PDU_MAX);
    if (n == 0u) {
        return 0u;
    }
    reply[0] = r->unit_id;
    uint16_t crc = piezo_rtu_crc16(reply, n + 1u);
    reply[n + 1u] = (uint8_t)crc;          /* CRC low byte first [SL 2.5.1.2] */
    reply[n + 2u] = (uint8_t)(crc >> 8);
    r->stats.answered++;
    return n + 3u;
}
