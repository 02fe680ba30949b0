/* cli.c — argument parsing of the `splat` command (see cli.h). */
#include "cli.h"

#include "framing.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

int cli_parse_vec3(const char *s, double v[3])
{
    const char *p = s;
    for (int i = 0; i < 3; i++) {
        char *end;
        errno = 0;
        v[i] = strtod(p, &end);
        if (end == p || errno || !isfinite(v[i])) return -1;
        p = end;
        if (i < 2) {
            if (*p != ',') return -1;
            p++;
        }
    }
    return *p ? -1 : 0;
}

int cli_parse_size(const char *s, uint32_t *w, uint32_t *h)
{
    char *end;
    errno = 0;
    unsigned long a = strtoul(s, &end, 10);
    if (end == s || (*end != 'x' && *end != 'X') || errno) return -1;
    const char *p = end + 1;
    unsigned long b = strtoul(p, &end, 10);
    if (end == p || *end || errno || a < 1 || b < 1 || a > 16384 || b > 16384) return -1;
    if (s[0] == '-' || p[0] == '-' || s[0] == '+' || p[0] == '+') return -1;
    *w = (uint32_t)a;
    *h = (uint32_t)b;
    return 0;
}

/* parse_long: a whole decimal number in [lo, hi]. 0 or -1. */
static int parse_long(const char *s, long lo, long hi, long *out)
{
    char *end;
    errno = 0;
    long v = strtol(s, &end, 10);
    if (end == s || *end || errno || v < lo || v > hi) return -1;
    *out = v;
    return 0;
}

/* is_command: 1 for the names of splat's commands. */
static int is_command(const char *s)
{
    return !strcmp(s, "list") || !strcmp(s, "info") || !strcmp(s, "render") || !strcmp(s, "path");
}

/* scan_help: --help/-h or --version anywhere before "--" answer before anything else is
 * checked (so `splat render --help` works without a NAME or -o); the command named anywhere
 * picks the help text. Returns 1 when one of them was found. */
static int scan_help(int argc, char **argv, cli_args *a)
{
    for (int i = 1; i < argc && strcmp(argv[i], "--"); i++) {
        if (!strcmp(argv[i], "-h") || !strcmp(argv[i], "--help")) a->help = 1;
        else if (!strcmp(argv[i], "--version")) a->version = 1;
        else if (!a->command && is_command(argv[i])) a->command = argv[i];
    }
    if (a->help || a->version) return 1;
    a->command = NULL;
    return 0;
}

