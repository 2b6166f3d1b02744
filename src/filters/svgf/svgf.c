/*
 * svgf.c — the "svgf" filter: spatiotemporal variance-guided filtering.
 *
 *   import -> demodulate by albedo -> temporal accumulation of colour and
 *   luminance moments (src/temporal, shared with "accumulate") -> variance
 *   from the moments, or a 7x7 bilateral spatial estimate while the history
 *   is short -> edge-avoiding a-trous (5x5 B3 kernel, step 2^i), guided by
 *   depth (with its screen-space gradient), normal and luminance (scaled by
 *   the 3x3-blurred variance), the variance filtered along with squared
 *   weights -> the first level fed back as the colour history -> remodulate
 *   -> optionally TAA (src/temporal/taa.h, parameter "taa"; off by default,
 *   the "taa" filter can also follow svgf).
 *
 * Follows Dundr 2018 §4.1.4-4.1.5 (a-trous, weights, variance propagation)
 * and §4.4 (spatial variance while history < 4 frames), with the published
 * defaults of Schied et al. 2017 given in papers/NOTES.md ("SVGF").
 *
 * Layout: planar floats. The a-trous loops go tap-outer, pixel-inner over a
 * row, with per-thread row accumulators, so the inner loop is a plain
 * vectorisable loop over x; image borders are handled by clamping the tap
 * coordinates (done in short separate loops at the row ends). Every pixel is
 * computed on its own: the result does not depend on the thread count.
 */
#include "filters/albedo.h"
#include "filters/filter.h"
#include "filters/gbuffer.h"
#include "temporal/accumulation.h"
#include "temporal/reproject.h"
#include "temporal/taa.h"

#include <math.h>
#include <omp.h>
#include <stdlib.h>
#include <string.h>

/* Albedo below this is clamped before dividing (demodulation). */
/* Keep the depth and luminance weights' denominators away from 0: a flat
 * facing plane (zero gradient) or zero variance must not divide by 0. */
#define SVGF_EPS_Z 1e-3f
#define SVGF_EPS_L 1e-4f

enum {
  P_NONFINITE = 0,
  P_ALPHA,
  P_ALPHA_MOMENTS,
  P_MAX_AGE,
  P_DEPTH_TOLERANCE,
  P_DEPTH_GRADIENT,
  P_NORMAL_THRESHOLD,
  P_USE_ID,
  P_FALLBACK_3X3,
  P_DEMODULATE,
  P_ITERATIONS,
  P_SIGMA_Z,
  P_SIGMA_N,
  P_SIGMA_L,
  P_SPATIAL_VARIANCE_FRAMES,
  P_FEEDBACK_FIRST_LEVEL,
  P_TAA,
  P_TAA_ALPHA,
  P_COUNT
};

