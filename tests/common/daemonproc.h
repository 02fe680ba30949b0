/* daemonproc.h — runs the splatd binary as a child process for end-to-end tests: started with
 * --port-file in a test's directory, stderr to a log file, stopped with SIGTERM. */
#pragma once
#include <sys/types.h>

typedef struct tu_daemon {
    pid_t pid;       /* 0 when not running */
    int port;        /* the bound port, once started */
    char log[700];   /* its stderr */
} tu_daemon;

/* tu_daemon_start: runs $SPLATD_BIN (default build/bin/splatd) with args (NULL-terminated)
 * plus --port-file DIR/portN, stderr to DIR/splatdN.log; waits up to 60 s for the port file.
 * Returns 0, or -1 when the daemon exited first (its wait status in *status when not NULL) or
 * did not start in time (then it is killed). */
int tu_daemon_start(tu_daemon *d, const char *dir, int *status, const char *const *args);

/* tu_daemon_stop: SIGTERM, then waits up to 20 s (SIGKILL after that). Returns the exit status,
 * -1 when it died of a signal or was not running, -2 when it had to be killed. */
int tu_daemon_stop(tu_daemon *d);

/* tu_daemon_log_count: occurrences of needle in the daemon's log (0 when it cannot be read). */
int tu_daemon_log_count(const tu_daemon *d, const char *needle);

/* tu_splatd_bin, tu_splat_bin: the binaries under test ($SPLATD_BIN, $SPLAT_BIN). */
const char *tu_splatd_bin(void);
const char *tu_splat_bin(void);
