#!/usr/bin/env bash
# run-bmfr-reference.sh — runs the PUBLISHED OpenCL BMFR code (Koskela et al.
# 2019, github.com/maZZZu/bmfr, bmfr-koskela-2019.md §6.1) on a sequence that
# `hush render ... --export bmfr` wrote, and converts its outputs into a hush
# sequence, so that `hush eval` can put the reference implementation next to
# hush's filters on exactly the same frames. docs/bmfr-reference.md explains
# the comparison and what the published code's output is.
#
#   tools/run-bmfr-reference.sh SEQ_DIR OUT_DIR [options]
#
# SEQ_DIR is the directory of `hush render --out SEQ_DIR --export bmfr`
# (cameras.json, frame_NNNN.exr, bmfr/). OUT_DIR receives frame_NNNN.exr (one
# layer "color": the published code's output, linear), cameras.json (SEQ_DIR's),
# bmfr-log.txt (the code's own per-kernel timings) and bmfr-changes.diff (every
# change made to the published code, which is otherwise built as published).
#
# Needs: git (unless --src), make, g++, an OpenCL ICD loader and runtime with
# headers (Debian/Ubuntu: pocl-opencl-icd ocl-icd-opencl-dev opencl-headers;
# PoCL runs it on the CPU), OpenImageIO 2.x (libopenimageio-dev), libGL
# (CLUtils references glX), and the hush CLI. Not part of `make test`.
set -euo pipefail

# The commit of github.com/maZZZu/bmfr this script was written and checked
# against ("Added group and university to README", the TOG supplementary code).
BMFR_REPO=${BMFR_REPO:-https://github.com/maZZZu/bmfr.git}  # $BMFR_REPO: a mirror
BMFR_COMMIT=4b821c6efcf7813c774ffc0d4891b9603f1c911f

usage() {
  cat <<'EOF'
usage: tools/run-bmfr-reference.sh SEQ_DIR OUT_DIR [options]

Clones the published BMFR code at a pinned commit, sets its compile-time
image size, frame count and input path for SEQ_DIR/bmfr, builds it against
the OpenCL runtime (PoCL on a CPU), runs it, and writes its outputs to
OUT_DIR as a hush sequence (frame_NNNN.exr + cameras.json).

options:
  --src DIR        use this copy of the published code (a checkout of the
                   pinned commit, holding opencl/) instead of cloning it
  --work DIR       build here and keep it (default: a temporary directory,
                   removed at the end)
  --hush PATH      the hush CLI (default: $HUSH, else build/hush of this
                   checkout, else `hush` on the PATH)
  --platform I     OpenCL platform index (default 0)
  --device J       OpenCL device index (default 0)
  --no-clamp       also remove the clamp to [0, 1] of the code's tone mapping
                   (its output is otherwise display-referred: radiance above 1
                   is lost); every other line of the algorithm stays as published
  -h, --help       show this help
EOF
}

die() { echo "run-bmfr-reference.sh: $*" >&2; exit 1; }

# ---- arguments ----------------------------------------------------------------
SEQ='' OUT='' SRC='' WORK='' HUSH_BIN=${HUSH:-} PLATFORM=0 DEVICE=0 NO_CLAMP=0
while [ $# -gt 0 ]; do
  case $1 in
    -h|--help) usage; exit 0 ;;
    --src) SRC=${2:?--src needs a directory}; shift 2 ;;
    --work) WORK=${2:?--work needs a directory}; shift 2 ;;
    --hush) HUSH_BIN=${2:?--hush needs a path}; shift 2 ;;
    --platform) PLATFORM=${2:?--platform needs an index}; shift 2 ;;
    --device) DEVICE=${2:?--device needs an index}; shift 2 ;;
    --no-clamp) NO_CLAMP=1; shift ;;
    -*) die "unknown option '$1' (see --help)" ;;
    *) if [ -z "$SEQ" ]; then SEQ=$1; elif [ -z "$OUT" ]; then OUT=$1; else
         die "unexpected argument '$1' (see --help)"; fi; shift ;;
  esac
done
[ -n "$SEQ" ] && [ -n "$OUT" ] || { usage >&2; exit 2; }
case $PLATFORM$DEVICE in *[!0-9]*) die "--platform and --device take integers" ;; esac

# This checkout's build first: `hush` on the PATH may be BusyBox's shell.
if [ -z "$HUSH_BIN" ]; then
  HUSH_BIN=$(cd "$(dirname "$0")/.." && pwd)/build/hush
  if [ ! -x "$HUSH_BIN" ] && command -v hush > /dev/null 2>&1; then HUSH_BIN=$(command -v hush); fi
fi
[ -x "$HUSH_BIN" ] || die "no hush CLI at '$HUSH_BIN' (build it, or give --hush)"

