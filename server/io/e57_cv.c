/* e57_cv.c — compressed vector sections and their packets (e57_cv.h). */
#include "e57_cv.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "e57_bitpack.h"

enum { PACKET_MAX = 65536, CACHE_SLOTS = 8, SECTION_HEADER = 32 };
enum { PKT_INDEX = 0, PKT_DATA = 1, PKT_EMPTY = 2 };

typedef struct slot {
    uint64_t phys; /* where the packet starts; UINT64_MAX: empty slot */
    uint64_t next; /* the physical offset of the packet after it */
    uint64_t stamp; /* last use, for eviction */
    uint32_t len; /* logical length */
    uint8_t *data; /* PACKET_MAX bytes */
} slot;

typedef struct chan {
    e57_bp bp;
    uint64_t next; /* the next packet this field has not taken its buffer from */
} chan;

struct e57_cv {
    e57_file *f;
    const e57_scan *s;
    uint64_t sec_off, sec_len, sec_end, data_off;
    uint64_t done; /* records handed out */
    chan *ch; /* one per field */
    slot cache[CACHE_SLOTS];
    uint64_t clock, reads;
};

static uint16_t rd16(const uint8_t *p)
{
    return (uint16_t)(p[0] | p[1] << 8);
}

static uint64_t rd64(const uint8_t *p)
{
    uint64_t v = 0;
    for (int i = 7; i >= 0; i--) v = v << 8 | p[i];
    return v;
}

uint64_t e57_cv_logical_len(const e57_cv *cv)
{
    return cv->sec_len;
}

uint64_t e57_cv_reads(const e57_cv *cv)
{
    return cv->reads;
}

void e57_cv_close(e57_cv *cv)
{
    if (!cv) return;
    for (uint32_t i = 0; cv->ch && i < cv->s->nfields; i++) e57_bp_free(&cv->ch[i].bp);
    free(cv->ch);
    for (int k = 0; k < CACHE_SLOTS; k++) free(cv->cache[k].data);
    free(cv);
}

int e57_cv_open(e57_file *f, const e57_scan *s, e57_cv **out, sd_err *err)
{
    *out = NULL;
    uint8_t h[SECTION_HEADER];
    if (s->cv_offset >= f->size)
        return sd_errf(err, SD_EFORMAT,
                       "%s: scan %u (XML line %lu): its compressed vector's "
                       "fileOffset %llu is past the end of the file (%llu bytes)",
                       f->path, s->index, s->line, (unsigned long long)s->cv_offset,
                       (unsigned long long)f->size);
    int rc = e57_file_read(f, s->cv_offset, h, sizeof h, err);
    if (rc < 0) return rc;
    uint64_t len = rd64(h + 8), data = rd64(h + 16);
    if (h[0] != 1)
        return sd_errf(err, SD_EFORMAT,
                       "%s: scan %u: the compressed vector section at physical "
                       "offset %llu has section id %u, not 1: an invalid header",
                       f->path, s->index, (unsigned long long)s->cv_offset, h[0]);
    uint64_t room = e57_logical_room(f, s->cv_offset);
    if (len < SECTION_HEADER || len > room)
        return sd_errf(err, len > room ? SD_ETRUNC : SD_EFORMAT,
                       "%s: scan %u: the compressed "
                       "vector section at physical offset %llu says it is %llu logical bytes "
                       "long; the file holds %llu from there",
                       f->path, s->index, (unsigned long long)s->cv_offset, (unsigned long long)len,
                       (unsigned long long)room);
    e57_cv *cv = calloc(1, sizeof *cv);
    if (!cv) return sd_errf(err, SD_ENOMEM, "%s: out of memory", f->path);
    cv->f = f;
    cv->s = s;
    cv->sec_off = s->cv_offset;
    cv->sec_len = len;
    cv->sec_end = e57_phys_advance(f, s->cv_offset, len);
    cv->data_off = data;
    uint64_t first = e57_phys_advance(f, s->cv_offset, SECTION_HEADER);
    if (s->records > 0 && (data < first || data >= cv->sec_end || data % f->page >= f->page - 4)) {
        rc = sd_errf(err, SD_EFORMAT,
                     "%s: scan %u: the compressed vector section at physical "
                     "offset %llu puts its data packets at physical offset %llu, outside the "
                     "section (%llu to %llu)",
                     f->path, s->index, (unsigned long long)s->cv_offset, (unsigned long long)data,
                     (unsigned long long)first, (unsigned long long)cv->sec_end);
        e57_cv_close(cv);
        return rc;
    }
    cv->ch = calloc(s->nfields ? s->nfields : 1, sizeof *cv->ch);
    for (int k = 0; k < CACHE_SLOTS; k++) cv->cache[k].phys = UINT64_MAX;
    if (!cv->ch) {
        e57_cv_close(cv);
        return sd_errf(err, SD_ENOMEM, "%s: out of memory", f->path);
    }
    for (uint32_t i = 0; i < s->nfields; i++) cv->ch[i].next = data;
    *out = cv;
    return 0;
}

/* packet: the packet at physical offset phys (from the cache or read), its header checked
 * against the section. */
