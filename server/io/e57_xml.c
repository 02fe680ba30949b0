/* e57_xml.c — the E57 XML section as a tree, through expat (e57_xml.h). */
#include "e57_xml.h"

#include <expat.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define E57_URI "http://www.astm.org/COMMIT/E57/2010-e57-v1.0"
#define NOR_URI "http://www.libe57.org/E57_NOR_surface_normals.txt"
#define SEP '\x01' /* between URI, local name and prefix in expat's names; never in a URI */

typedef struct arena_block {
    struct arena_block *next;
    size_t used, cap;
    _Alignas(16) unsigned char data[];
} arena_block;

struct e57_xml {
    XML_Parser p;
    arena_block *arena;
    e57_node *root, *cur;
    e57_node *last[E57_XML_MAX_DEPTH + 1]; /* the latest child of the open element at depth d */
    int depth;
    size_t nodes;
    char *text; /* the current element's character data so far */
    size_t text_len, text_cap;
    int failed; /* a handler stopped the parse: msg says why */
    char msg[200];
    int done;
};

static void *arena_alloc(e57_xml *x, size_t n)
{
    n = (n + 15) & ~(size_t)15;
    arena_block *b = x->arena;
    if (!b || b->cap - b->used < n) {
        size_t cap = n > 65536 ? n : 65536;
        b = malloc(sizeof *b + cap);
        if (!b) return NULL;
        b->next = x->arena;
        b->used = 0;
        b->cap = cap;
        x->arena = b;
    }
    void *r = b->data + b->used;
    b->used += n;
    return r;
}

static char *arena_strndup(e57_xml *x, const char *s, size_t n)
{
    char *d = arena_alloc(x, n + 1);
    if (!d) return NULL;
    memcpy(d, s, n);
    d[n] = 0;
    return d;
}

/* stop: ends the parse from a handler with a message (line of the current position). */
static void stop(e57_xml *x, const char *fmt, const char *arg)
{
    if (x->failed) return;
    x->failed = 1;
    char m[160];
    snprintf(m, sizeof m, fmt, arg);
    snprintf(x->msg, sizeof x->msg, "line %lu: %s", (unsigned long)XML_GetCurrentLineNumber(x->p),
             m);
    XML_StopParser(x->p, XML_FALSE);
}

/* split_name: expat's "URI<SEP>local<SEP>prefix" (or "local" without a namespace) into the
 * local name and the namespace class. */
static int split_name(const char *full, const char **local)
{
    const char *a = strchr(full, SEP);
    if (!a) {
        *local = full;
        return E57_NS_E57; /* no namespace: E57 files without xmlns read as E57 */
    }
    const char *b = strchr(a + 1, SEP);
    size_t ulen = (size_t)(a - full);
    *local = a + 1; /* NUL-terminated by the caller's copy below when b is set */
    if (ulen == strlen(E57_URI) && !memcmp(full, E57_URI, ulen)) return E57_NS_E57;
    if (ulen == strlen(NOR_URI) && !memcmp(full, NOR_URI, ulen)) return E57_NS_NOR;
    if (b && !strcmp(b + 1, "nor")) return E57_NS_NOR;
    return E57_NS_OTHER;
}

static void XMLCALL on_start(void *ud, const XML_Char *name, const XML_Char **atts)
{
    e57_xml *x = ud;
    if (x->failed) return;
    if (x->depth >= E57_XML_MAX_DEPTH) {
        stop(x, "elements nested deeper than %s levels", "64");
        return;
    }
    if (x->nodes >= E57_XML_MAX_NODES) {
        stop(x, "more than %s elements", "4194304");
        return;
    }
    e57_node *n = arena_alloc(x, sizeof *n);
    if (!n) {
        stop(x, "%s", "out of memory");
        return;
    }
    memset(n, 0, sizeof *n);
    const char *local;
    n->ns = split_name(name, &local);
    const char *end = strchr(local, SEP);
    n->name = arena_strndup(x, local, end ? (size_t)(end - local) : strlen(local));
    n->type = "";
    n->text = "";
    n->line = (unsigned long)XML_GetCurrentLineNumber(x->p);
    size_t na = 0;
    for (const XML_Char **a = atts; a[0]; a += 2) na++;
    const char **attrs = arena_alloc(x, (2 * na + 1) * sizeof *attrs);
    if (!n->name || !attrs) {
        stop(x, "%s", "out of memory");
        return;
    }
    size_t k = 0;
    for (const XML_Char **a = atts; a[0]; a += 2) {
        if (!strcmp(a[0], "type")) {
            n->type = arena_strndup(x, a[1], strlen(a[1]));
            if (!n->type) n->type = "";
            continue;
        }
        attrs[k] = arena_strndup(x, a[0], strlen(a[0]));
        attrs[k + 1] = arena_strndup(x, a[1], strlen(a[1]));
        if (!attrs[k] || !attrs[k + 1]) {
            stop(x, "%s", "out of memory");
            return;
        }
        k += 2;
    }
    attrs[k] = NULL;
    n->attrs = attrs;
    n->parent = x->cur;
    if (x->cur) {
        if (x->cur->child)
            x->last[x->depth]->next = n;
        else
            x->cur->child = n;
        x->last[x->depth] = n;
    } else if (!x->root) {
        x->root = n;
    }
    x->cur = n;
    x->depth++;
    x->nodes++;
    x->text_len = 0; /* a parent's text is not kept */
}

