#!/usr/bin/env bash
# Fails when the AVX2 tile forward of a built binary holds a masked store (`vmaskmovps`).
#
# The forward writes its pixel states with a blend and a plain store
# (`tile_forward_avx2::store_blend_ps`); a compiler left to "load, blend, store back" emits
# masked stores instead, which are slow on AMD Zen cores (docs/perf.md, 2026-11-29). This
# check keeps them out: `tools/no_masked_stores.sh target/release/deps/raster-<hash>` (any
# binary that links the rasterizer: a bench, an example or `bbsplat`).
set -euo pipefail
exe=${1:?usage: no_masked_stores.sh BINARY}
listing=$(objdump -d --no-show-raw-insn "$exe" | awk '
  /^[0-9a-f]+ <.*>:$/ { inside = index($0, "composite_tile_avx2") > 0; if (inside) found++ }
  inside && /vp?maskmov/ { print }
  END { if (!found) print "no composite_tile_avx2 in the binary" > "/dev/stderr"; exit !found }')
if [ -n "$listing" ]; then
  echo "masked stores in composite_tile_avx2 of $exe:" >&2
  echo "$listing" >&2
  exit 1
fi
echo "no masked stores in composite_tile_avx2 of $exe"
