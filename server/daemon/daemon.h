/* daemon.h — the daemon's entry with a renderer of the caller's (splatd --mpi, server/mpi/). */
#pragma once
#include "render_thread.h"

/* daemon_run: cmd_daemon (the daemon: options, event loop, workers) with hooks given to the
 * render thread (render_thread.h; NULL: the local renderer). Returns the exit status. */
int daemon_run(int argc, char **argv, const rt_hooks *hooks);
