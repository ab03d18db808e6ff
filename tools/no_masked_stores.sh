#!/usr/bin/env bash
# Fails when a function of bbsplat in a built binary holds a masked store (`vmaskmovps`,
# `vpmaskmovd` and their kin).
#
# Compilers turn "load, blend with what was loaded, store back" into a masked store. It gives
# the same bits but is slow on AMD Zen cores, and a load of what it stored waits for it
# (docs/perf-log.md, 2026-11-29): the AVX2 tile forward lost a sixth of its time to nine of them
# per run. The forward's blended stores are written to prevent it
# (`tile_forward_avx2::store_blend_at`), and `SupportQuad::row_spans` keeps its spans in
# registers; this check keeps masked stores from coming back anywhere in the crate's code:
# `tools/no_masked_stores.sh target/release/deps/raster-<hash>` (a bench, an example or the
# `bbsplat` binary). It also fails when the binary holds no AVX2 tile forward to check.
set -euo pipefail
exe=${1:?usage: no_masked_stores.sh BINARY}
listing=$(objdump -d --no-show-raw-insn "$exe" | awk '
  /^[0-9a-f]+ <.*>:$/ { ours = index($0, "bbsplat") > 0; name = $2; if (index($0, "composite_tile_avx2")) forward++ }
  ours && /vp?maskmov/ { print name ": " $0 }
  END { if (!forward) { print "no composite_tile_avx2 in the binary" > "/dev/stderr"; exit 1 } }')
if [ -n "$listing" ]; then
  echo "masked stores in $exe:" >&2
  echo "$listing" >&2
  exit 1
fi
echo "no masked stores in bbsplat's code in $exe"