static const hush_param_info svgf_params[P_COUNT] = {
    HUSH_PARAM_NONFINITE_ENTRY,
    {"alpha", HUSH_PARAM_FLOAT, 0.2, 0.0, 1.0,
     "minimum weight of the new frame in the colour blend: max(alpha, 1/history_length)", NULL},
    {"alpha_moments", HUSH_PARAM_FLOAT, 0.2, 0.0, 1.0,
     "minimum weight of the new frame in the luminance-moment blend", NULL},
    {"max_age", HUSH_PARAM_INT, 32, 1, 65535, "history length cap in frames", NULL},
    {"depth_tolerance", HUSH_PARAM_FLOAT, 0.1, 0.0, 1e6,
     "reprojection: a history tap is kept when its depth is within this fraction (plus the "
     "gradient term)",
     NULL},
    {"depth_gradient", HUSH_PARAM_FLOAT, 1.0, 0.0, 1e3,
     "reprojection: weight of the screen-space depth gradient in the depth test", NULL},
    {"normal_threshold", HUSH_PARAM_FLOAT, 0.9, -1.0, 1.0,
     "reprojection: a history tap is kept when dot(normal, previous normal) >= this (-1: off)",
     NULL},
    {"use_id", HUSH_PARAM_BOOL, 1, 0, 1,
     "reject history from a pixel with another id (when 'id' is bound)", NULL},
    {"fallback_3x3", HUSH_PARAM_BOOL, 1, 0, 1,
     "search the 3x3 neighbourhood when no tap of the bilinear footprint is consistent", NULL},
    {"demodulate", HUSH_PARAM_BOOL, 1, 0, 1,
     "with 'albedo' bound: filter color / max(albedo, 1e-3), multiply back after", NULL},
    {"iterations", HUSH_PARAM_INT, 5, 0, 10,
     "a-trous iterations of the 5x5 B3 kernel, tap step 2^i (0: accumulation only)", NULL},
    {"sigma_z", HUSH_PARAM_FLOAT, 1.0, 1e-6, 1e6,
     "depth weight exp(-|z_p - z_q| / (sigma_z |grad z . (p - q)| + eps))", NULL},
    {"sigma_n", HUSH_PARAM_FLOAT, 128.0, 0.0, 1024.0,
     "normal weight max(0, n_p . n_q)^sigma_n", NULL},
    {"sigma_l", HUSH_PARAM_FLOAT, 4.0, 1e-6, 1e6,
     "luminance weight exp(-|l_p - l_q| / (sigma_l sqrt(g3x3(var_p)) + eps))", NULL},
    {"spatial_variance_frames", HUSH_PARAM_INT, 4, 0, 65535,
     "below this history length the variance is a 7x7 bilateral spatial estimate (0: never)",
     NULL},
    {"feedback_first_level", HUSH_PARAM_BOOL, 1, 0, 1,
     "the first a-trous level becomes the next frame's colour history (else the accumulation)",
     NULL},
    {"taa", HUSH_PARAM_BOOL, 0, 0, 1,
     "finish with temporal anti-aliasing of the remodulated output (as the 'taa' filter: 3x3 "
     "YCoCg clamp, tone-mapped); off by default so that svgf alone can be compared",
     NULL},
    {"taa_alpha", HUSH_PARAM_FLOAT, 0.1, 0.01, 1.0,
     "with taa: weight of the current frame in the TAA blend", NULL},
};

enum {
  I_COLOR = 0,
  I_DEPTH,
  I_NORMAL,
  I_DEPTH_GRADIENT,
  I_POSITION,
  I_ID,
  I_MOTION,
  I_ALBEDO,
  I_OUTPUT,
  I_VARIANCE,
  I_HISTORY_LENGTH,
  I_COUNT
};

static const hush_image_info svgf_images[I_COUNT] = {
    {"color", HUSH_IMAGE_INPUT, 1, 3, "noisy radiance of this frame"},
    {"depth", HUSH_IMAGE_INPUT, 1, 1, "linear view depth (0: background)"},
    {"normal", HUSH_IMAGE_INPUT, 1, 3, "world-space shading normal"},
    {"depth_gradient", HUSH_IMAGE_INPUT, 0, 2,
     "d depth / d pixel in x and y (else the smaller one-sided difference of 'depth')"},
    {"position", HUSH_IMAGE_INPUT, 0, 3,
     "world-space position (camera reprojection; else reconstructed from depth)"},
    {"id", HUSH_IMAGE_INPUT, 0, 1, "mesh or material id: history only from the same id"},
    {"motion", HUSH_IMAGE_INPUT, 0, 2,
     "motion in pixels, previous minus current (required with HUSH_MOTION_VECTORS)"},
    {"albedo", HUSH_IMAGE_INPUT, 0, 3, "first-hit albedo, for demodulation (else 1)"},
    {"output", HUSH_IMAGE_OUTPUT, 1, 3, "filtered radiance"},
    {"variance", HUSH_IMAGE_OUTPUT, 0, 1,
     "luminance variance estimate that guides the first a-trous level (demodulated)"},
    {"history_length", HUSH_IMAGE_OUTPUT, 0, 1, "frames accumulated per pixel"},
};

