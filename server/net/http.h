/* http.h — the little HTTP/1.1 a browser listener needs: parse one request head (request line
 * and headers, RFC 9112) from a buffer, test a header's comma-separated tokens, and format a
 * response head. Pure functions over buffers, no sockets. Low-level: returns codes, never logs. */
#pragma once
#include <stddef.h>

enum {
    HTTP_HEAD_MAX = 8192,     /* bytes of request line + headers accepted (nginx: 8 KiB) */
    HTTP_FIELD_MAX = 256,     /* bytes of the one header values kept */
};

typedef struct http_req {
    char method[16];
    char target[HTTP_FIELD_MAX];     /* the request target, e.g. "/" or "/ws?x" */
    int minor;                       /* HTTP/1.<minor> */
    char host[HTTP_FIELD_MAX];
    char origin[HTTP_FIELD_MAX];
    int has_host, has_origin;
    char upgrade[HTTP_FIELD_MAX];
    char connection[HTTP_FIELD_MAX];
    char ws_key[HTTP_FIELD_MAX];
    char ws_version[16];
    int has_body;                    /* Content-Length other than 0, or Transfer-Encoding */
} http_req;

/* http_parse_request: parses the request head at the start of buf[0..len). Returns the head's
 * length (through its empty line) when complete, 0 when more bytes are needed (and len is
 * below HTTP_HEAD_MAX), or a negative HTTP status (-400 malformed, -414 target over 255
 * bytes, -431 head or a kept header too large, -505 not HTTP/1.x) with err naming what and
 * where. */
int http_parse_request(const char *buf, size_t len, http_req *r, char *err, size_t errlen);

/* http_has_token: 1 when the comma-separated header value holds token (case-insensitive,
 * spaces around items ignored), e.g. Connection "keep-alive, Upgrade" has "upgrade". */
int http_has_token(const char *value, const char *token);

/* http_response_head: writes "HTTP/1.1 status reason" and the headers (Content-Type and
 * Content-Length when ctype is not NULL, `extra` lines verbatim, each ending in \r\n) and the
 * empty line into out. Returns the length, or 0 when it does not fit in cap. */
size_t http_response_head(char *out, size_t cap, int status, const char *reason,
                          const char *ctype, size_t content_len, const char *extra);
