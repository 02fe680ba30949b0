/* ev_timer.c — the timer min-heap of the event loop (see ev.h). Ordered by (due_ms, order), so
 * timers due at the same millisecond fire in the order they were armed. */
#include "ev.h"

#include <stdlib.h>

static int t_less(const ev_timer *a, const ev_timer *b)
{
    if (a->due_ms != b->due_ms) return a->due_ms < b->due_ms;
    return a->order < b->order;
}

static void put(ev_theap *h, size_t i, ev_timer *t)
{
    h->v[i] = t;
    t->heap_index = i;
}

static void sift_up(ev_theap *h, size_t i)
{
    ev_timer *t = h->v[i];
    while (i > 0) {
        size_t p = (i - 1) / 2;
        if (!t_less(t, h->v[p])) break;
        put(h, i, h->v[p]);
        i = p;
    }
    put(h, i, t);
}

static void sift_down(ev_theap *h, size_t i)
{
    ev_timer *t = h->v[i];
    for (;;) {
        size_t c = 2 * i + 1;
        if (c >= h->n) break;
        if (c + 1 < h->n && t_less(h->v[c + 1], h->v[c])) c++;
        if (!t_less(h->v[c], t)) break;
        put(h, i, h->v[c]);
        i = c;
    }
    put(h, i, t);
}

int ev__theap_push(ev_theap *h, ev_timer *t)
{
    if (h->n == h->cap) {
        size_t cap = h->cap ? h->cap * 2 : 16;
        ev_timer **v = realloc(h->v, cap * sizeof *v);
        if (!v) return SD_ENOMEM;
        h->v = v;
        h->cap = cap;
    }
    t->order = h->next_order++;
    put(h, h->n++, t);
    sift_up(h, h->n - 1);
    return 0;
}

void ev__theap_remove(ev_theap *h, ev_timer *t)
{
    size_t i = t->heap_index;
    if (i == SIZE_MAX || i >= h->n || h->v[i] != t) return;
    t->heap_index = SIZE_MAX;
    ev_timer *last = h->v[--h->n];
    if (i == h->n) return;
    put(h, i, last);
    /* The moved element may belong above or below its new place. */
    if (i > 0 && t_less(last, h->v[(i - 1) / 2])) sift_up(h, i);
    else sift_down(h, i);
}

ev_timer *ev__theap_top(const ev_theap *h)
{
    return h->n ? h->v[0] : NULL;
}

void ev__theap_free(ev_theap *h)
{
    for (size_t i = 0; i < h->n; i++) h->v[i]->heap_index = SIZE_MAX;
    free(h->v);
    h->v = NULL;
    h->n = h->cap = 0;
}

void ev_timer_init(ev_timer *t)
{
    t->heap_index = SIZE_MAX;
    t->due_ms = 0;
    t->order = 0;
    t->cb = NULL;
    t->data = NULL;
}

int ev_timer_armed(const ev_timer *t)
{
    return t->heap_index != SIZE_MAX;
}
