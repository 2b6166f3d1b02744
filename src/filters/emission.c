/*
 * emission.c — first-hit emission taken out before filtering and added
 * back after (see emission.h).
 */
#include "filters/emission.h"

#include "temporal/accumulation.h"

#include <math.h>

void hush__emission_subtract(hush_planar *color, const hush_planar *emission, int threads) {
  const int H = (int)color->height;
  const size_t W = color->width;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < H; y++)
    for (int c = 0; c < 3; c++) {
      float *col = color->plane[c] + (size_t)y * W;
      const float *em = emission->plane[c] + (size_t)y * W;
      /* the reflected part is never negative; rounding (or a colour that
       * is not the renderer's mean) must not make it so */
      for (size_t x = 0; x < W; x++) {
        const float r = col[x] - em[x];
        col[x] = r > 0.0f ? r : 0.0f;
      }
    }
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

void hush__emission_history_free(hush_emission_history *h) {
  hush__planar_free(&h->hist[0]);
  hush__planar_free(&h->hist[1]);
  h->valid = 0;
}

const hush_planar *hush__emission_accumulate(hush_emission_history *h,
                                             const hush_reproject_plan *plan, const float *age,
                                             float alpha_min, const hush_planar *emission,
                                             int threads) {
  return hush__emission_accumulate_holes(h, plan, age, alpha_min, emission, NULL, threads);
}

const hush_planar *hush__emission_accumulate_holes(hush_emission_history *h,
                                                   const hush_reproject_plan *plan,
                                                   const float *age, float alpha_min,
                                                   const hush_planar *emission, const float *spp,
                                                   int threads) {
  const int prev = h->latest, cur = 1 - prev;
  const float *const *hist = (const float *const *)h->hist[prev].plane;
  hush__temporal_blend(plan, h->valid ? hist : NULL, (const float *const *)emission->plane, 3,
                       age, alpha_min, h->hist[cur].plane, threads);
  if (spp && h->valid) {
    /* a hole takes no new sample: the history through the plan, as is */
    const long long n = (long long)plan->width * plan->height;
    float *const *out = h->hist[cur].plane;
#pragma omp parallel for schedule(static) num_threads(threads)
    for (long long i = 0; i < n; i++) {
      if (spp[i] > 0.0f) continue;
      int32_t idx[9];
      float w[9];
      const int taps = hush__reproject_taps(plan, (size_t)i, idx, w);
      for (int c = 0; c < 3 && taps; c++) out[c][i] = hush__reproject_apply(hist[c], idx, w, taps);
    }
  }
  h->latest = cur;
  h->valid = 1;
  return &h->hist[cur];
}
