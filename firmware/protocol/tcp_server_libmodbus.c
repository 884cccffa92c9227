/* Modbus TCP server loop on libmodbus: see tcp_server_libmodbus.h. */
#define _POSIX_C_SOURCE 200809L

#include "tcp_server_libmodbus.h"

#include <errno.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <poll.h>
#include <string.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

static uint64_t now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000u + (uint64_t)ts.tv_nsec / 1000000u;
}

/* Closes slot i and ends its session (its unlock and upload go with it). */
static void slot_close(piezo_tcp_server_t *s, int i)
{
    piezo_tcp_conn_t *c = &s->conn[i];
    if (c->fd >= 0) {
        close(c->fd);
        if (s->regs != NULL && s->regs->session != NULL) {
            s->regs->session(s->regs->ctx, (uint8_t)(PIEZO_MB_SESSION_TCP_FIRST + i), PIEZO_MB_SESSION_END);
        }
    }
    c->fd = -1;
    c->len = 0u;
}

int piezo_tcp_server_open(piezo_tcp_server_t *s, const char *address, uint16_t port,
                          uint8_t unit_id, const piezo_mb_regs_t *regs)
{
    memset(s, 0, sizeof *s);
    s->listen_fd = -1;
    for (int i = 0; i < PIEZO_TCP_MAX_CLIENTS; i++) {
        s->conn[i].fd = -1;
    }
    if (regs == NULL) {
        errno = EINVAL;
        return -1;
    }
    s->regs = regs;
    s->unit_id = unit_id;
    s->idle_ms = PIEZO_TCP_IDLE_TIMEOUT_MS;
    s->partial_ms = PIEZO_TCP_PARTIAL_TIMEOUT_MS;
    s->evict_ms = PIEZO_TCP_EVICT_MIN_IDLE_MS;
    s->ctx = modbus_new_tcp(address != NULL ? address : PIEZO_TCP_DEFAULT_ADDRESS, port);
    if (s->ctx == NULL) {
        return -1;
    }
    s->listen_fd = modbus_tcp_listen(s->ctx, PIEZO_TCP_MAX_CLIENTS);
    if (s->listen_fd < 0) {
        int e = errno;
        modbus_free(s->ctx);
        s->ctx = NULL;
        errno = e;
        return -1;
    }
    struct sockaddr_in sa;
    socklen_t salen = sizeof sa;
    if (getsockname(s->listen_fd, (struct sockaddr *)&sa, &salen) != 0 ||
        fcntl(s->listen_fd, F_SETFL, fcntl(s->listen_fd, F_GETFL) | O_NONBLOCK) != 0) {
        int e = errno;
        piezo_tcp_server_close(s);
        errno = e;
        return -1;
    }
    s->port = ntohs(sa.sin_port);
    return 0;
}

uint16_t piezo_tcp_server_port(const piezo_tcp_server_t *s)
{
    return s->port;
}

static void accept_client(piezo_tcp_server_t *s)
{
    int listen_fd = s->listen_fd;
    int fd = modbus_tcp_accept(s->ctx, &listen_fd);
    if (fd < 0) {
        return;  /* the client went away, or EAGAIN */
    }
    uint64_t now = now_ms();
    int slot = -1, idlest = -1;
    for (int i = 0; i < PIEZO_TCP_MAX_CLIENTS && slot < 0; i++) {
        if (s->conn[i].fd < 0) {
            slot = i;
        } else if (idlest < 0 || s->conn[i].last_ms < s->conn[idlest].last_ms) {
            idlest = i;
        }
    }
    if (slot < 0 && idlest >= 0 && s->conn[idlest].len == 0u && now - s->conn[idlest].last_ms >= s->evict_ms) {
        slot_close(s, idlest); /* the longest-idle connection makes room */
        s->evicted++;
        slot = idlest;
    }
    if (slot < 0 || fcntl(fd, F_SETFL, fcntl(fd, F_GETFL) | O_NONBLOCK) != 0) {
        s->refused++;
        close(fd);  /* every slot busy (or fcntl failed): refuse */
        return;
    }
    s->conn[slot].fd = fd;
    s->conn[slot].len = 0u;
    s->conn[slot].last_ms = now;
}