static const hush_filter_class_info svgf_info = {
    "svgf",
    "spatiotemporal variance-guided filtering: accumulation, variance, edge-avoiding a-trous",
    "Dundr 2018 §4.1.4-4.1.5, §4.4; Schied et al. 2017 (papers/NOTES.md)",
    svgf_params,
    P_COUNT,
    svgf_images,
    I_COUNT,
};

typedef struct svgf_state {
  hush_reprojector rp;
  hush_accum acc;
  hush_planar color;   /* this frame, demodulated in place */
  hush_planar grad;    /* 2: depth gradient (imported or computed) */
  hush_planar ping[2]; /* 4: a-trous colour (3) + variance (1) */
  hush_planar lum;     /* 1: luminance of the a-trous input */
  hush_planar gvar;    /* 1: 3x3 Gaussian of the variance, then the scratch of its blur */
  float *rows;         /* per thread: ROW_ARRAYS rows of width floats */
  int threads;
  /* allocated on first use: */
  hush_planar albedo;
  hush_gbuffer_inputs gin; /* position and motion between import and build */
  hush_taa taa; /* its planes allocated when "taa" is first on */
} svgf_state;

/* Row accumulators of the a-trous: weight, colour (3), variance, and the
 * reciprocal of the luminance weight's denominator. */
#define ROW_ARRAYS 6

static void svgf_destroy(void *state) {
  svgf_state *st = state;
  if (!st) return;
  hush__reprojector_free(&st->rp);
  hush__accum_free(&st->acc);
  hush__planar_free(&st->color);
  hush__planar_free(&st->grad);
  hush__planar_free(&st->ping[0]);
  hush__planar_free(&st->ping[1]);
  hush__planar_free(&st->lum);
  hush__planar_free(&st->gvar);
  hush__free_floats(st->rows);
  hush__planar_free(&st->albedo);
  hush__gbuffer_inputs_free(&st->gin);
  hush__taa_free(&st->taa);
  free(st);
}

static hush_status svgf_create(hush_filter f, void **state) {
  svgf_state *st = calloc(1, sizeof *st);
  if (!st) return hush__fail(f->device, HUSH_ERROR_OUT_OF_MEMORY, "svgf: out of memory");
  const uint32_t W = f->width, H = f->height;
  st->threads = f->device->threads > 0 ? f->device->threads : 1;
  hush_status s = hush__reprojector_init(f->device, &st->rp, W, H);
  if (!s) s = hush__accum_init(f->device, &st->acc, 3, W, H);
  if (!s) s = hush__planar_init(f->device, &st->color, 3, W, H);
  if (!s) s = hush__planar_init(f->device, &st->grad, 2, W, H);
  if (!s) s = hush__planar_init(f->device, &st->ping[0], 4, W, H);
  if (!s) s = hush__planar_init(f->device, &st->ping[1], 4, W, H);
  if (!s) s = hush__planar_init(f->device, &st->lum, 1, W, H);
  if (!s) s = hush__planar_init(f->device, &st->gvar, 2, W, H);
  if (!s) {
    st->rows = hush__alloc_floats((size_t)st->threads * ROW_ARRAYS * W);
    if (!st->rows) s = hush__fail(f->device, HUSH_ERROR_OUT_OF_MEMORY, "svgf: out of memory");
  }
  if (s) {
    svgf_destroy(st);
    return s;
  }
  *state = st;
  return HUSH_OK;
}

static inline int clampi(int v, int lo, int hi) { return v < lo ? lo : v > hi ? hi : v; }

/* e^x for x <= 0 (larger x is not needed), branch-free so loops over it
 * vectorise without -ffast-math: 2^n * 2^f with n = round(x log2 e),
 * |f| <= 1/2 and a degree-6 Taylor polynomial of 2^f (relative error about
 * 1e-7). Below -20 it returns exactly 0: such a tap weighs under 2e-9 of
 * the centre's, and tiny weights (squared for the variance) would
 * otherwise make subnormal numbers, which cost x86 a microcode assist each
 * (measured: 3x slower a-trous on frames with background). */
