/* ev.h — the daemon's small event loop: fd events with a mask, timers in a heap, a
 * before-sleep hook, and a wakeup other threads may call (redis ae.h, libuv timers).
 *
 * Threading: everything here runs on the loop's thread except ev_wakeup, which any thread may
 * call (it writes an eventfd; the loop then runs the wakeup callback once, however many wakeups
 * were posted). The epoll calls stay private in ev_epoll.c. */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "sd_err.h"

typedef struct ev_loop ev_loop;

enum { EV_READ = 1, EV_WRITE = 2, EV_HUP = 4 };

/* An fd callback: mask says which of EV_READ/EV_WRITE are ready (errors and hang-ups are
 * reported as EV_READ, so the read path sees the EOF or error). EV_HUP, asked for without
 * EV_READ, reports only that the peer hung up or the socket failed (EPOLLRDHUP, EPOLLHUP,
 * EPOLLERR), for a connection that must not be read yet but should not outlive its peer. */
typedef void (*ev_fd_cb)(ev_loop *l, int fd, int mask, void *data);

/* ---- timers: the caller owns the ev_timer (embedded in its own struct); no allocation ---- */
typedef struct ev_timer ev_timer;
typedef void (*ev_timer_cb)(ev_loop *l, ev_timer *t, void *data);
struct ev_timer {
    uint64_t due_ms;        /* absolute, ev_now_ms() clock */
    uint64_t order;         /* insertion order: timers due at the same time fire in that order */
    size_t heap_index;      /* position in the heap; SIZE_MAX when not armed */
    ev_timer_cb cb;
    void *data;
};

/* A binary min-heap of timers by (due_ms, order) (libuv src/timer.c). Exposed for the loop and
 * the tests; other code uses ev_timer_start/ev_timer_stop. */
typedef struct ev_theap {
    ev_timer **v;
    size_t n, cap;
    uint64_t next_order;
} ev_theap;

/* ev__theap_push: inserts t (which must not be armed). Returns 0 or SD_ENOMEM. */
int ev__theap_push(ev_theap *h, ev_timer *t);
/* ev__theap_remove: removes t if armed (no-op otherwise); t->heap_index becomes SIZE_MAX. */
void ev__theap_remove(ev_theap *h, ev_timer *t);
/* ev__theap_top: the earliest timer or NULL. */
ev_timer *ev__theap_top(const ev_theap *h);
/* ev__theap_free: frees the array (the timers belong to their owners); safe to call twice. */
void ev__theap_free(ev_theap *h);

/* ev_timer_init: marks t as not armed. Call once before the first ev_timer_start/stop. */
void ev_timer_init(ev_timer *t);
/* ev_timer_start: (re)arms t to fire once after ms milliseconds. Returns 0 or SD_ENOMEM. */
int ev_timer_start(ev_loop *l, ev_timer *t, uint64_t ms, ev_timer_cb cb, void *data);
/* ev_timer_stop: disarms t; safe when not armed. */
void ev_timer_stop(ev_loop *l, ev_timer *t);
/* ev_timer_armed: 1 when t is waiting to fire. */
int ev_timer_armed(const ev_timer *t);

/* ev_now_ms: CLOCK_MONOTONIC in milliseconds. */
uint64_t ev_now_ms(void);

/* ---- the loop ---- */

/* ev_create: a loop for fds below max_fds. Returns NULL with err filled. */
ev_loop *ev_create(int max_fds, sd_err *err);
/* ev_destroy: closes the epoll and eventfd descriptors and frees l (fds registered with it are
 * the callers'). NULL is allowed. */
void ev_destroy(ev_loop *l);

/* ev_watch: sets the events watched on fd to mask (0 removes it), with cb/data. Returns 0, or
 * SD_ELIMIT when fd >= max_fds, or SD_EIO with err filled. */
int ev_watch(ev_loop *l, int fd, int mask, ev_fd_cb cb, void *data, sd_err *err);
/* ev_mask: the events watched on fd (0 when none). */
int ev_mask(const ev_loop *l, int fd);
/* ev_unwatch: stops watching fd entirely (call before closing it). */
void ev_unwatch(ev_loop *l, int fd);

/* ev_set_before_sleep: fn runs on every iteration before the loop waits (safe point for
 * freeing closed clients, flushing output). */
void ev_set_before_sleep(ev_loop *l, void (*fn)(ev_loop *l, void *data), void *data);
/* ev_set_wakeup: fn runs on the loop thread after one or more ev_wakeup calls. */
void ev_set_wakeup(ev_loop *l, void (*fn)(ev_loop *l, void *data), void *data);
/* ev_wakeup: thread-safe; makes the loop run its wakeup callback soon. */
void ev_wakeup(ev_loop *l);

/* ev_run: runs until ev_stop. Returns 0, or SD_EIO when epoll_wait fails. */
int ev_run(ev_loop *l);
/* ev_run_once: one iteration of ev_run: the before-sleep hook, a wait of at most max_wait_ms
 * (< 0: until the next timer or event) and the callbacks of what is ready. For a caller that
 * drives the loop itself (the dispatch fuzzer). Returns 0, or SD_EIO when epoll_wait fails. */
int ev_run_once(ev_loop *l, int max_wait_ms);
/* ev_stop: makes ev_run return after the current iteration. */
void ev_stop(ev_loop *l);
