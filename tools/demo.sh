#!/usr/bin/env bash
# make demo: the main job end to end with nothing beyond the repository.
# Path-traces the built-in courtyard (orbiting camera, a moving sphere light,
# a moving box) at 1 spp with high-sample references, runs every filter the
# library has over it with `hush eval`, writes the HTML report, prints the
# summary table and says where report.html is.
#
# The defaults fit the issue's budget (build and demo within 5 minutes on
# 2 cores): the references dominate, about 3 s a frame at 320x180 and
# 32 spp on 2 cores. DEMO_SIZE, DEMO_FRAMES and DEMO_REF_SPP change them.
set -euo pipefail
hush=${1:-build/hush}
out=${2:-out/demo}
size=${DEMO_SIZE:-320x180}
frames=${DEMO_FRAMES:-24}
ref_spp=${DEMO_REF_SPP:-32}

filters=$("$hush" filters --names | paste -sd, -)
echo "demo: rendering builtin:courtyard ($frames frames, $size, 1 spp and $ref_spp spp references)," \
  "then running $filters into $out"
start=$(date +%s)
"$hush" eval --scene builtin:courtyard --path orbit --size "$size" --frames "$frames" \
  --ref-spp "$ref_spp" --filters "$filters" --out "$out" >/dev/null  # the table is printed below
echo
cat "$out/summary.md"
echo
echo "demo: done in $(( $(date +%s) - start )) s"
echo "demo: report: $(cd "$out" && pwd)/report.html"
