/* webdriver.h — drives Debian's headless Chromium through chromedriver's W3C WebDriver HTTP
 * interface (a few requests, JSON built and picked apart by hand), for the browser viewer's
 * end-to-end test: load a page, run a script, real pointer actions, element screenshots. */
#pragma once
#include <stddef.h>
#include <sys/types.h>

typedef struct tu_wd {
    pid_t pid;               /* chromedriver */
    pid_t browser;           /* chromium, started by us: chromedriver attaches to it */
    int port;
    char session[128];
    char log[700];
} tu_wd;

/* tu_wd_available: 1 when chromedriver and chromium are installed ($CHROMEDRIVER, $CHROMIUM,
 * else /usr/bin/chromedriver, /usr/bin/chromium); why says what is missing otherwise. */
int tu_wd_available(char *why, size_t len);

/* tu_wd_start: starts chromedriver (log in dir) and a headless Chromium session whose window
 * is width x height CSS pixels at device scale 1. Returns 0 or -1 with why filled. */
int tu_wd_start(tu_wd *wd, const char *dir, int width, int height, char *why, size_t len);
/* tu_wd_start_insecure: tu_wd_start with WebDriver's acceptInsecureCerts, so an https page whose
 * certificate the browser does not trust (a test's self-signed one) loads. */
int tu_wd_start_insecure(tu_wd *wd, const char *dir, int width, int height, char *why,
                         size_t len);

/* tu_wd_go: navigates to url and waits for its load. 0 or -1. */
int tu_wd_go(tu_wd *wd, const char *url);

/* tu_wd_eval: runs the body of a function (e.g. "return document.title") and copies the
 * string it returns into out (unescaped). 0, or -1 (out holds the reply). */
int tu_wd_eval(tu_wd *wd, const char *script, char *out, size_t cap);

/* tu_wd_element: the WebDriver id of the first element matching css into id. 0 or -1. */
int tu_wd_element(tu_wd *wd, const char *css, char *id, size_t cap);

/* tu_wd_post: POSTs body (JSON) to /session/ID/path. 0 when the reply is not an error. */
int tu_wd_post(tu_wd *wd, const char *path, const char *body);

/* tu_wd_screenshot: a PNG of element id (as the page shows it) written to path. 0 or -1. */
int tu_wd_screenshot(tu_wd *wd, const char *id, const char *path);

/* tu_wd_stop: ends the session and chromedriver (and the browser with it). */
void tu_wd_stop(tu_wd *wd);
