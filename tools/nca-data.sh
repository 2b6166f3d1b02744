#!/bin/sh
# nca-data.sh — renders the training data of `hush train-nca` (docs/nca.md):
# for each training scene and each start frame of an orbit, a 1 spp frame
# (input: color, normal, albedo) and a REF_SPP reference of the same camera
# and jitter. Never the evaluation scenes (classroom, living-room).
# usage: tools/nca-data.sh HUSH OUT_DIR [REF_SPP] [SIZE] [SCENES_DIR]
set -eu
HUSH=$1
OUT=$2
SPP=${3:-64}
SIZE=${4:-256x256}
SCENES=${5:-/work/shared/scenes}
mkdir -p "$OUT"
for scene in builtin:cornell builtin:courtyard builtin:moving-light \
             "$SCENES/cornell-box" "$SCENES/sponza-dabrovic"; do
  name=$(basename "$scene" | sed 's/builtin://')
  for first in 0 30 60 90; do
    d="$OUT/$name-$first"
    [ -f "$d/ref/frame_0000.exr" ] && continue
    "$HUSH" render --scene "$scene" --out "$d/noisy" --size "$SIZE" --frames 1 \
      --first "$first" --seed $((first + 1)) --threads 1 --quiet
    "$HUSH" render --scene "$scene" --out "$d/ref" --size "$SIZE" --frames 1 \
      --first "$first" --spp "$SPP" --seed $((first + 7919)) --threads 1 --quiet
  done
done
