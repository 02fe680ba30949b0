/* cloudtest.h — checks shared by the reader tests; each fails the running cmocka test with a
 * message naming what differed. */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "cloud.h"

/* tu_load_ok: pc_load of path into c; fails the test with the reader's message on an error. */
void tu_load_ok(const char *path, pc_cloud *c);

/* tu_check_point: point i of c, in file coordinates (pos + offset), equals p within tol. */
void tu_check_point(const pc_cloud *c, size_t i, const double p[3], double tol);

/* tu_read_data: the whole of tests/data/NAME, malloc'd; fails the test when it is missing. */
uint8_t *tu_read_data(const char *name, size_t *len);
