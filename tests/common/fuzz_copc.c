/* fuzz_copc.c — the body of the copc fuzz target (fuzz_targets.h): the COPC hierarchy reader
 * on arbitrary bytes. The input is the whole "file"; its first 160 bytes stand for the COPC
 * info VLR payload (root page offset and size at 40 and 48), so every page offset the fuzzer
 * writes points back into the input. */
#include "fuzz_targets.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "copc.h"

typedef struct walk {
    size_t len;
    uint64_t nodes;
} walk;

static int on_node(void *ctx, const copc_entry *e)
{
    walk *w = ctx;
    if (e->count < 0) {
        fprintf(stderr, "fuzz oracle failed (copc): a link entry reached the node callback\n");
        abort();
    }
    if (e->count > 0 && (e->off > w->len || (uint64_t)e->bytes > w->len - e->off)) {
        fprintf(stderr, "fuzz oracle failed (copc): node data outside the %zu-byte input\n",
                w->len);
        abort();
    }
    w->nodes++;
    return 0;
}

int fuzz_one_copc(const uint8_t *data, size_t len)
{
    if (len < 160) return -1;
    laz_file lf;
    memset(&lf, 0, sizeof lf);
    lf.path = "fuzz.copc.laz";
    lf.data = data;
    lf.size = len;
    lf.copc_info = data;
    walk w = {len, 0};
    sd_err err;
    memset(&err, 0, sizeof err);
    int rc = copc_visit(&lf, INT32_MAX, on_node, &w, &err);
    if (rc < 0 && (!err.msg[0] || !strstr(err.msg, lf.path))) {
        fprintf(stderr, "fuzz oracle failed (copc): code %d without a message naming the file: "
                "'%s'\n", rc, err.msg);
        abort();
    }
    /* each node entry is 32 input bytes of some page, and pages are read at most len/32 times */
    if (w.nodes > (uint64_t)(len / 32) * (len / 32 + 1)) {
        fprintf(stderr, "fuzz oracle failed (copc): %llu nodes from %zu bytes\n",
                (unsigned long long)w.nodes, len);
        abort();
    }
    return rc;
}
