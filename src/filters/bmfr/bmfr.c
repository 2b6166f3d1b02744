/*
 * bmfr.c — the "bmfr" filter: blockwise multi-order feature regression
 * (bmfr-koskela-2019.md, Fig. 2; the published code's choices from
 * papers/NOTES.md "BMFR reference implementation").
 *
 *   I   import -> demodulate by albedo (§3.1) -> reproject (world position
 *       / depth and normal discard tests per bilinear tap, §3.2) -> temporal
 *       accumulation, cumulative then exponential at alpha = 0.2, with a
 *       per-pixel sample count (src/temporal, shared with "accumulate");
 *   II  per block of the displaced grid (blocks.h), in parallel: gather the
 *       G-buffer channels into a block-contiguous buffer, build the
 *       multi-order features scaled to [-1, 1] (features.h), fit them to
 *       the accumulated radiance with stochastic regularisation and an R-only
 *       Householder QR, and take the weighted sum with the noise-free
 *       features (regression.h) — the block never leaves the core's cache;
 *   III second accumulation of the fitted result, cumulative then
 *       exponential at 0.1, through phase I's reprojection plan and sample
 *       counts (§3.5) -> remodulate -> TAA (src/temporal/taa.h, as svgf)
 *       -> the emission added back (emission.h), when it was kept out.
 *
 * Holes (depth <= 0: no surface) take no part in a fit and keep their
 * accumulated radiance.
 *
 * Adaptive temporal weights (A-SVGF, issue 7; parameter temporal_gradients,
 * adaptive.h): both blends take max(alpha_min, 1 / age) per pixel, so the
 * per-pixel weight a(p) of A-SVGF is applied by lowering phase I's ages to
 * min(age, 1 / a(p)) and blending its colour again where they were lowered;
 * phase III reads the lowered ages, and the kept history is shortened, as
 * A-SVGF's history-length reduction does; see docs/bmfr.md.
 *
 * Deterministic and independent of the thread count: every block is fitted
 * on its own and the noise depends on the frame index only.
 */
#include "core/stream.h" /* hush__prefetch */
#include "core/timer.h"   /* hush__now_ms */
#include "filters/albedo.h"
#include "filters/bmfr/adaptive.h"
#include "filters/emission.h"
#include "filters/bmfr/blocks.h"
#include "filters/bmfr/features.h"
#include "filters/bmfr/regression.h"
#include "filters/bmfr/simd.h"
#include "filters/filter.h"
#include "filters/gbuffer.h"
#include "filters/holes.h"
#include "temporal/accumulation.h"
#include "temporal/reproject.h"
#include "temporal/taa.h"

#include <float.h>
#include <omp.h>
#include <stdlib.h>
#include <string.h>

enum {
  P_NONFINITE = 0,
  P_ALPHA,
  P_ALPHA_FITTED,
  P_MAX_AGE,
  P_DEPTH_TOLERANCE,
  P_DEPTH_GRADIENT,
  P_NORMAL_THRESHOLD,
  P_USE_ID,
  P_FALLBACK_3X3,
  P_DEMODULATE,
  P_BLOCK_SIZE,
  P_DISPLACE,
  P_NOISE,
  P_REFINE,
  P_OUTLIER,
  P_NORMAL_EXP1,
  P_NORMAL_EXP2,
  P_POSITION_EXP1,
  P_POSITION_EXP2,
  P_DEPTH_EXP1,
  P_DEPTH_EXP2,
  P_ALBEDO_EXP1,
  P_ALBEDO_EXP2,
  P_GRADIENTS,
  P_TAA,
  P_TAA_ALPHA,
  P_EMISSION_BYPASS,
  P_TEMPORAL_GRADIENTS,
  P_GRADIENT_ITERATIONS,
  P_GRADIENT_SIGMA_L,
  P_GRADIENT_EXPONENT,
  P_HISTORY_RULE,
  P_GRADIENT_THRESHOLD,
  P_COUNT
};

/* The gradient reconstruction's depth and normal weights: svgf's defaults
 * (bmfr has no sigma_z / sigma_n of its own). */
#define GRADIENT_SIGMA_Z 1.0f
#define GRADIENT_SIGMA_N 128.0f

static const char *const history_rule_names[] = {"schied", "higginson"};

#define EXPONENT_DOC(what)                                                                 \
  "features " what ": each channel, scaled to [-1, 1] per block, raised to this exponent " \
  "(non-integer allowed; 0: none)"

static const hush_param_info bmfr_params[P_COUNT] = {
    HUSH_PARAM_NONFINITE_ENTRY,
    {"alpha", HUSH_PARAM_FLOAT, 0.2, 0.0, 1.0,
     "phase I: minimum weight of the new 1 spp frame, alpha = max(alpha, 1/sample_count)", NULL},
    {"alpha_fitted", HUSH_PARAM_FLOAT, 0.1, 0.0, 1.0,
     "phase III: minimum weight of the new fitted frame, max(alpha_fitted, 1/sample_count)",
     NULL},
    {"max_age", HUSH_PARAM_INT, 255, 1, 65535,
     "sample count cap (the published code keeps an 8-bit count)", NULL},
    HUSH_PARAM_DEPTH_TOLERANCE_ENTRY,
    HUSH_PARAM_DEPTH_GRADIENT_ENTRY,
    HUSH_PARAM_NORMAL_THRESHOLD_ENTRY,
    HUSH_PARAM_USE_ID_ENTRY,
    {"fallback_3x3", HUSH_PARAM_BOOL, 0, 0, 1,
     "search the 3x3 neighbourhood when no bilinear tap is consistent (the paper: off)", NULL},
    HUSH_PARAM_DEMODULATE_ENTRY,
    {"block_size", HUSH_PARAM_INT, 32, 16, 64, "side of the square fitting blocks in pixels",
     NULL},
    {"displace", HUSH_PARAM_BOOL, 1, 0, 1,
     "move the block grid every frame by one of 16 offsets (period 16 frames)", NULL},
    {"noise", HUSH_PARAM_FLOAT, 0.01, 0.0, 1.0,
     "stochastic regularisation: features get zero-mean uniform noise in [-noise, noise] for "
     "the factorisation",
     NULL},
    {"refine", HUSH_PARAM_INT, 2, 0, 4,
     "steps of iterative refinement of the block weights towards the noise-free fit, undoing "
     "the noise's errors-in-variables bias (0: the paper's plain solve)",
     NULL},
    {"outlier", HUSH_PARAM_FLOAT, 8.0, 0.0, 1e6,
     "bright patches (pixels above this times their block's mean luminance, with 3 such "
     "neighbours) keep their accumulated radiance and stay out of the fit, which would spread a "
     "visible light over the block; isolated fireflies stay in (0: off, as the paper)",
     NULL},
    {"normal_exponent1", HUSH_PARAM_FLOAT, 1.0, 0.0, 16.0, EXPONENT_DOC("from the shading normal"),
     NULL},
    {"normal_exponent2", HUSH_PARAM_FLOAT, 0.0, 0.0, 16.0,
     "a second shading normal feature set (0: none)", NULL},
    {"position_exponent1", HUSH_PARAM_FLOAT, 1.0, 0.0, 16.0,
     EXPONENT_DOC("from the world position (needs 'position')"), NULL},
    {"position_exponent2", HUSH_PARAM_FLOAT, 2.0, 0.0, 16.0,
     "a second world position feature set (0: none)", NULL},
    {"depth_exponent1", HUSH_PARAM_FLOAT, 0.0, 0.0, 16.0, EXPONENT_DOC("from the view depth"), NULL},
    {"depth_exponent2", HUSH_PARAM_FLOAT, 0.0, 0.0, 16.0, "a second view depth feature (0: none)",
     NULL},
    {"albedo_exponent1", HUSH_PARAM_FLOAT, 0.0, 0.0, 16.0, EXPONENT_DOC("from the albedo (needs 'albedo')"),
     NULL},
    {"albedo_exponent2", HUSH_PARAM_FLOAT, 0.0, 0.0, 16.0,
     "a second albedo feature set (0: none)", NULL},
    {"gradients", HUSH_PARAM_BOOL, 0, 0, 1,
     "add the block-local horizontal and vertical gradient features (paper §5)", NULL},
    {"taa", HUSH_PARAM_BOOL, 1, 0, 1,
     "finish with temporal anti-aliasing (3x3 YCoCg clamp, tone-mapped), as the paper", NULL},
    {"taa_alpha", HUSH_PARAM_FLOAT, 0.2, 0.01, 1.0,
     "with taa: weight of the current frame in the TAA blend", NULL},
    {"emission_bypass", HUSH_PARAM_BOOL, 1, 0, 1,
     "with 'emission' bound: fit color minus emission and add the emission back, so lights seen "
     "directly never enter a block's fit (cornell-box relMSE 0.084 -> 0.004; docs/bmfr.md)",
     NULL},
    {"temporal_gradients", HUSH_PARAM_BOOL, 0, 0, 1,
     "adaptive BMFR: A-SVGF's temporal gradients (image 'gradient', required when on) shorten "
     "phase I's history where the shading changed, and phase III reuses those counts "
     "(docs/asvgf.md)",
     NULL},
    {"gradient_iterations", HUSH_PARAM_INT, 3, 0, HUSH_GRADIENT_MAX_ITERATIONS,
     "with temporal_gradients: a-trous levels reconstructing the gradient on the 3x3-stratum "
     "grid, guided by depth and normal (0: the raw per-stratum gradient), as asvgf",
     NULL},
    {"gradient_sigma_l", HUSH_PARAM_FLOAT, 4.0, 1e-6, 1e6,
     "with temporal_gradients: relative luminance weight of the reconstruction, as asvgf", NULL},
    {"gradient_exponent", HUSH_PARAM_FLOAT, 1.0, 0.01, 100.0,
     "with temporal_gradients: lambda = min(|delta| / max(current, previous), 1)^exponent (1: "
     "Schied 2018; 2: Higginson 2023)",
     NULL},
    {"history_rule", HUSH_PARAM_ENUM, 0, 0, 1,
     "with temporal_gradients: schied, a = (1 - lambda) max(alpha, 1/N) + lambda, or higginson, "
     "N' = min((N - 1)(1 - lambda)^10 + 1, max_age); the count becomes min(N, 1/a), as asvgf",
     history_rule_names},
    {"gradient_threshold", HUSH_PARAM_FLOAT, 0.0, 0.0, 0.99,
     "with temporal_gradients: noise floor of the relative gradient, as asvgf", NULL},
};

