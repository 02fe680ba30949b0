/* ws.h — WebSocket framing (RFC 6455) as pure functions over buffers: the opening handshake's
 * accept key, frame headers, and an incremental frame decoder. No sockets, no allocation: the
 * decoder unmasks payload bytes straight into the caller's buffer and keeps control-frame
 * payloads (at most 125 bytes) in itself, so a frame's claimed length never sizes anything.
 * Used by the daemon's HTTP/WebSocket layer (ws_conn.c) and by the tests and bench client
 * (which decode server frames with require_mask = 0). Low-level: returns codes, never logs. */
#pragma once
#include <stddef.h>
#include <stdint.h>

enum {
    WS_MAX_HEADER = 14,     /* 2 + 8 (64-bit length) + 4 (mask) */
    WS_CONTROL_MAX = 125,   /* control frames: payload at most this, never fragmented */
    WS_KEY_LEN = 24,        /* Sec-WebSocket-Key: base64 of 16 bytes */
    WS_ACCEPT_LEN = 28,     /* Sec-WebSocket-Accept: base64 of a SHA-1 */
    WS_REASON_MAX = 123,    /* close reason bytes after the 2-byte code */
};

enum { WS_OP_CONT = 0, WS_OP_TEXT = 1, WS_OP_BINARY = 2, WS_OP_CLOSE = 8, WS_OP_PING = 9,
       WS_OP_PONG = 10 };

/* Close status codes (RFC 6455 7.4.1). */
enum { WS_CLOSE_NORMAL = 1000, WS_CLOSE_GOING_AWAY = 1001, WS_CLOSE_PROTOCOL = 1002,
       WS_CLOSE_UNSUPPORTED = 1003, WS_CLOSE_NO_STATUS = 1005, WS_CLOSE_INVALID = 1007,
       WS_CLOSE_POLICY = 1008, WS_CLOSE_TOO_BIG = 1009, WS_CLOSE_INTERNAL = 1011 };

/* What ws_decode stopped for. */
enum { WS_EV_NONE = 0,      /* input used up, or the output buffer is full */
       WS_EV_END,           /* a data message ended (its last bytes are in the output) */
       WS_EV_PING,          /* ev.payload holds the ping's payload: answer with a pong */
       WS_EV_PONG,
       WS_EV_CLOSE,         /* ev.code / ev.payload (reason): answer with a close */
       WS_EV_ERROR = -1 };  /* malformed input: ev.code is the close code to send, ev.why
                             * says why */

typedef struct ws_event {
    uint16_t code;                      /* CLOSE: the peer's code (1005 when none); ERROR: ours */
    uint8_t payload[WS_CONTROL_MAX];    /* PING/PONG payload; CLOSE reason (without the code) */
    size_t len;
    char why[160];                      /* ERROR: a sentence naming the fault */
} ws_event;

typedef struct ws_decoder {
    /* settings (zero-initialise, then set) */
    uint64_t max_message;   /* payload bytes one data message may carry (all fragments); 0: 2^63 */
    int require_mask;       /* 1 on a server: client frames must be masked (RFC 6455 5.1) */
    int binary_only;        /* 1: text messages are refused with 1003 */
    /* state */
    uint8_t hdr[WS_MAX_HEADER];
    size_t hdr_have, hdr_need;
    int in_frame;           /* header complete, payload bytes remain (or a control frame ends) */
    int opcode, fin, masked;
    uint8_t mask[4];
    uint64_t remaining, frame_off;
    int msg_opcode;         /* the data message in progress (TEXT/BINARY), 0 when none */
    uint64_t msg_len;
    uint8_t ctl[WS_CONTROL_MAX];
    size_t ctl_len;
    int failed;             /* an error was returned: every later call returns it again */
} ws_decoder;

/* ws_accept_key: the Sec-WebSocket-Accept value for a Sec-WebSocket-Key (base64 of
 * SHA-1(key + the RFC's GUID)), NUL-terminated in out. Returns 0, or -1 when key is not the
 * base64 text of 16 bytes (24 characters ending in "==", RFC 6455 4.1). */
int ws_accept_key(const char *key, size_t keylen, char out[WS_ACCEPT_LEN + 1]);

/* ws_frame_header: writes the header of one frame with fin, opcode and a payload of len bytes
 * into out; masked with mask when mask is not NULL (a client's frames; the caller masks the
 * payload with ws_mask). Returns the header's length (2 to 14). */
size_t ws_frame_header(uint8_t out[WS_MAX_HEADER], int fin, int opcode, uint64_t len,
                       const uint8_t *mask);

/* ws_mask: XORs n bytes of p with mask, starting at byte offset off of the payload (masking
 * and unmasking are the same operation). */
void ws_mask(uint8_t *p, size_t n, const uint8_t mask[4], uint64_t off);

/* ws_close_frame: a complete unmasked close frame with code and reason (cut to WS_REASON_MAX
 * bytes) in out. Returns its length (at most 2 + 2 + WS_REASON_MAX). */
size_t ws_close_frame(uint8_t out[4 + WS_REASON_MAX], uint16_t code, const char *reason);

/* ws_decode: consumes input in[0..n) and writes the unmasked payload bytes of data messages to
 * out (at most cap; *produced says how many), stopping at the first event: the end of a data
 * message, a complete control frame, or an error. *used says how much input was consumed; call
 * again with the rest. Every frame header is checked (reserved bits, opcode, masking, length
 * encoding, control-frame rules, fragment order, max_message) before any of its payload is
 * taken. Returns a WS_EV_* value; WS_EV_ERROR fills ev->code and ev->why, and the decoder
 * stays failed. */
int ws_decode(ws_decoder *d, const uint8_t *in, size_t n, size_t *used, uint8_t *out,
              size_t cap, size_t *produced, ws_event *ev);

/* ws_decoder_midway: 1 while part of a frame or a fragmented message has arrived (for a read
 * deadline), 0 at a message boundary. */
int ws_decoder_midway(const ws_decoder *d);
