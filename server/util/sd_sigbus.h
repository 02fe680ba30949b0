/* sd_sigbus.h — reads of mapped files that another process may shrink, without dying of it.
 *
 * A file mapped read-only and then truncated (or replaced in place by a shorter one) leaves the
 * pages past its new end without backing: reading them raises SIGBUS, which kills the process.
 * One SIGBUS handler serves two kinds of protection:
 *
 *  - a jump guard (sd_sigbus_run): a function run so that a SIGBUS on a given range in the
 *    calling thread ends it early, as from a setjmp. For parsers that only read the mapping
 *    with plain loads and memchr/memcpy/memcmp (no lock held, nothing to unwind).
 *  - a zero-fill region (sd_sigbus_region_add): a mapping whose missing pages, when any thread
 *    touches them, are replaced by zero pages and the region marked faulted; the reading code
 *    goes on (reading zeros) and its owner asks sd_sigbus_region_faulted afterwards. For reads
 *    that cannot be jumped out of: a GL driver copying from the mapping, a renderer's loops.
 *
 * A SIGBUS anywhere else puts back the disposition the handler replaced and returns, so the
 * access faults again and the process dies as it would have. The handler is (re)installed at
 * every guard's start: other code (a test harness) may have replaced it meanwhile. */
#pragma once
#include <stddef.h>

/* sd_sigbus_run: returns fn(arg), run so that a SIGBUS on [lo, lo + len) (rounded out to whole
 * pages) in this thread stops it: then *faulted = 1 and the return value is -1. fn stops
 * mid-way: whatever it allocated must be reachable from arg for the caller to free. Not
 * reentrant within one thread. */
int sd_sigbus_run(const void *lo, size_t len, int (*fn)(void *arg), void *arg, int *faulted);

/* sd_sigbus_region_add: guards the read-only mapping [addr, addr + len) (addr page aligned) by
 * zero fill. Returns a handle >= 0, or -1 when the table of regions is full (SD_SIGBUS_REGIONS
 * at once). */
enum { SD_SIGBUS_REGIONS = 4096 };
int sd_sigbus_region_add(const void *addr, size_t len);

/* sd_sigbus_region_faulted: 1 when a read of region h found a page without backing (the file
 * became shorter than its mapping: the pages from there on now read as zeros), else 0. */
int sd_sigbus_region_faulted(int h);

/* sd_sigbus_region_remove: forgets region h (call before unmapping it). */
void sd_sigbus_region_remove(int h);
