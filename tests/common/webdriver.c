/* webdriver.c — chromedriver over HTTP/1.1 (see webdriver.h). */
#include "webdriver.h"

#include <arpa/inet.h>
#include <errno.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <openssl/evp.h>

#include "testutil.h"

static const char *driver_bin(void) { return tu_env("CHROMEDRIVER", "/usr/bin/chromedriver"); }
static const char *browser_bin(void) { return tu_env("CHROMIUM", "/usr/bin/chromium"); }

int tu_wd_available(char *why, size_t len)
{
    if (access(driver_bin(), X_OK) != 0) {
        snprintf(why, len, "%s is not installed (Debian package chromium-driver)", driver_bin());
        return 0;
    }
    if (access(browser_bin(), X_OK) != 0) {
        snprintf(why, len, "%s is not installed (Debian package chromium)", browser_bin());
        return 0;
    }
    return 1;
}

/* request: one HTTP request to chromedriver; the reply's body (malloc'd) in *body. Returns
 * the HTTP status or -1. The reply is read until the server closes (Connection: close). */
static int request(const tu_wd *wd, const char *method, const char *path, const char *json,
                   char **body, int timeout_ms)
{
    *body = NULL;
    int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (fd < 0) return -1;
    struct sockaddr_in a = {.sin_family = AF_INET, .sin_port = htons((uint16_t)wd->port)};
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (connect(fd, (struct sockaddr *)&a, sizeof a) != 0) {
        close(fd);
        return -1;
    }
    size_t jl = json ? strlen(json) : 0;
    char head[512];
    int hl = snprintf(head, sizeof head, "%s %s HTTP/1.1\r\nHost: 127.0.0.1:%d\r\n"
                      "Content-Type: application/json\r\nContent-Length: %zu\r\n"
                      "Connection: close\r\n\r\n", method, path, wd->port, jl);
    if (tu_send_all(fd, head, (size_t)hl) != 0 || (jl && tu_send_all(fd, json, jl) != 0)) {
        close(fd);
        return -1;
    }
    size_t cap = 1 << 16, n = 0;
    char *buf = malloc(cap);
    for (;;) {
        if (n + 1 >= cap) {
            cap *= 2;
            buf = realloc(buf, cap);
        }
        struct pollfd p = {.fd = fd, .events = POLLIN};
        if (poll(&p, 1, timeout_ms) <= 0) break;
        ssize_t r = recv(fd, buf + n, cap - 1 - n, 0);
        if (r <= 0) break;
        n += (size_t)r;
        /* Done once the head and Content-Length bytes of body are in (chromedriver may keep
         * the connection open). */
        buf[n] = 0;
        char *end = strstr(buf, "\r\n\r\n"), *cl = strcasestr(buf, "\r\nContent-Length:");
        if (end && cl && cl < end && n >= (size_t)(end + 4 - buf) + strtoul(cl + 17, NULL, 10))
            break;
    }
    close(fd);
    buf[n] = 0;
    int status = -1;
    if (sscanf(buf, "HTTP/1.1 %d", &status) != 1) status = -1;
    char *b = strstr(buf, "\r\n\r\n");
    *body = strdup(b ? b + 4 : "");
    free(buf);
    return status;
}

/* json_string: the unescaped string value after "key": in j into out. 0 or -1. */
static int json_string(const char *j, const char *key, char *out, size_t cap)
{
    char pat[96];
    snprintf(pat, sizeof pat, "\"%s\":\"", key);
    const char *p = strstr(j, pat);
    if (!p) return -1;
    p += strlen(pat);
    size_t o = 0;
    for (; *p && *p != '"'; p++) {
        char c = *p;
        if (c == '\\') {
            p++;
            switch (*p) {
            case 'n': c = '\n'; break;
            case 't': c = '\t'; break;
            case 'u': {
                unsigned v = 0;
                if (sscanf(p + 1, "%4x", &v) != 1) return -1;
                p += 4;
                c = v < 128 ? (char)v : '?';
                break;
            }
            case 0: return -1;
            default: c = *p; break;
            }
        }
        if (o + 1 < cap) out[o++] = c;
    }
    out[o] = 0;
    return *p == '"' ? 0 : -1;
}

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

/* start_browser: headless Chromium with DevTools on 127.0.0.1 and a fresh profile in dir;
 * returns its DevTools port (from the profile's DevToolsActivePort) or -1 with why. */
