#!/usr/bin/env bash
# make demo: the main job end to end on a built-in scene, with nothing beyond
# the repository. Synthesises a moving-camera sequence with a moving object
# and exact references, runs every filter the library has over it, writes
# EXR and PNG results, and prints each filter's error against the reference.
set -euo pipefail
hush=${1:-build/hush}
out=${2:-out/demo}
size=${DEMO_SIZE:-640x360}
frames=${DEMO_FRAMES:-48}

mkdir -p "$out"
echo "demo: synthesising $frames frames at $size into $out/noisy"
"$hush" synth --out "$out/noisy" --size "$size" --frames "$frames" --camera orbit --quiet

filters=$("$hush" filters --names)
for f in $filters; do
  echo "demo: running '$f'"
  "$hush" denoise --filter "$f" --in "$out/noisy" --out "$out/$f" --png --quiet --ref ref
done

last=$(printf 'frame_%04d' $((frames - 1)))
"$hush" convert "$out/noisy/$last.exr" "$out/noisy-$last.png" --layer color
"$hush" convert "$out/noisy/$last.exr" "$out/reference-$last.png" --layer ref
echo "demo: pictures of the last frame: $out/noisy-$last.png, $out/reference-$last.png, $out/<filter>/$last.png"
