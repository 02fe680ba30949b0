/* daemonproc.c — see daemonproc.h. */
#include "daemonproc.h"

#include <fcntl.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

#include "testutil.h"

const char *tu_splatd_bin(void)
{
    return tu_env("SPLATD_BIN", "build/bin/splatd");
}

const char *tu_splat_bin(void)
{
    return tu_env("SPLAT_BIN", "build/bin/splat");
}

int tu_daemon_start(tu_daemon *d, const char *dir, int *status, const char *const *args)
{
    static int counter;
    char portfile[700];
    counter++;
    snprintf(portfile, sizeof portfile, "%s/port%d", dir, counter);
    snprintf(d->log, sizeof d->log, "%s/splatd%d.log", dir, counter);
    const char *argv[48];
    int n = 0;
    argv[n++] = tu_splatd_bin();
    for (int i = 0; args && args[i] && n < 44; i++) argv[n++] = args[i];
    argv[n++] = "--port-file";
    argv[n++] = portfile;
    argv[n] = NULL;
    pid_t pid = fork();
    if (pid < 0) return -1;
    if (pid == 0) {
        int fd = open(d->log, O_WRONLY | O_CREAT | O_TRUNC, 0644);
        if (fd >= 0) {
            dup2(fd, 2);
            close(fd);
        }
        execv(argv[0], (char *const *)argv);
        _exit(127);
    }
    d->pid = pid;
    d->port = 0;
    for (int i = 0; i < 6000; i++) {
        int st;
        if (waitpid(pid, &st, WNOHANG) == pid) {
            if (status) *status = st;
            d->pid = 0;
            return -1;
        }
        size_t len;
        uint8_t *b = tu_read_file(portfile, &len);
        if (b) {
            d->port = atoi((char *)b);
            free(b);
            if (d->port > 0) return 0;
        }
        usleep(10000);
    }
    kill(pid, SIGKILL);
    waitpid(pid, NULL, 0);
    d->pid = 0;
    return -1;
}

int tu_daemon_stop(tu_daemon *d)
{
    if (d->pid <= 0) return -1;
    kill(d->pid, SIGTERM);
    int st = 0;
    for (int i = 0; i < 2000; i++) {
        if (waitpid(d->pid, &st, WNOHANG) == d->pid) {
            d->pid = 0;
            return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
        }
        usleep(10000);
    }
    kill(d->pid, SIGKILL);
    waitpid(d->pid, &st, 0);
    d->pid = 0;
    return -2;
}

int tu_daemon_log_count(const tu_daemon *d, const char *needle)
{
    size_t len;
    char *log = (char *)tu_read_file(d->log, &len);
    if (!log) return 0;
    int n = 0;
    for (const char *p = log; (p = strstr(p, needle)); p += strlen(needle)) n++;
    free(log);
    return n;
}