# ---- the sequence: size and frame count from cameras.json ---------------------
SEQ=$(cd "$SEQ" && pwd) || die "no directory '$SEQ'"
CAMERAS=$SEQ/cameras.json
[ -f "$CAMERAS" ] || die "$CAMERAS is missing: SEQ_DIR must be a \`hush render\` output"
[ -f "$SEQ/bmfr/camera_matrices.h" ] ||
  die "$SEQ/bmfr/camera_matrices.h is missing: render with \`--export bmfr\`"
json_int() { sed -n "s/^ *\"$1\": *\([0-9][0-9]*\),*$/\1/p" "$CAMERAS" | head -n 1; }
WIDTH=$(json_int width) HEIGHT=$(json_int height) FRAMES=$(json_int frame_count)
[ -n "$WIDTH" ] && [ -n "$HEIGHT" ] && [ -n "$FRAMES" ] ||
  die "$CAMERAS: no width, height or frame_count"
# The code mirrors its 32x32 block grid, moved by up to 16 + 16 pixels, at the
# borders (mirror() in bmfr.cl works one image size out at most), and sizes its
# timing tables FRAME_COUNT - 1.
[ "$WIDTH" -gt 32 ] && [ "$HEIGHT" -gt 32 ] || die "frames must be larger than 32x32"
[ "$FRAMES" -ge 2 ] || die "the published code needs at least 2 frames"
mapfile -t FILES < <(sed -n 's/^ *{"file": *"\([^"]*\)",*$/\1/p' "$CAMERAS")
[ "${#FILES[@]}" -eq "$FRAMES" ] || die "$CAMERAS: ${#FILES[@]} frame files for $FRAMES frames"
for ((i = 0; i < FRAMES; i++)); do
  for f in color albedo shading_normal world_position; do
    [ -f "$SEQ/bmfr/$f$i.exr" ] || die "$SEQ/bmfr/$f$i.exr is missing"
  done
done

# ---- the published code, in a work directory -----------------------------------
if [ -z "$WORK" ]; then
  WORK=$(mktemp -d "${TMPDIR:-/tmp}/bmfr-reference.XXXXXX")
  trap 'rm -rf "$WORK"' EXIT
fi
mkdir -p "$WORK"
WORK=$(cd "$WORK" && pwd)
CODE=$WORK/bmfr
rm -rf "$CODE"
if [ -n "$SRC" ]; then
  [ -f "$SRC/opencl/bmfr.cpp" ] || die "--src: no opencl/bmfr.cpp in '$SRC'"
  mkdir -p "$CODE" && cp -R "$SRC/opencl" "$CODE/"
else
  # Only opencl/ is needed (not the Windows binaries in 3rd-party/).
  git clone --quiet --no-checkout "$BMFR_REPO" "$CODE" ||
    die "cannot clone $BMFR_REPO (no network? use --src)"
  git -C "$CODE" checkout --quiet "$BMFR_COMMIT" -- opencl ||
    die "$BMFR_REPO has no opencl/ at commit $BMFR_COMMIT"
fi
CL=$CODE/opencl
cp "$CL/bmfr.cpp" "$WORK/bmfr.cpp.orig"
cp "$CL/bmfr.cl" "$WORK/bmfr.cl.orig"

# The code #includes ../data/frames/camera_matrices.h and reads
# ../data/frames/<name>N.exr (INPUT_DATA_PATH, relative to opencl/): link the
# export there rather than editing a path that the preprocessor stringifies.
mkdir -p "$CODE/data" "$CL/outputs"
ln -sfn "$SEQ/bmfr" "$CODE/data/frames"

