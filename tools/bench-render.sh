#!/bin/sh
# bench-render.sh — the render speed figure of docs/renderer.md: the 1 spp
# configuration (1 bounce) of a scene at 1280x720 along its camera path,
# REPEATS runs of FRAMES frames, and the minimum and median of the per-frame
# render times that `hush render` prints (EXR writing excluded): wall time,
# process CPU time (all threads) and Mrays/s. The machine is shared, so the
# minimum is the figure least disturbed by other work, and CPU time is less
# disturbed than wall time; compare builds back to back (alternating runs).
# Threads are pinned (OMP_PLACES=cores OMP_PROC_BIND=spread).
#
# usage: tools/bench-render.sh [HUSH] [SCENE] [REPEATS] [FRAMES] [THREADS]
#   defaults: build/hush ../shared/scenes/classroom 3 3 0 (0: one per core)
set -eu
here=$(cd "$(dirname "$0")/.." && pwd)
hush=${1:-$here/build/hush}
scene=${2:-$here/../shared/scenes/classroom}
repeats=${3:-3}
frames=${4:-3}
threads=${5:-0}
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
i=0
while [ "$i" -lt "$repeats" ]; do
  OMP_PLACES=cores OMP_PROC_BIND=spread "$hush" render --scene "$scene" --path path \
    --size 1280x720 --frames "$frames" --spp 1 --threads "$threads" --out "$out/run" 2>&1 |
    awk '/^frame [0-9]+\/[0-9]+  render / {print $4, $6, $(NF-1)}' >>"$out/times"
  i=$((i + 1))
done
awk -v scene="$scene" -v threads="$threads" '
  { t[NR] = $1; m[NR] = $2; c[NR] = $3 }
  function sort(a, n,   i, j, x) {
    for (i = 2; i <= n; i++) { x = a[i]; for (j = i - 1; j >= 1 && a[j] > x; j--) a[j + 1] = a[j]; a[j + 1] = x }
  }
  END {
    n = NR; mid = int((n + 1) / 2)
    sort(t, n); sort(m, n); sort(c, n)
    printf "%s: %d frames, %s threads: render s/frame min %.3f median %.3f; " \
           "CPU s/frame min %.3f median %.3f; Mrays/s median %.2f\n",
           scene, n, threads == 0 ? "all" : threads, t[1], t[mid], c[1], c[mid], m[mid]
  }' "$out/times"
