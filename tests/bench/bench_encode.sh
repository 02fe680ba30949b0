#!/bin/sh
# Frame encoders and the client decoder at 1280x720: JPEG, PNG, LZ4, raw, EXR (PIZ, ZIP, RLE).
# Prints a Markdown table (median of 20 runs). Run by `make bench` (tests/bench/bench.sh);
# alone: SPLATD_BENCH=build/bench sh tests/bench/bench_encode.sh
set -eu
bench=${SPLATD_BENCH:-build/bench}
"$bench/enc_bench" 1280 720 20
