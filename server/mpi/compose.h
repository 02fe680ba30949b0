/* compose.h — sort-last compositing over MPI: binary swap (Ma et al. 1994) with the ranks
 * beyond the largest power of two folded in first, then a gather of the pieces to rank 0.
 *
 * Every rank holds an image of npix pixels of `stride` bytes each. In a fold, rank r >= p2
 * (p2 the largest power of two <= size) sends its whole image to rank r - p2; then in round
 * k = 0 .. log2(p2) - 1 each rank r < p2 keeps one half of its current pixel range (the lower
 * half when bit k of r is 0), sends the other half to rank r ^ 2^k and composites what it
 * receives into the half it keeps; finally rank 0 gathers each rank's range (npix / p2
 * pixels). Per rank that sends npix * stride * (1 - 1 / p2) bytes in the swap, plus the fold's
 * npix * stride for a folded rank and npix * stride / p2 in the gather.
 *
 * The operator composites two images of one range: `lo` is the image of the ranks that come
 * first in the order the schedule fixes (lower rank numbers in the swap; the rank folded into
 * comes before the folded one), `hi` the other; the result goes to dst, which is lo or hi. */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include <mpi.h>

typedef void (*cmp_op)(const uint8_t *lo, const uint8_t *hi, uint8_t *dst, size_t npix,
                       size_t stride, void *user);

/* How a rank waits for one request to complete: MPI_Wait, or a wait with a deadline (rank 0,
 * so that a rank that died makes a frame fail instead of hanging). Returns MPI_SUCCESS or an
 * error code. */
typedef int (*cmp_wait)(void *user, MPI_Request *rq);

typedef struct cmp_stats {
    uint64_t bytes_sent;       /* by this rank in this composite (fold, swap and gather) */
    double ms;                 /* wall time of the composite on this rank */
} cmp_stats;

/* cmp_composite: composites img (npix * stride bytes, overwritten) across comm with op; rank
 * 0 receives the whole composite in out (npix * stride bytes; others may pass NULL). scratch
 * holds npix * stride bytes. Every transfer is non-blocking and completed through wait.
 * Returns MPI_SUCCESS, MPI_ERR_COUNT for an image of 2 GiB or more
 * or more than 65536 ranks, MPI_ERR_NO_MEM, or the MPI error code (the communicator's
 * error handler must return errors for that to reach the caller). */
int cmp_composite(MPI_Comm comm, uint8_t *img, uint8_t *scratch, uint8_t *out, size_t npix,
                  size_t stride, cmp_op op, void *user, cmp_wait wait, void *wait_user,
                  cmp_stats *st);

/* cmp_composite_ordered: cmp_composite for an operator that is associative but not
 * commutative ("over"): order[0..size) lists the ranks front to back, and every call of op
 * gets as lo the image of ranks that all come before those of hi in that order. The ranks
 * take the schedule's places in that order; the first 2 (size - p2) places fold in adjacent
 * pairs (the second into the first), so every exchange of the swap joins two runs of
 * consecutive places. Bytes sent are those of cmp_composite. MPI_ERR_RANK when this rank is
 * not in order. */
int cmp_composite_ordered(MPI_Comm comm, const int *order, uint8_t *img, uint8_t *scratch,
                          uint8_t *out, size_t npix, size_t stride, cmp_op op, void *user,
                          cmp_wait wait, void *wait_user, cmp_stats *st);

/* cmp_range: the pixel range [*lo, *hi) rank r keeps after the swap among p2 ranks. */
void cmp_range(int r, int p2, size_t npix, size_t *lo, size_t *hi);

/* cmp_op_nearest: per pixel the nearer of lo and hi by the float depth in each pixel's first
 * 4 bytes (+inf: empty); lo wins a tie. */
void cmp_op_nearest(const uint8_t *lo, const uint8_t *hi, uint8_t *dst, size_t npix,
                    size_t stride, void *user);