enum {
  I_COLOR = 0,
  I_DEPTH,
  I_NORMAL,
  I_POSITION,
  I_ID,
  I_MOTION,
  I_ALBEDO,
  I_EMISSION,
  I_GRADIENT,
  I_SPP,
  I_OUTPUT,
  I_FITTED,
  I_HISTORY_LENGTH,
  I_COUNT
};

static const hush_image_info bmfr_images[I_COUNT] = {
    HUSH_IMAGE_COLOR_ENTRY,
    {"depth", HUSH_IMAGE_INPUT, 1, 1, "linear view depth (<= 0: no surface)"},
    HUSH_IMAGE_NORMAL_ENTRY,
    {"position", HUSH_IMAGE_INPUT, 0, 3,
     "world-space position: a feature (required while a position exponent is set) and the "
     "camera reprojection"},
    HUSH_IMAGE_ID_ENTRY,
    HUSH_IMAGE_MOTION_ENTRY,
    {"albedo", HUSH_IMAGE_INPUT, 0, 3, "first-hit albedo, for demodulation (else 1)"},
    {"emission", HUSH_IMAGE_INPUT, 0, 3,
     "radiance the camera sees directly at the first hit (lights, sky): kept out of the fit "
     "(color - emission), added back after TAA"},
    {"gradient", HUSH_IMAGE_INPUT, 0, 3,
     "temporal gradient samples (`hush render --gradients`), read with temporal_gradients on: "
     "per 3x3 stratum, at its top-left pixel, the current and previous luminance and the "
     "landing index 0..8 (-1: none)"},
    {"spp", HUSH_IMAGE_INPUT, 0, 1,
     "samples per pixel; 0 marks a hole (`hush render --spp-fraction`): it keeps its "
     "accumulated history and gets the fit; never sampled, it stays out of the fit and is "
     "filled from around (docs/holes.md)"},
    {"output", HUSH_IMAGE_OUTPUT, 1, 3, "filtered radiance"},
    {"fitted", HUSH_IMAGE_OUTPUT, 0, 3,
     "phase II result: this frame's block fit of the accumulated (demodulated) radiance"},
    {"history_length", HUSH_IMAGE_OUTPUT, 0, 1, "accumulated samples per pixel (phase I)"},
};

static const hush_filter_class_info bmfr_info = {
    "bmfr",
    "blockwise multi-order feature regression: accumulation, per-block feature fit, "
    "accumulation, TAA",
    "bmfr-koskela-2019.md §3 (Fig. 2); papers/NOTES.md (published code)",
    bmfr_params,
    P_COUNT,
    bmfr_images,
    I_COUNT,
};

/* Per-thread block scratch, in floats, for blocks of ld rows (ld = B^2
 * rounded up to 16): base channels, features, augmented matrix, radiance,
 * mask, fit, a spare column and the outlier test's padded grid ((B + 2)^2
 * <= 2 ld). */
#define SCRATCH_COLUMNS                                                                  \
  (BMFR_BASE_COUNT + BMFR_MAX_FEATURES + (BMFR_MAX_FEATURES + BMFR_CHANNELS) + BMFR_CHANNELS + \
   1 + BMFR_CHANNELS + 3)
#define MAX_LD (64 * 64 + 64) /* four blocks of 32x32 with their ld (1040), one of 64x64 */

/* The phases fused_frame runs block row by block row, timed per thread
 * (FUSED_STRIDE doubles apart: a cache line each). */
enum { FUSED_ACCUMULATE, FUSED_FIT, FUSED_ACCUMULATE_FITTED, FUSED_TAA, FUSED_PHASES };
#define FUSED_STRIDE 8

/* One block row of the fused frame (a unit): its image rows end at end
 * (they start at the previous unit's), it reads rows of units first ..
 * itself, and its flags (set once a frame, read by the other threads):
 * rows imported, rows built and blended, fit open to other threads,
 * strips taken and fitted, phase III done. */
typedef struct fused_row {
  int end, first;
  int done_import, done, fit_open, strip_next, strip_done, done3;
} fused_row;

typedef struct bmfr_state {
  hush_reprojector rp;
  hush_accum acc;      /* phase I */
  hush_planar color;   /* this frame, demodulated in place */
  hush_planar fitted;  /* phase II result */
  hush_planar fhist[2]; /* phase III results (ping-pong: the blend reads one, writes the other) */
  int flatest;
  float *noise;        /* BMFR_MAX_FEATURES columns of MAX_LD */
  float *scratch;      /* per thread: SCRATCH_COLUMNS columns of MAX_LD */
  int threads;
  /* allocated on first use: */
  hush_planar albedo;
  hush_planar emission; /* imported emission, then the output (emission.h) */
  hush_emission_history eh; /* the emission added back, accumulated */
  hush_gbuffer_inputs gin;
  hush_taa taa;
  bmfr_adaptive ad;    /* temporal_gradients */
  fused_row *rows;  /* fused_frame's, per block row */
  /* fused_frame's unit rows, UNIT_ROWS per thread: spare rows for the
   * colour of the rows above a unit (unit_rows_above), the albedo of the
   * unit it runs (unit_rows_cap rows) */
  hush_planar *unit_rows;
  int unit_rows_cap, unit_rows_above;
  double *phase_ms; /* fused_frame's, per thread */
  size_t *unit_bad; /* fused_frame's, per thread */
} bmfr_state;

/* Unit rows per thread (bmfr_state, fused_frame): the spare colour rows
 * (UNIT_SPARE), the albedo rows (UNIT_ALBEDO). */
enum { UNIT_SPARE, UNIT_ALBEDO, UNIT_ROWS };

static void unit_rows_free(bmfr_state *st) {
  if (st->unit_rows)
    for (int k = 0; k < UNIT_ROWS * st->threads; k++) hush__planar_free(&st->unit_rows[k]);
  free(st->unit_rows);
  st->unit_rows = NULL;
  st->unit_rows_cap = st->unit_rows_above = 0;
}

static void bmfr_destroy(void *state) {
  bmfr_state *st = state;
  if (!st) return;
  hush__reprojector_free(&st->rp);
  hush__accum_free(&st->acc);
  hush__planar_free(&st->color);
  hush__planar_free(&st->fitted);
  hush__planar_free(&st->fhist[0]);
  hush__planar_free(&st->fhist[1]);
  hush__free_floats(st->noise);
  hush__free_floats(st->scratch);
  hush__planar_free(&st->albedo);
  hush__planar_free(&st->emission);
  hush__emission_history_free(&st->eh);
  hush__gbuffer_inputs_free(&st->gin);
  hush__taa_free(&st->taa);
  bmfr_adaptive_free(&st->ad);
  free(st->rows);
  unit_rows_free(st);
  free(st->phase_ms);
  free(st->unit_bad);
  free(st);
}

