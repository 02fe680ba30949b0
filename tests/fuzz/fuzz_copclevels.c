/* fuzz_copclevels.c — libFuzzer entry for the copclevels target; the body and its checks are
 * fuzz_one_copclevels in tests/common/fuzz_targets.c (also replayed by tests/test_fuzz_regress.c).
 * Built and run by tests/fuzz/run.sh. */
#include <stddef.h>
#include <stdint.h>

#include "fuzz_targets.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    (void)fuzz_one_copclevels(data, size);
    return 0;
}
