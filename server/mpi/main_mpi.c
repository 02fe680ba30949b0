/* main_mpi.c — splatd-mpi, the program `splatd --mpi` runs (one per MPI rank, under mpirun):
 * rank 0 is the daemon with the sort-last renderer of mpi_render.h, the other ranks its
 * workers. Built only where mpicc is (the plain splatd never links MPI). */
#include <mpi.h>
#include <pthread.h>
#include <signal.h>
#include <stdio.h>
#include <string.h>

#include "daemon.h"
#include "mpi_render.h"

int main(int argc, char **argv)
{
    /* The daemon takes SIGTERM and SIGINT through a signalfd, with the signals blocked in every
     * thread: block them before MPI starts its own threads, which would otherwise receive them
     * and die of them. */
    sigset_t ss;
    sigemptyset(&ss);
    sigaddset(&ss, SIGTERM);
    sigaddset(&ss, SIGINT);
    pthread_sigmask(SIG_BLOCK, &ss, NULL);
    int have = 0;
    if (MPI_Init_thread(&argc, &argv, MPI_THREAD_SERIALIZED, &have) != MPI_SUCCESS) {
        fprintf(stderr, "splatd-mpi: MPI_Init_thread failed\n");
        return 1;
    }
    if (have < MPI_THREAD_SERIALIZED) {
        fprintf(stderr, "splatd-mpi: this MPI gives thread level %d; the daemon needs "
                "MPI_THREAD_SERIALIZED (%d)\n", have, MPI_THREAD_SERIALIZED);
        MPI_Abort(MPI_COMM_WORLD, 1);
    }
    /* errors come back as codes, so that a failed composite is an ERROR for the client */
    MPI_Comm_set_errhandler(MPI_COMM_WORLD, MPI_ERRORS_RETURN);
    mr_ctx *m = mr_create(MPI_COMM_WORLD, argc, argv);
    if (!m) {
        fprintf(stderr, "splatd-mpi: out of memory\n");
        MPI_Abort(MPI_COMM_WORLD, 1);
    }
    int rank = 0;
    MPI_Comm_rank(MPI_COMM_WORLD, &rank);
    int rc;
    if (rank == 0) {
        rc = daemon_run(argc, argv, mr_hooks(m));
        mr_quit(m);
        if (mr_broken(m)) {
            /* a rank is gone: MPI_Finalize would wait for it, and the ranks left wait for
             * rank 0's next command; end the whole job */
            fflush(NULL);
            MPI_Abort(MPI_COMM_WORLD, rc ? rc : 1);
        }
    } else {
        rc = mr_worker(m);
    }
    mr_destroy(m);
    MPI_Finalize();
    return rc;
}
