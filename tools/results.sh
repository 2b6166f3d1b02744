#!/usr/bin/env bash
# Writes docs/RESULTS.md from measurements taken now on this machine:
# `hush bench` CSV for speed (1 and 2 threads, same run) and `hush denoise
# --ref` on a synthetic sequence for quality. Nothing in the file is typed
# by hand; rerun this after changing a filter.
#   tools/results.sh [path/to/hush] [frames]
set -euo pipefail
hush=${1:-build/hush}
frames=${2:-60}
cd "$(dirname "$0")/.."
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

cpu=$(grep -m1 "model name" /proc/cpuinfo | cut -d: -f2- | sed 's/^ *//')
filters=$("$hush" filters --names | paste -sd, -)

"$hush" bench --filters "$filters" --size 1280x720 --frames "$frames" --threads 1 --csv "$work/t1.csv" >/dev/null
"$hush" bench --filters "$filters" --size 1280x720 --frames "$frames" --threads 2 --csv "$work/t2.csv" >/dev/null

"$hush" synth --out "$work/seq" --size 640x360 --frames 48 --camera orbit --quiet
quality=""
for f in ${filters//,/ }; do
  line=$("$hush" denoise --filter "$f" --in "$work/seq" --out "$work/$f" --quiet --ref ref)
  quality+="| \`$f\` | $(echo "$line" | sed -E 's/.*RMSE ([0-9.]+) \(input ([0-9.]+)\), PSNR ([0-9.]+) dB \(input ([0-9.]+) dB\).*/\2 | \1 | \4 | \3/') |"$'\n'
done

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
  echo "\`hush synth --size 640x360 --frames 48 --camera orbit\`, then \`hush denoise --filter F --ref ref\`:"
  echo "mean over all frames of the per-frame RMSE and PSNR against the exact expectation."
  echo "(The real scenes and \`hush eval\` come with the renderer and evaluation issues.)"
  echo
  echo "| filter | RMSE input | RMSE output | PSNR input (dB) | PSNR output (dB) |"
  echo "|---|---|---|---|---|"
  printf "%s" "$quality"
} > docs/RESULTS.md.tmp
mv docs/RESULTS.md.tmp docs/RESULTS.md
echo "wrote docs/RESULTS.md"
