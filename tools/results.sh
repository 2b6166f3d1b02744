#!/usr/bin/env bash
# Writes docs/RESULTS.md from measurements taken now on this machine:
# `hush bench` CSV for speed (1 and 2 threads, same run) and `hush denoise
# --ref` on a synthetic sequence for quality. Nothing in the file is typed
# by hand; rerun this after changing a filter.
#   tools/results.sh [path/to/hush] [frames]
set -euo pipefail
hush=${1:-build/hush}
frames=${2:-60}
# Pinned threads: on these VMs two unpinned OpenMP threads sometimes share a
# core (papers/NOTES.md), which makes 2-thread timings meaningless.
export OMP_PLACES=cores OMP_PROC_BIND=spread
cd "$(dirname "$0")/.."
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

cpu=$(grep -m1 "model name" /proc/cpuinfo | cut -d: -f2- | sed 's/^ *//')
filters=$("$hush" filters --names | paste -sd, -)

"$hush" bench --filters "$filters" --size 1280x720 --frames "$frames" --threads 1 --csv "$work/t1.csv" >/dev/null
"$hush" bench --filters "$filters" --size 1280x720 --frames "$frames" --threads 2 --csv "$work/t2.csv" >/dev/null

"$hush" synth --out "$work/seq" --size 640x360 --frames 48 --camera orbit --quiet
"$hush" eval --seq "$work/seq" --filters "$filters" --out "$work/eval" --no-video --quiet >/dev/null

render_line=""
if [ -d ../shared/scenes/classroom ]; then
  render_line=$(tools/bench-render.sh "$hush" ../shared/scenes/classroom 3 3)
fi

table() { # CSV -> Markdown rows: filter | stage | median | p5 | p95
  tail -n +2 "$1" | awk -F, '{ printf "| `%s` | %s | %.2f | %.2f | %.2f |\n", $1, $2, $(NF-2), $(NF-1), $NF }'
}

{
  echo "# Measured results"
  echo
  echo "Written by \`tools/results.sh\` on $(date -u +%Y-%m-%d) — do not edit by hand."
  echo
  echo "Machine: $cpu, $(nproc) cores, $(free -g | awk '/Mem:/ {print $2}') GiB. Shared and noisy: compare"
  echo "ratios within one run."
  echo
  echo "## Speed: \`hush bench --size 1280x720 --frames $frames\`"
  echo
  echo "Milliseconds per frame on synthetic frames in memory (no file I/O), warm-up excluded."
  echo
  echo "### 1 thread"
  echo
  echo "| filter | stage | median | p5 | p95 |"
  echo "|---|---|---|---|---|"
  table "$work/t1.csv"
  echo
  echo "### 2 threads"
  echo
  echo "| filter | stage | median | p5 | p95 |"
  echo "|---|---|---|---|---|"
  table "$work/t2.csv"
  echo
  echo "## Quality: synthetic orbit sequence, 640x360, 48 frames"
  echo
  echo "\`hush synth --size 640x360 --frames 48 --camera orbit\`, then \`hush eval --seq SEQ --filters $filters\`"
  echo "against the exact expectation stored in each frame (the \`ref\` layer). The shared scenes with"
  echo "rendered references are still to come (issue 4)."
  echo
  sed -n '/^| filter/,/^$/p' "$work/eval/summary.md"
  echo
  echo "## Renderer: 1 spp, 1 bounce, 1280x720, classroom camera path"
  echo
  if [ -n "$render_line" ]; then
    echo "\`tools/bench-render.sh build/hush ../shared/scenes/classroom 3 3\` (render time, EXR writing excluded):"
    echo
    echo "    $render_line"
  else
    echo "Not measured: ../shared/scenes/classroom is absent."
  fi
} > docs/RESULTS.md.tmp
mv docs/RESULTS.md.tmp docs/RESULTS.md
echo "wrote docs/RESULTS.md"
