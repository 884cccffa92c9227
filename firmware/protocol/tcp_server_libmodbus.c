/* Modbus TCP server loop on libmodbus: see tcp_server_libmodbus.h. */
#define _POSIX_C_SOURCE 200809L

#include "tcp_server_libmodbus.h"

#include <errno.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <poll.h>
#include <string.h>
#include <sys/socket.h>
#include <unistd.h>

static void conn_close(piezo_tcp_conn_t *c)
{
    if (c->fd >= 0) {
        close(c->fd);
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
    for (int i = 0; i < PIEZO_TCP_MAX_CLIENTS; i++) {
        if (s->conn[i].fd < 0) {
            if (fcntl(fd, F_SETFL, fcntl(fd, F_GETFL) | O_NONBLOCK) != 0) {
                break;
            }
            s->conn[i].fd = fd;
            s->conn[i].len = 0u;
            return;
        }
    }
    close(fd);  /* no free slot (or fcntl failed): refuse */
}

/* Reads what is there without blocking and answers complete requests. Returns
 * responses sent; closes the connection when the stream ends or is bad. */
static int service_client(piezo_tcp_server_t *s, piezo_tcp_conn_t *c)
{
    int sent = 0;
    for (int frames = 0; frames < PIEZO_TCP_FRAMES_PER_POLL;) {
        /* Read only up to the end of the current frame: the header first,
         * then what its length field announces. */
        int want = piezo_mb_tcp_frame_len(c->buf, c->len);
        if (want < 0) {
            s->dropped++;
            conn_close(c);
            return sent;
        }
        size_t need = want == 0 ? PIEZO_MBAP_HDR : (size_t)want;
        if (c->len < need) {
            ssize_t n = recv(c->fd, &c->buf[c->len], need - c->len, 0);
            if (n == 0) {
                conn_close(c);  /* orderly shutdown by the client */
                return sent;
            }
            if (n < 0) {
                if (errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR) {
                    conn_close(c);
                }
                return sent;
            }
            c->len = (uint16_t)(c->len + (size_t)n);
            continue;
        }
        /* A complete frame of `need` bytes. */
        uint8_t rsp[PIEZO_TCP_ADU_MAX];
        size_t out = piezo_mb_tcp_process(s->regs, s->unit_id, c->buf, need, rsp, sizeof rsp);
        c->len = 0u;
        frames++;
        if (out > 0u) {
            ssize_t w = send(c->fd, rsp, out, MSG_NOSIGNAL);
            if (w != (ssize_t)out) {
                s->dropped++;  /* the client does not read its answers */
                conn_close(c);
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
            sent += service_client(s, &s->conn[slot[k]]);
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
        conn_close(&s->conn[i]);
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
