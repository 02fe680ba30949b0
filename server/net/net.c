/* net.c — TCP listen/accept, address formatting (see net.h; redis anet.c) and the plain
 * transport net_tcp (transport.h). */
#include "net.h"
#include "ev.h"
#include "transport.h"

#include <arpa/inet.h>
#include <errno.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <unistd.h>

int net_parse_hostport(const char *s, char *host, size_t hostlen, int *port, sd_err *err)
{
    const char *colon, *h = s;
    size_t hl;
    if (!s || !*s) return sd_errf(err, SD_EINVAL, "listen address is empty; expected HOST:PORT");
    if (s[0] == '[') {
        const char *close = strchr(s, ']');
        if (!close || close[1] != ':')
            return sd_errf(err, SD_EINVAL, "listen address '%s': expected [IPV6]:PORT", s);
        h = s + 1;
        hl = (size_t)(close - h);
        colon = close + 1;
    } else {
        colon = strrchr(s, ':');
        if (!colon) return sd_errf(err, SD_EINVAL, "listen address '%s': expected HOST:PORT", s);
        hl = (size_t)(colon - s);
    }
    if (hl == 0 || hl >= hostlen)
        return sd_errf(err, SD_EINVAL, "listen address '%s': the host part is empty or too long", s);
    char *end;
    errno = 0;
    long p = strtol(colon + 1, &end, 10);
    if (colon[1] == 0 || *end || errno || p < 0 || p > 65535)
        return sd_errf(err, SD_EINVAL, "listen address '%s': the port must be a number in 0..65535", s);
    memcpy(host, h, hl);
    host[hl] = 0;
    *port = (int)p;
    return 0;
}

int net_host_is_loopback(const char *host)
{
    struct in_addr a4;
    struct in6_addr a6;
    if (strcmp(host, "localhost") == 0) return 1;
    if (inet_pton(AF_INET, host, &a4) == 1) return (ntohl(a4.s_addr) >> 24) == 127;
    if (inet_pton(AF_INET6, host, &a6) == 1) {
        if (IN6_IS_ADDR_LOOPBACK(&a6)) return 1;
        if (IN6_IS_ADDR_V4MAPPED(&a6)) return a6.s6_addr[12] == 127;
    }
    return 0;
}

int net_set_nonblock(int fd)
{
    int fl = fcntl(fd, F_GETFL);
    if (fl < 0 || fcntl(fd, F_SETFL, fl | O_NONBLOCK) < 0) return -errno;
    return 0;
}

/* fmt_addr: "A.B.C.D:P" or "[V6]:P" of sa into buf. */
static void fmt_addr(const struct sockaddr *sa, char *buf, size_t len)
{
    char ip[INET6_ADDRSTRLEN] = "?";
    int port = 0;
    if (sa->sa_family == AF_INET) {
        const struct sockaddr_in *s4 = (const struct sockaddr_in *)(const void *)sa;
        inet_ntop(AF_INET, &s4->sin_addr, ip, sizeof ip);
        port = ntohs(s4->sin_port);
        snprintf(buf, len, "%s:%d", ip, port);
    } else if (sa->sa_family == AF_INET6) {
        const struct sockaddr_in6 *s6 = (const struct sockaddr_in6 *)(const void *)sa;
        inet_ntop(AF_INET6, &s6->sin6_addr, ip, sizeof ip);
        port = ntohs(s6->sin6_port);
        snprintf(buf, len, "[%s]:%d", ip, port);
    } else {
        snprintf(buf, len, "unknown");
    }
}

int net_listen(const char *host, int port, int backlog, int *fd, int *bound, sd_err *err)
{
    struct addrinfo hints = { .ai_socktype = SOCK_STREAM, .ai_flags = AI_PASSIVE }, *res = NULL;
    char ps[16];
    snprintf(ps, sizeof ps, "%d", port);
    /* Numeric only, except "localhost": no DNS look-ups at start-up. */
    if (strcmp(host, "localhost") != 0) hints.ai_flags |= AI_NUMERICHOST;
    int rc = getaddrinfo(host, ps, &hints, &res);
    if (rc != 0)
        return sd_errf(err, SD_EINVAL, "listen address '%s': %s", host, gai_strerror(rc));
    int s = -1, saved = 0;
    for (struct addrinfo *ai = res; ai; ai = ai->ai_next) {
        s = socket(ai->ai_family, ai->ai_socktype | SOCK_NONBLOCK | SOCK_CLOEXEC, ai->ai_protocol);
        if (s < 0) { saved = errno; continue; }
        int one = 1;
        setsockopt(s, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
        if (bind(s, ai->ai_addr, ai->ai_addrlen) == 0 && listen(s, backlog) == 0) break;
        saved = errno;
        close(s);
        s = -1;
    }
    freeaddrinfo(res);
    if (s < 0)
        return sd_errf(err, SD_EIO, "cannot listen on %s:%d: %s", host, port, strerror(saved));
    struct sockaddr_storage ss;
    socklen_t sl = sizeof ss;
    if (getsockname(s, (struct sockaddr *)&ss, &sl) < 0) {
        int e = errno;
        close(s);
        return sd_errf(err, SD_EIO, "getsockname on %s:%d: %s", host, port, strerror(e));
    }
    *bound = ss.ss_family == AF_INET6 ? ntohs(((struct sockaddr_in6 *)&ss)->sin6_port)
                                      : ntohs(((struct sockaddr_in *)&ss)->sin_port);
    *fd = s;
    return 0;
}

int net_accept(int lfd, char *addr, size_t addrlen)
{
    struct sockaddr_storage ss;
    socklen_t sl = sizeof ss;
    int c = accept4(lfd, (struct sockaddr *)&ss, &sl, SOCK_NONBLOCK | SOCK_CLOEXEC);
    if (c < 0) return errno == EWOULDBLOCK ? -EAGAIN : -errno;
    int one = 1;
    setsockopt(c, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
    fmt_addr((struct sockaddr *)&ss, addr, addrlen);
    return c;
}

/* ---- the plain transport (transport.h) ---- */

static ssize_t tcp_read(void *ctx, int fd, void *buf, size_t len, int *want, char *err,
                        size_t errlen)
{
    (void)ctx;
    for (;;) {
        ssize_t r = recv(fd, buf, len, 0);
        if (r >= 0) return r;
        if (errno == EINTR) continue;
        if (errno == EAGAIN || errno == EWOULDBLOCK) {
            *want = EV_READ;
            return NET_AGAIN;
        }
        snprintf(err, errlen, "read failed: %s", strerror(errno));
        return NET_ERR;
    }
}

static ssize_t tcp_write(void *ctx, int fd, const void *buf, size_t len, int *want, char *err,
                         size_t errlen)
{
    (void)ctx;
    for (;;) {
        ssize_t w = send(fd, buf, len, MSG_NOSIGNAL);
        if (w >= 0) return w;
        if (errno == EINTR) continue;
        if (errno == EAGAIN || errno == EWOULDBLOCK) {
            *want = EV_WRITE;
            return NET_AGAIN;
        }
        snprintf(err, errlen, "write failed: %s", strerror(errno));
        return NET_ERR;
    }
}

static int tcp_pending(void *ctx)
{
    (void)ctx;
    return 0;
}

static void tcp_close(void *ctx, int graceful)
{
    (void)ctx; (void)graceful;
}

const net_transport net_tcp = {"tcp", tcp_read, tcp_write, tcp_pending, NULL, tcp_close};
