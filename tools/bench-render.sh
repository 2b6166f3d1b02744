#!/bin/sh
# bench-render.sh — the render speed figure of docs/renderer.md: the 1 spp
# configuration (1 bounce) of a scene at 1280x720 along its camera path,
# REPEATS runs of FRAMES frames, and the minimum and median of the per-frame
# render times that `hush render` prints (EXR writing excluded), with the
# median Mrays/s. The machine is shared, so the minimum is the figure least
# disturbed by other work; compare builds back to back.
#
# usage: tools/bench-render.sh [HUSH] [SCENE] [REPEATS] [FRAMES]
#   defaults: build/hush ../shared/scenes/classroom 3 3
set -eu
here=$(cd "$(dirname "$0")/.." && pwd)
hush=${1:-$here/build/hush}
scene=${2:-$here/../shared/scenes/classroom}
repeats=${3:-3}
frames=${4:-3}
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
i=0
while [ "$i" -lt "$repeats" ]; do
  "$hush" render --scene "$scene" --path path --size 1280x720 --frames "$frames" --spp 1 \
    --out "$out/run" 2>&1 | awk '/^frame [0-9]+\/[0-9]+  render / {print $4, $6}' >>"$out/times"
  i=$((i + 1))
done
sort -n "$out/times" | awk -v scene="$scene" '
  { t[NR] = $1; m[NR] = $2 }
  END {
    mid = int((NR + 1) / 2)
    printf "%s: %d frames, render s/frame min %.3f median %.3f, Mrays/s at the median %.2f\n",
           scene, NR, t[1], t[mid], m[mid]
  }'
