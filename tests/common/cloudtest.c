/* cloudtest.c — see cloudtest.h. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>
#include <math.h>

#include "cloudtest.h"
#include "testutil.h"

void tu_load_ok(const char *path, pc_cloud *c)
{
    sd_err e = {0};
    int rc = pc_load(path, c, &e);
    if (rc != 0) fail_msg("%s: %d %s", path, rc, e.msg);
}

void tu_check_point(const pc_cloud *c, size_t i, const double p[3], double tol)
{
    for (int k = 0; k < 3; k++) {
        double got = c->pos[3 * i + k] + c->offset[k];
        if (fabs(got - p[k]) > tol)
            fail_msg("point %zu axis %d: got %.9f, expected %.9f (tol %g)", i, k, got, p[k], tol);
    }
}

uint8_t *tu_read_data(const char *name, size_t *len)
{
    char p[1024];
    uint8_t *b = tu_read_file(tu_data(name, p, sizeof p), len);
    if (!b) fail_msg("cannot read tests/data/%s", name);
    return b;
}
