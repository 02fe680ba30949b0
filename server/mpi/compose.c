/* compose.c — binary-swap compositing over MPI with folding (see compose.h). */
#include "compose.h"

#include <limits.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static double now_ms(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec * 1e3 + t.tv_nsec / 1e6;
}

void cmp_range(int r, int p2, size_t npix, size_t *lo, size_t *hi)
{
    size_t a = 0, b = npix;
    for (int bit = 1; bit < p2; bit <<= 1) {
        size_t mid = a + (b - a) / 2;
        if (r & bit) a = mid;
        else b = mid;
    }
    *lo = a;
    *hi = b;
}

void cmp_op_nearest(const uint8_t *lo, const uint8_t *hi, uint8_t *dst, size_t npix,
                    size_t stride, void *user)
{
    (void)user;
    for (size_t i = 0; i < npix; i++) {
        float zl, zh;
        memcpy(&zl, lo + i * stride, sizeof zl);
        memcpy(&zh, hi + i * stride, sizeof zh);
        const uint8_t *w = zh < zl ? hi : lo;
        if (w != dst) memcpy(dst + i * stride, w + i * stride, stride);
    }
}

/* The schedule's positions. Without an order, position = rank and a rank r >= p2 folds into
 * r - p2 (any pairing does for a commutative operator). With an order (position i holds rank
 * order[i], front to back), the first 2e positions (e = size - p2) fold in adjacent pairs,
 * 2j + 1 into 2j, so that every swap index v holds a run of consecutive positions and each
 * exchange composites two runs that are adjacent in the order. */
typedef struct sched {
    const int *order;
    int size, p2, e;
} sched;

/* rank_at_v: the rank that holds swap index v. */
static int rank_at_v(const sched *s, int v)
{
    if (!s->order) return v;
    return s->order[v < s->e ? 2 * v : v + s->e];
}

static int composite(MPI_Comm comm, const int *order, uint8_t *img, uint8_t *scratch,
                     uint8_t *out, size_t npix, size_t stride, cmp_op op, void *user,
                     cmp_wait wait, void *wait_user, cmp_stats *st)
{
    MPI_Request rq, rq2;
    double t0 = now_ms();
    int rank, size, rc = MPI_SUCCESS;
    MPI_Comm_rank(comm, &rank);
    MPI_Comm_size(comm, &size);
    memset(st, 0, sizeof *st);
    if (npix * stride > (size_t)INT_MAX || size > 65536) return MPI_ERR_COUNT;
    int p2 = 1;
    while (p2 * 2 <= size) p2 *= 2;
    sched sc = {.order = order, .size = size, .p2 = p2, .e = size - p2};
    int pos = rank;
    if (order) {
        pos = -1;
        for (int i = 0; i < size; i++)
            if (order[i] == rank) pos = i;
        if (pos < 0) return MPI_ERR_RANK;
    }
    /* fold: my swap index v, or -1 when I hand my image to fold_to and am done */
    int v, fold_to = -1, fold_from = -1;
    if (!order) {
        v = pos < p2 ? pos : -1;
        if (pos >= p2) fold_to = pos - p2;
        else if (pos + p2 < size) fold_from = pos + p2;
    } else if (pos < 2 * sc.e) {
        v = pos % 2 ? -1 : pos / 2;
        if (pos % 2) fold_to = order[pos - 1];
        else fold_from = order[pos + 1];
    } else {
        v = pos - sc.e;
    }
    enum { TAG_FOLD = 71, TAG_SWAP = 72 };
    size_t a = 0, b = npix;
    if (v < 0) {
        rc = MPI_Isend(img, (int)(npix * stride), MPI_BYTE, fold_to, TAG_FOLD, comm, &rq);
        if (rc == MPI_SUCCESS) rc = wait(wait_user, &rq);
        st->bytes_sent += npix * stride;
        a = b = 0; /* nothing to gather */
    } else {
        if (fold_from >= 0) {
            rc = MPI_Irecv(scratch, (int)(npix * stride), MPI_BYTE, fold_from, TAG_FOLD, comm,
                           &rq);
            if (rc == MPI_SUCCESS) rc = wait(wait_user, &rq);
            if (rc != MPI_SUCCESS) return rc;
            op(img, scratch, img, npix, stride, user);
        }
        /* swap */
        for (int bit = 1; bit < p2; bit <<= 1) {
            size_t mid = a + (b - a) / 2;
            int partner = rank_at_v(&sc, v ^ bit);
            int low = !(v & bit);
            size_t keep_a = low ? a : mid, keep_b = low ? mid : b;
            size_t give_a = low ? mid : a, give_b = low ? b : mid;
            rc = MPI_Irecv(scratch, (int)((keep_b - keep_a) * stride), MPI_BYTE, partner,
                           TAG_SWAP, comm, &rq);
            if (rc == MPI_SUCCESS)
                rc = MPI_Isend(img + give_a * stride, (int)((give_b - give_a) * stride),
                               MPI_BYTE, partner, TAG_SWAP, comm, &rq2);
            if (rc == MPI_SUCCESS) rc = wait(wait_user, &rq2);
            if (rc == MPI_SUCCESS) rc = wait(wait_user, &rq);
            if (rc != MPI_SUCCESS) return rc;
            st->bytes_sent += (give_b - give_a) * stride;
            uint8_t *mine = img + keep_a * stride;
            if (low) op(mine, scratch, mine, keep_b - keep_a, stride, user);
            else op(scratch, mine, mine, keep_b - keep_a, stride, user);
            a = keep_a;
            b = keep_b;
        }
    }
    if (rc != MPI_SUCCESS) return rc;
    /* gather the ranges at rank 0 (which may have folded: then its count is 0) */
    int *counts = NULL, *displs = NULL;
    if (rank == 0) {
        counts = calloc((size_t)size, sizeof *counts);
        displs = calloc((size_t)size, sizeof *displs);
        if (!counts || !displs) {
            free(counts);
            free(displs);
            return MPI_ERR_NO_MEM;
        }
        for (int w = 0; w < p2; w++) {
            size_t lo = 0, hi = 0;
            cmp_range(w, p2, npix, &lo, &hi);
            int r = rank_at_v(&sc, w);
            counts[r] = (int)((hi - lo) * stride);
            displs[r] = (int)(lo * stride);
        }
        if (b > a) memcpy(out + a * stride, img + a * stride, (b - a) * stride);
    } else {
        st->bytes_sent += (b - a) * stride;
    }
    rc = MPI_Igatherv(rank == 0 ? MPI_IN_PLACE : img + a * stride, (int)((b - a) * stride),
                      MPI_BYTE, out, counts, displs, MPI_BYTE, 0, comm, &rq);
    if (rc == MPI_SUCCESS) rc = wait(wait_user, &rq);
    free(counts);
    free(displs);
    st->ms = now_ms() - t0;
    return rc;
}

int cmp_composite(MPI_Comm comm, uint8_t *img, uint8_t *scratch, uint8_t *out, size_t npix,
                  size_t stride, cmp_op op, void *user, cmp_wait wait, void *wait_user,
                  cmp_stats *st)
{
    return composite(comm, NULL, img, scratch, out, npix, stride, op, user, wait, wait_user, st);
}

int cmp_composite_ordered(MPI_Comm comm, const int *order, uint8_t *img, uint8_t *scratch,
                          uint8_t *out, size_t npix, size_t stride, cmp_op op, void *user,
                          cmp_wait wait, void *wait_user, cmp_stats *st)
{
    return composite(comm, order, img, scratch, out, npix, stride, op, user, wait, wait_user,
                     st);
}