static int packet(e57_cv *cv, uint64_t phys, const slot **out, sd_err *err)
{
    slot *victim = &cv->cache[0]; /* the least recently used; an empty slot has stamp 0 */
    for (int k = 0; k < CACHE_SLOTS; k++) {
        slot *c = &cv->cache[k];
        if (c->phys == phys) {
            c->stamp = ++cv->clock;
            *out = c;
            return 0;
        }
        if (c->stamp < victim->stamp) victim = c;
    }
    e57_file *f = cv->f;
    const e57_scan *s = cv->s;
    uint8_t h[4];
    int rc = e57_file_read(f, phys, h, sizeof h, err);
    if (rc < 0) return rc;
    uint32_t len = (uint32_t)rd16(h + 2) + 1;
    uint64_t next = e57_phys_advance(f, phys, len);
    if (h[0] > PKT_EMPTY || len < 4 || next > cv->sec_end)
        return sd_errf(err, SD_EFORMAT, "%s: scan %u: the packet at physical offset %llu %s",
                       f->path, s->index, (unsigned long long)phys,
                       h[0] > PKT_EMPTY ? "has an unknown type (not data, index or empty)"
                                        : "runs past the end of its compressed vector section");
    if (!victim->data && !(victim->data = malloc(PACKET_MAX)))
        return sd_errf(err, SD_ENOMEM, "%s: out of memory", f->path);
    victim->phys = UINT64_MAX;
    victim->stamp = 0;
    if ((rc = e57_file_read(f, phys, victim->data, len, err)) < 0) return rc;
    cv->reads++;
    if (h[0] == PKT_DATA) {
        const uint8_t *d = victim->data;
        uint32_t count = len >= 6 ? rd16(d + 4) : 0, head = 6 + 2 * count, sum = 0;
        for (uint32_t i = 0; i < count && head <= len; i++) sum += rd16(d + 6 + 2 * i);
        if (len < 6 || count != s->nfields || head > len || sum > len - head)
            return sd_errf(err, SD_EFORMAT,
                           "%s: scan %u: the data packet at physical offset "
                           "%llu (%u bytes) holds %u bytestreams for %u prototype fields, their "
                           "buffers %u bytes after a %u-byte header",
                           f->path, s->index, (unsigned long long)phys, len, count, s->nfields, sum,
                           head);
    }
    victim->phys = phys;
    victim->next = next;
    victim->len = len;
    victim->stamp = ++cv->clock;
    *out = victim;
    return 0;
}

/* fill: gives field i the buffer of the next data packet it has not taken one from. 1 when it
 * got bytes, 0 when the section has no packet left, negative on an error. */
static int fill(e57_cv *cv, uint32_t i, sd_err *err)
{
    chan *c = &cv->ch[i];
    while (c->next < cv->sec_end) {
        const slot *p = NULL;
        int rc = packet(cv, c->next, &p, err);
        if (rc < 0) return rc;
        c->next = p->next;
        if (p->data[0] != PKT_DATA) continue;
        size_t off = 6 + 2 * (size_t)cv->s->nfields;
        for (uint32_t j = 0; j < i; j++) off += rd16(p->data + 6 + 2 * j);
        size_t n = rd16(p->data + 6 + 2 * i);
        if (n == 0) continue;
        if (e57_bp_append(&c->bp, p->data + off, n) < 0)
            return sd_errf(err, SD_ENOMEM, "%s: out of memory", cv->f->path);
        return 1;
    }
    return 0;
}

static const char *field_name(const e57_field *f, uint32_t i, char *buf, size_t len)
{
    if (f->role >= 0) return e57_role_name(f->role);
    snprintf(buf, len, "#%u", i);
    return buf;
}

int64_t e57_cv_read(e57_cv *cv, double *const *cols, size_t n, sd_err *err)
{
    const e57_scan *s = cv->s;
    if (n > s->records - cv->done) n = (size_t)(s->records - cv->done);
    if (n == 0) return 0;
    for (uint32_t i = 0; i < s->nfields; i++) {
        if (!cols[i]) continue;
        const e57_field *f = &s->fields[i];
        chan *c = &cv->ch[i];
        size_t got = 0;
        while (got < n) {
            size_t avail = e57_bp_avail(&c->bp, f->bits);
            if (avail == 0) {
                int rc = fill(cv, i, err);
                if (rc < 0) return rc;
                if (rc == 0) {
                    char b[16];
                    return sd_errf(err, SD_EFORMAT,
                                   "%s: scan %u: the bytestream of field %s "
                                   "ends after %llu of the %llu records the XML declares (the "
                                   "compressed vector section at physical offset %llu holds no "
                                   "more)",
                                   cv->f->path, s->index, field_name(f, i, b, sizeof b),
                                   (unsigned long long)(cv->done + got),
                                   (unsigned long long)s->records, (unsigned long long)cv->sec_off);
                }
                continue;
            }
            size_t m = avail < n - got ? avail : n - got;
            int64_t bad = e57_bp_decode(&c->bp, f, cols[i] + got, m);
            if (bad >= 0) {
                char b[16];
                return sd_errf(err, SD_EFORMAT,
                               "%s: scan %u: record %llu: field %s holds a "
                               "value over the prototype's maximum %lld",
                               cv->f->path, s->index,
                               (unsigned long long)(cv->done + got + (uint64_t)bad),
                               field_name(f, i, b, sizeof b), (long long)f->max);
            }
            got += m;
        }
    }
    cv->done += n;
    return (int64_t)n;
}
