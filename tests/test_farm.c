/* test_farm.c — camera-path farms (issue 17, part 1): which frames a shard renders (--shard,
 * JOB_COMPLETION_INDEX, SLURM_ARRAY_TASK_ID), three shards against two daemons on loopback
 * writing exactly the frames of one unsharded run (byte-identical PNG), a shard killed half-way
 * and restarted rendering only what is missing, the Slurm array script run as its tasks would
 * be, and the Kubernetes manifests checked for structure (python3-yaml: kubectl has no offline
 * validation, see tests/tools/check_k8s.py). */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <dirent.h>
#include <fcntl.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "common/daemonproc.h"
#include "common/testutil.h"
#include "shard.h"
#include "testutil.h"

typedef struct fx {
    char root[512];
    char data[600];
    tu_daemon a, b;
} fx;

static int setup(void **state)
{
    fx *f = calloc(1, sizeof *f);
    if (!f || !tu_tmpdir(f->root, sizeof f->root)) return -1;
    if (tu_data_dir(f->root, "bun000.ply", "bunny.ply", f->data, sizeof f->data) != 0) return -1;
    signal(SIGPIPE, SIG_IGN);
    *state = f;
    return 0;
}

static int teardown(void **state)
{
    fx *f = *state;
    if (f->a.pid > 0) tu_daemon_stop(&f->a);
    if (f->b.pid > 0) tu_daemon_stop(&f->b);
    tu_rm_rf(f->root);
    free(f);
    return 0;
}

/* start: a daemon on loopback serving f->data with its own cache directory (a machine of its
 * own, as far as the farm can tell). */
static void start(fx *f, tu_daemon *d, const char *cache_name)
{
    char cache[700];
    snprintf(cache, sizeof cache, "%s/%s", f->root, cache_name);
    const char *args[] = {"--listen", "127.0.0.1:0", "--data", f->data, "--cache", cache, NULL};
    assert_int_equal(tu_daemon_start(d, f->root, NULL, args), 0);
}

/* count_files: regular files in dir whose names end in suffix; names containing ".tmp." are
 * counted into *tmp (when not NULL) instead. */
static int count_files(const char *dir, const char *suffix, int *tmp)
{
    DIR *d = opendir(dir);
    if (!d) return 0;
    int n = 0;
    if (tmp) *tmp = 0;
    struct dirent *e;
    size_t sl = strlen(suffix);
    while ((e = readdir(d))) {
        size_t l = strlen(e->d_name);
        if (strstr(e->d_name, ".tmp.")) {
            if (tmp) (*tmp)++;
        } else if (l > sl && !strcmp(e->d_name + l - sl, suffix)) {
            n++;
        }
    }
    closedir(d);
    return n;
}

/* png_complete: the file is a PNG from its signature to its IEND chunk (a partial write would
 * end before IEND). */