static inline float exp_neg(float x) {
  const int keep = x > -20.0f;
  x = hush__select_bits(keep, x, -20.0f);
  const float t = x * 1.44269504f;
  const float n = hush__floorf_vec(t + 0.5f);
  const float f = (t - n) * 0.693147181f; /* 2^(t-n) = e^f */
  const float p =
      1.0f + f * (1.0f + f * (0.5f + f * (1.0f / 6 + f * (1.0f / 24 + f * (1.0f / 120 + f * (1.0f / 720))))));
  const int32_t bits = ((int32_t)n + 127) << 23;
  float scale;
  memcpy(&scale, &bits, sizeof scale);
  return hush__select_bits(keep, p * scale, 0.0f);
}

/* ln(d) for d > 0 (d <= 0 is taken as 1e-30), branch-free like exp_neg:
 * d = m 2^e with m in [sqrt(1/2), sqrt(2)), ln m = 2 atanh(s), s = (m-1)/(m+1),
 * |s| < 0.172, by its series to s^9 (absolute error below 1e-9). It lets
 * the normal weight max(0, dot)^sigma_n join the one exp of the tap. */
static inline float log_pos(float d) {
  d = hush__select_bits(d > 1e-30f, d, 1e-30f);
  int32_t bits;
  memcpy(&bits, &d, sizeof bits);
  float e = (float)((bits >> 23) - 127);
  const int32_t mbits = (bits & 0x007fffff) | 0x3f800000;
  float m;
  memcpy(&m, &mbits, sizeof m);
  const int big = m > 1.41421356f;
  m = hush__select_bits(big, 0.5f * m, m);
  e = hush__select_bits(big, e + 1.0f, e);
  const float sv = (m - 1.0f) / (m + 1.0f), s2 = sv * sv;
  const float series = 1.0f + s2 * (1.0f / 3 + s2 * (1.0f / 5 + s2 * (1.0f / 7 + s2 * (1.0f / 9))));
  return e * 0.693147181f + 2.0f * sv * series;
}

/* ---- demodulation ---------------------------------------------------------- */

/* ---- depth gradient -------------------------------------------------------- */

/* The smaller of the two one-sided differences: at a depth edge one side
 * still sees the surface, so the edge does not inflate the gradient (which
 * would make the depth weight accept the other side). */
static inline float smaller_diff(float a, float b) { return fabsf(a) < fabsf(b) ? a : b; }

static void depth_gradient(const float *z, hush_planar *grad, int threads) {
  const int H = (int)grad->height, W = (int)grad->width;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < H; y++) {
    const float *r = z + (size_t)y * W;
    const float *up = z + (size_t)(y > 0 ? y - 1 : y) * W;
    const float *dn = z + (size_t)(y < H - 1 ? y + 1 : y) * W;
    float *gx = grad->plane[0] + (size_t)y * W, *gy = grad->plane[1] + (size_t)y * W;
    for (int x = 0; x < W; x++) {
      const int xl = x > 0 ? x - 1 : x, xr = x < W - 1 ? x + 1 : x;
      gx[x] = smaller_diff(r[xr] - r[x], r[x] - r[xl]);
      gy[x] = smaller_diff(dn[x] - r[x], r[x] - up[x]);
    }
  }
}

/* ---- variance ------------------------------------------------------------- */

typedef struct guide {
  int W, H;
  const float *z, *gx, *gy;
  const float *n[3];
  float sigma_z, sigma_n;
} guide;

/* Depth and normal weight (no luminance) of q seen from p, offset (dx, dy). */
static inline float geometry_weight(const guide *g, size_t p, size_t q, float dx, float dy) {
  const float dz = fabsf(g->z[p] - g->z[q]);
  const float dd = g->sigma_z * fabsf(g->gx[p] * dx + g->gy[p] * dy) + SVGF_EPS_Z;
  const float dn = g->n[0][p] * g->n[0][q] + g->n[1][p] * g->n[1][q] + g->n[2][p] * g->n[2][q];
  return exp_neg(g->sigma_n * log_pos(dn) - dz / dd);
}