static hush_status bmfr_create(hush_filter f, void **state) {
  bmfr_state *st = calloc(1, sizeof *st);
  if (!st) return hush__fail(f->device, HUSH_ERROR_OUT_OF_MEMORY, "bmfr: out of memory");
  const uint32_t W = f->width, H = f->height;
  st->threads = hush__filter_threads(f);
  hush_status s = hush__reprojector_init(f->device, &st->rp, W, H);
  if (!s) s = hush__accum_init_color(f->device, &st->acc, 3, W, H);
  if (!s) s = hush__planar_init(f->device, &st->color, 3, W, H);
  if (!s) s = hush__planar_init(f->device, &st->fitted, 3, W, H);
  if (!s) s = hush__planar_init(f->device, &st->fhist[0], 3, W, H);
  if (!s) s = hush__planar_init(f->device, &st->fhist[1], 3, W, H);
  if (!s) {
    st->noise = hush__alloc_floats((size_t)BMFR_MAX_FEATURES * MAX_LD);
    st->scratch = hush__alloc_floats((size_t)st->threads * SCRATCH_COLUMNS * MAX_LD);
    /* block rows: at most H / 16 + 1 (the smallest blocks, displaced) */
    const size_t units = (size_t)H / 16 + 2;
    st->rows = malloc(units * sizeof *st->rows);
    st->phase_ms = calloc((size_t)st->threads * FUSED_STRIDE, sizeof *st->phase_ms);
    st->unit_bad = calloc((size_t)st->threads * FUSED_STRIDE, sizeof *st->unit_bad);
    if (!st->noise || !st->scratch || !st->rows || !st->phase_ms || !st->unit_bad)
      s = hush__fail(f->device, HUSH_ERROR_OUT_OF_MEMORY, "bmfr: out of memory");
  }
  if (s) {
    bmfr_destroy(st);
    return s;
  }
  *state = st;
  return HUSH_OK;
}

/* ---- phase II: the block fit ------------------------------------------------ */

/* What every block of a frame reads. */
typedef struct fit_frame {
  bmfr_grid grid;
  const bmfr_feature_set *set;
  const float *depth;
  const float *base[BMFR_BASE_COUNT]; /* image planes of the gathered channels, NULL: unused */
  const float *z[BMFR_CHANNELS];      /* accumulated radiance */
  const float *noise;
  float *out[BMFR_CHANNELS];          /* fitted radiance */
  int refine;                         /* refinement steps of the fit */
  float outlier;                      /* outlier ratio, 0: off */
  int n;                              /* B^2 */
  size_t ld;
} fit_frame;

/* Where a block lies: its first pixel (x0, y0; outside the image for a
 * block of the border, whose outside pixels are mirrored), the image
 * columns and rows of each of its pixels (xs, ys), and the range of its
 * columns (c0..c1-1) and rows (r0..r1-1) inside the image. */
typedef struct block_geom {
  int x0, y0, c0, c1, r0, r1;
  int xs[64], ys[64];
} block_geom;

static void block_geom_of(const bmfr_grid *grid, int bx, int by, block_geom *g) {
  const int B = grid->block, W = grid->width, H = grid->height;
  g->x0 = grid->x0 + bx * B;
  g->y0 = grid->y0 + by * B;
  for (int i = 0; i < B; i++) {
    g->xs[i] = hush__bmfr_mirror(g->x0 + i, W);
    g->ys[i] = hush__bmfr_mirror(g->y0 + i, H);
  }
  g->c0 = g->x0 < 0 ? -g->x0 : 0;
  g->c1 = g->x0 + B > W ? W - g->x0 : B;
  g->r0 = g->y0 < 0 ? -g->y0 : 0;
  g->r1 = g->y0 + B > H ? H - g->y0 : B;
}

/*
 * The pixels of `count` side-by-side blocks of one block row (geometry g)
 * from plane into column `col` of each block's scratch (blocks `span`
 * floats apart): dst[r B + c] = plane[ys[r] W + xs[c]]. Row by row across
 * the blocks, so that each image row is read as one run of count B pixels
 * (block by block, the 32 pieces of 128 bytes of a block come from 32
 * pages and leave the hardware prefetcher nothing to follow).
 */
#define GATHER_AHEAD 4
static void gather_strip(const float *plane, int W, const block_geom *g, int count, int B,
                         float *scratch, size_t span, size_t col) {
  for (int r = 0; r < B; r++) {
    const float *row = plane + (size_t)g[0].ys[r] * W; /* one block row: the same ys */
    /* the run of the row GATHER_AHEAD rows further, line by line: each
     * row's run is a new stream of 8 lines, too short for the hardware
     * prefetchers to pick up (fit stage 13.0-13.25 -> 12.55-13.0 ms on 2
     * threads, 24.2-25.0 -> 23.5-24.3 on one; 1280x720, Zen 3, alternated
     * runs; 8 rows ahead the same). */
    if (r + GATHER_AHEAD < B) {
      const float *ahead = plane + (size_t)g[0].ys[r + GATHER_AHEAD] * W;
      const int xa = g[0].x0 + g[0].c0, xe = g[count - 1].x0 + g[count - 1].c1;
      for (int x = xa; x < xe + 16; x += 16)
        hush__prefetch(ahead, (ptrdiff_t)x * (ptrdiff_t)sizeof(float));
    }
    for (int k = 0; k < count; k++) {
      const block_geom *b = &g[k];
      float *restrict d = scratch + (size_t)k * span + col + (size_t)r * B;
      if (B == 32 && b->c0 == 0 && b->c1 == 32) {
        /* the default block inside the image: a copy of known size, inlined */
        memcpy(d, row + b->x0, 32 * sizeof(float));
        continue;
      }
      for (int c = 0; c < b->c0; c++) d[c] = row[b->xs[c]];
      memcpy(d + b->c0, row + b->x0 + b->c0, (size_t)(b->c1 - b->c0) * sizeof(float));
      for (int c = b->c1; c < B; c++) d[c] = row[b->xs[c]];
    }
  }
}

/*
 * Takes bright *patches* out of the fit (mask 0): a pixel whose luminance
 * exceeds ratio times the mean luminance of the block's valid pixels and
 * that has at least 3 such neighbours (of 8, inside the block), twice, the
 * second time with the mean of the pixels left; returns how many stay
 * valid. A least-squares fit spreads a light seen directly over its whole
 * block (paper §8); kept out, such pixels keep their own accumulated
 * radiance, as holes do. An isolated firefly stays in: spreading its
 * energy over the block is the fit's best estimate (it keeps the block's
 * mean), while keeping it raw would keep the error where it is.
 * lum: B^2 floats, pad: (B + 2)^2 floats of scratch.
 */
static int exclude_outliers(float *const z[BMFR_CHANNELS], float *restrict mask, int B,
                            float ratio, int nvalid, float *restrict lum, float *restrict pad) {
  const int n = B * B, P = B + 2;
  const float *restrict r = z[0], *restrict g = z[1], *restrict b = z[2];
  /* lane sums in a fixed order (16 lanes, each summing rows l, l + 16, ..
   * in turn): vectorised and deterministic */
  enum { LANES = 16, SUMS = LANES / VF_LANES };
  float sum[LANES] = {0}, cnt[LANES] = {0};
  /* the luminances, their brightest and the sums in one pass (vectors: a
   * block with none above the limit, the usual one, leaves after it) */
  float brightest = -FLT_MAX;
  {
    const vf c0 = vf_set1(0.2126f), c1 = vf_set1(0.7152f), c2 = vf_set1(0.0722f);
    vf vs[SUMS], vc[SUMS], vb[SUMS];
    for (int k = 0; k < SUMS; k++) {
      vs[k] = vc[k] = (vf){0};
      vb[k] = vf_set1(-FLT_MAX);
    }
    int i = 0;
    for (; i + LANES <= n; i += LANES)
      for (int k = 0; k < SUMS; k++) {
        const int j = i + k * VF_LANES;
        const vf mk = vf_load(mask + j);
        const vf l = mk * (c0 * vf_load(r + j) + c1 * vf_load(g + j) + c2 * vf_load(b + j));
        vf_store(lum + j, l);
        vs[k] += l;
        vc[k] += mk;
        vb[k] = vf_max(vb[k], l);
      }
    for (int k = 0; k < SUMS; k++)
      for (int l = 0; l < VF_LANES; l++) {
        sum[k * VF_LANES + l] = vs[k][l];
        cnt[k * VF_LANES + l] = vc[k][l];
        brightest = vb[k][l] > brightest ? vb[k][l] : brightest;
      }
    for (; i < n; i++) {
      const float l = mask[i] * (0.2126f * r[i] + 0.7152f * g[i] + 0.0722f * b[i]);
      lum[i] = l;
      brightest = l > brightest ? l : brightest;
      sum[0] += l;
      cnt[0] += mask[i];
    }
  }
  for (int pass = 0; pass < 2; pass++) {
    if (pass > 0) { /* the sums again, of the pixels left */
      for (int l = 0; l < LANES; l++) sum[l] = cnt[l] = 0.0f;
      int i = 0;
      for (; i + LANES <= n; i += LANES)
        for (int l = 0; l < LANES; l++) {
          sum[l] += lum[i + l];
          cnt[l] += mask[i + l];
        }
      for (; i < n; i++) {
        sum[0] += lum[i];
        cnt[0] += mask[i];
      }
    }
    float total = 0.0f, count = 0.0f;
    for (int l = 0; l < LANES; l++) {
      total += sum[l];
      count += cnt[l];
    }
    if (!(count > 0.0f)) return 0;
    const float limit = ratio * total / count;
    /* nothing above the limit: the mask stays, and so would a second
     * pass's mean and limit (the luminances are finite) */
    if (!(brightest > limit)) return nvalid;
    if (pass == 0) memset(pad, 0, (size_t)P * P * sizeof *pad);
    /* bright flags on a grid with a zero border, then the neighbour count */
    for (int y = 0; y < B; y++) {
      float *restrict row = pad + (size_t)(y + 1) * P + 1;
      const float *restrict l = lum + (size_t)y * B;
#pragma omp simd
      for (int x = 0; x < B; x++) row[x] = l[x] > limit ? 1.0f : 0.0f;
    }
    brightest = -FLT_MAX;
    for (int y = 0; y < B; y++) {
      const float *restrict up = pad + (size_t)y * P + 1, *restrict mid = up + P,
                            *restrict dn = mid + P;
      float *restrict m = mask + (size_t)y * B, *restrict l = lum + (size_t)y * B;
#pragma omp simd reduction(max : brightest)
      for (int x = 0; x < B; x++) {
        const float around = up[x - 1] + up[x] + up[x + 1] + mid[x - 1] + mid[x + 1] +
                             dn[x - 1] + dn[x] + dn[x + 1];
        const float keep = mid[x] > 0.0f && around >= 3.0f ? 0.0f : m[x];
        m[x] = keep;
        l[x] *= keep;
        brightest = l[x] > brightest ? l[x] : brightest;
      }
    }
    nvalid = 0;
#pragma omp simd reduction(+ : nvalid)
    for (int k = 0; k < n; k++) nvalid += mask[k] > 0.0f;
  }
  return nvalid;
}