static int png_complete(const char *path)
{
    size_t len;
    uint8_t *b = tu_read_file(path, &len);
    static const uint8_t sig[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
    int ok = b && len > 20 && !memcmp(b, sig, 8) && !memcmp(b + len - 8, "IEND", 4);
    free(b);
    return ok;
}

/* ---- which frames a shard renders ---- */

static void test_shard_parse_and_env(void **state)
{
    (void)state;
    long i, n;
    assert_int_equal(shard_parse("2/5", &i, &n), 0);
    assert_int_equal(i, 2);
    assert_int_equal(n, 5);
    static const char *const bad[] = {"5/5", "-1/3", "1/0", "1", "/3", "1/", "a/3", "1/3x",
                                      "+1/3", "1/1000001", " 1/3", "\t1/3", "1/\n3",
                                      "1/ 3"};
    for (size_t k = 0; k < sizeof bad / sizeof bad[0]; k++)
        if (shard_parse(bad[k], &i, &n) == 0) fail_msg("'%s' was taken", bad[k]);

    char err[300];
    shard s;
    shard_env none = {0};
    assert_int_equal(shard_resolve(&none, &s, err, sizeof err), 0);
    assert_int_equal(s.count, 1);
    assert_string_equal(s.source, "");
    /* --shard wins over the environment */
    shard_env e1 = {.shard_flag = "1/4", .job_index = "3", .shard_count = "8"};
    assert_int_equal(shard_resolve(&e1, &s, err, sizeof err), 0);
    assert_int_equal(s.index, 1);
    assert_int_equal(s.count, 4);
    assert_string_equal(s.source, "--shard");
    /* Kubernetes: the index from the Job, the count from SPLAT_SHARD_COUNT or --shards */
    shard_env e2 = {.job_index = "3", .shard_count = "8", .slurm_id = "1", .slurm_count = "2"};
    assert_int_equal(shard_resolve(&e2, &s, err, sizeof err), 0);
    assert_int_equal(s.index, 3);
    assert_int_equal(s.count, 8);
    assert_string_equal(s.source, "JOB_COMPLETION_INDEX");
    shard_env e3 = {.job_index = "3"};
    assert_int_equal(shard_resolve(&e3, &s, err, sizeof err), -1);
    assert_non_null(strstr(err, "SPLAT_SHARD_COUNT"));
    e3.shards_flag = "4";
    assert_int_equal(shard_resolve(&e3, &s, err, sizeof err), 0);
    assert_int_equal(s.count, 4);
    e3.shards_flag = "3";
    assert_int_equal(shard_resolve(&e3, &s, err, sizeof err), -1); /* index 3 of 3 */
    assert_non_null(strstr(err, "not below"));
    /* Slurm: --array=1-4 numbers tasks from SLURM_ARRAY_TASK_MIN */
    shard_env e4 = {.slurm_id = "4", .slurm_count = "4", .slurm_min = "1"};
    assert_int_equal(shard_resolve(&e4, &s, err, sizeof err), 0);
    assert_int_equal(s.index, 3);
    assert_int_equal(s.count, 4);
    assert_string_equal(s.source, "SLURM_ARRAY_TASK_ID");
    shard_env e5 = {.slurm_id = "x1", .slurm_count = "4"};
    assert_int_equal(shard_resolve(&e5, &s, err, sizeof err), -1);
    assert_non_null(strstr(err, "SLURM_ARRAY_TASK_ID"));
    /* digits only, in the environment too: strtol alone takes leading white space */
    shard_env e5b = {.job_index = "\n2", .shard_count = "4"};
    assert_int_equal(shard_resolve(&e5b, &s, err, sizeof err), -1);
    assert_non_null(strstr(err, "JOB_COMPLETION_INDEX"));
    e5b.job_index = "2", e5b.shard_count = "\t4";
    assert_int_equal(shard_resolve(&e5b, &s, err, sizeof err), -1);
    assert_non_null(strstr(err, "SPLAT_SHARD_COUNT"));
    shard_env e6 = {.shards_flag = "3"};
    assert_int_equal(shard_resolve(&e6, &s, err, sizeof err), -1);

    /* shard 1 of 3 of frames 0..9 minus the done frames 4 and 7 */
    long todo[] = {0, 1, 2, 3, 5, 6, 8, 9};
    shard s13 = {.index = 1, .count = 3};
    long k = shard_filter(&s13, todo, 8);
    assert_int_equal(k, 1); /* 1 (4 and 7 are done) */
    assert_int_equal(todo[0], 1);
    long all[] = {0, 1, 2, 3, 4, 5, 6, 7, 8, 9};
    shard s03 = {.index = 0, .count = 3};
    assert_int_equal(shard_filter(&s03, all, 10), 4);
    assert_int_equal(all[3], 9);
}

/* Three shards, one from each source of the index, against two daemons: the union of their
 * frames is exactly the unsharded run's, byte for byte (PNG, the default splat pipeline). */
static void test_three_shards_two_daemons(void **state)
{
    fx *f = *state;
    start(f, &f->a, "cache-a");
    start(f, &f->b, "cache-b");
    enum { FRAMES = 9 };
    const char *common = "path bunny --orbit 9 --size 160x120";
    char out[16384];
    int rc = tu_run(out, sizeof out, "'%s' --port %d %s -o '%s/one/%%03d.png' 2>&1", tu_splat_bin(),
                 f->a.port, common, f->root);
    if (rc) fail_msg("unsharded run: %s", out);
    /* the three shards at once: 0 and 2 on daemon a, 1 on daemon b */
    rc = tu_run(out, sizeof out,
             "cd '%s' && S='%s'; "
             "$S --port %d %s -o 'farm/%%03d.png' --shard 0/3 >s0.log 2>&1 & p0=$!; "
             "JOB_COMPLETION_INDEX=1 SPLAT_SHARD_COUNT=3 "
             "$S --port %d %s -o 'farm/%%03d.png' >s1.log 2>&1 & p1=$!; "
             "SLURM_ARRAY_TASK_ID=3 SLURM_ARRAY_TASK_MIN=1 SLURM_ARRAY_TASK_COUNT=3 "
             "$S --port %d %s -o 'farm/%%03d.png' >s2.log 2>&1 & p2=$!; "
             "wait $p0; r0=$?; wait $p1; r1=$?; wait $p2; r2=$?; cat s0.log s1.log s2.log; "
             "exit $((r0 | r1 | r2))",
             f->root, tu_splat_bin(), f->a.port, common, f->b.port, common, f->a.port, common);
    if (rc) fail_msg("a shard failed: %s", out);
    /* each says which source it used, and renders its 3 of 9 */
    assert_non_null(strstr(out, "shard 0 of 3 (from --shard)"));
    assert_non_null(strstr(out, "shard 1 of 3 (from JOB_COMPLETION_INDEX)"));
    assert_non_null(strstr(out, "shard 2 of 3 (from SLURM_ARRAY_TASK_ID)"));
    char *p = out;
    int summaries = 0;
    while ((p = strstr(p, "3 frames in"))) summaries++, p++;
    assert_int_equal(summaries, 3);

    char dir1[700], dir2[700];
    snprintf(dir1, sizeof dir1, "%s/one", f->root);
    snprintf(dir2, sizeof dir2, "%s/farm", f->root);
    int tmp;
    assert_int_equal(count_files(dir1, ".png", NULL), FRAMES);
    assert_int_equal(count_files(dir2, ".png", &tmp), FRAMES);
    assert_int_equal(tmp, 0);
    for (int i = 0; i < FRAMES; i++) {
        char a[800], b[800];
        snprintf(a, sizeof a, "%s/%03d.png", dir1, i);
        snprintf(b, sizeof b, "%s/%03d.png", dir2, i);
        size_t la, lb;
        uint8_t *da = tu_read_file(a, &la), *db = tu_read_file(b, &lb);
        assert_non_null(da);
        assert_non_null(db);
        if (la != lb || memcmp(da, db, la))
            fail_msg("frame %d differs (%zu / %zu bytes)", i, la, lb);
        assert_true(la > 100);
        free(da);
        free(db);
    }
    /* a second round of the same shard does no work */
    rc = tu_run(out, sizeof out, "'%s' --port %d %s -o '%s/farm/%%03d.png' --shard 1/3 2>&1",
             tu_splat_bin(), f->b.port, common, f->root);
    assert_int_equal(rc, 0);
    if (!strstr(out, "all 3 frames of")) fail_msg("retry rendered: %s", out);
}

/* A shard killed (SIGKILL) after a few frames and started again renders only the frames that
 * are missing: the frames written before keep their inode and mtime, the restart reports the
 * rest as its whole work, and every file is a complete PNG. */
static void test_killed_shard_resumes(void **state)
{
    fx *f = *state;
    start(f, &f->a, "cache-a");
    enum { FRAMES = 24, MINE = 12 }; /* shard 1 of 2: the odd frames */
    char pattern[800], dir[700], port[16];
    snprintf(dir, sizeof dir, "%s/frames", f->root);
    snprintf(pattern, sizeof pattern, "%s/%%03d.png", dir);
    snprintf(port, sizeof port, "%d", f->a.port);
    pid_t pid = fork();
    assert_true(pid >= 0);
    if (pid == 0) {
        int nul = open("/dev/null", O_WRONLY);
        dup2(nul, 1);
        dup2(nul, 2);
        execl(tu_splat_bin(), "splat", "--port", port, "-q", "path", "bunny", "--orbit", "24",
              "--size", "960x720", "--inflight", "1", "--shard", "1/2", "-o", pattern,
              (char *)NULL);
        _exit(127);
    }
    /* wait for the third frame, then kill it */
    int n = 0;
    for (int t = 0; t < 60000 && n < 3; t++) {
        n = count_files(dir, ".png", NULL);
        if (n < 3) usleep(1000);
    }
    kill(pid, SIGKILL);
    int st;
    waitpid(pid, &st, 0);
    assert_true(WIFSIGNALED(st));
    n = count_files(dir, ".png", NULL);
    if (n < 3 || n >= MINE) fail_msg("killed after %d of %d frames: not half-way", n, MINE);

    struct stat before[FRAMES];
    int had[FRAMES] = {0};
    for (int i = 0; i < FRAMES; i++) {
        char name[800];
        snprintf(name, sizeof name, "%s/%03d.png", dir, i);
        if (stat(name, &before[i]) == 0) {
            had[i] = 1;
            assert_int_equal(i % 2, 1);
            assert_true(png_complete(name));
        }
    }
    usleep(20000); /* a re-written file would get a later mtime */
    char out[16384];
    int rc = tu_run(out, sizeof out, "'%s' --port %d path bunny --orbit 24 --size 960x720 "
                 "--shard 1/2 -o '%s' 2>&1", tu_splat_bin(), f->a.port, pattern);
    if (rc) fail_msg("restart failed: %s", out);
    char want[200];
    snprintf(want, sizeof want, "resuming: %d of %d frames exist, %d to render", n, MINE, MINE - n);
    if (!strstr(out, want)) fail_msg("expected '%s' in: %s", want, out);
    snprintf(want, sizeof want, "\n%d frames in", MINE - n);
    if (!strstr(out, want)) fail_msg("expected '%s' in: %s", want + 1, out);
    int tmp;
    assert_int_equal(count_files(dir, ".png", &tmp), MINE);
    for (int i = 0; i < FRAMES; i++) {
        char name[800];
        snprintf(name, sizeof name, "%s/%03d.png", dir, i);
        struct stat now;
        int exists = stat(name, &now) == 0;
        assert_int_equal(exists, i % 2 == 1);
        if (!exists) continue;
        assert_true(png_complete(name));
        if (had[i]) {
            if (now.st_ino != before[i].st_ino ||
                now.st_mtim.tv_sec != before[i].st_mtim.tv_sec ||
                now.st_mtim.tv_nsec != before[i].st_mtim.tv_nsec)
                fail_msg("frame %d was written again by the restart", i);
        }
    }
}

/* repo_file: a file of the source tree (SPLATD_SHADERS is its shaders/ folder). */
static const char *repo_file(const char *rel, char *buf, size_t len)
{
    char sh[600];
    snprintf(sh, sizeof sh, "%s", tu_env("SPLATD_SHADERS", "shaders"));
    char *slash = strrchr(sh, '/');
    if (slash) {
        *slash = 0;
        snprintf(buf, len, "%s/%s", sh, rel);
    } else {
        snprintf(buf, len, "%s", rel);
    }
    return buf;
}

/* deploy/slurm/splat-farm.sbatch run as two array tasks would run it (bash, the Slurm
 * variables set, a daemon of its own per task): the frames equal a direct unsharded run's. */
static void test_slurm_array_script(void **state)
{
    fx *f = *state;
    if (system("command -v bash >/dev/null 2>&1") != 0) TU_SKIP("bash is not installed");
    char script[700], splatd_abs[700], splat_abs[700], out[32768];
    repo_file("deploy/slurm/splat-farm.sbatch", script, sizeof script);
    assert_non_null(realpath(tu_splatd_bin(), splatd_abs));
    assert_non_null(realpath(tu_splat_bin(), splat_abs));
    for (int task = 0; task < 2; task++) {
        int rc = tu_run(out, sizeof out,
                     "cd '%s' && SLURM_ARRAY_TASK_ID=%d SLURM_ARRAY_TASK_COUNT=2 "
                     "SLURM_ARRAY_TASK_MIN=0 SPLAT_CLOUD=bunny SPLAT_DATA='%s' "
                     "SPLAT_OUT='%s/slurm/%%02d.png' SPLAT_PATH_ARGS='--orbit 5 --size 96x64' "
                     "SPLATD_BIN='%s' SPLAT_BIN='%s' TMPDIR='%s' bash '%s' 2>&1",
                     f->root, task, f->data, f->root, splatd_abs, splat_abs, f->root, script);
        if (rc) fail_msg("task %d: %s", task, out);
        char want[100];
        snprintf(want, sizeof want, "shard %d of 2 (from SLURM_ARRAY_TASK_ID)", task);
        if (!strstr(out, want)) fail_msg("task %d: no '%s' in %s", task, want, out);
    }
    /* the tasks stopped their daemons and removed their work directories */
    int rc = tu_run(out, sizeof out, "ls -d '%s'/splat-farm.* 2>/dev/null | wc -l", f->root);
    assert_int_equal(rc, 0);
    assert_int_equal(atoi(out), 0);
    start(f, &f->a, "cache-a");
    rc = tu_run(out, sizeof out, "'%s' --port %d path bunny --orbit 5 --size 96x64 -o "
             "'%s/direct/%%02d.png' 2>&1 && cd '%s' && for i in 00 01 02 03 04; do "
             "cmp slurm/$i.png direct/$i.png || exit 1; done && ls slurm | wc -l",
             tu_splat_bin(), f->a.port, f->root, f->root);
    if (rc) fail_msg("frames differ: %s", out);
    assert_non_null(strstr(out, "\n5\n"));
}

/* replace_into: writes src with the first occurrence of from replaced by to into dst. */
static void replace_into(const char *src, const char *dst, const char *from, const char *to)
{
    size_t len;
    char *b = (char *)tu_read_file(src, &len);
    assert_non_null(b);
    b = realloc(b, len + 1);
    b[len] = 0;
    char *at = strstr(b, from);
    if (!at) fail_msg("'%s' is not in %s", from, src);
    FILE *o = fopen(dst, "w");
    assert_non_null(o);
    fwrite(b, 1, (size_t)(at - b), o);
    fputs(to, o);
    fputs(at + strlen(from), o);
    fclose(o);
    free(b);
}

/* deploy/k8s: the manifests pass the structural check, and each broken copy fails it naming
 * what is wrong (so the check can fail). */
static void test_k8s_manifests(void **state)
{
    fx *f = *state;
    if (system("python3 -c 'import yaml' >/dev/null 2>&1") != 0)
        TU_SKIP("python3 with the yaml module (Debian python3-yaml) is not installed");
    char checker[700], dep[700], job[700], out[16384];
    repo_file("tests/tools/check_k8s.py", checker, sizeof checker);
    repo_file("deploy/k8s/splatd.yaml", dep, sizeof dep);
    repo_file("deploy/k8s/farm-job.yaml", job, sizeof job);
    int rc = tu_run(out, sizeof out, "python3 '%s' '%s' '%s' 2>&1", checker, dep, job);
    if (rc) fail_msg("the manifests fail the check: %s", out);
    assert_non_null(strstr(out, "ok: 5 documents"));

    static const struct {
        int which; /* 0 the daemon's file, 1 the job's */
        const char *from, *to, *expect;
    } cases[] = {
        {1, "value: \"8\"", "value: \"4\"", "SPLAT_SHARD_COUNT 4 is not the completions 8"},
        {1, "completionMode: Indexed", "completionMode: NonIndexed", "not Indexed"},
        {1, "--host, splatd,", "--host, splatd-x,", "the Service is splatd:7878"},
        {0, "mountPath: /data, readOnly: true", "mountPath: /data",
         "is not a read-only mount of a claim"},
        {0, "tcpSocket: {port: splatd}\n            initialDelaySeconds: 2",
         "httpGet: {port: splatd}\n            initialDelaySeconds: 2", "not a tcpSocket probe"},
        {0, "\"0.0.0.0:7878\"", "\"0.0.0.0:7979\"", "the probe checks port 7878"},
        {0, "claimName: splatd-cache", "claimName:", "without claimName"},
        {0, "secret: {secretName: splatd-token, defaultMode: 0444}", "emptyDir: {}",
         "no Secret volume"},
        {0, "selector: {app.kubernetes.io/name: splatd}\n  ports",
         "selector: {app.kubernetes.io/name: other}\n  ports", "selects no Deployment pods"},
        {0, "apiVersion: apps/v1", "apiVersion: v1", "expected apps/v1"},
    };
    for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++) {
        char bad[800];
        snprintf(bad, sizeof bad, "%s/bad.yaml", f->root);
        replace_into(cases[k].which ? job : dep, bad, cases[k].from, cases[k].to);
        rc = tu_run(out, sizeof out, "python3 '%s' '%s' '%s' 2>&1", checker,
                 cases[k].which ? dep : bad, cases[k].which ? bad : job);
        if (rc != 1 || !strstr(out, cases[k].expect))
            fail_msg("case %zu (%s -> %s): exit %d, expected '%s' in: %s", k, cases[k].from,
                     cases[k].to, rc, cases[k].expect, out);
    }
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_shard_parse_and_env),
        cmocka_unit_test_setup_teardown(test_three_shards_two_daemons, setup, teardown),
        cmocka_unit_test_setup_teardown(test_killed_shard_resumes, setup, teardown),
        cmocka_unit_test_setup_teardown(test_slurm_array_script, setup, teardown),
        cmocka_unit_test_setup_teardown(test_k8s_manifests, setup, teardown),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
