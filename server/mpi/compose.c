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

int cmp_composite(MPI_Comm comm, uint8_t *img, uint8_t *scratch, uint8_t *out, size_t npix,
                  size_t stride, cmp_op op, void *user, cmp_wait wait, void *wait_user,
                  cmp_stats *st)
{
    MPI_Request rq, rq2;
    double t0 = now_ms();
    int rank, size, rc;
    MPI_Comm_rank(comm, &rank);
    MPI_Comm_size(comm, &size);
    memset(st, 0, sizeof *st);
    if (npix * stride > (size_t)INT_MAX || size > 65536) return MPI_ERR_COUNT;
    int p2 = 1;
    while (p2 * 2 <= size) p2 *= 2;
    enum { TAG_FOLD = 71, TAG_SWAP = 72 };
    /* fold: ranks beyond p2 hand their image to rank - p2 and are done */
    if (rank >= p2) {
        rc = MPI_Isend(img, (int)(npix * stride), MPI_BYTE, rank - p2, TAG_FOLD, comm, &rq);
        if (rc == MPI_SUCCESS) rc = wait(wait_user, &rq);
        st->bytes_sent += npix * stride;
        if (rc == MPI_SUCCESS)
            rc = MPI_Igatherv(NULL, 0, MPI_BYTE, NULL, NULL, NULL, MPI_BYTE, 0, comm, &rq);
        if (rc == MPI_SUCCESS) rc = wait(wait_user, &rq);
        st->ms = now_ms() - t0;
        return rc;
    }
    if (rank + p2 < size) {
        rc = MPI_Irecv(scratch, (int)(npix * stride), MPI_BYTE, rank + p2, TAG_FOLD, comm, &rq);
        if (rc == MPI_SUCCESS) rc = wait(wait_user, &rq);
        if (rc != MPI_SUCCESS) return rc;
        op(img, scratch, img, npix, stride, user);
    }
    /* swap */
    size_t a = 0, b = npix;
    for (int bit = 1; bit < p2; bit <<= 1) {
        size_t mid = a + (b - a) / 2;
        int partner = rank ^ bit;
        int low = !(rank & bit);
        size_t keep_a = low ? a : mid, keep_b = low ? mid : b;
        size_t give_a = low ? mid : a, give_b = low ? b : mid;
        rc = MPI_Irecv(scratch, (int)((keep_b - keep_a) * stride), MPI_BYTE, partner, TAG_SWAP,
                       comm, &rq);
        if (rc == MPI_SUCCESS)
            rc = MPI_Isend(img + give_a * stride, (int)((give_b - give_a) * stride), MPI_BYTE,
                           partner, TAG_SWAP, comm, &rq2);
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
    /* gather the ranges at rank 0, whose own range starts at pixel 0 */
    int *counts = NULL, *displs = NULL;
    if (rank == 0) {
        counts = malloc((size_t)size * sizeof *counts);
        displs = malloc((size_t)size * sizeof *displs);
        if (!counts || !displs) {
            free(counts);
            free(displs);
            return MPI_ERR_NO_MEM;
        }
        for (int r = 0; r < size; r++) {
            size_t lo = 0, hi = 0;
            if (r < p2) cmp_range(r, p2, npix, &lo, &hi);
            counts[r] = (int)((hi - lo) * stride);
            displs[r] = (int)(lo * stride);
        }
        memcpy(out, img, (b - a) * stride);
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