/* The columns of a block's scratch (ld floats each; see SCRATCH_COLUMNS). */
typedef struct block_cols {
  float *base, *T, *A, *zb, *mask, *y, *spare;
} block_cols;

static block_cols block_cols_of(float *scratch, size_t ld) {
  block_cols b;
  b.base = scratch;
  b.T = b.base + (size_t)BMFR_BASE_COUNT * ld;
  b.A = b.T + (size_t)BMFR_MAX_FEATURES * ld;
  b.zb = b.A + (size_t)(BMFR_MAX_FEATURES + BMFR_CHANNELS) * ld;
  b.mask = b.zb + (size_t)BMFR_CHANNELS * ld;
  b.y = b.mask + ld;
  b.spare = b.y + (size_t)BMFR_CHANNELS * ld;
  return b;
}

/* The fit of one gathered block (geometry g): depth in spare, radiance in
 * zb, the feature channels in base. A block that spans its columns of the
 * image and has a valid pixel goes straight into the fitted planes (its
 * rows in the image; returns 1): the weighted sum stored where the
 * write-back would have put it, without the round trip through y (the
 * fit stage 3.81 -> 3.71 ms, docs/bmfr.md, thirteenth round). Otherwise
 * leaves the fit in y (where the mask is 1) for fit_strip's write-back. */
static int fit_gathered(const fit_frame *fr, const block_geom *g, block_cols *b) {
  const int B = fr->grid.block, n = fr->n;
  const size_t ld = fr->ld;
  int nvalid = 0;
  for (int i = 0; i < n; i++) {
    b->mask[i] = b->spare[i] > 0.0f ? 1.0f : 0.0f;
    nvalid += b->spare[i] > 0.0f;
  }
  for (size_t i = (size_t)n; i < ld; i++) b->mask[i] = 0.0f;
  float *zc[BMFR_CHANNELS];
  for (int c = 0; c < BMFR_CHANNELS; c++) {
    zc[c] = b->zb + (size_t)c * ld;
    for (size_t i = (size_t)n; i < ld; i++) zc[c][i] = 0.0f; /* the fit reads ld rows */
  }
  if (fr->outlier > 0.0f)
    nvalid = exclude_outliers(zc, b->mask, B, fr->outlier, nvalid, b->spare, b->spare + ld);
  if (fr->set->gradients)
    for (int r = 0; r < B; r++)
      for (int c = 0; c < B; c++) {
        b->base[(size_t)BMFR_BASE_GRADIENT * ld + (size_t)r * B + c] = (float)c;
        b->base[(size_t)(BMFR_BASE_GRADIENT + 1) * ld + (size_t)r * B + c] = (float)r;
      }
  if (nvalid > 0) {
    const int count = fr->set->count;
    float coef[BMFR_CHANNELS][BMFR_MAX_FEATURES];
    hush__bmfr_features_block(fr->set, b->base, b->mask, n, ld, b->T, b->spare);
    hush__bmfr_fit(b->T, count, (const float *const *)zc, fr->noise, b->mask, n, nvalid, ld, b->A,
                   fr->refine, coef);
    if (B % (2 * VF_LANES) == 0 && g->c0 == 0 && g->c1 == B) {
      const int W = fr->grid.width;
      const size_t first = (size_t)(g->y0 + g->r0) * W + (size_t)g->x0;
      float *const out[BMFR_CHANNELS] = {fr->out[0] + first, fr->out[1] + first,
                                         fr->out[2] + first};
      hush__bmfr_synthesize_rows(b->T, count, ld, B, (const float(*)[BMFR_MAX_FEATURES])coef,
                                 b->mask, (const float *const *)zc, g->r0, g->r1, out, (size_t)W);
      return 1;
    }
    float *yc[BMFR_CHANNELS];
    for (int c = 0; c < BMFR_CHANNELS; c++) yc[c] = b->y + (size_t)c * ld;
    hush__bmfr_synthesize(b->T, count, n, ld, (const float(*)[BMFR_MAX_FEATURES])coef, yc);
  }
  return 0;
}

/*
 * Asks for the lines of the fitted planes that block g's write-back will
 * store into, before the block is fitted: its rows of 32 floats at a 5 KiB
 * stride (1280 wide) cover three lines each, which the hardware
 * prefetchers do not foresee, and a store to an absent line waits for it
 * to be read. Fit stage 7.9 -> 7.65 ms (1280x720, 2 threads, Zen 5,
 * alternated runs); the same bits.
 */
static void prefetch_write_back(const fit_frame *fr, const block_geom *g) {
  const int W = fr->grid.width;
  for (int r = g->r0; r < g->r1; r++) {
    const size_t first = (size_t)(g->y0 + r) * W + (size_t)(g->x0 + g->c0);
    const size_t last = first + (size_t)(g->c1 - g->c0) - 1;
    for (int c = 0; c < BMFR_CHANNELS; c++) {
      /* each line from the first pixel's to the last pixel's */
      const uintptr_t a = (uintptr_t)(fr->out[c] + first) & ~(uintptr_t)63;
      const uintptr_t e = (uintptr_t)(fr->out[c] + last);
      for (uintptr_t p = a; p <= e; p += 64) __builtin_prefetch((const void *)p, 1, 3);
    }
  }
}

/* Blocks per strip: side by side in a block row, gathered and written
 * back row by row across the strip (gather_strip). */
#define STRIP_MAX 4

/* The blocks bx0 .. bx0 + count - 1 of block row by: gathered together,
 * fitted one by one, written back together (each block's own pixels, not
 * its mirrored margin; holes and outliers keep their accumulated radiance). */
static void fit_strip(const fit_frame *fr, int bx0, int count, int by, float *scratch) {
  const int B = fr->grid.block, W = fr->grid.width;
  const size_t ld = fr->ld, span = (size_t)SCRATCH_COLUMNS * ld;
  block_geom g[STRIP_MAX];
  block_cols b[STRIP_MAX];
  for (int k = 0; k < count; k++) {
    block_geom_of(&fr->grid, bx0 + k, by, &g[k]);
    b[k] = block_cols_of(scratch + (size_t)k * span, ld);
    /* the features and the augmented matrix live only while the block is
     * fitted: one set for the strip, kept in L2 from block to block */
    b[k].T = b[0].T;
    b[k].A = b[0].A;
  }
  const size_t base_col = (size_t)(b[0].base - scratch), zb_col = (size_t)(b[0].zb - scratch),
               spare_col = (size_t)(b[0].spare - scratch);
  gather_strip(fr->depth, W, g, count, B, scratch, span, spare_col);
  for (int c = 0; c < BMFR_CHANNELS; c++)
    gather_strip(fr->z[c], W, g, count, B, scratch, span, zb_col + (size_t)c * ld);
  for (int k = 0; k < BMFR_BASE_COUNT; k++)
    if (fr->base[k]) gather_strip(fr->base[k], W, g, count, B, scratch, span, base_col + (size_t)k * ld);
  int direct[STRIP_MAX];
  for (int k = 0; k < count; k++) {
    prefetch_write_back(fr, &g[k]);
    direct[k] = fit_gathered(fr, &g[k], &b[k]);
  }
  for (int r = g[0].r0; r < g[0].r1; r++) {
    const size_t row = (size_t)(g[0].y0 + r) * W;
    const int i0 = r * B;
    for (int c = 0; c < BMFR_CHANNELS; c++)
      for (int k = 0; k < count; k++) {
        if (direct[k]) continue;
        float *restrict dst = fr->out[c] + row + g[k].x0;
        const float *restrict src = b[k].y + (size_t)c * ld + i0,
                              *restrict zz = b[k].zb + (size_t)c * ld + i0,
                              *restrict mk = b[k].mask + i0;
        if (B == 2 * VF_LANES && g[k].c0 == 0 && g[k].c1 == B) {
          /* the default block inside the image: two vectors, no checks */
          for (int v = 0; v < 2; v++) {
            const vf m = vf_load(mk + v * VF_LANES);
            vf_store(dst + v * VF_LANES, vf_select(m > (vf){0}, vf_load(src + v * VF_LANES),
                                                   vf_load(zz + v * VF_LANES)));
          }
          continue;
        }
        for (int x = g[k].c0; x < g[k].c1; x++) dst[x] = mk[x] > 0.0f ? src[x] : zz[x];
      }
  }
}

