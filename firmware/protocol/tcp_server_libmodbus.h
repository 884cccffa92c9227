/* Modbus TCP server loop for the SIL and Linux targets, built on libmodbus.
 *
 * libmodbus opens, binds and listens (modbus_new_tcp, modbus_tcp_listen) and
 * accepts connections (modbus_tcp_accept). Requests are read here, without
 * blocking, and answered by our own PDU server through modbus_tcp.h; the
 * register map is the application's piezo_mb_regs_t. modbus_receive() and
 * modbus_reply() are not used, because in libmodbus 3.1.6 modbus_receive()
 * waits (up to the byte timeout) for the rest of a frame once the first byte
 * is there, which would stall a 10 kHz loop, and it frames a request by its
 * function code rather than by the MBAP length, so one request with an
 * unknown function code and a body desynchronises the stream; modbus_reply()
 * would answer from a modbus_mapping_t instead of the application's map.
 *
 * piezo_tcp_server_poll() is poll-friendly: with timeout_ms = 0 it returns at
 * once, so the SIL loop can service the server between ticks. A bad request
 * gets an exception response; a stream that cannot be a Modbus stream
 * (protocol id != 0, impossible length), a client that does not read its
 * answers, or a closed connection closes that connection only.
 *
 * Slots and timeouts (common/interface.toml [modbus.tcp], docs/protocol.md):
 * PIEZO_TCP_SLOTS connections at once. A connection with no complete
 * request for idle_ms is closed, and so is one whose request stays
 * incomplete partial_ms after its first byte. A client that connects while
 * every slot is taken replaces the connection that has been idle longest, if
 * that one has been idle evict_ms; otherwise it is closed at once. Each slot
 * is a session of the register map (piezo_mb_regs_t.session, id 1 + slot):
 * it begins with every request and ends when the connection closes, for
 * whatever reason, so an unlock or an upload never outlives its connection.
 */
#ifndef PIEZO_TCP_SERVER_LIBMODBUS_H
#define PIEZO_TCP_SERVER_LIBMODBUS_H

#include <stdint.h>

#include <modbus.h>

#include "modbus_pdu.h"
#include "modbus_tcp.h"
#include "piezo_interface.h"

#define PIEZO_TCP_MAX_CLIENTS ((int)PIEZO_TCP_SLOTS)
#define PIEZO_TCP_DEFAULT_ADDRESS "127.0.0.1"
/* Frames answered per client and poll: bounds the time one poll can take. */
#define PIEZO_TCP_FRAMES_PER_POLL 8

typedef struct piezo_tcp_conn {
    int fd;                             /* -1: free slot */
    uint16_t len;                       /* bytes of the current request so far */
    uint64_t last_ms;                   /* connected, or last complete request */
    uint64_t first_ms;                  /* first byte of the current request */
    uint8_t buf[PIEZO_TCP_ADU_MAX];
} piezo_tcp_conn_t;

typedef struct piezo_tcp_server {
    modbus_t *ctx;
    int listen_fd;
    uint16_t port;
    uint8_t unit_id;
    const piezo_mb_regs_t *regs;
    piezo_tcp_conn_t conn[PIEZO_TCP_MAX_CLIENTS];
    unsigned long answered;             /* responses sent */
    unsigned long dropped;              /* connections closed for a bad stream */
    unsigned long timed_out;            /* closed for the idle or the partial timeout */
    unsigned long evicted;              /* replaced by a new client */
    unsigned long refused;              /* new clients closed: every slot busy */
    uint32_t idle_ms;                   /* timeouts, from interface.toml; a test may lower them */
    uint32_t partial_ms;
    uint32_t evict_ms;
} piezo_tcp_server_t;

/* Listens on address:port (address NULL: 127.0.0.1; port 0: a free port the
 * kernel picks, see piezo_tcp_server_port()). regs must outlive the server.
 * Returns 0, or -1 with errno set. */
int piezo_tcp_server_open(piezo_tcp_server_t *s, const char *address, uint16_t port,
                          uint8_t unit_id, const piezo_mb_regs_t *regs);

/* The port the server listens on. */
uint16_t piezo_tcp_server_port(const piezo_tcp_server_t *s);

/* Accepts new connections and answers complete requests, waiting at most
 * timeout_ms for activity (0: do not wait; -1: wait indefinitely). Returns
 * the number of responses sent, or -1 with errno set when waiting failed
 * (EINTR included). */
int piezo_tcp_server_poll(piezo_tcp_server_t *s, int timeout_ms);

/* Closes every connection and the listening socket. */
void piezo_tcp_server_close(piezo_tcp_server_t *s);

#endif /* PIEZO_TCP_SERVER_LIBMODBUS_H */
