/* ev_epoll.c — the event loop on epoll + eventfd (see ev.h; redis ae_epoll.c). */
#include "ev.h"

#include <errno.h>
#include <stdlib.h>
#include <string.h>
#include <sys/epoll.h>
#include <sys/eventfd.h>
#include <time.h>
#include <unistd.h>

typedef struct ev_fdslot {
    int mask;
    ev_fd_cb cb;
    void *data;
} ev_fdslot;

struct ev_loop {
    int epfd, wakefd;
    int max_fds;
    int stop;
    ev_fdslot *fds;
    ev_theap timers;
    void (*before_sleep)(ev_loop *, void *);
    void *before_sleep_data;
    void (*on_wakeup)(ev_loop *, void *);
    void *wakeup_data;
};

enum { EV_MAX_EVENTS = 64 };

uint64_t ev_now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000u + (uint64_t)ts.tv_nsec / 1000000u;
}

ev_loop *ev_create(int max_fds, sd_err *err)
{
    if (max_fds < 16) max_fds = 16;
    ev_loop *l = calloc(1, sizeof *l);
    if (!l) { sd_errf(err, SD_ENOMEM, "event loop: out of memory"); return NULL; }
    l->epfd = l->wakefd = -1;
    l->max_fds = max_fds;
    l->fds = calloc((size_t)max_fds, sizeof *l->fds);
    if (!l->fds) { sd_errf(err, SD_ENOMEM, "event loop: out of memory for %d fds", max_fds); goto fail; }
    l->epfd = epoll_create1(EPOLL_CLOEXEC);
    if (l->epfd < 0) { sd_errf(err, SD_EIO, "event loop: epoll_create1: %s", strerror(errno)); goto fail; }
    l->wakefd = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
    if (l->wakefd < 0) { sd_errf(err, SD_EIO, "event loop: eventfd: %s", strerror(errno)); goto fail; }
    struct epoll_event ee = { .events = EPOLLIN, .data.fd = -1 };
    if (epoll_ctl(l->epfd, EPOLL_CTL_ADD, l->wakefd, &ee) < 0) {
        sd_errf(err, SD_EIO, "event loop: epoll_ctl(eventfd): %s", strerror(errno));
        goto fail;
    }
    return l;
fail:
    ev_destroy(l);
    return NULL;
}

void ev_destroy(ev_loop *l)
{
    if (!l) return;
    if (l->epfd >= 0) close(l->epfd);
    if (l->wakefd >= 0) close(l->wakefd);
    ev__theap_free(&l->timers);
    free(l->fds);
    free(l);
}

int ev_watch(ev_loop *l, int fd, int mask, ev_fd_cb cb, void *data, sd_err *err)
{
    if (fd < 0 || fd >= l->max_fds)
        return sd_errf(err, SD_ELIMIT, "event loop: fd %d is over the limit of %d descriptors", fd, l->max_fds);
    ev_fdslot *s = &l->fds[fd];
    if (mask == 0) { ev_unwatch(l, fd); return 0; }
    struct epoll_event ee = { .data.fd = fd };
    if (mask & EV_READ) ee.events |= EPOLLIN;
    if (mask & EV_WRITE) ee.events |= EPOLLOUT;
    if (mask & EV_HUP) ee.events |= EPOLLRDHUP;
    int op = s->mask ? EPOLL_CTL_MOD : EPOLL_CTL_ADD;
    if (epoll_ctl(l->epfd, op, fd, &ee) < 0)
        return sd_errf(err, SD_EIO, "event loop: epoll_ctl(fd %d): %s", fd, strerror(errno));
    s->mask = mask;
    s->cb = cb;
    s->data = data;
    return 0;
}

int ev_mask(const ev_loop *l, int fd)
{
    return (fd >= 0 && fd < l->max_fds) ? l->fds[fd].mask : 0;
}

