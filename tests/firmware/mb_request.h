/* mb_request.h - Modbus request PDUs built by the C tests (one builder for the
 * protocol, register-map and parameter-store tests). Big-endian fields as in
 * the Modbus Application Protocol V1.1b3, section 6.12 (FC 16). */
#ifndef MB_REQUEST_H
#define MB_REQUEST_H

#include <stddef.h>
#include <stdint.h>

#include "modbus_pdu.h"

/* FC 16, write multiple registers: v[0..n) at addr into q (at least
 * 6 + 2 n bytes); returns the PDU's length. */
static inline size_t mb_req_write_multiple(uint8_t *q, uint16_t addr, const uint16_t *v, uint16_t n)
{
    q[0] = PIEZO_MB_FC_WRITE_MULTIPLE;
    q[1] = (uint8_t)(addr >> 8);
    q[2] = (uint8_t)addr;
    q[3] = (uint8_t)(n >> 8);
    q[4] = (uint8_t)n;
    q[5] = (uint8_t)(2u * n);
    for (uint16_t i = 0; i < n; i++) {
        q[6 + 2 * i] = (uint8_t)(v[i] >> 8);
        q[7 + 2 * i] = (uint8_t)v[i];
    }
    return 6u + 2u * n;
}

#endif /* MB_REQUEST_H */
