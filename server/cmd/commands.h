/* commands.h — the sub-commands of the splatd binary, dispatched by main.c. Each takes the
 * arguments after its name (argv[0] is the sub-command) and returns the process exit status. */
#pragma once

int cmd_prep(int argc, char **argv);    /* cmd_prep.c:   splatd prep FILE [--k N] [--cache DIR] */
int cmd_render(int argc, char **argv);  /* cmd_render.c: splatd render FILE -o OUT [...] */
int cmd_daemon(int argc, char **argv);  /* daemon.c:     splatd [--listen ...] (the daemon) */

struct lod_desc;
/* cmd_prep_lod.c: `splatd prep` of a cloud in the LOD form; cmd_lod_status prints the build's
 * status lines (points/s, ETA) on stderr. */
int cmd_prep_lod(const char *file, const struct lod_desc *d);
void cmd_lod_status(void *user, const char *line);