static int start_browser(tu_wd *wd, const char *dir, int width, int height, int insecure,
                         char *why, size_t len)
{
    char prof[700], portfile[760], profarg[720], winarg[64], blog[720];
    snprintf(prof, sizeof prof, "%s/chromium-profile", dir);
    snprintf(portfile, sizeof portfile, "%s/DevToolsActivePort", prof);
    snprintf(profarg, sizeof profarg, "--user-data-dir=%s", prof);
    snprintf(winarg, sizeof winarg, "--window-size=%d,%d", width, height);
    snprintf(blog, sizeof blog, "%s/chromium.log", dir);
    unlink(portfile);
    pid_t pid = fork();
    if (pid < 0) {
        snprintf(why, len, "fork: %s", strerror(errno));
        return -1;
    }
    if (pid == 0) {
        int fd = open(blog, O_WRONLY | O_CREAT | O_TRUNC, 0644);
        if (fd >= 0) {
            dup2(fd, 1);
            dup2(fd, 2);
        }
        setpgid(0, 0); /* its renderer and GPU processes go with it */
        execl(browser_bin(), browser_bin(), "--headless", "--no-sandbox", "--disable-gpu",
              "--disable-extensions", "--no-first-run", "--force-device-scale-factor=1", winarg,
              "--remote-debugging-address=127.0.0.1", "--remote-debugging-port=0", profarg,
              insecure ? "--ignore-certificate-errors" : "--no-default-browser-check",
              "about:blank", (char *)NULL);
        _exit(127);
    }
    wd->browser = pid;
    double t0 = now_s();
    while (now_s() - t0 < 20) {
        FILE *f = fopen(portfile, "r");
        int port = 0;
        if (f) {
            if (fscanf(f, "%d", &port) != 1) port = 0;
            fclose(f);
        }
        if (port > 0) return port;
        if (waitpid(pid, NULL, WNOHANG) == pid) {
            wd->browser = 0;
            snprintf(why, len, "chromium exited at start (see %s)", blog);
            return -1;
        }
        usleep(50000);
    }
    snprintf(why, len, "chromium did not open its DevTools port in 20 s (see %s)", blog);
    return -1;
}

static void stop_pid(pid_t pid)
{
    kill(-pid, SIGTERM);
    kill(pid, SIGTERM);
    for (int i = 0; i < 200 && waitpid(pid, NULL, WNOHANG) == 0; i++) usleep(10000);
    if (waitpid(pid, NULL, WNOHANG) == 0) {
        kill(-pid, SIGKILL);
        waitpid(pid, NULL, 0);
    }
}

static int wd_start(tu_wd *wd, const char *dir, int width, int height, int insecure, char *why,
                    size_t len)
{
    memset(wd, 0, sizeof *wd);
    /* A free port for chromedriver: bound once by us, then handed over. */
    int s = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    struct sockaddr_in a = {.sin_family = AF_INET};
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    socklen_t sl = sizeof a;
    if (s < 0 || bind(s, (struct sockaddr *)&a, sizeof a) != 0 ||
        getsockname(s, (struct sockaddr *)&a, &sl) != 0) {
        snprintf(why, len, "no free port: %s", strerror(errno));
        if (s >= 0) close(s);
        return -1;
    }
    wd->port = ntohs(a.sin_port);
    close(s);
    snprintf(wd->log, sizeof wd->log, "%s/chromedriver.log", dir);
    char portarg[32];
    snprintf(portarg, sizeof portarg, "--port=%d", wd->port);
    fflush(stdout);
    pid_t pid = fork();
    if (pid < 0) {
        snprintf(why, len, "fork: %s", strerror(errno));
        return -1;
    }
    if (pid == 0) {
        int fd = open(wd->log, O_WRONLY | O_CREAT | O_TRUNC, 0644);
        if (fd >= 0) {
            dup2(fd, 1);
            dup2(fd, 2);
        }
        setpgid(0, 0); /* its browser processes go with it */
        execl(driver_bin(), driver_bin(), portarg, (char *)NULL);
        _exit(127);
    }
    wd->pid = pid;
    double t0 = now_s();
    char *body = NULL;
    while (now_s() - t0 < 15) {
        int st = request(wd, "GET", "/status", NULL, &body, 1000);
        int ready = st == 200 && strstr(body, "\"ready\":true");
        free(body);
        if (ready) break;
        if (waitpid(pid, NULL, WNOHANG) == pid) {
            wd->pid = 0;
            snprintf(why, len, "chromedriver exited at start (see %s)", wd->log);
            return -1;
        }
        usleep(50000);
    }
    /* The browser is started here with its DevTools on 127.0.0.1 and chromedriver attaches to
     * it (debuggerAddress): a browser chromedriver starts itself is reached at "localhost",
     * which does not resolve on a machine without /etc/hosts (a fresh debootstrap root). */
    int dport = start_browser(wd, dir, width, height, insecure, why, len);
    if (dport < 0) {
        tu_wd_stop(wd);
        return -1;
    }
    char caps[1024];
    snprintf(caps, sizeof caps,
             "{\"capabilities\":{\"alwaysMatch\":{%s\"goog:chromeOptions\":"
             "{\"debuggerAddress\":\"127.0.0.1:%d\"}}}}",
             insecure ? "\"acceptInsecureCerts\":true," : "", dport);
    int st = request(wd, "POST", "/session", caps, &body, 30000);
    if (st != 200 || json_string(body, "sessionId", wd->session, sizeof wd->session) != 0) {
        snprintf(why, len, "no WebDriver session (HTTP %d): %.300s", st, body ? body : "");
        free(body);
        tu_wd_stop(wd);
        return -1;
    }
    free(body);
    return 0;
}