/* Blocks per strip: as many as the per-thread scratch holds (MAX_LD rows a
 * column: 4 blocks of 32x32), at most STRIP_MAX. */
static int strip_blocks(const fit_frame *fr) {
  const int per = (int)(MAX_LD / fr->ld);
  return per < 1 ? 1 : per > STRIP_MAX ? STRIP_MAX : per;
}

static void fit_frame_blocks(const fit_frame *fr, float *scratch, int threads) {
  const int nx = fr->grid.nx, ny = fr->grid.ny;
  /* as many blocks per strip as the per-thread scratch holds (MAX_LD rows
   * per column: 4 blocks of 32x32) */
  const int per = strip_blocks(fr);
  const int strips_x = (nx + per - 1) / per;
  const size_t per_thread = (size_t)SCRATCH_COLUMNS * MAX_LD;
#pragma omp parallel num_threads(threads)
  {
    float *mine = scratch + (size_t)omp_get_thread_num() * per_thread;
#pragma omp for schedule(dynamic, 1)
    for (int s = 0; s < strips_x * ny; s++) {
      const int bx0 = (s % strips_x) * per, by = s / strips_x;
      fit_strip(fr, bx0, nx - bx0 < per ? nx - bx0 : per, by, mine);
    }
  }
}

/* ---- phases I and II together, block row by block row --------------------------- */

/* A waiting thread's busy loop: the pause keeps it from flooding the core
 * with speculative loads of the flag. */
static inline void spin_pause(void) {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_ia32_pause();
#endif
}

/*
 * Phases I to III and TAA, block row by block row (docs/bmfr.md, "Block
 * row by block row"): unit u imports its rows of the inputs, builds and
 * blends phase I for them, fits block row u, then runs phase III and TAA
 * on its image rows. The rows a block row reads (its own and, at the
 * image's top and bottom, the mirrored ones) all belong to units <= u, and
 * each unit waits only for the earlier units it reads, which the threads
 * took before it: no order of threads can deadlock. Every row and block is
 * computed on its own: the same bits as the phases one after the other.
 */
typedef struct fused_frame {
  const fit_frame *fr;
  const hush_reproject_job *job;
  hush_reproject_plan *plan;
  const hush_accum *acc;
  const float *const *sample;
  const hush_accum_params *ap;
  fused_row *rows;     /* per unit */
  int units;
  /* phase III, per block row after its fit (NULL prev3: no history) */
  const float *const *prev3;
  float *const *out3;
  const float *age;
  float alpha3;
  /* TAA (NULL: none), per block row after phase III's rows around it */
  const hush_taa_job *taa;
  /* per thread (FUSED_STRIDE apart: a cache line each), the milliseconds
   * spent in each phase (FUSED_PHASES), for the stage table */
  double *phase_ms;
  /* the demodulated colour and the albedo imported by each unit for its
   * rows (colour NULL: imported before), their NaN/Inf counts per thread
   * (FUSED_STRIDE apart) */
  const hush_image_view *colour, *albedo_view;
  hush_planar *colour_dst, *albedo_dst;
  /* the 'fitted' view (NULL: not bound), exported block row by block row
   * (the fit goes into phase III's output, blended over right after) */
  const hush_image_view *fit_view;
  /* NULL, or per thread (UNIT_ROWS me + UNIT_SPARE, UNIT_ALBEDO) spare
   * rows for the colour of the rows above its unit, and its unit's albedo
   * rows (unit_first_row's on): the albedo goes there instead, kept in the
   * caches for TAA, and the colour into the blend's output rows */
  hush_planar *unit_rows;
  /* the G-buffer imported by each unit (NULL: imported before): its rows
   * moved one down (the plan's depth slopes read the rows above and
   * below) */
  const hush_gbuffer_import_job *gbuffer;
  size_t *bad;
  int strips, per; /* a unit's fit: strips of per blocks */
} fused_frame;

static const char *const fused_stage_names[FUSED_PHASES] = {"accumulate", "fit",
                                                            "accumulate_fitted", "taa"};

/* The units' rows (end) and the first unit each one reads (first). */
static void fused_units(const bmfr_grid *grid, fused_row *rows) {
  const int B = grid->block, H = grid->height;
  int end = 0;
  for (int u = 0; u < grid->ny; u++) {
    int lo = H, hi = 0;
    for (int r = 0; r < B; r++) {
      const int y = hush__bmfr_mirror(grid->y0 + u * B + r, H);
      lo = y < lo ? y : lo;
      hi = y + 1 > hi ? y + 1 : hi;
    }
    int natural = grid->y0 + (u + 1) * B;
    natural = natural > H ? H : natural;
    end = end > natural ? end : natural;
    end = end > hi ? end : hi;
    rows[u].end = u == grid->ny - 1 ? H : end;
    int v = 0;
    while (v < u && rows[v].end <= lo) v++;
    rows[u].first = v;
  }
}

/* Fits the next unclaimed strip of unit u's block row, if any (returns 0
 * when none is left). Strips are claimed one at a time, so a thread with no
 * block row left can take some of the last rows' (fused_frame_run): without
 * it, one thread waited 0.13-0.33 ms a frame for the other's last row. */
static int fused_fit_strip(const fused_frame *ff, int u, float *scratch) {
  const int s = __atomic_fetch_add(&ff->rows[u].strip_next, 1, __ATOMIC_RELAXED);
  if (s >= ff->strips) return 0;
  const fit_frame *fr = ff->fr;
  const int bx0 = s * ff->per, nx = fr->grid.nx;
  fit_strip(fr, bx0, nx - bx0 < ff->per ? nx - bx0 : ff->per, u, scratch);
  __atomic_fetch_add(&ff->rows[u].strip_done, 1, __ATOMIC_RELEASE);
  return 1;
}

/* The first row of the inputs' colour and albedo that unit u reads: its
 * own first row, or the two rows above its block row that TAA's box reads,
 * if earlier. */
static int unit_first_row(const bmfr_grid *grid, const fused_row *rows, int u) {
  if (u == 0) return 0;
  const int y0 = rows[u - 1].end;
  int a0 = grid->y0 + u * grid->block - 2;
  a0 = a0 < 0 ? 0 : a0;
  return a0 < y0 ? a0 : y0;
}

/* Rows y0 .. y0 + n - 1 of v as a view of their own. */
static hush_image_view view_rows(const hush_image_view *v, int y0, int n) {
  hush_image_view r = *v;
  r.row_stride = hush__view_row_stride(v);
  r.byte_offset += (size_t)y0 * r.row_stride;
  r.height = (uint32_t)n;
  return r;
}

/* Rows y0 .. y0 + n - 1 of p as a planar image of their own. */
static hush_planar planar_rows(const hush_planar *p, int y0, int n) {
  hush_planar r = *p;
  for (int c = 0; c < p->channels; c++) r.plane[c] = p->plane[c] + (size_t)y0 * p->width;
  r.height = (uint32_t)n;
  return r;
}

/* Unit u on thread me (its scratch and TAA ring); each phase's time (the
 * waits included in the phase that waits) into its phase_ms. */