void ev_unwatch(ev_loop *l, int fd)
{
    if (fd < 0 || fd >= l->max_fds || !l->fds[fd].mask) return;
    epoll_ctl(l->epfd, EPOLL_CTL_DEL, fd, NULL);
    memset(&l->fds[fd], 0, sizeof l->fds[fd]);
}

void ev_set_before_sleep(ev_loop *l, void (*fn)(ev_loop *, void *), void *data)
{
    l->before_sleep = fn;
    l->before_sleep_data = data;
}

void ev_set_wakeup(ev_loop *l, void (*fn)(ev_loop *, void *), void *data)
{
    l->on_wakeup = fn;
    l->wakeup_data = data;
}

void ev_wakeup(ev_loop *l)
{
    uint64_t one = 1;
    /* EAGAIN means the counter is already non-zero: the loop will wake anyway. */
    ssize_t r = write(l->wakefd, &one, sizeof one);
    (void)r;
}

int ev_timer_start(ev_loop *l, ev_timer *t, uint64_t ms, ev_timer_cb cb, void *data)
{
    ev__theap_remove(&l->timers, t);
    t->due_ms = ev_now_ms() + ms;
    t->cb = cb;
    t->data = data;
    return ev__theap_push(&l->timers, t);
}

void ev_timer_stop(ev_loop *l, ev_timer *t)
{
    ev__theap_remove(&l->timers, t);
}

void ev_stop(ev_loop *l)
{
    l->stop = 1;
}

/* run_timers: fires every timer due by now; a callback may re-arm or stop any timer. */
static void run_timers(ev_loop *l)
{
    uint64_t now = ev_now_ms();
    ev_timer *t;
    while ((t = ev__theap_top(&l->timers)) && t->due_ms <= now) {
        ev__theap_remove(&l->timers, t);
        t->cb(l, t, t->data);
    }
}

int ev_run(ev_loop *l)
{
    l->stop = 0;
    while (!l->stop) {
        int rc = ev_run_once(l, -1);
        if (rc < 0) return rc;
    }
    return 0;
}

int ev_run_once(ev_loop *l, int max_wait_ms)
{
    struct epoll_event evs[EV_MAX_EVENTS];
    if (l->before_sleep) l->before_sleep(l, l->before_sleep_data);
    if (l->stop) return 0;
    int timeout = -1;
    ev_timer *t = ev__theap_top(&l->timers);
    if (t) {
        uint64_t now = ev_now_ms();
        timeout = t->due_ms <= now ? 0 : (int)(t->due_ms - now > 60000 ? 60000 : t->due_ms - now);
    }
    if (max_wait_ms >= 0 && (timeout < 0 || timeout > max_wait_ms)) timeout = max_wait_ms;
    int n = epoll_wait(l->epfd, evs, EV_MAX_EVENTS, timeout);
    if (n < 0) return errno == EINTR ? 0 : SD_EIO;
    for (int i = 0; i < n; i++) {
        int fd = evs[i].data.fd;
        if (fd == -1) {
            uint64_t v;
            ssize_t r = read(l->wakefd, &v, sizeof v);
            (void)r;
            if (l->on_wakeup) l->on_wakeup(l, l->wakeup_data);
            continue;
        }
        ev_fdslot *s = &l->fds[fd];
        int mask = 0;
        if (evs[i].events & (EPOLLIN | EPOLLERR | EPOLLHUP)) mask |= EV_READ;
        if (evs[i].events & (EPOLLOUT | EPOLLERR | EPOLLHUP)) mask |= EV_WRITE;
        if (evs[i].events & (EPOLLRDHUP | EPOLLERR | EPOLLHUP)) mask |= EV_HUP;
        mask &= s->mask ? s->mask : 0;
        /* A callback earlier in this batch may have unwatched this fd: s->mask is 0 then. */
        if (mask && s->cb) s->cb(l, fd, mask, s->data);
    }
    run_timers(l);
    return 0;
}