int tu_wd_post(tu_wd *wd, const char *path, const char *json)
{
    char url[512];
    snprintf(url, sizeof url, "/session/%s/%s", wd->session, path);
    char *body;
    int st = request(wd, "POST", url, json, &body, 30000);
    if (st != 200) fprintf(stderr, "webdriver %s: HTTP %d %.400s\n", path, st, body ? body : "");
    free(body);
    return st == 200 ? 0 : -1;
}

int tu_wd_go(tu_wd *wd, const char *url)
{
    char j[1024];
    snprintf(j, sizeof j, "{\"url\":\"%s\"}", url);
    return tu_wd_post(wd, "url", j);
}

int tu_wd_eval(tu_wd *wd, const char *script, char *out, size_t cap)
{
    char url[256];
    snprintf(url, sizeof url, "/session/%s/execute/sync", wd->session);
    size_t sl = strlen(script);
    char *j = malloc(2 * sl + 64), *o = j;
    o += sprintf(o, "{\"script\":\"");
    for (const char *p = script; *p; p++) {
        if (*p == '"' || *p == '\\') *o++ = '\\';
        *o++ = *p;
    }
    sprintf(o, "\",\"args\":[]}");
    char *body;
    int st = request(wd, "POST", url, j, &body, 30000);
    free(j);
    int rc = st == 200 && json_string(body, "value", out, cap) == 0 ? 0 : -1;
    if (rc) snprintf(out, cap, "HTTP %d %.200s", st, body ? body : "");
    free(body);
    return rc;
}

int tu_wd_element(tu_wd *wd, const char *css, char *id, size_t cap)
{
    char url[256], j[512];
    snprintf(url, sizeof url, "/session/%s/element", wd->session);
    snprintf(j, sizeof j, "{\"using\":\"css selector\",\"value\":\"%s\"}", css);
    char *body;
    int st = request(wd, "POST", url, j, &body, 30000);
    int rc = st == 200 && json_string(body, "element-6066-11e4-a52e-4f735466cecf", id, cap) == 0;
    free(body);
    return rc ? 0 : -1;
}

int tu_wd_screenshot(tu_wd *wd, const char *id, const char *path)
{
    char url[512];
    snprintf(url, sizeof url, "/session/%s/element/%s/screenshot", wd->session, id);
    char *body;
    int st = request(wd, "GET", url, NULL, &body, 30000);
    int rc = -1;
    char *b64 = st == 200 ? strstr(body, "\"value\":\"") : NULL;
    if (b64) {
        b64 += 9;
        char *e = strchr(b64, '"');
        size_t n = e ? (size_t)(e - b64) : 0;
        unsigned char *png = malloc(n / 4 * 3 + 3);
        int m = n % 4 == 0 ? EVP_DecodeBlock(png, (unsigned char *)b64, (int)n) : -1;
        if (m > 0) {
            /* EVP_DecodeBlock counts the padding as data: drop what '=' stood for. */
            while (n > 0 && b64[n - 1] == '=') n--, m--;
            rc = tu_write_file(path, png, (size_t)m);
        }
        free(png);
    }
    free(body);
    return rc;
}

void tu_wd_stop(tu_wd *wd)
{
    if (wd->session[0] && wd->pid) {
        char url[256], *body;
        snprintf(url, sizeof url, "/session/%s", wd->session);
        request(wd, "DELETE", url, NULL, &body, 10000);
        free(body);
    }
    wd->session[0] = 0;
    if (wd->pid) {
        stop_pid(wd->pid);
        wd->pid = 0;
    }
    if (wd->browser) {
        stop_pid(wd->browser);
        wd->browser = 0;
    }
}

int tu_wd_start(tu_wd *wd, const char *dir, int width, int height, char *why, size_t len)
{
    return wd_start(wd, dir, width, height, 0, why, len);
}

int tu_wd_start_insecure(tu_wd *wd, const char *dir, int width, int height, char *why,
                         size_t len)
{
    return wd_start(wd, dir, width, height, 1, why, len);
}
