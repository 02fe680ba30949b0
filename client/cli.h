/* cli.h — argument parsing of the `splat` command (not part of the public library API). */
#pragma once
#include <stddef.h>
#include <stdint.h>

enum { CLI_MAX_SETS = 64 };

typedef struct cli_args {
    const char *host;          /* default "127.0.0.1" */
    int port;                  /* default 7878 */
    const char *token_file;    /* default NULL */
    int tls;                   /* --tls */
    const char *tls_ca;        /* --tls-ca FILE (implies --tls) */
    const char *tls_name;      /* --tls-name NAME (implies --tls) */
    int timeout_s;             /* default 60 (per blocking call) */
    const char *command;       /* list, info, render, path */
    const char *name;          /* cloud name */
    const char *output;        /* -o */
    const char *path_file;     /* --path */
    long orbit;                /* --orbit N (0: none) */
    int inflight;              /* --inflight K, default 2 */
    int prefetch;              /* --prefetch K, default 4: next cameras announced (PREFETCH) */
    int force;                 /* --force */
    const char *shard;         /* --shard I/N, or NULL */
    const char *shards;        /* --shards N (count for an index from the environment) */
    int quiet;                 /* -q: no progress */
    int help;                  /* --help/-h: command is the command named, or NULL */
    int version;               /* --version */
    const char *sets[CLI_MAX_SETS];
    int nsets;
    int have_eye, have_target, have_up, have_fov, have_size;
    double eye[3], target[3], up[3];
    float fov;
    uint32_t width, height;    /* default 1280x720 */
} cli_args;

/* cli_parse: parses argv (argv[0] is the program) into a. Options may come before or after
 * the command; "--opt value" and "--opt=value" both work. Returns 0, or -1 with err naming
 * the argument (unknown option, missing value, bad number/vector/size, missing or extra
 * operands for the command). With --help or --version anywhere, returns 0 with a->help or
 * a->version set (and a->command the command named, if any) without checking more. */
int cli_parse(int argc, char **argv, cli_args *a, char *err, size_t errlen);

/* cli_parse_vec3: "x,y,z" into v. 0 or -1. */
int cli_parse_vec3(const char *s, double v[3]);

/* cli_parse_size: "WxH" (1..16384 each) into w, h. 0 or -1. */
int cli_parse_size(const char *s, uint32_t *w, uint32_t *h);
