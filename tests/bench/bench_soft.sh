#!/bin/sh
# Soft Transparency benchmark: ms per frame at 1280x720 of splat (SP), olt (OLT), soft with the
# Express-Model (ST: order=auto, the default, and each order alone), and the Concentric- and
# Base-Models, on
# autzen_trim.las (airborne lidar, field=uncertainty), Guanyin.ply and a synthetic 1M cloud
# whose half is noisy vegetation (gen_cloud --vegetation 0.5), all at the defaults (t = 0.5,
# lambda = 0.5, field=uncertainty). Prints the ratios beside the paper's Table 1 (GTX 1080:
# ST/SP 0.65-0.81, OLT/SP 0.54-0.76, Base at least 10x slower than Express) and the issue's
# targets on this machine (ST/SP >= 0.85, Express >= 20x faster than Base). "Solid ms" is soft at
# lambda = 0: the same split and the same splat passes over the solid points with no soft layer,
# the part of the frame Express and Base share. From it: Base/Express of the soft layer alone,
# (Base - solid) / (ST - solid), and the bound Base / solid, the most the whole-frame ratio could
# reach if the soft layer cost nothing. Ratios come from
# one render_bench run per cloud (medians of SPLATD_BENCH_SOFT_FRAMES frames, default 5), wall
# clock and process CPU. Run by `make bench`; alone:
#   SPLATD_BENCH=build/bench SPLATD_TOOLS=build/tools SPLATD_TESTDATA=tests/data \
#     sh tests/bench/bench_soft.sh
set -eu
bench=${SPLATD_BENCH:-build/bench}
tools=${SPLATD_TOOLS:-build/tools}
data=${SPLATD_TESTDATA:-tests/data}
frames=${SPLATD_BENCH_SOFT_FRAMES:-5}
backend=${SPLATD_BENCH_BACKEND:-auto}
size=1280x720
pipes=points,splat,olt,soft,soft:order=axis,soft:order=tile,soft:model=concentric,soft:model=base,soft:lambda=0

for f in "$bench/render_bench" "$tools/gen_cloud"; do
    if [ ! -x "$f" ]; then
        echo "bench_soft: $f is missing; run 'make bench' (it builds it)" >&2
        exit 1
    fi
done
tmp=$(mktemp -d "${TMPDIR:-/tmp}/splatd-bench-soft.XXXXXX")
trap 'rm -rf "$tmp"' EXIT
trap 'exit 130' INT TERM
"$tools/gen_cloud" 1000000 "$tmp/veg-1M.ply" --vegetation 0.5

echo "### Soft Transparency (${size}, t = 0.5, lambda = 0.5, field=uncertainty, $frames frames)"
echo
echo "load average at the start: $(cut -d' ' -f1-3 /proc/loadavg)"
echo
echo "| cloud | points | SP ms | OLT ms | ST ms (auto) | ST axis ms | ST tile ms | Concentric ms | Base ms | Solid ms | ST/SP | OLT/SP | Base/Express | Base/Express, soft layer | Base/solid (bound) | CPU: ST/SP, OLT/SP, Base/Express |"
echo "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|"
for c in autzen_trim Guanyin veg-1M; do
    case $c in
        autzen_trim) f="$data/autzen_trim.las" ;;
        Guanyin) f="$data/Guanyin.ply" ;;
        *) f="$tmp/veg-1M.ply" ;;
    esac
    o="$tmp/$c"
    if ! "$bench/render_bench" "$f" --frames "$frames" --size "$size" --backend "$backend" \
           --pipelines "$pipes" --label "$c" > "$o.out" 2> "$o.err"; then
        echo "| $c | render_bench failed: $(tail -1 "$o.err") | | | | | | | | | | | | | | |"
        continue
    fi
    awk -F'|' -v c="$c" '
        FNR == NR { if ($0 ~ /^cpu: /) { split($0, w, " "); cpu[w[3]] = w[4] + 0 }; next }
        $4 ~ /[a-z]/ { name = $4; gsub(/^ +| +$/, "", name); ms[name] = $5 + 0; n = $3 + 0 }
        END {
            sp = ms["splat"]; st = ms["soft"]; b = ms["soft:model=base"]
            so = ms["soft:lambda=0"]
            # the soft layer alone: "-" where ST is not above the solid passes by 0.5 ms
            # (frame-to-frame noise)
            layer = st - so > 0.5 ? sprintf("%.1f", (b - so) / (st - so)) : "-"
            printf "| %s | %d | %.1f | %.1f | %.1f | %.1f | %.1f | %.1f | %.1f | %.1f | %.2f | %.2f | %.1f | %s | %.1f | %.2f, %.2f, %.1f |\n",
                c, n, sp, ms["olt"], st, ms["soft:order=axis"], ms["soft:order=tile"],
                ms["soft:model=concentric"], b, so,
                sp / st, sp / ms["olt"], b / st, layer, b / so, cpu["splat"] / cpu["soft"],
                cpu["splat"] / cpu["olt"], cpu["soft:model=base"] / cpu["soft"]
        }' "$o.err" "$o.out"
    sed -n 's/^flags: /  (frame flags: /p' "$o.err"
done
echo
echo "Paper (Table 1, GTX 1080, frame-rate ratios): ST/SP 0.65-0.81, OLT/SP 0.54-0.76; Base at least"
echo "10x slower than Express. Targets here: ST/SP >= 0.85, Base/Express >= 20. ST = soft at its"
echo "defaults (order=auto); Solid = soft at lambda = 0 (the splat passes over the solid points that"
echo "Express and Base share); where Base/solid is under 20, no Express frame reaches 20x on this"
echo "renderer. The renderer: $(sed -n 's/^renderer: //p' "$tmp/Guanyin.out")."
