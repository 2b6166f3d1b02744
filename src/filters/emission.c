/*
 * emission.c — first-hit emission taken out before filtering and added
 * back after (see emission.h).
 */
#include "filters/emission.h"

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

void hush__emission_add(hush_planar *emission, const hush_planar *filtered, int threads) {
  const int H = (int)emission->height;
  const size_t W = emission->width;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < H; y++)
    for (int c = 0; c < 3; c++) {
      float *em = emission->plane[c] + (size_t)y * W;
      const float *flt = filtered->plane[c] + (size_t)y * W;
      for (size_t x = 0; x < W; x++) em[x] = flt[x] + em[x];
    }
}
