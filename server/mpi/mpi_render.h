/* mpi_render.h — splatd --mpi: sort-last rendering over MPI ranks (issue 17).
 *
 * Rank 0 is the daemon clients talk to (daemon_run with the hooks below); every other rank runs
 * mr_worker. On rank 0's render thread the hooks broadcast each cloud load and each frame to
 * all ranks: every rank opens the cloud through the (shared) prep cache, keeps the spatial part
 * pc_partition gives it (about 1/N of the points and of their splat area, a box of whole
 * octree cells) and uploads only that;
 * every rank renders its part with the frame's pipeline and camera, and the ranks composite
 * (compose.h: binary swap with folding, then a gather to rank 0), which encodes and sends.
 *
 * Rank 0 waits for the others at most $SPLATD_MPI_TIMEOUT seconds (default 60) per step: a
 * rank that died (under mpirun --enable-recovery, which keeps the others running) makes the
 * frame fail with an error naming the timeout, and every later request fail at once.
 *
 * Supported pipelines: points (per pixel the nearest depth wins: exact, because every rank
 * renders with the exact raster form and the whole cloud's near and far planes, see
 * partition.h); splat (its per-pixel state exchanged between its passes, rnd_exchange); soft
 * (model=express) and olt: every rank renders its part with a black background and coverage
 * in alpha, the images go premultiplied "over" each other front to back in the order of the
 * parts' boxes as seen from the eye (boxorder.h, over.h; binary swap keeping that order,
 * compose.h), and rank 0 puts the background under the result. That differs from the single
 * image only where splats and discs reach across a cut (README "Farms and sort-last" gives the
 * PSNR). The others are refused with an error naming why (mr_supported). */
#pragma once
#include <mpi.h>

#include "render_thread.h"

typedef struct mr_ctx mr_ctx;

/* mr_create: the state of this rank in comm (MPI initialised with at least
 * MPI_THREAD_SERIALIZED: rank 0 calls MPI from its render thread). argv: the daemon's options,
 * of which the workers read --cache, --backend and --shader-dir. NULL when out of memory. */
mr_ctx *mr_create(MPI_Comm comm, int argc, char **argv);
void mr_destroy(mr_ctx *m);

/* mr_hooks: rank 0's render-thread hooks (the pointers stay valid while m lives). */
const rt_hooks *mr_hooks(mr_ctx *m);

/* mr_worker: the loop of ranks > 0 until rank 0 says quit (mr_quit). Returns the exit status. */
int mr_worker(mr_ctx *m);

/* mr_quit: rank 0, after daemon_run returned: tells the workers to stop and logs the
 * compositing statistics. */
void mr_quit(mr_ctx *m);

/* mr_broken: 1 when rank 0 gave up waiting for the other ranks (then MPI_Finalize would wait
 * for them too: the job should end with MPI_Abort). */
int mr_broken(const mr_ctx *m);

/* mr_supported: 0 when a frame with params can be rendered sort-last, else SD_EUNSUP with err
 * saying why. */
int mr_supported(const sp_params *params, sd_err *err);