/* Reads what is there without blocking and answers complete requests. Returns
 * responses sent; closes the connection when the stream ends or is bad. */
static int service_client(piezo_tcp_server_t *s, int slot)
{
    piezo_tcp_conn_t *c = &s->conn[slot];
    int sent = 0;
    for (int frames = 0; frames < PIEZO_TCP_FRAMES_PER_POLL;) {
        /* Read only up to the end of the current frame: the header first,
         * then what its length field announces. */
        int want = piezo_mb_tcp_frame_len(c->buf, c->len);
        if (want < 0) {
            s->dropped++;
            slot_close(s, slot);
            return sent;
        }
        size_t need = want == 0 ? PIEZO_MBAP_HDR : (size_t)want;
        if (c->len < need) {
            ssize_t n = recv(c->fd, &c->buf[c->len], need - c->len, 0);
            if (n == 0) {
                slot_close(s, slot);  /* orderly shutdown by the client */
                return sent;
            }
            if (n < 0) {
                if (errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR) {
                    slot_close(s, slot);
                }
                return sent;
            }
            if (c->len == 0u) {
                c->first_ms = now_ms(); /* the partial timeout runs from here */
            }
            c->len = (uint16_t)(c->len + (size_t)n);
            continue;
        }
        /* A complete frame of `need` bytes. */
        uint8_t rsp[PIEZO_TCP_ADU_MAX];
        if (s->regs->session != NULL) {
            s->regs->session(s->regs->ctx, (uint8_t)(PIEZO_MB_SESSION_TCP_FIRST + slot), PIEZO_MB_SESSION_BEGIN);
        }
        size_t out = piezo_mb_tcp_process(s->regs, s->unit_id, c->buf, need, rsp, sizeof rsp);
        c->len = 0u;
        c->last_ms = now_ms();
        frames++;
        if (out > 0u) {
            ssize_t w = send(c->fd, rsp, out, MSG_NOSIGNAL);
            if (w != (ssize_t)out) {
                s->dropped++;  /* the client does not read its answers */
                slot_close(s, slot);
                return sent;
            }
            s->answered++;
            sent++;
        }
    }
    return sent;
}

int piezo_tcp_server_poll(piezo_tcp_server_t *s, int timeout_ms)
{
    struct pollfd pfd[1 + PIEZO_TCP_MAX_CLIENTS];
    int slot[1 + PIEZO_TCP_MAX_CLIENTS];
    nfds_t n = 0;
    pfd[n].fd = s->listen_fd;
    pfd[n].events = POLLIN;
    slot[n++] = -1;
    for (int i = 0; i < PIEZO_TCP_MAX_CLIENTS; i++) {
        if (s->conn[i].fd >= 0) {
            pfd[n].fd = s->conn[i].fd;
            pfd[n].events = POLLIN;
            slot[n++] = i;
        }
    }
    int rc = poll(pfd, n, timeout_ms);
    if (rc < 0) {
        return -1;
    }
    int sent = 0;
    for (nfds_t k = 1; k < n; k++) {
        if (pfd[k].revents != 0) {
            sent += service_client(s, slot[k]);
        }
    }
    /* the timeouts: a silent connection, a request that never completes */
    uint64_t now = now_ms();
    for (int i = 0; i < PIEZO_TCP_MAX_CLIENTS; i++) {
        piezo_tcp_conn_t *c = &s->conn[i];
        if (c->fd >= 0 && ((c->len > 0u && now - c->first_ms >= s->partial_ms) ||
                           (c->len == 0u && now - c->last_ms >= s->idle_ms))) {
            slot_close(s, i);
            s->timed_out++;
        }
    }
    if ((pfd[0].revents & POLLIN) != 0) {
        accept_client(s);
    }
    return sent;
}

void piezo_tcp_server_close(piezo_tcp_server_t *s)
{
    for (int i = 0; i < PIEZO_TCP_MAX_CLIENTS; i++) {
        slot_close(s, i);
    }
    if (s->listen_fd >= 0) {
        close(s->listen_fd);
        s->listen_fd = -1;
    }
    if (s->ctx != NULL) {
        /* The context holds the last accepted socket, closed above. */
        modbus_set_socket(s->ctx, -1);
        modbus_free(s->ctx);
        s->ctx = NULL;
    }
}
