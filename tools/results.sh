#!/usr/bin/env bash
# Writes docs/RESULTS.md from measurements taken on this machine. Nothing in
# it is typed by hand: each part is measured and written to docs/results/,
# and RESULTS.md is their concatenation, so a part can be re-measured alone
# (the speed part wants a quiet machine, the scenes part takes long).
#
#   tools/results.sh [PART...]     PART: speed synthetic scenes render (default: all);
#                                  join: only rewrite RESULTS.md from the parts
#
# Environment: HUSH (build/hush), BENCH_FRAMES (60), SPEED_ROUNDS (3: each bench of
# the speed part runs that many times, and each filter's row is its fastest run's,
# as the shared host's busy phases only add time); for the scenes part
# SCENE_SIZE (640x360), SCENE_FRAMES (16), SCENE_REF_SPP (64); the scenes and
# render parts need ../shared/scenes and are skipped without it.
set -euo pipefail
# Pinned threads: on these VMs two unpinned OpenMP threads sometimes share a
# core (papers/NOTES.md), which makes 2-thread timings meaningless.
export OMP_PLACES=cores OMP_PROC_BIND=spread
cd "$(dirname "$0")/.."
hush=${HUSH:-build/hush}
parts=${*:-speed synthetic scenes render}
mkdir -p docs/results
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
filters=$("$hush" filters --names | paste -sd, -)
today=$(date -u +%Y-%m-%d)

bench_table() { # bench CSV -> Markdown rows: filter | stage | median | p5 | p95
  tail -n +2 "$1" | awk -F, '{ printf "| `%s` | %s | %.2f | %.2f | %.2f |\n", $1, $2, $(NF-2), $(NF-1), $NF }'
}

summary_table() { # the table of a hush eval summary.md
  sed -n '/^| filter/,/^$/p' "$1"
}

# bench_best OUT.csv BENCH-ARGS...: hush bench SPEED_ROUNDS times; OUT.csv gets,
# per filter, the rows of the run with the smallest total (the last run's
# stdout goes to OUT.txt)
bench_best() {
  local out=$1 r
  shift
  for ((r = 0; r < ${SPEED_ROUNDS:-3}; r++)); do
    "$hush" bench "$@" --csv "$out.$r" >"${out%.csv}.txt"
  done
  awk -F, 'FNR == 1 { file++; if (file == 1) print; next }
    { row[file, $1] = row[file, $1] $0 "\n" }
    $2 == "total" { if (!($1 in best) || $(NF-2) + 0 < total[$1]) { best[$1] = file; total[$1] = $(NF-2) + 0 } }
    file == 1 && !($1 in seen) { seen[$1] = 1; order[++n] = $1 }
    END { for (i = 1; i <= n; i++) printf "%s", row[best[order[i]], order[i]] }' "$out".*  >"$out"
  rm -f "$out".*
}