static void XMLCALL on_end(void *ud, const XML_Char *name)
{
    e57_xml *x = ud;
    (void)name;
    if (x->failed || !x->cur) return;
    e57_node *n = x->cur;
    if (!n->child) {
        char *t = arena_strndup(x, x->text ? x->text : "", x->text_len);
        if (!t) {
            stop(x, "%s", "out of memory");
            return;
        }
        n->text = t;
    }
    x->text_len = 0;
    x->cur = n->parent;
    x->depth--;
}

static void XMLCALL on_text(void *ud, const XML_Char *s, int len)
{
    e57_xml *x = ud;
    if (x->failed || !x->cur || x->cur->child || len <= 0) return;
    if (x->text_len + (size_t)len + 1 > x->text_cap) {
        size_t cap = x->text_cap ? x->text_cap : 256;
        while (cap < x->text_len + (size_t)len + 1) cap *= 2;
        char *t = realloc(x->text, cap);
        if (!t) {
            stop(x, "%s", "out of memory");
            return;
        }
        x->text = t;
        x->text_cap = cap;
    }
    memcpy(x->text + x->text_len, s, (size_t)len);
    x->text_len += (size_t)len;
}

static void XMLCALL on_doctype(void *ud, const XML_Char *name, const XML_Char *sysid,
                               const XML_Char *pubid, int has_internal_subset)
{
    (void)sysid, (void)pubid, (void)has_internal_subset;
    stop(ud, "a document type declaration (<!DOCTYPE %s>): E57 has none", name);
}

e57_xml *e57_xml_new(void)
{
    e57_xml *x = calloc(1, sizeof *x);
    if (!x) return NULL;
    x->p = XML_ParserCreateNS(NULL, SEP);
    if (!x->p) {
        free(x);
        return NULL;
    }
    XML_SetReturnNSTriplet(x->p, 1);
    XML_SetUserData(x->p, x);
    XML_SetElementHandler(x->p, on_start, on_end);
    XML_SetCharacterDataHandler(x->p, on_text);
    XML_SetStartDoctypeDeclHandler(x->p, on_doctype);
    return x;
}

int e57_xml_feed(e57_xml *x, const char *p, size_t n, int final, const char *what, sd_err *err)
{
    if (x->done) return sd_errf(err, SD_EINVAL, "%s: fed after its end", what);
    while (n > 0 || final) {
        int chunk = n > (1u << 30) ? 1 << 30 : (int)n;
        int last = final && (size_t)chunk == n;
        enum XML_Status st = XML_Parse(x->p, p, chunk, last);
        if (st != XML_STATUS_OK || x->failed) {
            int ours = x->failed;
            x->done = 1;
            x->failed = 1; /* no root for e57_xml_root */
            if (ours)
                return sd_errf(err,
                               strstr(x->msg, "out of memory") ? SD_ENOMEM
                                   : strstr(x->msg, "more than") || strstr(x->msg, "deeper")
                                   ? SD_ELIMIT
                                   : SD_EFORMAT,
                               "%s: %s", what, x->msg);
            return sd_errf(err, SD_EFORMAT, "%s: line %lu, column %lu: %s", what,
                           (unsigned long)XML_GetCurrentLineNumber(x->p),
                           (unsigned long)XML_GetCurrentColumnNumber(x->p),
                           XML_ErrorString(XML_GetErrorCode(x->p)));
        }
        p += chunk;
        n -= (size_t)chunk;
        if (last) {
            x->done = 1;
            break;
        }
    }
    return 0;
}

const e57_node *e57_xml_root(const e57_xml *x)
{
    return x->done && !x->failed ? x->root : NULL;
}

void e57_xml_free(e57_xml *x)
{
    if (!x) return;
    if (x->p) XML_ParserFree(x->p);
    for (arena_block *b = x->arena; b;) {
        arena_block *nb = b->next;
        free(b);
        b = nb;
    }
    free(x->text);
    free(x);
}

const e57_node *e57_child(const e57_node *n, const char *name)
{
    if (!n) return NULL;
    for (const e57_node *c = n->child; c; c = c->next)
        if (c->ns == E57_NS_E57 && !strcmp(c->name, name)) return c;
    return NULL;
}

const char *e57_attr(const e57_node *n, const char *name)
{
    if (!n || !n->attrs) return NULL;
    for (const char *const *a = n->attrs; a[0]; a += 2)
        if (!strcmp(a[0], name)) return a[1];
    return NULL;
}
