#!/bin/bash
# The block chain against one run of the same step time, on the street and on beer_colmap
# (docs/cluster.md, "Tier 2"): `bbsplat blocks run`, then `bbsplat train --minutes M` with M the
# chain's summed step time; one line per run in OUT/summary.txt, and both models' PSNR in the seam
# bands (`bbsplat blocks seams`). Needs a release build
# (`cargo build --release`) and the shared data; takes about 25 minutes on 2 cores.
# Usage: tools/blocks_against_single.sh [OUT] [DATA]   (defaults /tmp/blocks_against_single, ../shared/data)
set -u
B=$(realpath "${BBSPLAT:-target/release/bbsplat}")
data=$(realpath "${2:-../shared/data}")
out=${1:-/tmp/blocks_against_single}
mkdir -p "$out" && cd "$out" || exit 1
rm -f summary.txt
measure() { # name scene grid coarse block polish
  name=$1; scene=$2
  rm -rf $name; mkdir -p $name
  s=$(date +%s.%N)
  $B blocks run $scene -o $name/chain --grid $3 --coarse-iterations $4 --block-iterations $5 --polish-iterations $6 > $name/chain.log 2>&1
  e=$(date +%s.%N)
  echo "$name chain wall $(echo "$e - $s" | bc) s" >> summary.txt
  total=$(python3 -c "import json; print(json.load(open('$name/chain/report.json'))['total_seconds'])")
  minutes=$(python3 -c "print($total/60)")
  s=$(date +%s.%N)
  $B train $scene -o $name/single --minutes $minutes --quiet > $name/single.log 2>&1
  e=$(date +%s.%N)
  echo "$name single wall $(echo "$e - $s" | bc) s (--minutes $minutes)" >> summary.txt
  # Both models where the cells meet (the band from the chain's coarse depth).
  $B blocks seams $name/chain --model $name/single > $name/seams.log 2>&1
  grep -E '^seam band|PSNR' $name/seams.log | sed "s|^|$name seams: |" >> summary.txt
  python3 - "$name" >> summary.txt <<'PY'
import json,sys
n=sys.argv[1]
r=json.load(open(f'{n}/chain/report.json')); s=json.load(open(f'{n}/single/summary.json'))
print(n, 'chain', 'psnr %.2f ssim %.4f billboards %d total %.1f s overlap %.3f' % (r['polish']['test_psnr'], r['polish']['test_ssim'], r['polish']['billboards'], r['total_seconds'], r['overlap_factor']),
      'wall', [(w['machines'], round(w['seconds'],1)) for w in r['wall_time']],
      'blocks', [(b['steps'], round(b['seconds'],1), b['billboards']) for b in r['blocks']], 'coarse %.1f s psnr %.2f' % (r['coarse']['seconds'], r['coarse']['test_psnr']))
print(n, 'single', 'psnr %.2f ssim %.4f billboards %d steps %d seconds %.1f' % (s['test_psnr'], s['test_ssim'], s['billboards'], s['iterations'], s['train_seconds']))
PY
}
$B demo --export street8 --street 8 --resolution 128 > /dev/null
measure street street8 4x1 1000 3000 500
measure beer "$data/beer_colmap" 2x1 500 1000 300
echo done >> summary.txt