static void fused_unit(const fused_frame *ff, int u, int me, float *scratch) {
  const fit_frame *fr = ff->fr;
  double *ms = ff->phase_ms + (size_t)me * FUSED_STRIDE;
  double t0 = hush__now_ms();
  fused_row *rows = ff->rows;
  const int y0 = u ? rows[u - 1].end : 0, y1 = rows[u].end;
  /* the unit's rows of the inputs: read while the other thread computes
   * (the passes over the frame before were bound by memory alone) */
  if (ff->gbuffer) {
    const int H = fr->grid.height;
    /* (a block row may already end at the image's last row: mirroring
     * extends the first rows' units, and small images have few rows) */
    const int g0 = u ? y0 + 1 : 0, g1 = u == ff->units - 1 || y1 + 1 > H ? H : y1 + 1;
    ff->bad[(size_t)me * FUSED_STRIDE] += hush__gbuffer_import_rows(ff->gbuffer, g0, g1);
    __atomic_store_n(&rows[u].done_import, 1, __ATOMIC_RELEASE);
  }
  const float *const *sample = ff->sample;
  const hush_taa_job *taa = ff->taa;
  hush_taa_job unit_taa;
  if (ff->colour && ff->unit_rows) {
    /* the albedo into the thread's unit rows, cached for TAA; the
     * demodulated colour into the blend's own output rows, which it blends
     * in place (each pixel's sample is read before its result is written):
     * imported into the frame's planes, both went out to memory and came
     * back, and rows of their own were one more set of lines to keep */
    hush_planar *albedo = &ff->unit_rows[UNIT_ROWS * me + UNIT_ALBEDO];
    const hush_planar *out = &ff->acc->color[1 - ff->acc->latest];
    const int a0 = unit_first_row(&fr->grid, rows, u);
    if (a0 < y0) {
      /* the rows above the unit's own that TAA's box reads: their albedo
       * (the colour into spare rows; their NaN/Inf counted again, which
       * changes nothing) */
      const hush_image_view cv = view_rows(ff->colour, a0, y0 - a0),
                            av = view_rows(ff->albedo_view, a0, y0 - a0);
      ff->bad[(size_t)me * FUSED_STRIDE] += hush__import_albedo_demodulated_rows(
          &cv, &ff->unit_rows[UNIT_ROWS * me + UNIT_SPARE], &av, albedo, 0, y0 - a0, 0);
    }
    const hush_image_view cv = view_rows(ff->colour, y0, y1 - y0),
                          av = view_rows(ff->albedo_view, y0, y1 - y0);
    hush_planar own = planar_rows(out, y0, y1 - y0),
                own_albedo = planar_rows(albedo, y0 - a0, y1 - y0);
    ff->bad[(size_t)me * FUSED_STRIDE] +=
        hush__import_albedo_demodulated_rows(&cv, &own, &av, &own_albedo, 0, y1 - y0, 0);
    sample = (const float *const *)out->plane;
    if (taa) {
      unit_taa = *taa;
      unit_taa.albedo = (const float *const *)albedo->plane;
      unit_taa.albedo_row0 = a0;
      taa = &unit_taa;
    }
  } else if (ff->colour) {
    ff->bad[(size_t)me * FUSED_STRIDE] += hush__import_albedo_demodulated_rows(
        ff->colour, ff->colour_dst, ff->albedo_view, ff->albedo_dst, y0, y1, 1);
  }
  if (ff->gbuffer && u > 0) /* rows y0 - 1 and y0 */
    while (!__atomic_load_n(&rows[u - 1].done_import, __ATOMIC_ACQUIRE)) spin_pause();
  hush__reproject_rows(ff->job, ff->plan, y0, y1);
  hush__accum_blend_rows(ff->acc, ff->plan, sample, ff->ap, y0, y1, 0);
  __atomic_store_n(&rows[u].done, 1, __ATOMIC_RELEASE);
  double t1 = hush__now_ms();
  ms[FUSED_ACCUMULATE] += t1 - t0;
  for (int v = rows[u].first; v < u; v++)
    while (!__atomic_load_n(&rows[v].done, __ATOMIC_ACQUIRE)) spin_pause();
  /* the fit's strips, shared with a thread that has no block row left */
  __atomic_store_n(&rows[u].fit_open, 1, __ATOMIC_RELEASE);
  while (fused_fit_strip(ff, u, scratch)) {
  }
  while (__atomic_load_n(&rows[u].strip_done, __ATOMIC_ACQUIRE) < ff->strips) spin_pause();
  t0 = hush__now_ms();
  ms[FUSED_FIT] += t0 - t1;
  const int B = fr->grid.block, H = fr->grid.height;
  int r0 = fr->grid.y0 + u * B, r1 = r0 + B;
  r0 = r0 < 0 ? 0 : r0;
  r1 = r1 > H ? H : r1;
  if (ff->fit_view) /* the block row's fit, before phase III blends over it */
    for (int y = r0; y < r1; y++) {
      const size_t i = (size_t)y * (size_t)fr->grid.width;
      const float *const in[3] = {fr->out[0] + i, fr->out[1] + i, fr->out[2] + i};
      hush__view_export_span(in, 3, ff->fit_view, (uint32_t)y, 0, (uint32_t)fr->grid.width);
    }
  /* in place (fr->out is out3); with TAA next, phase III's rows stay in
   * the caches for it */
  hush__temporal_blend_range(ff->plan, ff->prev3, (const float *const *)fr->out, BMFR_CHANNELS,
                             ff->age, ff->alpha3, ff->out3, r0, r1, taa == NULL);
  t1 = hush__now_ms();
  ms[FUSED_ACCUMULATE_FITTED] += t1 - t0;
  if (!taa) return;
  /* TAA's rows r0 - 1 .. r1 - 2: its 3x3 box reads phase III's rows r0 - 2
   * .. r1 - 1, the first two of the block row above (at least two rows) */
  __atomic_store_n(&rows[u].done3, 1, __ATOMIC_RELEASE);
  if (u > 0)
    while (!__atomic_load_n(&rows[u - 1].done3, __ATOMIC_ACQUIRE)) spin_pause();
  hush__taa_rows(taa, me, u > 0 ? r0 - 1 : 0, u == ff->units - 1 ? H : r1 - 1);
  ms[FUSED_TAA] += hush__now_ms() - t1;
}

/* The per-thread unit rows for the units of rows (fused_units), grown as
 * needed; NULL where they cannot be had (the frame's planes serve then). */
static hush_planar *unit_rows_for(bmfr_state *st, hush_device device, const bmfr_grid *grid,
                                  const fused_row *rows) {
  int cap = 0, above = 1; /* the albedo's rows; the rows above a unit's own */
  for (int u = 0; u < grid->ny; u++) {
    const int a0 = unit_first_row(grid, rows, u), y0 = u ? rows[u - 1].end : 0;
    cap = rows[u].end - a0 > cap ? rows[u].end - a0 : cap;
    above = y0 - a0 > above ? y0 - a0 : above;
  }
  if (st->unit_rows && cap <= st->unit_rows_cap && above <= st->unit_rows_above)
    return st->unit_rows;
  unit_rows_free(st);
  st->unit_rows = calloc(UNIT_ROWS * (size_t)st->threads, sizeof *st->unit_rows);
  if (!st->unit_rows) return NULL;
  for (int k = 0; k < UNIT_ROWS * st->threads; k++)
    if (hush__planar_init(device, &st->unit_rows[k], 3, (uint32_t)grid->width,
                          (uint32_t)(k % UNIT_ROWS == UNIT_ALBEDO ? cap : above))) {
      unit_rows_free(st);
      return NULL;
    }
  st->unit_rows_cap = cap;
  st->unit_rows_above = above;
  return st->unit_rows;
}

static void fused_frame_run(fused_frame *ff, float *scratch, int threads) {
  const size_t per_thread = (size_t)SCRATCH_COLUMNS * MAX_LD;
  int next = 0;
  for (int u = 0; u < ff->units; u++) {
    fused_row *r = &ff->rows[u];
    r->done_import = r->done = r->fit_open = r->strip_next = r->strip_done = r->done3 = 0;
  }
  for (int k = 0; k < threads * FUSED_STRIDE; k++) {
    ff->phase_ms[k] = 0.0;
    ff->bad[k] = 0;
  }
#pragma omp parallel num_threads(threads)
  {
    const int me = omp_get_thread_num();
    float *mine = scratch + (size_t)me * per_thread;
    for (;;) {
      const int u = __atomic_fetch_add(&next, 1, __ATOMIC_RELAXED);
      if (u >= ff->units) break;
      fused_unit(ff, u, me, mine);
    }
    /* no block row left: fit strips of the rows still running, until every
     * row's fit has been opened and no strip is left to take */
    double t0 = hush__now_ms();
    for (int busy = 1; busy;) {
      busy = 0;
      for (int u = 0; u < ff->units; u++) {
        if (!__atomic_load_n(&ff->rows[u].fit_open, __ATOMIC_ACQUIRE)) {
          busy = 1; /* not yet: look again */
          continue;
        }
        while (fused_fit_strip(ff, u, mine)) {
        }
      }
      if (busy) spin_pause();
    }
    ff->phase_ms[(size_t)me * FUSED_STRIDE + FUSED_FIT] += hush__now_ms() - t0;
  }
}

/* ---- execute ------------------------------------------------------------------ */

