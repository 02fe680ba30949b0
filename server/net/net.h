/* net.h — TCP sockets for the daemon: parse HOST:PORT, listen, accept, address text.
 * All sockets are non-blocking and close-on-exec. Low-level: returns codes, never logs. */
#pragma once
#include <stddef.h>

#include "sd_err.h"

enum { NET_ADDR_LEN = 64 }; /* "[ffff:...]:65535" fits */

/* net_parse_hostport: splits "HOST:PORT" or "[V6]:PORT" into host (without brackets) and port
 * (0..65535). Returns 0 or SD_EINVAL with err naming the text. */
int net_parse_hostport(const char *s, char *host, size_t hostlen, int *port, sd_err *err);

/* net_host_is_loopback: 1 when host is a literal loopback address (127.0.0.0/8, ::1) or
 * "localhost"; 0 otherwise (including wildcard 0.0.0.0 and ::). */
int net_host_is_loopback(const char *host);

/* net_listen: binds host:port (numeric address or "localhost"), listens, returns the fd in *fd
 * and the bound port in *bound (useful with port 0). Returns 0 or SD_EIO with err filled. */
int net_listen(const char *host, int port, int backlog, int *fd, int *bound, sd_err *err);

/* net_accept: accepts one connection (non-blocking, close-on-exec, TCP_NODELAY); writes the
 * peer "ADDR:PORT" into addr. Returns the fd, -EAGAIN when none is pending, or another
 * negative errno. */
int net_accept(int lfd, char *addr, size_t addrlen);

/* net_set_nonblock: sets O_NONBLOCK on fd. Returns 0 or -errno. */
int net_set_nonblock(int fd);