part_speed() {
  local frames=${BENCH_FRAMES:-60}
  bench_best "$work/t1.csv" --filters "$filters" --size 1280x720 --frames "$frames" --threads 1
  bench_best "$work/t2.csv" --filters "$filters" --size 1280x720 --frames "$frames" --threads 2
  # the same filters on rendered frames: a real camera path's motion (windows
  # and gathers instead of contiguous history reads, disocclusions), lights
  # seen directly (the emission's own blend), no sky to skip
  local scene=../shared/scenes/classroom
  [ -f "$scene/scene.json" ] || scene=builtin:cornell-moving
  local scene_filters
  scene_filters=$(tr , '\n' <<<"$filters" | grep -vx -e asvgf -e nca | paste -sd, -)
  bench_best "$work/scene2.csv" --scene "$scene" --filters "$scene_filters" --size 1280x720 \
    --frames "$frames" --distinct 8 --threads 2
  # psf filters the path tracer's vertices: a built-in scene, so no ../shared needed
  local t
  for t in 1 2; do
    bench_best "$work/psf$t.csv" --scene builtin:courtyard --filters psf --size 1280x720 \
      --frames "$frames" --distinct 8 --threads $t
  done
  {
    echo "## Speed: \`hush bench --size 1280x720 --frames $frames\` ($today)"
    echo
    echo "Milliseconds per frame on synthetic frames in memory (no file I/O), warm-up excluded, on"
    echo "$(sed -n '1s/.*thread(s), //p' "$work/t1.txt") ($(nproc) cores; the project's VM, whose host CPU changes between sessions)."
    echo "Each bench ran ${SPEED_ROUNDS:-3} times; each filter's rows are from its run with the smallest"
    echo "total (the shared host's busy phases only add time). Each filter's required output only"
    echo "is bound (as a renderer would; \`--all-outputs\` would add the optional ones' exports)."
    echo
    for t in 1 2; do
      echo "### $t thread(s)"
      echo
      echo "| filter | stage | median | p5 | p95 |"
      echo "|---|---|---|---|---|"
      bench_table "$work/t$t.csv"
      echo
    done
    echo "### Rendered frames, 2 threads"
    echo
    echo "\`hush bench --scene $(sed 's|^\.\./shared/|shared/|' <<<"$scene") --filters $scene_filters --size 1280x720 --frames $frames --distinct 8\`:"
    echo "8 frames of the scene's camera path rendered at 1 spp, played forwards and backwards. Slower"
    echo "than the synthetic frames above: the path's parallax spreads history reads over windows"
    echo "and gathers instead of contiguous rows, more pixels lose their history (the 3x3 search, the"
    echo "spatial variance), the lights' emission has its own temporal blend, and there is no sky to"
    echo "skip (docs/svgf-speed.md, twelfth round)."
    echo
    echo "| filter | stage | median | p5 | p95 |"
    echo "|---|---|---|---|---|"
    bench_table "$work/scene2.csv"
    echo
    echo "### psf (hashed path-space filtering) through its public API"
    echo
    echo "\`hush bench --scene builtin:courtyard --filters psf --size 1280x720 --frames $frames --distinct 8\`:"
    echo "the vertices of 8 rendered frames of the orbit, replayed through \`hush_psf_add_vertices\`"
    echo "(the device's threads), \`hush_psf_resolve\` and \`hush_psf_lookup\`; default parameters."
    echo
    echo "| threads | stage | median | p5 | p95 |"
    echo "|---|---|---|---|---|"
    for t in 1 2; do
      tail -n +2 "$work/psf$t.csv" | awk -F, -v t=$t '{ printf "| %s | %s | %.2f | %.2f | %.2f |\n", t, $2, $(NF-2), $(NF-1), $NF }'
    done
    echo
    for t in 1 2; do
      echo "$t thread(s): $(grep -o 'medians per frame:.*' "$work/psf$t.txt")"
      echo
    done
  } >docs/results/speed.md
}

part_synthetic() {
  # asvgf needs the renderer's gradient samples, which synthetic frames do not have
  local synth_filters
  synth_filters=$(tr , '\n' <<<"$filters" | grep -vx asvgf | paste -sd, -)
  "$hush" synth --out "$work/seq" --size 640x360 --frames 48 --camera orbit --quiet
  "$hush" eval --seq "$work/seq" --filters "$synth_filters" --out "$work/eval" --no-video --quiet >/dev/null
  {
    echo "## Quality: synthetic orbit sequence, 640x360, 48 frames ($today)"
    echo
    echo "\`hush synth --size 640x360 --frames 48 --camera orbit\`, then \`hush eval --seq SEQ --filters $synth_filters\`"
    echo "against the exact expectation stored in each frame (the \`ref\` layer)."
    echo
    summary_table "$work/eval/summary.md"
  } >docs/results/synthetic.md
}