static hush_status bmfr_execute(hush_filter f, void *state, const hush_frame_info *info) {
  bmfr_state *st = state;
  const int threads = st->threads;
  hush_status s;
  hush__filter_timing_begin(f);

  const int has_albedo = hush__filter_view(f, I_ALBEDO) != NULL;
  const int demod = hush__param_i(f, P_DEMODULATE) && has_albedo;
  const int with_taa = hush__param_i(f, P_TAA);
  const int emis = hush__filter_view(f, I_EMISSION) != NULL && hush__param_i(f, P_EMISSION_BYPASS);
  if (!with_taa) st->taa.has_history = 0; /* switched back on later: start over */

  bmfr_feature_set set;
  const float exps[BMFR_SRC_COUNT][2] = {
      {hush__param_f(f, P_NORMAL_EXP1), hush__param_f(f, P_NORMAL_EXP2)},
      {hush__param_f(f, P_POSITION_EXP1), hush__param_f(f, P_POSITION_EXP2)},
      {hush__param_f(f, P_DEPTH_EXP1), hush__param_f(f, P_DEPTH_EXP2)},
      {hush__param_f(f, P_ALBEDO_EXP1), hush__param_f(f, P_ALBEDO_EXP2)},
  };
  hush__bmfr_features_build(&set, exps, hush__param_i(f, P_GRADIENTS));
  if ((set.needs & (1u << BMFR_SRC_POSITION)) && !hush__filter_view(f, I_POSITION))
    return hush__fail(f->device, HUSH_ERROR_INVALID_OPERATION,
                      "bmfr: the features use the world position but the 'position' image is "
                      "not bound (set position_exponent1 and position_exponent2 to 0 to fit "
                      "without it)");
  if ((set.needs & (1u << BMFR_SRC_ALBEDO)) && !has_albedo)
    return hush__fail(f->device, HUSH_ERROR_INVALID_OPERATION,
                      "bmfr: the features use the albedo but the 'albedo' image is not bound");

  /* ---- import: nothing of the history changes until every input is read */
  const int need_albedo = demod || (set.needs & (1u << BMFR_SRC_ALBEDO));
  if (need_albedo && (s = hush__filter_scratch(f, &st->albedo, 3))) return s;
  if (!emis) st->eh.valid = 0; /* bound again later: start over */
  if (emis && ((s = hush__filter_scratch(f, &st->emission, 3)) ||
               (s = hush__filter_scratch(f, &st->eh.hist[0], 3)) ||
               (s = hush__filter_scratch(f, &st->eh.hist[1], 3)) ||
               (s = hush__emission_history_rows(f->device, &st->eh, f->height))))
    return s;
  if (with_taa && !st->taa.current.plane[0] &&
      (s = hush__taa_init(f->device, &st->taa, f->width, f->height)))
    return s;
  static const hush_gbuffer_images gimages = {I_DEPTH, I_NORMAL, I_POSITION, I_ID, I_MOTION};
  /* the colour demodulated as it is imported (one pass less), unless the
   * emission comes off first or holes may change the albedo (as svgf) */
  const int demod_fused = demod && !emis && !hush__filter_view(f, I_SPP);
  const int adaptive = hush__param_i(f, P_TEMPORAL_GRADIENTS);
  /* phases I and II block row by block row (fused_frame) where phase I is
   * the plan and the blend alone: no emission or demodulation pass between
   * them, no holes (demod_fused: no 'spp' bound), no gradients (whose pass
   * reads the whole blend); then each block row imports its inputs itself
   * (defer) */
  const int defer = demod_fused && !adaptive && !(st->acc.has_history && st->acc.empty);
  if (!demod_fused && (s = hush__filter_import(f, I_COLOR, &st->color))) return s;
  const int use_id = hush__param_i(f, P_USE_ID);
  hush_gbuffer_import_job gjob;
  if (defer) {
    if ((s = hush__gbuffer_import_begin(f, &gimages, use_id, info, &st->rp, &st->gin, &gjob)))
      return s;
  } else if ((s = hush__gbuffer_import(f, &gimages, use_id, info, &st->rp, &st->gin))) {
    return s;
  }
  if (demod_fused && !defer) {
    if ((s = hush__filter_import_albedo_demodulated(f, I_ALBEDO, I_COLOR, &st->albedo, &st->color)))
      return s;
  } else if (!demod_fused && need_albedo && (s = hush__filter_import(f, I_ALBEDO, &st->albedo))) {
    return s;
  }
  if (emis && (s = hush__filter_import(f, I_EMISSION, &st->emission))) return s;
  if (adaptive && (s = bmfr_adaptive_import(f, &st->ad, I_GRADIENT))) return s;
  hush_planar *const fill[2] = {need_albedo ? &st->albedo : NULL, emis ? &st->emission : NULL};
  if ((s = hush__gbuffer_fill_holes(f, I_SPP, &st->rp, &st->gin, fill, 2, info, threads))) return s;
  hush__filter_timing_stage(f, "import");

  /* ---- phase I: reproject + accumulate the demodulated 1 spp radiance */
  hush_reproject_params rp;
  rp.depth_tolerance = hush__param_f(f, P_DEPTH_TOLERANCE);
  rp.depth_gradient = hush__param_f(f, P_DEPTH_GRADIENT);
  rp.normal_threshold = hush__param_f(f, P_NORMAL_THRESHOLD);
  rp.use_id = hush__param_i(f, P_USE_ID);
  rp.fallback_3x3 = hush__param_i(f, P_FALLBACK_3X3);
  hush_accum_params ap;
  ap.alpha_min = hush__param_f(f, P_ALPHA);
  ap.alpha_moments_min = ap.alpha_min;
  ap.max_age = hush__param_i(f, P_MAX_AGE);
  int fused = !emis && !(demod && !demod_fused) && !adaptive &&
              !hush__gbuffer_holes_spp(&st->gin) && !(st->acc.has_history && st->acc.empty);
  const int had_history = st->acc.has_history;
  hush_taa_params tp;
  tp.alpha = hush__param_f(f, P_TAA_ALPHA);
  tp.box = HUSH_TAA_CLAMP;
  tp.tonemap = 1;
  /* without the emission to add, the output is written as TAA resolves
   * each row */
  tp.out_view = emis ? NULL : hush__filter_view(f, I_OUTPUT);
  int fused_taa = 0;
  int fit_exported = 0; /* by the fused frame, block row by block row */
  /* the reprojector as it was, should the fused frame have to be redone */
  const int rp_latest = st->rp.latest, rp_had_history = st->rp.has_history;
  /* a second pass only when the fused one met NaN/Inf in the inputs it
   * imported: redone pass by pass, after the import that applies the policy */
  for (int pass = 0;; pass++) {
    const int deferred = defer && pass == 0; /* (defer implies fused) */
    hush_reproject_job job;
    if (fused) {
      /* the plan streamed past the caches even so: its stores' reads for
       * ownership cost phase I more than the blend's reads of it back from
       * memory (accumulate 4.30 -> 4.05 ms, three alternated runs); the
       * blend's and phase III's results stay cached for the fit and TAA,
       * which read them right after (streamed, both were slower) */
      if ((s = hush__gbuffer_reproject_begin(f, &st->rp, &st->gin, info, &rp, &job))) return s;
    } else {
      if (emis) hush__emission_wildcard_ids(&st->rp, &st->emission, threads);
      if ((s = hush__gbuffer_reproject(f, &st->rp, &st->gin, info, &rp, threads))) return s;
      if (emis)
        hush__emission_subtract_demodulate(&st->color, &st->emission, demod ? &st->albedo : NULL,
                                           &st->eh, threads);
      else if (demod && !demod_fused)
        hush__demodulate(&st->color, &st->albedo, threads);
      hush__accum_blend_holes(&st->acc, &st->rp.plan, (const float *const *)st->color.plane,
                              hush__gbuffer_holes_spp(&st->gin), &ap, NULL, threads);
      hush__filter_timing_stage(f, "accumulate");
    }
    if (adaptive) {
      st->ad.params.iterations = hush__param_i(f, P_GRADIENT_ITERATIONS);
      st->ad.params.sigma_z = GRADIENT_SIGMA_Z;
      st->ad.params.sigma_n = GRADIENT_SIGMA_N;
      st->ad.params.sigma_l = hush__param_f(f, P_GRADIENT_SIGMA_L);
      st->ad.params.exponent = hush__param_f(f, P_GRADIENT_EXPONENT);
      st->ad.params.threshold = hush__param_f(f, P_GRADIENT_THRESHOLD);
      st->ad.rule = hush__param_i(f, P_HISTORY_RULE) ? HUSH_HISTORY_HIGGINSON : HUSH_HISTORY_SCHIED;
      const hush_gbuffer_store *cur = hush__reprojector_latest(&st->rp);
      bmfr_adaptive_history(&st->ad, &st->acc, had_history, &st->rp.plan,
                            (const float *const *)st->color.plane, &ap, cur->depth.plane[0],
                            (const float *const *)cur->normal.plane, threads);
      hush__filter_timing_stage(f, "gradient");
    }

    /* ---- phase II: features, fit, weighted sum, per block */
    const int B = hush__param_i(f, P_BLOCK_SIZE);
    fit_frame fr;
    memset(&fr, 0, sizeof fr);
    int ox, oy;
    hush__bmfr_block_offset(info->frame_index, B, hush__param_i(f, P_DISPLACE), &ox, &oy);
    hush__bmfr_grid(&fr.grid, (int)f->width, (int)f->height, B, ox, oy);
    fr.set = &set;
    fr.refine = hush__param_i(f, P_REFINE);
    fr.outlier = hush__param_f(f, P_OUTLIER);
    fr.n = B * B;
    fr.ld = ((size_t)fr.n + 15) & ~(size_t)15;
    /* columns a multiple of 1 KiB apart (B = 16, 32, 64) put the same
     * rows of several columns at the same address bits 0-11, and a load
     * after a store to another column then waits on a false dependency
     * (4K aliasing) */
    if (fr.ld % 256 == 0) fr.ld += 16;
    const hush_gbuffer_store *gb = hush__reprojector_latest(&st->rp);
    fr.depth = fused ? gb->depth.plane[0]
                     : hush__gbuffer_depth_with_data(
                           &st->gin, gb->depth.plane[0],
                           st->acc.empty ? hush__accum_age(&st->acc)->plane[0] : NULL,
                           threads); /* never-sampled holes: out of the fit */
    for (int c = 0; c < 3; c++) {
      if (set.needs & (1u << BMFR_SRC_NORMAL)) fr.base[BMFR_BASE_NORMAL + c] = gb->normal.plane[c];
      if (set.needs & (1u << BMFR_SRC_POSITION))
        fr.base[BMFR_BASE_POSITION + c] = st->gin.position.plane[c];
      if (set.needs & (1u << BMFR_SRC_ALBEDO)) fr.base[BMFR_BASE_ALBEDO + c] = st->albedo.plane[c];
    }
    if (set.needs & (1u << BMFR_SRC_DEPTH)) fr.base[BMFR_BASE_DEPTH] = gb->depth.plane[0];
    /* fused: the set the blend writes, which becomes the latest after it */
    const hush_planar *z = fused ? &st->acc.color[1 - st->acc.latest] : hush__accum_color(&st->acc);
    for (int c = 0; c < BMFR_CHANNELS; c++) {
      fr.z[c] = z->plane[c];
      /* fused: the fit into phase III's output, which phase III blends in
       * place (tblend: each pixel's sample read before its result) */
      fr.out[c] = fused ? st->fhist[1 - st->flatest].plane[c] : st->fitted.plane[c];
    }
    hush__bmfr_noise_table(st->noise, set.count, fr.n, fr.ld, info->frame_index,
                           hush__param_f(f, P_NOISE));
    fr.noise = st->noise;
    /* TAA's rings: 3 rows a thread */
    fused_taa = fused && with_taa && (int)f->height >= 3 * threads;
    if (fused) {
      fused_frame ff;
      hush_taa_job tj;
      if (fused_taa)
        hush__taa_begin(&st->taa, &st->rp.plan,
                        (const float *const *)st->fhist[1 - st->flatest].plane,
                        demod ? (const float *const *)st->albedo.plane : NULL, &tp, &tj);
      ff.taa = fused_taa ? &tj : NULL;
      ff.phase_ms = st->phase_ms;
      ff.fr = &fr;
      ff.job = &job;
      ff.plan = &st->rp.plan;
      ff.acc = &st->acc;
      ff.sample = (const float *const *)st->color.plane;
      ff.ap = &ap;
      ff.units = fr.grid.ny;
      fused_units(&fr.grid, st->rows);
      ff.rows = st->rows;
      ff.prev3 = (const float *const *)st->fhist[st->flatest].plane;
      ff.out3 = st->fhist[1 - st->flatest].plane;
      ff.age = st->acc.age[1 - st->acc.latest].plane[0];
      ff.alpha3 = hush__param_f(f, P_ALPHA_FITTED);
      ff.gbuffer = deferred ? &gjob : NULL;
      ff.colour = deferred ? hush__filter_view(f, I_COLOR) : NULL;
      ff.albedo_view = hush__filter_view(f, I_ALBEDO);
      ff.colour_dst = &st->color;
      ff.albedo_dst = &st->albedo;
      /* the albedo in per-thread unit rows where nothing reads it after
       * the unit: TAA remodulates (no export of the albedo), no feature
       * takes the albedo */
      ff.unit_rows = deferred && fused_taa && !(set.needs & (1u << BMFR_SRC_ALBEDO))
                         ? unit_rows_for(st, f->device, &fr.grid, st->rows)
                         : NULL;
      ff.fit_view = hush__filter_view(f, I_FITTED);
      ff.bad = st->unit_bad;
      ff.per = strip_blocks(&fr);
      ff.strips = (fr.grid.nx + ff.per - 1) / ff.per;
      fused_frame_run(&ff, st->scratch, threads);
      size_t bad = 0;
      for (int t = 0; t < threads; t++) bad += st->unit_bad[t * FUSED_STRIDE];
      if (bad) {
        /* nothing of the history has changed but the reprojector's turn */
        st->rp.latest = rp_latest;
        st->rp.has_history = rp_had_history;
        if ((s = hush__gbuffer_import(f, &gimages, use_id, info, &st->rp, &st->gin)) ||
            (s = hush__filter_import_albedo_demodulated(f, I_ALBEDO, I_COLOR, &st->albedo,
                                                        &st->color)))
          return s;
        fused = 0;
        continue;
      }
      hush__accum_blend_done(&st->acc);
      fit_exported = 1;
      st->flatest = 1 - st->flatest;
      if (fused_taa) hush__taa_done(&st->taa);
      /* the stage table as the passes one after the other would give it:
       * the loop's time shared in proportion to the threads' time in each */
      double weight[FUSED_PHASES] = {0};
      for (int t = 0; t < threads; t++)
        for (int k = 0; k < FUSED_PHASES; k++) weight[k] += st->phase_ms[t * FUSED_STRIDE + k];
      hush__filter_timing_split(f, fused_stage_names, weight, fused_taa ? 4 : 3);
    } else {
      fit_frame_blocks(&fr, st->scratch, threads);
      hush__filter_timing_stage(f, "fit");

      /* ---- phase III: accumulate the fit with phase I's plan and counts */
      const int prev = st->flatest, cur = 1 - prev;
      hush__temporal_blend(&st->rp.plan, (const float *const *)st->fhist[prev].plane,
                           (const float *const *)st->fitted.plane, BMFR_CHANNELS,
                           hush__accum_age(&st->acc)->plane[0], hush__param_f(f, P_ALPHA_FITTED),
                           st->fhist[cur].plane, threads);
      st->flatest = cur;
      if (st->acc.empty) /* never-sampled holes: filled from around */
        hush__holes_fill(st->gin.holes.pyramid, f->width, f->height,
                         hush__accum_age(&st->acc)->plane[0], st->fhist[cur].plane, 3, threads);
      hush__filter_timing_stage(f, "accumulate_fitted");
    }
    break;
  }
  const int cur = st->flatest;

  /* ---- remodulate, TAA, emission, export: with TAA, the remodulation is
   * fused into its first pass (one read of the fit and the albedo); without
   * TAA, into the export, as is adding the emission back */
  const hush_planar *result = &st->fhist[cur];
  hush_planar rgb = {{result->plane[0], result->plane[1], result->plane[2]}, 3, f->width,
                     f->height};
  int exported = 0;
  if (with_taa) {
    exported = tp.out_view != NULL;
    if (!fused_taa)
      hush__taa_resolve_modulated(&st->taa, &st->rp.plan, (const float *const *)rgb.plane,
                                  demod ? (const float *const *)st->albedo.plane : NULL, &tp,
                                  threads);
    rgb = *hush__taa_output(&st->taa);
  }
  /* the emission after TAA: its history has already averaged the lights'
   * edges over frames, and TAA's tone-mapped blend would darken them */
  const hush_planar *e =
      emis ? hush__emission_accumulate_holes(&st->eh, &st->rp.plan,
                                             hush__accum_age(&st->acc)->plane[0], ap.alpha_min,
                                             &st->emission, hush__gbuffer_holes_spp(&st->gin),
                                             threads)
           : NULL;
  hush__filter_timing_stage(f, "taa");
  /* the remodulation (without TAA) and the emission fused into the export */
  const hush_planar *albedo = !with_taa && demod ? &st->albedo : NULL;
  if (albedo || e)
    hush__export_remodulated(&rgb, albedo, e, e ? hush__emission_rows_of(&st->eh) : NULL,
                             hush__filter_view(f, I_OUTPUT), threads);
  else if (!exported)
    hush__view_export(&rgb, hush__filter_view(f, I_OUTPUT), threads);
  const hush_image_view *fit_view = hush__filter_view(f, I_FITTED);
  if (fit_view && !fit_exported) hush__view_export(&st->fitted, fit_view, threads);
  const hush_image_view *age_view = hush__filter_view(f, I_HISTORY_LENGTH);
  if (age_view) hush__view_export(hush__accum_age(&st->acc), age_view, threads);
  hush__filter_timing_stage(f, "export");
  return HUSH_OK;
}

const hush_filter_class hush__filter_bmfr = {
    &bmfr_info,
    bmfr_create,
    bmfr_destroy,
    bmfr_execute,
};
