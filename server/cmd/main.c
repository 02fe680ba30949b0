/* main.c — the splatd binary: `splatd prep`, `splatd render`, or the daemon (default). */
#include <stdio.h>
#include <string.h>

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
            "  splatd --version\n");
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
    if (argc >= 2 && !strcmp(argv[1], "prep")) return cmd_prep(argc - 1, argv + 1);
    if (argc >= 2 && !strcmp(argv[1], "render")) return cmd_render(argc - 1, argv + 1);
    if (argc >= 2 && argv[1][0] != '-') {
        fprintf(stderr, "splatd: unknown command '%s'\n", argv[1]);
        usage(stderr);
        return 2;
    }
    return cmd_daemon(argc, argv);
}
