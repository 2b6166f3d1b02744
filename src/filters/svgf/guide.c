/*
 * guide.c — the SVGF guide planes (see guide.h; Dundr 2018 §4.1.4.3).
 */
#include "filters/svgf/guide.h"

#include <string.h>

void svgf_guide_import(svgf_padded *zn, const float *depth, const float *const normal[3],
                       int threads) {
  svgf_padded_import(zn, 0, depth, threads);
  for (int c = 0; c < 3; c++) svgf_padded_import(zn, 1 + c, normal[c], threads);
}

/* The one of a (forward) and b (backward) difference with the smaller
 * magnitude (b on a tie). */
static inline float smaller_diff(float a, float b) {
  return hush__select_bits(fabsf(a) < fabsf(b), a, b);
}

void svgf_guide_gradient(const svgf_padded *zn, int has_grad, hush_planar *grad, float *zon,
                         float steep, int threads) {
  const int W = zn->width, H = zn->height;
  const float steep2 = steep * steep;
  const int use_steep = steep > 0.0f;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < H; y++) {
    /* the pads repeat the border pixel: the outward difference there is 0,
     * as with a clamped index */
    const float *restrict r = svgf_padded_row(zn, 0, y);
    const float *restrict up = svgf_padded_row(zn, 0, y > 0 ? y - 1 : y);
    const float *restrict dn = svgf_padded_row(zn, 0, y < H - 1 ? y + 1 : y);
    float *restrict gx = grad->plane[0] + (size_t)y * W;
    float *restrict gy = grad->plane[1] + (size_t)y * W;
    float *restrict on = zon + (size_t)y * W;
    if (!has_grad) {
#pragma omp simd
      for (int x = 0; x < W; x++) {
        gx[x] = smaller_diff(r[x + 1] - r[x], r[x] - r[x - 1]);
        gy[x] = smaller_diff(dn[x] - r[x], r[x] - up[x]);
      }
    }
#pragma omp simd
    for (int x = 0; x < W; x++) {
      const float g2 = gx[x] * gx[x] + gy[x] * gy[x];
      const int off = use_steep & (g2 > steep2 * r[x] * r[x]);
      on[x] = hush__select_bits(off, 0.0f, 1.0f);
    }
  }
}