/* var = max(0, m2 - m1^2) from the temporal moments (already there), except
 * where the history is shorter than min_age: there the moments are averaged
 * over 7x7 with depth and normal weights first (Dundr §4.4: too few frames
 * for a temporal estimate). */
static void spatial_variance(const guide *g, const hush_planar *moments, const float *age,
                             float min_age, float *var, int threads) {
  const float *m1 = moments->plane[0], *m2 = moments->plane[1];
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < g->H; y++)
    for (int x = 0; x < g->W; x++) {
      const size_t p = (size_t)y * g->W + x;
      if (age[p] >= min_age) continue;
      float sw = 0.0f, s1 = 0.0f, s2 = 0.0f;
      for (int j = -3; j <= 3; j++) {
        const size_t row = (size_t)clampi(y + j, 0, g->H - 1) * g->W;
        for (int i = -3; i <= 3; i++) {
          const size_t q = row + clampi(x + i, 0, g->W - 1);
          const float w = (i == 0 && j == 0) ? 1.0f : geometry_weight(g, p, q, (float)i, (float)j);
          sw += w;
          s1 += w * m1[q];
          s2 += w * m2[q];
        }
      }
      s1 /= sw;
      s2 /= sw;
      const float v = s2 - s1 * s1;
      var[p] = v > 0.0f ? v : 0.0f;
    }
}

/* out = 3x3 Gaussian (1 2 1)/4 x (1 2 1)/4 of in, clamped at the borders;
 * tmp is a scratch plane. */
static void gauss3x3(const float *in, float *tmp, float *out, int W, int H, int threads) {
#pragma omp parallel num_threads(threads)
  {
#pragma omp for schedule(static)
    for (int y = 0; y < H; y++) {
      const float *r = in + (size_t)y * W;
      float *t = tmp + (size_t)y * W;
      for (int x = 0; x < W; x++) {
        const int xl = x > 0 ? x - 1 : x, xr = x < W - 1 ? x + 1 : x;
        t[x] = 0.25f * r[xl] + 0.5f * r[x] + 0.25f * r[xr];
      }
    }
#pragma omp for schedule(static)
    for (int y = 0; y < H; y++) {
      const float *up = tmp + (size_t)(y > 0 ? y - 1 : y) * W;
      const float *mid = tmp + (size_t)y * W;
      const float *dn = tmp + (size_t)(y < H - 1 ? y + 1 : y) * W;
      float *o = out + (size_t)y * W;
      for (int x = 0; x < W; x++) o[x] = 0.25f * up[x] + 0.5f * mid[x] + 0.25f * dn[x];
    }
  }
}

/* ---- a-trous ------------------------------------------------------------- */

static const float b3[5] = {1.0f / 16, 1.0f / 4, 3.0f / 8, 1.0f / 4, 1.0f / 16};

typedef struct atrous_row {
  const guide *g;
  const float *lum;  /* luminance of the input colour */
  const float *c[3]; /* input colour */
  const float *var;  /* input variance */
  float *sw, *sc[3], *sv, *inv_l; /* row accumulators, indexed by x */
  size_t prow, qrow;              /* row offsets of p and of the tap row */
  float h, dx, dy;
  int ix;                         /* tap offset in x, pixels */
} atrous_row;

/* Adds the taps (x + ix, tap row) of pixels x in [x0, x1) of the p row; with
 * clamp (a constant at each call) the tap column is clamped to the image.
 * One exp per tap: exp(-dz/dd - dl/dl_max + sigma_n ln(dot)). */
