#!/usr/bin/env bash
# The acceptance runs of issues 5, 6 and 9 (svgf, bmfr, nca): every filter on 1 spp input at
# 640x360 against 1024-spp references: 60 frames of the classroom camera path and of the built-in
# moving-light scene, 8 frames of the living-room camera path. The references take hours on 2
# cores (CPU time per 1024-spp frame at 640x360: classroom about 300 s, moving-light 175 s,
# living-room about 600 s, hence its 8 frames), so they are rendered one frame per call into a
# cache directory and the script resumes where it stopped; run it again after an interruption
# (or in the background at low priority: nice -n 19 tools/acceptance.sh render).
#
#   tools/acceptance.sh [render|eval|all]   (default all: render what is missing, then evaluate
#                                            the scenes whose references are complete)
#
# The input (ACCEPT_DIR/NAME/seq) carries asvgf's gradient samples (--gradients).
# Environment: HUSH (build/hush), ACCEPT_DIR (../acceptance), ACCEPT_FRAMES (60; the living room
# takes 8 unless it is set), ACCEPT_SPP (1024), ACCEPT_SIZE (640x360), ACCEPT_REEVAL (1: evaluate
# again scenes whose evaluation is newer than their references and the hush binary). Per scene NAME: ACCEPT_DIR/NAME/seq (the 1 spp input, seed 1),
# ref (the reference sequence, seed 2: its cameras, and its frames once all are rendered; ref/DONE
# marks it complete), ref-frames (the rendered frames so far), eval (the hush eval report).
# Writes docs/results/acceptance.md from the complete scenes. Needs ../shared/scenes for the
# classroom and living-room (skipped without it).
set -euo pipefail
cd "$(dirname "$0")/.."
hush=$(realpath "${HUSH:-build/hush}")
dir=${ACCEPT_DIR:-../acceptance}
frames=${ACCEPT_FRAMES:-60}
living_frames=${ACCEPT_FRAMES:-8}
spp=${ACCEPT_SPP:-1024}
size=${ACCEPT_SIZE:-640x360}
what=${1:-all}
scenes_dir=../shared/scenes
mkdir -p "$dir"

# name scene-argument camera-path frames
scene_list() {
  [ -f "$scenes_dir/classroom/scene.json" ] && echo "classroom $scenes_dir/classroom path $frames"
  echo "moving-light builtin:moving-light static $frames"
  [ -f "$scenes_dir/living-room/scene.json" ] &&
    echo "living-room $scenes_dir/living-room path $living_frames"
  return 0
}

render_scene() { # name scene path frames
  local name=$1 scene=$2 path=$3 frames=$4 d=$dir/$1
  mkdir -p "$d/ref-frames"
  # with asvgf's gradient samples (the colour is the same as without them)
  [ -f "$d/seq/cameras.json" ] || "$hush" render --scene "$scene" --path "$path" --size "$size" \
    --frames "$frames" --spp 1 --seed 1 --gradients --quiet --out "$d/seq"
  [ -f "$d/ref/cameras.json" ] || "$hush" render --scene "$scene" --path "$path" --size "$size" \
    --frames "$frames" --spp 1 --seed 2 --quiet --out "$d/ref"
  [ -f "$d/ref/DONE" ] && return 0
  for ((k = 0; k < frames; k++)); do
    local f
    f=$(printf 'frame_%04d.exr' "$k")
    [ -f "$d/ref-frames/$f" ] && continue
    rm -rf "$d/tmp"
    "$hush" render --scene "$scene" --path "$path" --size "$size" --first "$k" --frames 1 \
      --spp "$spp" --seed 2 --quiet --out "$d/tmp"
    mv "$d/tmp/frame_0000.exr" "$d/ref-frames/$f"
    echo "$(date -u +%H:%M) $name $f"
  done
  for ((k = 0; k < frames; k++)); do
    f=$(printf 'frame_%04d.exr' "$k")
    cp "$d/ref-frames/$f" "$d/ref/$f"
  done
  touch "$d/ref/DONE"
}

eval_scene() { # name
  local d=$dir/$1
  [ -f "$d/ref/DONE" ] || { echo "acceptance: $1: references incomplete, not evaluated" >&2; return 0; }
  # an evaluation newer than the references and the hush binary stands (ACCEPT_REEVAL=1: redo)
  if [ "${ACCEPT_REEVAL:-0}" != 1 ] && [ "$d/eval/summary.md" -nt "$d/ref/DONE" ] &&
    [ "$d/eval/summary.md" -nt "$hush" ]; then
    return 0
  fi
  "$hush" eval --seq "$d/seq" --ref "$d/ref" --filters "$("$hush" filters --names | paste -sd, -)" \
    --no-video --quiet --out "$d/eval" >/dev/null
}

if [ "$what" = render ] || [ "$what" = all ]; then
  while read -r name scene path n; do render_scene "$name" "$scene" "$path" "$n"; done < <(scene_list)
fi
if [ "$what" = eval ] || [ "$what" = all ]; then
  while read -r name _ _ _; do eval_scene "$name"; done < <(scene_list)
  {
    echo "# Acceptance runs: $size, 1 spp input, $spp-spp references"
    echo
    echo "\`tools/acceptance.sh\` ($(date -u +%Y-%m-%d)): \`hush render --spp 1 --seed 1\` for the input,"
    echo "\`--spp $spp --seed 2\` for the references, then \`hush eval\` with every filter. Means over"
    echo "the frames; the temporal error of the row \"reference\" is the reference's own."
    echo
    while read -r name scene path n; do
      [ -f "$dir/$name/eval/summary.md" ] || continue
      echo "## $name (\`$scene\`, camera: $path, $n frames)"
      echo
      sed -n '/^| filter/,/^$/p' "$dir/$name/eval/summary.md"
      echo
    done < <(scene_list)
  } >docs/results/acceptance.md
  echo "wrote docs/results/acceptance.md"
fi
