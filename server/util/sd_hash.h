/* sd_hash.h — a fast non-cryptographic 64-bit hash for change detection (cache keys and cache
 * corruption checks), not for security. Four independent multiply-rotate lanes over 8-byte
 * words run at memory bandwidth, so hashing a source file on every cached load stays cheap. */
#pragma once
#include <stddef.h>
#include <stdint.h>

uint64_t sd_hash64(const void *data, size_t len, uint64_t seed);
