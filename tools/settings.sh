#!/usr/bin/env bash
# Writes docs/results/settings.md: what svgf's and bmfr's settings cost and
# buy, each configuration's quality on the classroom's camera path (hush eval)
# next to its speed on the bench frames at 1280x720 (hush bench), so that a
# user who needs a frame faster than the published defaults give it can see
# what each step down costs in the image.
#
#   tools/settings.sh [DIR]   DIR keeps the rendered classroom frames between
#                             runs (default: a temporary directory)
#
# Environment: HUSH (build/hush); SETTINGS_SIZE (640x360), SETTINGS_FRAMES
# (16), SETTINGS_REF_SPP (64) for the quality part; ROUNDS (3) and
# BENCH_FRAMES (20) for the speed part, whose configurations are run in turn,
# round after round, so that a busy phase of the shared host falls on all of
# them alike; the table gives the fastest round's median per configuration
# (the host's busy phases only ever add time, and come and go within a
# minute). Needs ../shared/scenes/classroom.
set -euo pipefail
export OMP_PLACES=cores OMP_PROC_BIND=spread
cd "$(dirname "$0")/.."
hush=${HUSH:-build/hush}
scene=../shared/scenes/classroom/scene.json
[ -f "$scene" ] || { echo "settings: $scene is absent (../shared/scenes)" >&2; exit 1; }
size=${SETTINGS_SIZE:-640x360}
frames=${SETTINGS_FRAMES:-16}
spp=${SETTINGS_REF_SPP:-64}
rounds=${ROUNDS:-3}
bench_frames=${BENCH_FRAMES:-20}
if [ $# -ge 1 ]; then
  dir=$1
  mkdir -p "$dir"
else
  dir=$(mktemp -d)
  trap 'rm -rf "$dir"' EXIT
fi

# filter | settings (KEY=VALUE ..., empty: the defaults) | the stage they change
configs=(
  "svgf||atrous"
  "svgf|weight_exp=accurate|atrous"
  "svgf|iterations=4|atrous"
  "svgf|kernel=3x3 iterations=6|atrous"
  "svgf|kernel=3x3 iterations=6 order=0-then-decreasing|atrous"
  "svgf|kernel=3x3 iterations=5|atrous"
  "bmfr||fit"
  "bmfr|refine=1|fit"
  "bmfr|refine=0|fit"
  "bmfr|taa=0|taa"
  "bmfr|block_size=64|fit"
)

[ -f "$dir/seq/cameras.json" ] ||
  "$hush" render --scene "$scene" --path path --frames "$frames" --size "$size" --spp 1 --seed 1 \
    --out "$dir/seq" >/dev/null
[ -f "$dir/ref/cameras.json" ] ||
  "$hush" render --scene "$scene" --path path --frames "$frames" --size "$size" --spp "$spp" \
    --seed 2 --out "$dir/ref" >/dev/null

sets() { # $1 prefix ("" or "svgf."), $2 settings -> --set arguments
  local kv
  for kv in $2; do printf -- '--set %s%s ' "$1" "$kv"; done
}

# the RMSE, relMSE, SSIM and temporal-error cells of filter $1's row in summary $2
row_of() {
  awk -F'|' -v f="$1" '$2 ~ "^ *"f" *$" { printf "%s |%s |%s |%s", $3, $4, $5, $7; exit }' "$2"
}

# quality: one hush eval per configuration, the filter's row of its summary
# (every summary holds the accumulate baseline too: the first one gives it)
declare -A quality
for i in "${!configs[@]}"; do
  IFS='|' read -r f s _ <<<"${configs[$i]}"
  # shellcheck disable=SC2046
  "$hush" eval --seq "$dir/seq" --ref "$dir/ref" --filters "$f" $(sets "$f." "$s") --no-video \
    --quiet --out "$dir/eval$i" >/dev/null
  quality[$i]=$(row_of "$f" "$dir/eval$i/summary.md")
done
baseline=$(row_of accumulate "$dir/eval0/summary.md")

# speed: the configurations in turn, ROUNDS times; "total:stage" per run
declare -A runs
for ((r = 0; r < rounds; r++)); do
  for i in "${!configs[@]}"; do
    IFS='|' read -r f s stage <<<"${configs[$i]}"
    # shellcheck disable=SC2046
    "$hush" bench --filters "$f" --size 1280x720 --frames "$bench_frames" --threads 2 \
      $(sets "" "$s") --csv "$dir/bench.csv" >/dev/null
    runs[$i]+="$(awk -F, -v s="$stage" '$2 == "total" { t = $(NF-2) } $2 == s { g = $(NF-2) }
      END { print t ":" g }' "$dir/bench.csv") "
  done
done
# the run with the smallest total: "total | stage ms"
fastest() { tr ' ' '\n' | sed '/^$/d' | sort -t: -k1,1g | awk -F: -v s="$1" 'NR == 1 { printf "%.1f | %s %.1f", $1, s, $2 }'; }

# the CPU as hush bench names it: model name, family and model, the build's vectors
cpu=$("$hush" bench --filters taa --size 16x16 --frames 1 --warmup 0 --threads 1 | sed -n '1s/.*thread(s), //p')
{
  echo "# Settings: speed against quality for svgf and bmfr ($(date -u +%Y-%m-%d))"
  echo
  echo "\`tools/settings.sh\`. Quality: \`hush eval\` on the classroom's camera path ($frames frames, $size,"
  echo "1 spp input, $spp-spp references; means over the frames). Speed: \`hush bench --size 1280x720"
  echo "--frames $bench_frames --threads 2\` on the bench's synthetic frames, $cpu (2 cores, threads"
  echo "pinned), the configurations run in turn $rounds times; per configuration the fastest run's"
  echo "median (the shared host's busy phases only add time), in milliseconds per frame, with the stage"
  echo "the setting changes (its median in the run of that total). The first row of each filter is its"
  echo "defaults (the published ones, plus hush's additions: docs/filters.md)."
  echo
  echo "| filter | settings | RMSE | relMSE | SSIM | temporal error | ms/frame | stage (ms) |"
  echo "| --- | --- | ---: | ---: | ---: | ---: | ---: | --- |"
  echo "| accumulate | (the baseline) |$baseline | - | - |"
  for i in "${!configs[@]}"; do
    IFS='|' read -r f s stage <<<"${configs[$i]}"
    echo "| $f | ${s:-defaults} |${quality[$i]} | $(fastest "$stage" <<<"${runs[$i]}") |"
  done
} >docs/results/settings.md.tmp
mv docs/results/settings.md.tmp docs/results/settings.md
echo "wrote docs/results/settings.md"
