/* fuzz_lodsrc.c — libFuzzer entry for the lodsrc target; the body and its checks are
 * fuzz_one_lodsrc in tests/common/fuzz_lodsrc.c (also replayed by tests/test_fuzz_regress.c).
 * Built and run by tests/fuzz/run.sh. */
#include <stddef.h>
#include <stdint.h>

#include "fuzz_targets.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    (void)fuzz_one_lodsrc(data, size);
    return 0;
}
