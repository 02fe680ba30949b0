/* ws.c — WebSocket framing (see ws.h; RFC 6455 sections 4.2.2, 5 and 7). */
#include "ws.h"

#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include <openssl/evp.h>
#include <openssl/sha.h>

static const char ws_guid[] = "258EAFA5-E914-47DA-95CA-C5AB0DC85B11";

int ws_accept_key(const char *key, size_t keylen, char out[WS_ACCEPT_LEN + 1])
{
    /* 16 random bytes in base64: 22 characters of the alphabet and "==". */
    if (keylen != WS_KEY_LEN || key[22] != '=' || key[23] != '=') return -1;
    for (size_t i = 0; i < 22; i++) {
        char c = key[i];
        if (!((c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') ||
              c == '+' || c == '/'))
            return -1;
    }
    uint8_t buf[WS_KEY_LEN + sizeof ws_guid];
    memcpy(buf, key, WS_KEY_LEN);
    memcpy(buf + WS_KEY_LEN, ws_guid, sizeof ws_guid - 1);
    uint8_t md[SHA_DIGEST_LENGTH];
    SHA1(buf, WS_KEY_LEN + sizeof ws_guid - 1, md);
    /* EVP_EncodeBlock writes 4 * ceil(20 / 3) = 28 characters and a NUL. */
    return EVP_EncodeBlock((unsigned char *)out, md, SHA_DIGEST_LENGTH) == WS_ACCEPT_LEN ? 0 : -1;
}

size_t ws_frame_header(uint8_t out[WS_MAX_HEADER], int fin, int opcode, uint64_t len,
                       const uint8_t *mask)
{
    size_t n = 0;
    out[n++] = (uint8_t)((fin ? 0x80 : 0) | (opcode & 0x0f));
    uint8_t m = mask ? 0x80 : 0;
    if (len < 126) {
        out[n++] = (uint8_t)(m | len);
    } else if (len <= 0xffff) {
        out[n++] = m | 126;
        out[n++] = (uint8_t)(len >> 8);
        out[n++] = (uint8_t)len;
    } else {
        out[n++] = m | 127;
        for (int i = 7; i >= 0; i--) out[n++] = (uint8_t)(len >> (8 * i));
    }
    if (mask) {
        memcpy(out + n, mask, 4);
        n += 4;
    }
    return n;
}

void ws_mask(uint8_t *p, size_t n, const uint8_t mask[4], uint64_t off)
{
    for (size_t i = 0; i < n; i++) p[i] ^= mask[(off + i) & 3];
}

size_t ws_close_frame(uint8_t out[4 + WS_REASON_MAX], uint16_t code, const char *reason)
{
    size_t rl = reason ? strlen(reason) : 0;
    if (rl > WS_REASON_MAX) rl = WS_REASON_MAX;
    out[0] = 0x80 | WS_OP_CLOSE;
    out[1] = (uint8_t)(2 + rl);
    out[2] = (uint8_t)(code >> 8);
    out[3] = (uint8_t)code;
    if (rl) memcpy(out + 4, reason, rl);
    return 4 + rl;
}

int ws_decoder_midway(const ws_decoder *d)
{
    return d->hdr_have > 0 || d->in_frame || d->msg_opcode != 0;
}

static int fail(ws_decoder *d, ws_event *ev, uint16_t code, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
static int fail(ws_decoder *d, ws_event *ev, uint16_t code, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    d->failed = 1;
    ev->code = code;
    vsnprintf(ev->why, sizeof ev->why, fmt, ap);
    va_end(ap);
    return WS_EV_ERROR;
}

/* first_bytes: the checks the first two header bytes allow, and the header's full length.
 * Returns 0 or WS_EV_ERROR. */
static int first_bytes(ws_decoder *d, ws_event *ev)
{
    uint8_t b0 = d->hdr[0], b1 = d->hdr[1];
    int op = b0 & 0x0f, len7 = b1 & 0x7f;
    d->fin = b0 >> 7;
    d->opcode = op;
    d->masked = b1 >> 7;
    if (b0 & 0x70)
        return fail(d, ev, WS_CLOSE_PROTOCOL, "frame with reserved bits 0x%llx set (no extension "
                    "was negotiated)", (unsigned long long)(b0 & 0x70));
    if ((op > WS_OP_BINARY && op < WS_OP_CLOSE) || op > WS_OP_PONG)
        return fail(d, ev, WS_CLOSE_PROTOCOL, "frame with reserved opcode %llu",
                    (unsigned long long)op);
    if (d->require_mask && !d->masked)
        return fail(d, ev, WS_CLOSE_PROTOCOL, "unmasked frame (opcode %llu) from a client",
                    (unsigned long long)op);
    if (op >= WS_OP_CLOSE) {
        if (!d->fin)
            return fail(d, ev, WS_CLOSE_PROTOCOL, "fragmented control frame (opcode %llu)",
                        (unsigned long long)op);
        if (len7 > WS_CONTROL_MAX)
            return fail(d, ev, WS_CLOSE_PROTOCOL, "control frame (opcode %llu) longer than 125 "
                        "bytes", (unsigned long long)op);
    } else if (op == WS_OP_CONT && !d->msg_opcode) {
        return fail(d, ev, WS_CLOSE_PROTOCOL, "continuation frame without a message to "
                    "continue");
    } else if (op != WS_OP_CONT && d->msg_opcode) {
        return fail(d, ev, WS_CLOSE_PROTOCOL, "new data frame (opcode %llu) inside a fragmented "
                    "message", (unsigned long long)op);
    } else if (op == WS_OP_TEXT && d->binary_only) {
        return fail(d, ev, WS_CLOSE_UNSUPPORTED, "text message; this endpoint takes binary "
                    "messages only");
    }
    d->hdr_need = 2 + (len7 == 126 ? 2 : len7 == 127 ? 8 : 0) + (d->masked ? 4 : 0);
    return 0;
}

/* whole_header: the length and mask of a complete header, checked. Returns 0 or WS_EV_ERROR. */
static int whole_header(ws_decoder *d, ws_event *ev)
{
    int len7 = d->hdr[1] & 0x7f;
    size_t p = 2;
    uint64_t len = (uint64_t)len7;
    if (len7 == 126) {
        len = (uint64_t)d->hdr[2] << 8 | d->hdr[3];
        p = 4;
        if (len < 126)
            return fail(d, ev, WS_CLOSE_PROTOCOL, "16-bit length %llu where 7 bits suffice "
                        "(RFC 6455 5.2: the minimal encoding)", (unsigned long long)len);
    } else if (len7 == 127) {
        len = 0;
        for (int i = 0; i < 8; i++) len = len << 8 | d->hdr[2 + i];
        p = 10;
        if (len >> 63)
            return fail(d, ev, WS_CLOSE_PROTOCOL, "64-bit length with its most significant bit "
                        "set");
        if (len <= 0xffff)
            return fail(d, ev, WS_CLOSE_PROTOCOL, "64-bit length %llu where 16 bits suffice "
                        "(RFC 6455 5.2: the minimal encoding)", (unsigned long long)len);
    }
    if (d->masked) memcpy(d->mask, d->hdr + p, 4);
    if (d->opcode < WS_OP_CLOSE) {
        uint64_t cap = d->max_message ? d->max_message : UINT64_MAX >> 1;
        if (len > cap || d->msg_len > cap - len)
            return fail(d, ev, WS_CLOSE_TOO_BIG, "message of %llu bytes or more; the limit is "
                        "%llu", (unsigned long long)(d->msg_len + len), (unsigned long long)cap);
        d->msg_len += len;
        if (d->opcode != WS_OP_CONT) d->msg_opcode = d->opcode;
    } else if (d->opcode == WS_OP_CLOSE && len == 1) {
        return fail(d, ev, WS_CLOSE_PROTOCOL, "close frame with a 1-byte payload (a code takes "
                    "2)");
    }
    d->remaining = len;
    d->frame_off = 0;
    d->ctl_len = 0;
    d->in_frame = 1;
    d->hdr_have = d->hdr_need = 0;
    return 0;
}

static int valid_close_code(unsigned c)
{
    /* RFC 6455 7.4: 1000-1003, 1007-1011 defined; 1004-1006 and 1015 never sent; 3000-4999
     * registered and private use. */
    return (c >= 1000 && c <= 1003) || (c >= 1007 && c <= 1011) || (c >= 3000 && c <= 4999);
}

/* control_done: a complete control frame into ev. Returns its event or WS_EV_ERROR. */
static int control_done(ws_decoder *d, ws_event *ev)
{
    d->in_frame = 0;
    if (d->opcode == WS_OP_CLOSE) {
        ev->code = WS_CLOSE_NO_STATUS;
        ev->len = 0;
        if (d->ctl_len >= 2) {
            unsigned c = (unsigned)d->ctl[0] << 8 | d->ctl[1];
            if (!valid_close_code(c))
                return fail(d, ev, WS_CLOSE_PROTOCOL, "close frame with invalid code %llu",
                            (unsigned long long)c);
            ev->code = (uint16_t)c;
            ev->len = d->ctl_len - 2;
            memcpy(ev->payload, d->ctl + 2, ev->len);
        }
        return WS_EV_CLOSE;
    }
    ev->len = d->ctl_len;
    memcpy(ev->payload, d->ctl, d->ctl_len);
    return d->opcode == WS_OP_PING ? WS_EV_PING : WS_EV_PONG;
}

int ws_decode(ws_decoder *d, const uint8_t *in, size_t n, size_t *used, uint8_t *out,
              size_t cap, size_t *produced, ws_event *ev)
{
    size_t i = 0, o = 0;
    int rc = WS_EV_NONE;
    *used = 0;
    *produced = 0;
    if (d->failed) {
        ev->code = WS_CLOSE_PROTOCOL;
        snprintf(ev->why, sizeof ev->why, "the stream already failed");
        return WS_EV_ERROR;
    }
    for (;;) {
        if (!d->in_frame) {
            while (d->hdr_have < 2 && i < n) d->hdr[d->hdr_have++] = in[i++];
            if (d->hdr_have < 2) break;
            if (d->hdr_need == 0 && (rc = first_bytes(d, ev)) != 0) break;
            while (d->hdr_have < d->hdr_need && i < n) d->hdr[d->hdr_have++] = in[i++];
            if (d->hdr_have < d->hdr_need) break;
            if ((rc = whole_header(d, ev)) != 0) break;
        }
        if (d->opcode >= WS_OP_CLOSE) {
            size_t k = n - i < d->remaining ? n - i : (size_t)d->remaining;
            memcpy(d->ctl + d->ctl_len, in + i, k);
            if (d->masked) ws_mask(d->ctl + d->ctl_len, k, d->mask, d->frame_off);
            d->ctl_len += k;
            d->frame_off += k;
            d->remaining -= k;
            i += k;
            if (d->remaining) break;
            rc = control_done(d, ev);
            break;
        }
        size_t k = d->remaining;
        if (k > n - i) k = n - i;
        if (k > cap - o) k = cap - o;
        if (k) {
            memcpy(out + o, in + i, k);
            if (d->masked) ws_mask(out + o, k, d->mask, d->frame_off);
            o += k;
            i += k;
            d->frame_off += k;
            d->remaining -= k;
        }
        if (d->remaining) break;
        d->in_frame = 0;
        if (d->fin) {
            d->msg_opcode = 0;
            d->msg_len = 0;
            rc = WS_EV_END;
            break;
        }
    }
    *used = i;
    *produced = o;
    return rc;
}
