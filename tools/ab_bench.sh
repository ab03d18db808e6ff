#!/usr/bin/env bash
# Interleaved A/B runs of criterion bench binaries: one bench, several builds, alternating
# round by round, so that the host's drift (±15 % within minutes on our 2-vCPU VMs) falls on
# every build alike. Prints each round's criterion median per binary, then per binary the
# ratios of its medians to the first binary's, round by round, and their median.
#
# usage: tools/ab_bench.sh ROUNDS 'BENCH_FILTER$' MEASUREMENT_SECONDS BINARY_A BINARY_B [...]
#
# The binaries are criterion bench executables (`cargo bench --features bench --no-run` prints
# their paths, e.g. target/release/deps/raster-<hash>); copy each build's aside before building
# the next one. Example, the working tree against a commit:
#
#   executable() { cargo bench --features bench --bench raster --no-run 2>&1 |
#       sed -n 's/.*Executable .*(\(.*\))$/\1/p'; }
#   git worktree add --detach /tmp/base COMMIT
#   base=/tmp/base/$(cd /tmp/base && executable)
#   new=$(executable)
#   tools/ab_bench.sh 4 'raster/fwd_bwd/256/50000$' 5 "$base" "$new"
#
# (A build of the same crate keeps the executable's name, so a build in the same directory
# replaces the previous one: a worktree per commit, or a copy, keeps both.)
#
# Run it from the repository root (some benches read files relative to it), on an otherwise
# idle machine: anything else running shows up in every figure.
set -euo pipefail
if [ "$#" -lt 5 ]; then
    sed -n '2,24p' "$0" | sed 's/^# \{0,1\}//' >&2
    exit 2
fi
rounds=$1 filter=$2 seconds=$3
shift 3
results=$(mktemp)
trap 'rm -f "$results"' EXIT
for round in $(seq "$rounds"); do
    for index in $(seq "$#"); do
        binary=${!index}
        # Criterion's line `time: [low median high]`, the median in milliseconds.
        line=$("$binary" --bench "$filter" --warm-up-time 2 --measurement-time "$seconds" 2>/dev/null |
            grep -m1 'time:' || true)
        if [ -z "$line" ]; then
            echo "no criterion result from $binary for '$filter'" >&2
            exit 1
        fi
        median_ms=$(echo "$line" | awk '{
            for (i = 1; i <= NF; i++) if ($i == "time:") { v = $(i + 3); u = $(i + 4); break }
            if (u == "s") v *= 1000; else if (u == "µs" || u == "us") v /= 1000; else if (u == "ns") v /= 1e6
            printf "%.4f", v }')
        echo "$round $index $median_ms" >>"$results"
        printf 'round %d  %-60s %10.3f ms\n' "$round" "$binary" "$median_ms"
    done
done
echo
awk -v n="$#" '
    { ms[$1, $2] = $3; if ($1 > rounds) rounds = $1 }
    END {
        for (b = 2; b <= n; b++) {
            line = ""; k = 0
            for (r = 1; r <= rounds; r++) { ratio[++k] = ms[r, b] / ms[r, 1]; line = line sprintf(" %.3f", ratio[k]) }
            # Median of the k ratios (insertion sort; k is small).
            for (i = 2; i <= k; i++) { v = ratio[i]; j = i - 1; while (j > 0 && ratio[j] > v) { ratio[j + 1] = ratio[j]; j-- } ratio[j + 1] = v }
            median = (k % 2) ? ratio[(k + 1) / 2] : (ratio[k / 2] + ratio[k / 2 + 1]) / 2
            printf "binary %d / binary 1, per round:%s  median %.3f\n", b, line, median
        }
    }' "$results"
