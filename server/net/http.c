/* http.c — HTTP/1.1 request heads and response heads (see http.h). */
#include "http.h"

#include <stdio.h>
#include <string.h>
#include <strings.h>

static int bad(char *err, size_t errlen, int status, const char *what)
{
    snprintf(err, errlen, "%s", what);
    return -status;
}

/* keep: copies value[0..n) into dst (cap bytes with the NUL). Returns 0, or -1 when too long. */
static int keep(char *dst, size_t cap, const char *v, size_t n)
{
    if (n >= cap) return -1;
    memcpy(dst, v, n);
    dst[n] = 0;
    return 0;
}

/* line_end: the end of the line that starts at p, its terminator excluded, given nl, the LF
 * that ends it: a CR right before the LF belongs to the terminator (RFC 9112 2.2: a recipient
 * may take a bare LF as the line terminator and ignore a CR before it). */
static const char *line_end(const char *p, const char *nl)
{
    return nl > p && nl[-1] == '\r' ? nl - 1 : nl;
}

int http_parse_request(const char *buf, size_t len, http_req *r, char *err, size_t errlen)
{
    memset(r, 0, sizeof *r);
    /* The head ends at its first empty line: CR LF CR LF, or the same with bare LFs. */
    size_t scan = len < HTTP_HEAD_MAX ? len : HTTP_HEAD_MAX;
    const char *head_end = NULL; /* just past the empty line's LF */
    for (const char *p = buf, *nl; !head_end && (nl = memchr(p, '\n', scan - (size_t)(p - buf)));
         p = nl + 1)
        if (line_end(p, nl) == p) head_end = nl + 1;
    if (!head_end) {
        if (len >= HTTP_HEAD_MAX) {
            snprintf(err, errlen, "request head over %d bytes", HTTP_HEAD_MAX);
            return -431;
        }
        return 0;
    }
    size_t head_len = (size_t)(head_end - buf);
    /* Request line: METHOD SP TARGET SP HTTP/1.x */
    const char *p = buf, *nl = memchr(p, '\n', head_len), *eol = line_end(p, nl);
    const char *sp1 = memchr(p, ' ', (size_t)(eol - p));
    const char *sp2 = sp1 ? memchr(sp1 + 1, ' ', (size_t)(eol - sp1 - 1)) : NULL;
    if (!sp1 || !sp2) return bad(err, errlen, 400, "request line is not 'METHOD TARGET VERSION'");
    if (keep(r->method, sizeof r->method, p, (size_t)(sp1 - p)) != 0 || sp1 == p)
        return bad(err, errlen, 400, "request method empty or over 15 bytes");
    if (sp2 == sp1 + 1 || keep(r->target, sizeof r->target, sp1 + 1, (size_t)(sp2 - sp1 - 1)) != 0)
        return bad(err, errlen, 414, "request target empty or over 255 bytes");
    size_t vl = (size_t)(eol - sp2 - 1);
    if (vl != 8 || memcmp(sp2 + 1, "HTTP/1.", 7) != 0 || sp2[8] < '0' || sp2[8] > '9')
        return bad(err, errlen, 505, "not an HTTP/1.x request");
    r->minor = sp2[8] - '0';
    for (const char *c = buf; c < eol; c++)
        if ((unsigned char)*c < 0x21 && *c != ' ')
            return bad(err, errlen, 400, "control character in the request line");
    /* Headers: NAME ":" OWS VALUE OWS, each ending in CR LF or LF, up to the empty line. A CR
     * anywhere else is a control character: refused, never read as a line end. */
    int line = 2;
    for (p = nl + 1; (nl = memchr(p, '\n', (size_t)(head_end - p))) && line_end(p, nl) != p;
         p = nl + 1, line++) {
        eol = line_end(p, nl);
        const char *colon = memchr(p, ':', (size_t)(eol - p));
        if (!colon || colon == p) {
            snprintf(err, errlen, "header line %d has no 'name:'", line);
            return -400;
        }
        for (const char *c = p; c < colon; c++)
            if (*c == ' ' || *c == '\t' || (unsigned char)*c < 0x21 || (unsigned char)*c > 0x7e) {
                snprintf(err, errlen, "header line %d: invalid character in its name", line);
                return -400;
            }
        const char *v = colon + 1, *ve = eol;
        while (v < ve && (*v == ' ' || *v == '\t')) v++;
        while (ve > v && (ve[-1] == ' ' || ve[-1] == '\t')) ve--;
        for (const char *c = v; c < ve; c++)
            if (((unsigned char)*c < 0x20 && *c != '\t') || *c == 0x7f) {
                snprintf(err, errlen, "header line %d: control character in its value", line);
                return -400;
            }
        size_t nlen = (size_t)(colon - p), vlen = (size_t)(ve - v);
        char *dst = NULL;
        size_t cap = 0;
        int *flag = NULL;
#define HDR_(lit, field, fl)                                               \
        if (nlen == sizeof lit - 1 && !strncasecmp(p, lit, nlen)) {        \
            dst = r->field;                                                \
            cap = sizeof r->field;                                         \
            flag = fl;                                                     \
        } else
        HDR_("Host", host, &r->has_host)
        HDR_("Origin", origin, &r->has_origin)
        HDR_("Upgrade", upgrade, NULL)
        HDR_("Connection", connection, NULL)
        HDR_("Sec-WebSocket-Key", ws_key, NULL)
        HDR_("Sec-WebSocket-Version", ws_version, NULL)
        { /* another header: ignored, except those announcing a body */ }
#undef HDR_
        if ((nlen == 14 && !strncasecmp(p, "Content-Length", nlen) && !(vlen == 1 && *v == '0')) ||
            (nlen == 17 && !strncasecmp(p, "Transfer-Encoding", nlen)))
            r->has_body = 1;
        if (dst) {
            if (flag && *flag) {
                snprintf(err, errlen, "header line %d: a second %.*s header", line, (int)nlen, p);
                return -400;
            }
            if (keep(dst, cap, v, vlen) != 0) {
                snprintf(err, errlen, "header line %d: %.*s value over %zu bytes", line,
                         (int)nlen, p, cap - 1);
                return -431;
            }
            if (flag) *flag = 1;
        }
    }
    return (int)head_len;
}

int http_has_token(const char *value, const char *token)
{
    size_t tl = strlen(token);
    const char *p = value;
    while (*p) {
        while (*p == ' ' || *p == '\t' || *p == ',') p++;
        const char *s = p;
        while (*p && *p != ',') p++;
        const char *e = p;
        while (e > s && (e[-1] == ' ' || e[-1] == '\t')) e--;
        if ((size_t)(e - s) == tl && !strncasecmp(s, token, tl)) return 1;
    }
    return 0;
}

size_t http_response_head(char *out, size_t cap, int status, const char *reason,
                          const char *ctype, size_t content_len, const char *extra)
{
    int n;
    if (ctype)
        n = snprintf(out, cap,
                     "HTTP/1.1 %d %s\r\nContent-Type: %s\r\nContent-Length: %zu\r\n%s\r\n",
                     status, reason, ctype, content_len, extra ? extra : "");
    else
        n = snprintf(out, cap, "HTTP/1.1 %d %s\r\n%s\r\n", status, reason, extra ? extra : "");
    return n > 0 && (size_t)n < cap ? (size_t)n : 0;
}