static HUSH_ALWAYS_INLINE void atrous_span(const atrous_row *r, int x0, int x1, int W,
                                           int clamp) {
  const guide *g = r->g;
  /* unclamped: the tap rows are addressed from x + ix, so every access in
   * the loop is p[x], a plain vector load */
  const size_t qo = r->qrow + (size_t)(clamp ? 0 : r->ix);
  const float *restrict zp = g->z + r->prow, *restrict zq = g->z + qo;
  const float *restrict gx = g->gx + r->prow, *restrict gy = g->gy + r->prow;
  const float *restrict n0p = g->n[0] + r->prow, *restrict n1p = g->n[1] + r->prow,
                        *restrict n2p = g->n[2] + r->prow;
  const float *restrict n0q = g->n[0] + qo, *restrict n1q = g->n[1] + qo,
                        *restrict n2q = g->n[2] + qo;
  const float *restrict lp = r->lum + r->prow, *restrict lq = r->lum + qo;
  const float *restrict c0 = r->c[0] + qo, *restrict c1 = r->c[1] + qo,
                        *restrict c2 = r->c[2] + qo, *restrict vq = r->var + qo;
  const float *restrict inv_l = r->inv_l;
  float *restrict sw = r->sw, *restrict s0 = r->sc[0], *restrict s1 = r->sc[1],
                  *restrict s2 = r->sc[2], *restrict sv = r->sv;
  const float h = r->h, dx = r->dx, dy = r->dy, sigma_z = g->sigma_z, sigma_n = g->sigma_n;
  const int ix = r->ix;
  /* every x is independent (the accumulators are indexed by x) */
#pragma omp simd
  for (int x = x0; x < x1; x++) {
    const int q = clamp ? clampi(x + ix, 0, W - 1) : x;
    const float dz = fabsf(zp[x] - zq[q]);
    const float dd = sigma_z * fabsf(gx[x] * dx + gy[x] * dy) + SVGF_EPS_Z;
    const float dl = fabsf(lp[x] - lq[q]);
    const float dn = n0p[x] * n0q[q] + n1p[x] * n1q[q] + n2p[x] * n2q[q];
    const float w = h * exp_neg(sigma_n * log_pos(dn) - dz / dd - dl * inv_l[x]);
    sw[x] += w;
    s0[x] += w * c0[q];
    s1[x] += w * c1[q];
    s2[x] += w * c2[q];
    sv[x] += w * w * vq[q];
  }
}

/* One tap offset over a whole row: clamped coordinates only where the tap
 * leaves the image, so the middle span is a plain strided loop. */
static void atrous_tap_row(const atrous_row *r, int W) {
  int xa = r->ix < 0 ? -r->ix : 0;
  int xb = r->ix > 0 ? W - r->ix : W;
  xa = xa < W ? xa : W;
  xb = xb > xa ? xb : xa;
  atrous_span(r, 0, xa, W, 1);
  atrous_span(r, xa, xb, W, 0);
  atrous_span(r, xb, W, W, 1);
}

/* One a-trous level with tap step `step`: in (colour 3 + variance) -> out. */
static void atrous_level(const guide *g, const hush_planar *in, const float *lum,
                         const float *gvar, hush_planar *out, int step, float sigma_l,
                         float *rows, int threads) {
  const int W = g->W, H = g->H;
#pragma omp parallel num_threads(threads)
  {
    float *base = rows + (size_t)omp_get_thread_num() * ROW_ARRAYS * W;
    atrous_row r;
    r.g = g;
    r.lum = lum;
    for (int c = 0; c < 3; c++) r.c[c] = in->plane[c];
    r.var = in->plane[3];
    r.sw = base;
    for (int c = 0; c < 3; c++) r.sc[c] = base + (size_t)(1 + c) * W;
    r.sv = base + (size_t)4 * W;
    r.inv_l = base + (size_t)5 * W;
#pragma omp for schedule(static)
    for (int y = 0; y < H; y++) {
      const size_t prow = (size_t)y * W;
      r.prow = prow;
      /* the centre tap: every weight 1 */
      const float h0 = b3[2] * b3[2];
      for (int x = 0; x < W; x++) {
        r.inv_l[x] = 1.0f / (sigma_l * sqrtf(gvar[prow + x]) + SVGF_EPS_L);
        r.sw[x] = h0;
        for (int c = 0; c < 3; c++) r.sc[c][x] = h0 * r.c[c][prow + x];
        r.sv[x] = h0 * h0 * r.var[prow + x];
      }
      for (int j = -2; j <= 2; j++) {
        r.qrow = (size_t)clampi(y + j * step, 0, H - 1) * W;
        r.dy = (float)(j * step);
        for (int i = -2; i <= 2; i++) {
          if (i == 0 && j == 0) continue;
          r.ix = i * step;
          r.dx = (float)r.ix;
          r.h = b3[i + 2] * b3[j + 2];
          atrous_tap_row(&r, W);
        }
      }
      for (int x = 0; x < W; x++) {
        const float inv = 1.0f / r.sw[x];
        for (int c = 0; c < 3; c++) out->plane[c][prow + x] = r.sc[c][x] * inv;
        out->plane[3][prow + x] = r.sv[x] * inv * inv;
      }
    }
  }
}