int cli_parse(int argc, char **argv, cli_args *a, char *err, size_t errlen)
{
    memset(a, 0, sizeof *a);
    if (scan_help(argc, argv, a)) return 0;
    a->host = "127.0.0.1";
    a->port = 7878;
    a->timeout_s = 60;
    a->inflight = 2;
    a->prefetch = 4;
    a->width = SP_DEFAULT_WIDTH;
    a->height = SP_DEFAULT_HEIGHT;
    const char *pos[4];
    int npos = 0;
    for (int i = 1; i < argc; i++) {
        const char *arg = argv[i];
        if (!strcmp(arg, "--")) { /* the rest are operands */
            for (i++; i < argc; i++) {
                if (npos == 4) goto too_many;
                pos[npos++] = argv[i];
            }
            break;
        }
        if (arg[0] != '-' || !arg[1]) {
            if (npos == 4) goto too_many;
            pos[npos++] = arg;
            continue;
        }
        if (!strcmp(arg, "--force")) { a->force = 1; continue; }
        if (!strcmp(arg, "--tls")) { a->tls = 1; continue; }
        if (!strcmp(arg, "-q") || !strcmp(arg, "--quiet")) { a->quiet = 1; continue; }
        /* options with a value: --opt value or --opt=value */
        char opt[32];
        const char *val = NULL;
        const char *eq = strchr(arg, '=');
        if (eq && arg[1] == '-') {
            size_t l = (size_t)(eq - arg);
            if (l >= sizeof opt) l = sizeof opt - 1;
            memcpy(opt, arg, l);
            opt[l] = 0;
            val = eq + 1;
        } else {
            snprintf(opt, sizeof opt, "%s", arg);
        }
        static const char *with_value[] = {"--host", "--port", "--token-file", "--tls-ca", "--tls-name",
                                           "-o", "--output",
                                           "--path", "--orbit", "--inflight", "--prefetch", "--set",
                                           "--eye", "--target", "--up", "--fov", "--size", "--timeout",
                                           "--shard", "--shards", NULL};
        int known = 0;
        for (int k = 0; with_value[k]; k++) known |= !strcmp(opt, with_value[k]);
        if (!known) {
            snprintf(err, errlen, "unknown option '%s' (see splat --help)", arg);
            return -1;
        }
        if (!val) {
            if (i + 1 >= argc) {
                snprintf(err, errlen, "option %s needs a value", opt);
                return -1;
            }
            val = argv[++i];
        }
        long l;
        if (!strcmp(opt, "--host")) {
            a->host = val;
        } else if (!strcmp(opt, "--port")) {
            if (parse_long(val, 1, 65535, &l) < 0) goto bad_value;
            a->port = (int)l;
        } else if (!strcmp(opt, "--token-file")) {
            a->token_file = val;
        } else if (!strcmp(opt, "--tls-ca")) {
            a->tls_ca = val;
            a->tls = 1;
        } else if (!strcmp(opt, "--tls-name")) {
            a->tls_name = val;
            a->tls = 1;
        } else if (!strcmp(opt, "-o") || !strcmp(opt, "--output")) {
            a->output = val;
        } else if (!strcmp(opt, "--path")) {
            a->path_file = val;
        } else if (!strcmp(opt, "--shard")) {
            a->shard = val;
        } else if (!strcmp(opt, "--shards")) {
            a->shards = val;
        } else if (!strcmp(opt, "--orbit")) {
            if (parse_long(val, 1, 10000000, &l) < 0) goto bad_value;
            a->orbit = l;
        } else if (!strcmp(opt, "--inflight")) {
            if (parse_long(val, 1, 64, &l) < 0) goto bad_value;
            a->inflight = (int)l;
        } else if (!strcmp(opt, "--prefetch")) {
            if (parse_long(val, 0, 16, &l) < 0) goto bad_value;
            a->prefetch = (int)l;
        } else if (!strcmp(opt, "--timeout")) {
            if (parse_long(val, 0, 86400, &l) < 0) goto bad_value;
            a->timeout_s = (int)l;
        } else if (!strcmp(opt, "--set")) {
            if (a->nsets == CLI_MAX_SETS) {
                snprintf(err, errlen, "more than %d --set options", CLI_MAX_SETS);
                return -1;
            }
            if (!strchr(val, '=') || val[0] == '=') goto bad_value;
            a->sets[a->nsets++] = val;
        } else if (!strcmp(opt, "--eye")) {
            if (cli_parse_vec3(val, a->eye) < 0) goto bad_value;
            a->have_eye = 1;
        } else if (!strcmp(opt, "--target")) {
            if (cli_parse_vec3(val, a->target) < 0) goto bad_value;
            a->have_target = 1;
        } else if (!strcmp(opt, "--up")) {
            if (cli_parse_vec3(val, a->up) < 0) goto bad_value;
            a->have_up = 1;
        } else if (!strcmp(opt, "--fov")) {
            char *end;
            double f = strtod(val, &end);
            if (end == val || *end || !(f > 0 && f < 180)) goto bad_value;
            a->fov = (float)f;
            a->have_fov = 1;
        } else if (!strcmp(opt, "--size")) {
            if (cli_parse_size(val, &a->width, &a->height) < 0) goto bad_value;
            a->have_size = 1;
        }
        continue;
    bad_value:
        snprintf(err, errlen, "bad value '%s' for %s (%s)", val, opt,
                 !strcmp(opt, "--port") ? "1 to 65535"
                 : !strcmp(opt, "--orbit") ? "a frame count >= 1"
                 : !strcmp(opt, "--inflight") ? "1 to 64"
                 : !strcmp(opt, "--prefetch") ? "0 to 16 cameras, 0 = off"
                 : !strcmp(opt, "--timeout") ? "seconds, 0 = none"
                 : !strcmp(opt, "--set") ? "key=value"
                 : !strcmp(opt, "--fov") ? "degrees in (0, 180)"
                 : !strcmp(opt, "--size") ? "WxH, 1 to 16384 each"
                 : "x,y,z");
        return -1;
    }
    if (npos == 0) {
        snprintf(err, errlen, "no command given (list, info, render, path; see splat --help)");
        return -1;
    }
    a->command = pos[0];
    int want; /* operands after the command */
    if (!strcmp(a->command, "list")) want = 0;
    else if (is_command(a->command)) want = 1;
    else {
        snprintf(err, errlen, "unknown command '%s' (list, info, render, path)", a->command);
        return -1;
    }
    if (npos - 1 != want) {
        snprintf(err, errlen, "%s takes %s", a->command, want ? "one cloud NAME" : "no operands");
        return -1;
    }
    if (want) a->name = pos[1];
    if (!strcmp(a->command, "render") && !a->output) {
        snprintf(err, errlen, "render needs -o FILE (.jpg, .png, .exr or .raw)");
        return -1;
    }
    if (!strcmp(a->command, "path")) {
        if (!a->output) {
            snprintf(err, errlen, "path needs -o PATTERN, e.g. -o 'out/%%05d.jpg'");
            return -1;
        }
        if (!a->path_file == !a->orbit) {
            snprintf(err, errlen, "path needs exactly one of --path FILE and --orbit N");
            return -1;
        }
    }
    return 0;
too_many:
    snprintf(err, errlen, "too many operands (starting at '%s')", argv[argc - 1]);
    return -1;
}