part_scenes() {
  [ -d ../shared/scenes ] || { echo "results: ../shared/scenes absent, scenes part skipped" >&2; return 0; }
  local size=${SCENE_SIZE:-640x360} frames=${SCENE_FRAMES:-16} spp=${SCENE_REF_SPP:-64}
  # The path-space filter runs inside the renderer, so only rendered scenes can have it.
  local filters="$filters,psf,psf+svgf,psf+bmfr"
  {
    echo "## Quality: the shared scenes ($today)"
    echo
    echo "Each scene rendered at 1 spp (the papers' configuration: primary ray, one secondary ray, two"
    echo "shadow rays) and at $spp spp as the reference (same cameras, jitter and bounce count, another"
    echo "seed), then evaluated: $frames frames at $size, means over the frames. The filters' acceptance"
    echo "runs (60+ frames, 1024-spp references) use this script with SCENE_FRAMES and SCENE_REF_SPP raised."
    echo "With low-spp references, RMSE and relMSE are dominated by the references' own noise where light"
    echo "arrives through rare paths (the living room is lit through glass: a fifth of its 32-spp reference"
    echo "pixels are exactly 0) and at light sources' edges; SSIM separates the filters more reliably there."
    echo
    for entry in classroom:path living-room:path sponza-dabrovic:orbit cornell-box:orbit \
                 builtin+moving-light:static builtin+light-off:static; do
      local name=${entry%%:*} move=${entry##*:} scene
      case $name in
        builtin+*) name=${name#builtin+}; scene=builtin:$name ;;
        *) scene=../shared/scenes/$name ;;
      esac
      "$hush" eval --scene "$scene" --path "$move" --size "$size" --frames "$frames" \
        --ref-spp "$spp" --filters "$filters" --no-video --quiet --out "$work/scene-$name" >/dev/null
      echo "### $name"
      echo
      echo "\`hush eval --scene $scene --path $move --size $size --frames $frames --ref-spp $spp --filters $filters\`"
      echo
      summary_table "$work/scene-$name/summary.md"
    done
  } >"$work/scenes.md"
  mv "$work/scenes.md" docs/results/scenes.md
}

part_render() {
  [ -d ../shared/scenes/classroom ] || { echo "results: classroom absent, render part skipped" >&2; return 0; }
  local line
  line=$(tools/bench-render.sh "$hush" ../shared/scenes/classroom 3 3)
  {
    echo "## Renderer: 1 spp, 1 bounce, 1280x720, classroom camera path ($today)"
    echo
    echo "\`tools/bench-render.sh build/hush ../shared/scenes/classroom 3 3\` (render time, EXR writing excluded):"
    echo
    echo "    $line"
    echo
  } >docs/results/render.md
}

for p in $parts; do
  case $p in
    speed | synthetic | scenes | render) "part_$p" ;;
    join) ;;
    *) echo "results: unknown part '$p' (speed, synthetic, scenes, render)" >&2; exit 2 ;;
  esac
done

# the CPU as hush bench names it: model name, family and model, the build's vectors
cpu=$("$hush" bench --filters taa --size 16x16 --frames 1 --warmup 0 --threads 1 | sed -n '1s/.*thread(s), //p')
{
  echo "# Measured results"
  echo
  echo "Written by \`tools/results.sh\` from the parts in \`docs/results/\` — do not edit by hand. Each"
  echo "part carries the date it was measured."
  echo
  echo "Machine: $cpu, $(nproc) cores, $(free -g | awk '/Mem:/ {print $2}') GiB, Debian 12. Shared and"
  echo "noisy: compare ratios measured within one run."
  echo
  for p in speed synthetic scenes render; do
    [ -f "docs/results/$p.md" ] && { cat "docs/results/$p.md"; echo; }
  done
  # pages measured by hand (their commands are in them), not by a part of this script
  echo "## Other measurements"
  echo
  for f in docs/results/*.md; do
    case $(basename "$f" .md) in speed | synthetic | scenes | render) continue ;; esac
    echo "- [$(basename "$f")](results/$(basename "$f")): $(head -1 "$f" | sed 's/^# *//')"
  done
  echo "- [holes.md](holes.md): the temporal filters at fewer than 1 spp, before and after hole handling"
} >docs/RESULTS.md.tmp
mv docs/RESULTS.md.tmp docs/RESULTS.md
echo "wrote docs/RESULTS.md ($parts)"
