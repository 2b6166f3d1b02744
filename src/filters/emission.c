/*
 * emission.c — first-hit emission taken out before filtering and added
 * back after (see emission.h).
 */
#include "filters/emission.h"

#include "core/vecmath.h"
#include "filters/albedo.h"

#include "temporal/accumulation.h"

#include <math.h>
#include <string.h>

/* One row of one channel: col = max(col - em, 0), divided by
 * max(alb, eps) with DEMOD; returns the OR of em's bits. */
static HUSH_ALWAYS_INLINE uint32_t subtract_row_of(float *restrict col, const float *restrict em,
                                                   const float *restrict alb, size_t n,
                                                   const int DEMOD) {
  uint32_t any = 0;
  for (size_t x = 0; x < n; x++) {
    /* the reflected part is never negative; rounding (or a colour that is
     * not the renderer's mean) must not make it so */
    const float r = col[x] - em[x];
    const float v = r > 0.0f ? r : 0.0f;
    /* hush__demodulate's division, so the same bits as its pass after */
    col[x] = DEMOD ? v / (alb[x] > HUSH_ALBEDO_EPS ? alb[x] : HUSH_ALBEDO_EPS) : v;
    uint32_t bits;
    memcpy(&bits, &em[x], sizeof bits);
    any |= bits;
  }
  return any;
}

/* subtract_row_of with the division when alb is not NULL. */
static uint32_t subtract_row(float *col, const float *em, const float *alb, size_t n) {
  return alb ? subtract_row_of(col, em, alb, n, 1) : subtract_row_of(col, em, NULL, n, 0);
}

void hush__emission_subtract_demodulate(hush_planar *color, const hush_planar *emission,
                                        const hush_planar *albedo, hush_emission_history *h,
                                        int threads) {
  const int H = (int)color->height;
  const size_t W = color->width;
  float *lit = h ? h->rows.plane[EMISSION_ROW_LIT] : NULL;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < H; y++) {
    uint32_t any = 0;
    for (int c = 0; c < 3; c++) {
      const size_t at = (size_t)y * W;
      any |= subtract_row(color->plane[c] + at, emission->plane[c] + at,
                          albedo ? albedo->plane[c] + at : NULL, W);
    }
    if (lit) lit[y] = any ? 1.0f : 0.0f;
  }
  if (lit) h->lit_fresh = 1;
}

void hush__emission_subtract(hush_planar *color, const hush_planar *emission,
                             hush_emission_history *h, int threads) {
  hush__emission_subtract_demodulate(color, emission, NULL, h, threads);
}

void hush__emission_add(hush_planar *out, const hush_planar *emission, const hush_planar *filtered,
                        int threads) {
  const int H = (int)out->height;
  const size_t W = out->width;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < H; y++)
    for (int c = 0; c < 3; c++) {
      float *o = out->plane[c] + (size_t)y * W;
      const float *em = emission->plane[c] + (size_t)y * W;
      const float *flt = filtered->plane[c] + (size_t)y * W;
      for (size_t x = 0; x < W; x++) o[x] = flt[x] + em[x];
    }
}

void hush__emission_wildcard_ids(hush_reprojector *rp, const hush_planar *emission, int threads) {
  hush_gbuffer_store *g = hush__reprojector_next(rp);
  if (!g->has_id) return;
  float *id = g->id.plane[0];
  const int H = (int)emission->height;
  const size_t W = emission->width;
  const float wild = NAN;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < H; y++) {
    const size_t o = (size_t)y * W;
    const float *e0 = emission->plane[0] + o, *e1 = emission->plane[1] + o,
                *e2 = emission->plane[2] + o;
    float *row = id + o;
    for (size_t x = 0; x < W; x++) {
      const int lit = (e0[x] > 0.0f) | (e1[x] > 0.0f) | (e2[x] > 0.0f);
      row[x] = lit ? wild : row[x];
    }
  }
}

hush_status hush__emission_history_rows(hush_device device, hush_emission_history *h,
                                        uint32_t height) {
  if (h->rows.plane[0]) return HUSH_OK;
  const hush_status s = hush__planar_init(device, &h->rows, 4, height, 1);
  if (s) return s;
  /* what the histories hold is not known yet: every row may be non-zero */
  for (uint32_t y = 0; y < height; y++) {
    h->rows.plane[EMISSION_ROW_LIT][y] = 1.0f;
    h->rows.plane[EMISSION_ROW_HIST][y] = 1.0f;
    h->rows.plane[EMISSION_ROW_HIST + 1][y] = 1.0f;
    h->rows.plane[EMISSION_ROW_NEED][y] = 1.0f;
  }
  h->lit_fresh = 0;
  return HUSH_OK;
}

void hush__emission_history_free(hush_emission_history *h) {
  hush__planar_free(&h->hist[0]);
  hush__planar_free(&h->hist[1]);
  hush__planar_free(&h->rows);
  h->valid = 0;
  h->lit_fresh = 0;
}

const hush_planar *hush__emission_accumulate(hush_emission_history *h,
                                             const hush_reproject_plan *plan, const float *age,
                                             float alpha_min, const hush_planar *emission,
                                             int threads) {
  return hush__emission_accumulate_holes(h, plan, age, alpha_min, emission, NULL, threads);
}

