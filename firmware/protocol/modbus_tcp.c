/* Modbus TCP MBAP handling: see modbus_tcp.h. [TCP x.y] = MODBUS Messaging on
 * TCP/IP Implementation Guide V1.0b. */
#include "modbus_tcp.h"

int piezo_mb_tcp_frame_len(const uint8_t *buf, size_t have)
{
    if (have < 6u) {
        return 0;
    }
    uint16_t protocol = (uint16_t)(((uint16_t)buf[2] << 8) | buf[3]);
    uint16_t length = (uint16_t)(((uint16_t)buf[4] << 8) | buf[5]);
    if (protocol != 0u || length < 2u || length > 1u + PIEZO_MB_PDU_MAX) {
        return -1;  /* [TCP 3.1.3]: protocol 0 is MODBUS; unit id + PDU */
    }
    return 6 + (int)length;
}

size_t piezo_mb_tcp_process(const piezo_mb_regs_t *regs, uint8_t unit_id, const uint8_t *req,
                            size_t n, uint8_t *rsp, size_t cap)
{
    if (req == NULL || rsp == NULL || cap < PIEZO_TCP_ADU_MAX) {
        return 0u;
    }
    int len = piezo_mb_tcp_frame_len(req, n);
    if (len <= 0 || (size_t)len != n) {
        return 0u;
    }
    uint8_t unit = req[6];
    if (unit != unit_id && unit != 0u && unit != 0xFFu) {
        return 0u;
    }
    size_t out = piezo_mb_pdu_process(regs, &req[PIEZO_MBAP_HDR], n - PIEZO_MBAP_HDR,
                                      &rsp[PIEZO_MBAP_HDR], PIEZO_MB_PDU_MAX);
    if (out == 0u) {
        return 0u;
    }
    rsp[0] = req[0];  /* transaction id echoed [TCP 3.1.3] */
    rsp[1] = req[1];
    rsp[2] = 0u;      /* protocol id */
    rsp[3] = 0u;
    rsp[4] = (uint8_t)((out + 1u) >> 8);
    rsp[5] = (uint8_t)(out + 1u);
    rsp[6] = unit;
    return PIEZO_MBAP_HDR + out;
}