static void luminance(const hush_planar *img, float *lum, int threads) {
  const int H = (int)img->height;
  const size_t W = img->width;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < H; y++) {
    const size_t o = (size_t)y * W;
    for (size_t x = 0; x < W; x++)
      lum[o + x] = hush_luminance(img->plane[0][o + x], img->plane[1][o + x], img->plane[2][o + x]);
  }
}

static void copy_planes(const hush_planar *src, hush_planar *dst, int channels) {
  const size_t n = hush__planar_pixels(src);
  for (int c = 0; c < channels; c++) memcpy(dst->plane[c], src->plane[c], n * sizeof(float));
}

/* ---- execute --------------------------------------------------------------- */

static hush_status svgf_execute(hush_filter f, void *state, const hush_frame_info *info) {
  svgf_state *st = state;
  const int threads = st->threads;
  const int W = (int)f->width, H = (int)f->height;
  hush_status s;
  hush__filter_timing_begin(f);

  const int has_dgrad = hush__filter_view(f, I_DEPTH_GRADIENT) != NULL;
  const int demod = hush__param_i(f, P_DEMODULATE) && hush__filter_view(f, I_ALBEDO);
  const int with_taa = hush__param_i(f, P_TAA);
  if (!with_taa) st->taa.has_history = 0; /* switched back on later: start over */

  /* ---- import: nothing of the history changes until every input is read */
  if (demod && (s = hush__filter_scratch(f, &st->albedo, 3))) return s;
  if (with_taa && !st->taa.current.plane[0] &&
      (s = hush__taa_init(f->device, &st->taa, f->width, f->height)))
    return s;
  static const hush_gbuffer_images gimages = {I_DEPTH, I_NORMAL, I_POSITION, I_ID, I_MOTION};
  if ((s = hush__filter_import(f, I_COLOR, &st->color))) return s;
  if ((s = hush__gbuffer_import(f, &gimages, hush__param_i(f, P_USE_ID), info, &st->rp, &st->gin)))
    return s;
  if (has_dgrad && (s = hush__filter_import(f, I_DEPTH_GRADIENT, &st->grad))) return s;
  if (demod && (s = hush__filter_import(f, I_ALBEDO, &st->albedo))) return s;
  hush__filter_timing_stage(f, "import");

  /* ---- reproject + accumulate */
  hush_reproject_params rp;
  rp.depth_tolerance = hush__param_f(f, P_DEPTH_TOLERANCE);
  rp.depth_gradient = hush__param_f(f, P_DEPTH_GRADIENT);
  rp.normal_threshold = hush__param_f(f, P_NORMAL_THRESHOLD);
  rp.use_id = hush__param_i(f, P_USE_ID);
  rp.fallback_3x3 = hush__param_i(f, P_FALLBACK_3X3);
  if ((s = hush__gbuffer_reproject(f, &st->rp, &st->gin, info, &rp, threads))) return s;
  if (demod) hush__demodulate(&st->color, &st->albedo, threads);
  hush_accum_params ap;
  ap.alpha_min = hush__param_f(f, P_ALPHA);
  ap.alpha_moments_min = hush__param_f(f, P_ALPHA_MOMENTS);
  ap.max_age = hush__param_i(f, P_MAX_AGE);
  hush_planar *cur = &st->ping[0];
  hush__accum_blend(&st->acc, &st->rp.plan, (const float *const *)st->color.plane, &ap,
                    cur->plane[3], threads);
  hush__filter_timing_stage(f, "accumulate");

  /* ---- variance */
  const hush_gbuffer_store *gb = hush__reprojector_latest(&st->rp);
  if (!has_dgrad) depth_gradient(gb->depth.plane[0], &st->grad, threads);
  guide gd;
  gd.W = W;
  gd.H = H;
  gd.z = gb->depth.plane[0];
  gd.gx = st->grad.plane[0];
  gd.gy = st->grad.plane[1];
  for (int c = 0; c < 3; c++) gd.n[c] = gb->normal.plane[c];
  gd.sigma_z = hush__param_f(f, P_SIGMA_Z);
  gd.sigma_n = hush__param_f(f, P_SIGMA_N);
  spatial_variance(&gd, hush__accum_moments(&st->acc), hush__accum_age(&st->acc)->plane[0],
                   (float)hush__param_i(f, P_SPATIAL_VARIANCE_FRAMES), cur->plane[3], threads);
  const hush_image_view *var_view = hush__filter_view(f, I_VARIANCE);
  if (var_view) {
    hush_planar v = {{cur->plane[3]}, 1, f->width, f->height};
    hush__view_export(&v, var_view, threads);
  }
  copy_planes(hush__accum_color(&st->acc), cur, 3);
  hush__filter_timing_stage(f, "variance");

  /* ---- a-trous */
  const int iterations = hush__param_i(f, P_ITERATIONS);
  const float sigma_l = hush__param_f(f, P_SIGMA_L);
  for (int i = 0; i < iterations; i++) {
    hush_planar *next = cur == &st->ping[0] ? &st->ping[1] : &st->ping[0];
    luminance(cur, st->lum.plane[0], threads);
    gauss3x3(cur->plane[3], st->gvar.plane[1], st->gvar.plane[0], W, H, threads);
    atrous_level(&gd, cur, st->lum.plane[0], st->gvar.plane[0], next, 1 << i, sigma_l, st->rows,
                 threads);
    cur = next;
    /* the history keeps some spatial filtering (Schied 2017 §4.4): less
     * noise is fed back, at the cost of a little extra blur over time */
    if (i == 0 && hush__param_i(f, P_FEEDBACK_FIRST_LEVEL))
      copy_planes(cur, hush__accum_color(&st->acc), 3);
  }
  hush__filter_timing_stage(f, "atrous");

  /* ---- export */
  const hush_planar *result = cur;
  if (demod) {
    hush__remodulate(&st->albedo, cur, threads);
    result = &st->albedo;
  }
  hush_planar rgb = {{result->plane[0], result->plane[1], result->plane[2]}, 3, f->width,
                     f->height};
  if (with_taa) {
    /* the paper's order: remodulate, then TAA on the final radiance */
    hush_taa_params tp;
    tp.alpha = hush__param_f(f, P_TAA_ALPHA);
    tp.box = HUSH_TAA_CLAMP;
    tp.tonemap = 1;
    hush__taa_resolve(&st->taa, &st->rp.plan, (const float *const *)rgb.plane, &tp, threads);
    rgb = *hush__taa_output(&st->taa);
  }
  hush__view_export(&rgb, hush__filter_view(f, I_OUTPUT), threads);
  const hush_image_view *age_view = hush__filter_view(f, I_HISTORY_LENGTH);
  if (age_view) hush__view_export(hush__accum_age(&st->acc), age_view, threads);
  hush__filter_timing_stage(f, "export");
  return HUSH_OK;
}

const hush_filter_class hush__filter_svgf = {
    &svgf_info,
    svgf_create,
    svgf_destroy,
    svgf_execute,
};