static int32_t floor_div(int32_t a, int32_t b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

/* Whether a row of the history hist[prev] with a non-zero value lies in
 * reach of row y's footprints: rows from the smallest origin's to three
 * past the largest's (a 3x3 footprint spans three rows, and its top-left
 * tap may lie a column before the row it is counted in). */
static int history_in_reach(const hush_reproject_plan *plan, int y, const float *hist_rows) {
  const int32_t W = (int32_t)plan->width, H = (int32_t)plan->height;
  const int32_t *origin = plan->origin + (size_t)y * (size_t)W;
  const uint8_t *kind = plan->kind + (size_t)y * (size_t)W;
  int32_t lo = INT32_MAX, hi = INT32_MIN;
  /* a min and max reduction GCC vectorises when told (the conditional
   * update was a scalar loop of about 4 cycles a pixel) */
#pragma omp simd reduction(min : lo) reduction(max : hi)
  for (int32_t x = 0; x < W; x++) {
    const int taps = kind[x] != HUSH_FOOTPRINT_NONE;
    const int32_t o = origin[x];
    const int32_t ol = taps ? o : INT32_MAX, oh = taps ? o : INT32_MIN;
    lo = ol < lo ? ol : lo;
    hi = oh > hi ? oh : hi;
  }
  if (lo > hi) return 0;
  int32_t r0 = floor_div(lo, W), r1 = floor_div(hi, W) + 3;
  r0 = r0 < 0 ? 0 : r0;
  r1 = r1 > H - 1 ? H - 1 : r1;
  int any = 0;
  for (int32_t r = r0; r <= r1; r++) any |= hist_rows[r] != 0.0f;
  return any;
}

/* The rows of hist[cur] this frame blends (h->rows' NEED plane): where the
 * emission is lit, or a non-zero history is in reach. Every other row of
 * the result is exactly 0 (a blend of zeros: +0 in every pixel kind, and
 * the LIT and HIST flags test bits, so a -0 counts as non-zero): it is
 * zeroed here unless it already is. */
static const float *rows_to_blend(hush_emission_history *h, const hush_reproject_plan *plan,
                                  int prev, int cur, int threads) {
  const int H = (int)plan->height;
  const size_t W = plan->width;
  const float *lit = h->rows.plane[EMISSION_ROW_LIT];
  const float *hist_rows = h->rows.plane[EMISSION_ROW_HIST + prev];
  float *cur_rows = h->rows.plane[EMISSION_ROW_HIST + cur];
  float *need = h->rows.plane[EMISSION_ROW_NEED];
  float *const *out = h->hist[cur].plane;
  const int valid = h->valid;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < H; y++) {
    const int blend = lit[y] != 0.0f || (valid && history_in_reach(plan, y, hist_rows));
    need[y] = blend ? 1.0f : 0.0f;
    if (blend || cur_rows[y] == 0.0f) continue;
    for (int c = 0; c < 3; c++) memset(out[c] + (size_t)y * W, 0, W * sizeof(float));
    cur_rows[y] = 0.0f;
  }
  return need;
}

/* h->rows' HIST flags of hist[cur] for the rows blended (need[y]). */
static void note_rows(hush_emission_history *h, int cur, const float *need, int threads) {
  const int H = (int)h->hist[cur].height;
  const size_t W = h->hist[cur].width;
  float *cur_rows = h->rows.plane[EMISSION_ROW_HIST + cur];
  float *const *out = h->hist[cur].plane;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < H; y++) {
    if (need[y] == 0.0f) continue;
    uint32_t any = 0;
    for (int c = 0; c < 3; c++) {
      const float *row = out[c] + (size_t)y * W;
      for (size_t x = 0; x < W; x++) {
        uint32_t bits;
        memcpy(&bits, &row[x], sizeof bits);
        any |= bits;
      }
    }
    cur_rows[y] = any ? 1.0f : 0.0f;
  }
}

const hush_planar *hush__emission_accumulate_holes(hush_emission_history *h,
                                                   const hush_reproject_plan *plan,
                                                   const float *age, float alpha_min,
                                                   const hush_planar *emission, const float *spp,
                                                   int threads) {
  const int prev = h->latest, cur = 1 - prev;
  const float *const *hist = (const float *const *)h->hist[prev].plane;
  /* only with this frame's lit rows (else every row is blended) */
  const float *need =
      h->rows.plane[0] && h->lit_fresh ? rows_to_blend(h, plan, prev, cur, threads) : NULL;
  h->lit_fresh = 0;
  hush__temporal_blend_rows(plan, h->valid ? hist : NULL, (const float *const *)emission->plane,
                            3, age, alpha_min, h->hist[cur].plane, need, threads);
  if (spp && h->valid) {
    /* a hole takes no new sample: the history through the plan, as is
     * (rows not blended hold 0, which is what their history gives) */
    const int H = (int)plan->height;
    const size_t W = plan->width;
    float *const *out = h->hist[cur].plane;
#pragma omp parallel for schedule(static) num_threads(threads)
    for (int y = 0; y < H; y++) {
      if (need && need[y] == 0.0f) continue;
      for (size_t i = (size_t)y * W; i < (size_t)(y + 1) * W; i++) {
        if (spp[i] > 0.0f) continue;
        int32_t idx[9];
        float w[9];
        const int taps = hush__reproject_taps(plan, i, idx, w);
        for (int c = 0; c < 3 && taps; c++)
          out[c][i] = hush__reproject_apply(hist[c], idx, w, taps);
      }
    }
  }
  if (need) {
    note_rows(h, cur, need, threads);
  } else if (h->rows.plane[0]) {
    /* blended without flags: every row may be non-zero */
    for (uint32_t y = 0; y < h->rows.width; y++) h->rows.plane[EMISSION_ROW_HIST + cur][y] = 1.0f;
  }
  h->latest = cur;
  h->valid = 1;
  return &h->hist[cur];
}
