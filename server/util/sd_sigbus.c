/* sd_sigbus.c — the process's SIGBUS handler: jump guards and zero-fill regions (sd_sigbus.h).
 *
 * The handler reads only the calling thread's jump guard (thread-local) and the region table
 * (atomics, written under a mutex outside the handler); its one system call, mmap over the
 * faulting page onwards, is a plain system call (no lock, no allocation). Signal handlers
 * cannot be given a context, so the table and the previous disposition are the module's. */
#include "sd_sigbus.h"

#include <pthread.h>
#include <setjmp.h>
#include <signal.h>
#include <stdatomic.h>
#include <stdint.h>
#include <string.h>
#include <sys/mman.h>
#include <unistd.h>

typedef struct jump_guard {
    sigjmp_buf jb;
    uintptr_t lo, hi;
} jump_guard;

typedef struct region {
    _Atomic uintptr_t lo, hi;  /* hi == 0: free */
    atomic_int faulted;
} region;

static _Thread_local jump_guard *volatile tl_guard;
static region regions[SD_SIGBUS_REGIONS];
static atomic_int nregions;          /* slots [0, nregions) may be in use */
static atomic_uintptr_t page_size;
static pthread_mutex_t mu = PTHREAD_MUTEX_INITIALIZER;
static struct sigaction prev;

static void on_sigbus(int sig, siginfo_t *si, void *uc)
{
    (void)sig;
    (void)uc;
    uintptr_t a = (uintptr_t)si->si_addr;
    jump_guard *g = tl_guard;
    if (g && a >= g->lo && a < g->hi) {
        tl_guard = NULL;
        siglongjmp(g->jb, 1);
    }
    int n = atomic_load(&nregions);
    uintptr_t ps = atomic_load(&page_size);
    for (int i = 0; i < n; i++) {
        uintptr_t lo = atomic_load(&regions[i].lo), hi = atomic_load(&regions[i].hi);
        if (!hi || a < lo || a >= hi) continue;
        /* Zero pages from the faulting one to the region's end: past a missing page the rest
         * of the file is missing too (a shorter file), and one call is cheaper than a fault
         * per page. The faulting read is then retried and finds a page. */
        uintptr_t at = a & ~(ps - 1);
        void *m = mmap((void *)at, hi - at, PROT_READ, MAP_PRIVATE | MAP_ANONYMOUS | MAP_FIXED,
                       -1, 0);
        if (m == MAP_FAILED) break;
        atomic_store(&regions[i].faulted, 1);
        return;
    }
    /* Not a guarded read: the disposition from before, and the access faults again. */
    sigaction(SIGBUS, &prev, NULL);
}

/* install: makes on_sigbus the SIGBUS handler, keeping the one it replaces as the disposition
 * to go back to. mu held. */
static void install(void)
{
    if (!atomic_load(&page_size)) atomic_store(&page_size, (uintptr_t)sysconf(_SC_PAGESIZE));
    struct sigaction cur;
    if (sigaction(SIGBUS, NULL, &cur) == 0 && (cur.sa_flags & SA_SIGINFO) &&
        cur.sa_sigaction == on_sigbus)
        return;
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_sigaction = on_sigbus;
    sa.sa_flags = SA_SIGINFO;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGBUS, &sa, &prev);
}

/* span_end: lo + len rounded up to a whole page. */
static uintptr_t span_end(uintptr_t lo, size_t len)
{
    uintptr_t ps = atomic_load(&page_size);
    return (lo + len + ps - 1) & ~(ps - 1);
}

int sd_sigbus_run(const void *lo, size_t len, int (*fn)(void *arg), void *arg, int *faulted)
{
    *faulted = 0;
    pthread_mutex_lock(&mu);
    install();
    pthread_mutex_unlock(&mu);
    jump_guard g;
    g.lo = (uintptr_t)lo & ~(atomic_load(&page_size) - 1);
    g.hi = span_end((uintptr_t)lo, len);
    if (sigsetjmp(g.jb, 1)) {
        tl_guard = NULL;
        *faulted = 1;
        return -1;
    }
    tl_guard = &g;
    int rc = fn(arg);
    tl_guard = NULL;
    return rc;
}

int sd_sigbus_region_add(const void *addr, size_t len)
{
    pthread_mutex_lock(&mu);
    install();
    int h = -1, n = atomic_load(&nregions);
    for (int i = 0; i < n && h < 0; i++)
        if (!atomic_load(&regions[i].hi)) h = i;
    if (h < 0 && n < SD_SIGBUS_REGIONS) h = n;
    if (h >= 0) {
        atomic_store(&regions[h].faulted, 0);
        atomic_store(&regions[h].lo, (uintptr_t)addr);
        atomic_store(&regions[h].hi, span_end((uintptr_t)addr, len));
        if (h == n) atomic_store(&nregions, n + 1);
    }
    pthread_mutex_unlock(&mu);
    return h;
}

int sd_sigbus_region_faulted(int h)
{
    return h >= 0 && h < SD_SIGBUS_REGIONS && atomic_load(&regions[h].faulted);
}

void sd_sigbus_region_remove(int h)
{
    if (h < 0 || h >= SD_SIGBUS_REGIONS) return;
    pthread_mutex_lock(&mu);
    atomic_store(&regions[h].hi, 0);
    atomic_store(&regions[h].lo, 0);
    pthread_mutex_unlock(&mu);
}
