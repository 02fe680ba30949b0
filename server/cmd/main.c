/* main.c — the splatd binary: `splatd prep`, `splatd render`, or the daemon (default). */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "commands.h"

#ifndef SPLATD_VERSION
#define SPLATD_VERSION "0.1.0"
#endif

static void usage(FILE *f)
{
    fprintf(f,
            "splatd " SPLATD_VERSION " — a headless point-cloud rendering daemon\n"
            "\n"
            "usage:\n"
            "  splatd [--listen HOST:PORT] --data DIR [--cache DIR] [--backend auto|egl|osmesa]\n"
            "         [--token-file F] [--preload NAME ...]     run the daemon (see splatd --help-daemon)\n"
            "  splatd prep FILE [--k N] [--cache DIR] [--threads N] [--force] [--quiet]\n"
            "                                                   preprocess and cache one file\n"
            "  splatd render FILE -o OUT.jpg|png|exr [options]  render one frame (splatd render --help)\n"
            "  splatd --mpi [daemon options]                     under mpirun -np N: sort-last\n"
            "                                                   rendering over N ranks (splatd-mpi)\n"
            "  splatd --version\n");
}

/* exec_mpi: `splatd --mpi ...` runs splatd-mpi (built only where MPI is, so that splatd never
 * links it) with the same arguments but --mpi: $SPLATD_MPI_BIN, else splatd-mpi next to this
 * program, else the one on PATH. Every rank mpirun starts does this before MPI_Init. Returns
 * only when none could run. */
static int exec_mpi(int argc, char **argv)
{
    char **av = calloc((size_t)argc + 1, sizeof *av);
    if (!av) return 1;
    int n = 0;
    av[n++] = "splatd-mpi";
    for (int i = 1; i < argc; i++)
        if (strcmp(argv[i], "--mpi")) av[n++] = argv[i];
    av[n] = NULL;
    const char *env = getenv("SPLATD_MPI_BIN");
    if (env && env[0]) {
        execv(env, av);
        fprintf(stderr, "splatd: --mpi: cannot run %s: %s\n", env, strerror(errno));
        free(av);
        return 1;
    }
    char self[4096];
    ssize_t len = readlink("/proc/self/exe", self, sizeof self - 16);
    if (len > 0) {
        self[len] = 0;
        char *slash = strrchr(self, '/');
        if (slash) {
            strcpy(slash + 1, "splatd-mpi");
            execv(self, av);
        }
    }
    execvp("splatd-mpi", av);
    fprintf(stderr, "splatd: --mpi needs splatd-mpi, built where Open MPI's mpicc is (apt-get "
            "install libopenmpi-dev openmpi-bin, then make): %s\n", strerror(errno));
    free(av);
    return 1;
}

int main(int argc, char **argv)
{
    if (argc >= 2 && (!strcmp(argv[1], "--help") || !strcmp(argv[1], "-h"))) {
        usage(stdout);
        return 0;
    }
    if (argc >= 2 && !strcmp(argv[1], "--version")) {
        printf("splatd %s\n", SPLATD_VERSION);
        return 0;
    }
    if (argc >= 2 && !strcmp(argv[1], "--help-daemon")) {
        char *hv[] = {argv[0], "--help", NULL};
        return cmd_daemon(2, hv);
    }
    for (int i = 1; i < argc; i++)
        if (!strcmp(argv[i], "--mpi")) return exec_mpi(argc, argv);
    if (argc >= 2 && !strcmp(argv[1], "prep")) return cmd_prep(argc - 1, argv + 1);
    if (argc >= 2 && !strcmp(argv[1], "render")) return cmd_render(argc - 1, argv + 1);
    if (argc >= 2 && argv[1][0] != '-') {
        fprintf(stderr, "splatd: unknown command '%s'\n", argv[1]);
        usage(stderr);
        return 2;
    }
    return cmd_daemon(argc, argv);
}