# Edits one line pattern of a file with sed and fails unless it changed
# something, so that a different upstream version cannot be patched silently.
edit() {
  local file=$1 expr=$2 before
  before=$(cksum < "$file")
  sed -i "$expr" "$file"
  [ "$(cksum < "$file")" != "$before" ] || die "patching $(basename "$file") failed: '$expr'"
}
# Sets one of the code's #define lines (which must exist) to a value.
set_define() {
  local name=$1 value=$2
  grep -q "^#define $name " "$CL/bmfr.cpp" || die "bmfr.cpp has no '#define $name'"
  sed -i "s/^#define $name .*\$/#define $name $value/" "$CL/bmfr.cpp"
}
# Inputs: the compile-time size, frame count and OpenCL device.
set_define IMAGE_WIDTH "$WIDTH"
set_define IMAGE_HEIGHT "$HEIGHT"
set_define FRAME_COUNT "$FRAMES"
set_define PLATFORM_INDEX "$PLATFORM"
set_define DEVICE_INDEX "$DEVICE"
# OpenImageIO 2.x: ImageInput::open returns a unique_ptr (the code targets 1.5).
edit "$CL/bmfr.cpp" 's/OpenImageIO::ImageInput \*in = /auto in = /'
# Outputs: float EXR instead of 8-bit PNG, and linear: the last kernel stores
# clamp(pow(albedo * colour, 0.454545), 0, 1) (then TAA); raising it to
# 1 / 0.454545 undoes the gamma exactly, so the output compares with linear
# references. TAA's YCoCg clamp can leave a channel slightly below 0, where the
# power would be NaN: it becomes 0, as the PNG writer would have clamped it.
# The tone mapping's clamp to [0, 1] stays unless --no-clamp.
edit "$CL/bmfr.cpp" 's/std::to_string(frame) + "\.png"/std::to_string(frame) + ".exr"/'
edit "$CL/bmfr.cpp" 's|^\( *\)// Crops back from WORKSET_SIZE to IMAGE_SIZE|\1// hush: undo the gamma of accumulate_filtered_data (linear radiance)\n\1for (auto \&v : out_data[frame]) v = std::pow(std::max(v, 0.f), 1.f / 0.454545f);\n&|'
if [ "$NO_CLAMP" = 1 ]; then
  edit "$CL/bmfr.cl" 'N;s|clamp(\n\( *\)powr(max(0.f, my_albedo \* accumulated_color), 0.454545f), 0.f, 1.f);|(\n\1powr(max(0.f, my_albedo * accumulated_color), 0.454545f));|;P;D'
fi
(cd "$WORK" && { diff -u bmfr.cpp.orig "$CL/bmfr.cpp" || true; diff -u bmfr.cl.orig "$CL/bmfr.cl" || true; }) \
  > "$WORK/bmfr-changes.diff"

# ---- build ---------------------------------------------------------------------
OIIO_VERSION_H=$(echo '#include <OpenImageIO/oiioversion.h>' | g++ -M -x c++ - 2> /dev/null |
  tr -s ' \\' '\n' | grep 'oiioversion.h$' | head -n 1 || true)
[ -n "$OIIO_VERSION_H" ] ||
  die "OpenImageIO headers not found (Debian/Ubuntu: apt-get install libopenimageio-dev)"
CFLAGS="-std=c++14 -O2 -DUNIX -m64 -w"
# OpenImageIO 2.x names its namespace OIIO; the code says OpenImageIO.
if grep -q '^#define OIIO_VERSION_MAJOR *[2-9]' "$OIIO_VERSION_H"; then
  CFLAGS="$CFLAGS -DOpenImageIO=OIIO"
fi
LIBS="-lOpenCL -lGL -lOpenImageIO -lOpenImageIO_Util -fopenmp"
# With libglvnd, glX* lives in libGLX, which -lGL alone does not pull in.
if echo 'int main(void){return 0;}' | gcc -x c - -o /dev/null -lGLX 2> /dev/null; then
  LIBS="$LIBS -lGLX"
fi
echo "building the published code in $CL" >&2
make -C "$CL" --no-print-directory CFLAGS="$CFLAGS" LIBS="$LIBS" > "$WORK/build.log" 2>&1 ||
  { tail -n 30 "$WORK/build.log" >&2; die "the build failed (log: $WORK/build.log)"; }

# ---- run -------------------------------------------------------------------------
mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)
echo "running it on $WIDTH x $HEIGHT, $FRAMES frames of $SEQ" >&2
START=$(date +%s.%N)
(cd "$CL" && ./bmfr) > "$OUT/bmfr-log.txt" 2>&1 ||
  { tail -n 20 "$OUT/bmfr-log.txt" >&2; die "the published code failed (log: $OUT/bmfr-log.txt)"; }
END=$(date +%s.%N)
cp "$WORK/bmfr-changes.diff" "$OUT/"

# ---- convert: one hush frame per output, named as in cameras.json ---------------
for ((i = 0; i < FRAMES; i++)); do
  "$HUSH_BIN" convert "$CL/outputs/output$i.exr" "$OUT/${FILES[i]}" ||
    die "converting output$i.exr failed"
done
cp "$CAMERAS" "$OUT/cameras.json"

KERNELS=$(awk '/^ *Total time in all kernels/ {t = 1} t && /Mean/ {print $3; exit}' \
  "$OUT/bmfr-log.txt")
DEVICE_NAME=$(sed -n 's/^Using device named: //p' "$OUT/bmfr-log.txt")
printf 'published BMFR: %s x %s, %s frames on %s: %s ms per frame in its kernels (mean of frames 1..%s), %.1f s in all (loading, OpenCL compile, writing)\n' \
  "$WIDTH" "$HEIGHT" "$FRAMES" "$DEVICE_NAME" "${KERNELS:-?}" "$((FRAMES - 1))" \
  "$(awk -v a="$START" -v b="$END" 'BEGIN {print b - a}')"
echo "outputs: $OUT (hush eval --seq or --ref)"
