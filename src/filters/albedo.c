/*
 * albedo.c — albedo demodulation and remodulation (see albedo.h).
 */
#include "filters/albedo.h"

static inline float albedo_clamped(float a) { return a > HUSH_ALBEDO_EPS ? a : HUSH_ALBEDO_EPS; }

void hush__demodulate(hush_planar *color, const hush_planar *albedo, int threads) {
  const int H = (int)color->height;
  const size_t W = color->width;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < H; y++)
    for (int c = 0; c < 3; c++) {
      float *col = color->plane[c] + (size_t)y * W;
      const float *alb = albedo->plane[c] + (size_t)y * W;
      for (size_t x = 0; x < W; x++) col[x] = col[x] / albedo_clamped(alb[x]);
    }
}

void hush__remodulate(hush_planar *albedo, const hush_planar *filtered, int threads) {
  const int H = (int)albedo->height;
  const size_t W = albedo->width;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < H; y++)
    for (int c = 0; c < 3; c++) {
      float *alb = albedo->plane[c] + (size_t)y * W;
      const float *flt = filtered->plane[c] + (size_t)y * W;
      for (size_t x = 0; x < W; x++) alb[x] = flt[x] * albedo_clamped(alb[x]);
    }
}
