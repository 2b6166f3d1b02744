/*
 * adaptive.c — the adaptive temporal stage of A-SVGF (adaptive.h):
 * gradient import, lambda, history lowered and the blend redone.
 * Schied, Peters, Dachsbacher 2018 §4.3-4.4; docs/asvgf.md.
 */
#include "filters/svgf/adaptive.h"

#include "core/hmath.h"

#include <stdlib.h>
#include <string.h>

void svgf_adaptive_free(svgf_adaptive *ad) {
  hush__planar_free(&ad->gradient);
  hush__planar_free(&ad->lambda);
  hush__planar_free(&ad->lum);
  hush__planar_free(&ad->lowered);
  free(ad->scratch);
  ad->scratch = NULL;
}

hush_status svgf_adaptive_import(hush_filter f, svgf_adaptive *ad) {
  hush_status s;
  if ((s = hush__filter_scratch(f, &ad->gradient, 3)) ||
      (s = hush__filter_scratch(f, &ad->lambda, 1)) || (s = hush__filter_scratch(f, &ad->lum, 1)) ||
      (s = hush__filter_scratch(f, &ad->lowered, 1)))
    return s;
  if (!ad->scratch) {
    ad->scratch =
        hush__alloc_counted(hush__gradient_scratch_floats(f->width, f->height), sizeof(float));
    if (!ad->scratch)
      return hush__fail(f->device, HUSH_ERROR_OUT_OF_MEMORY, "asvgf: out of memory");
  }
  /* the class table marks it required, so filter.c already refused an
   * unbound layer; say so here too for any other caller */
  if (!hush__filter_view(f, ad->image))
    return hush__fail(f->device, HUSH_ERROR_INVALID_OPERATION,
                      "asvgf: image 'gradient' (hush render --gradients) is not bound");
  return hush__filter_import(f, ad->image, &ad->gradient);
}

/* lum <- luminance of color (+ second). */
static void luminance(const float *const color[3], const float *const second[3], float *lum,
                      size_t n, int threads) {
  const float *restrict r = color[0], *restrict g = color[1], *restrict b = color[2];
  if (second) {
    const float *restrict r2 = second[0], *restrict g2 = second[1], *restrict b2 = second[2];
#pragma omp parallel for simd schedule(static) num_threads(threads)
    for (size_t i = 0; i < n; i++)
      lum[i] = hush_luminance(r[i] + r2[i], g[i] + g2[i], b[i] + b2[i]);
  } else {
#pragma omp parallel for simd schedule(static) num_threads(threads)
    for (size_t i = 0; i < n; i++) lum[i] = hush_luminance(r[i], g[i], b[i]);
  }
}

void svgf_adaptive_lambda(svgf_adaptive *ad, const float *depth, const float *const normal[3],
                          const float *gx, const float *gy, const float *const color[3],
                          const float *const second[3], int threads) {
  const uint32_t W = ad->lambda.width, H = ad->lambda.height;
  luminance(color, second, ad->lum.plane[0], hush__planar_pixels(&ad->lum), threads);
  hush_gradient_guides gd;
  gd.depth = depth;
  for (int k = 0; k < 3; k++) gd.normal[k] = normal[k];
  gd.depth_grad[0] = gx;
  gd.depth_grad[1] = gy;
  gd.luminance = ad->lum.plane[0];
  hush__gradient_lambda((const float *const *)ad->gradient.plane, &gd, W, H, &ad->params,
                        ad->scratch, ad->lambda.plane[0], threads);
}

/* Where lowered < age: the blend redone with the new frame's weight
 * a' = max(alpha, 1 / lowered) instead of the blend's a = max(alpha, 1 / age)
 * (am, am' for the moments with alpha_moments), without gathering the
 * history again: the blend gave c = (1 - a) h + a x, so
 *   c' = (1 - a') h + a' x = (1 - a') / (1 - a) (c - a x) + a' x.
 * Lowered pixels have a < 1 (age > 1 and alpha < 1, else nothing is
 * lowered). The variance is updated from the new moments; the age becomes
 * the lowered one. One pass, no branch. */
static void rescale(const svgf_adaptive *ad, hush_accum *acc, const float *const sample[3],
                    const hush_accum_params *ap, float *restrict variance, size_t n,
                    int threads) {
  float *restrict age = hush__accum_age(acc)->plane[0];
  hush_planar *color = hush__accum_color(acc), *mom = hush__accum_moments(acc);
  float *restrict cr = color->plane[0], *restrict cg = color->plane[1],
                  *restrict cb = color->plane[2];
  float *restrict m1p = mom->plane[0], *restrict m2p = mom->plane[1];
  const float *restrict xr = sample[0], *restrict xg = sample[1], *restrict xb = sample[2];
  const float *restrict low = ad->lowered.plane[0];
  const float alpha = ap->alpha_min, alpha_m = ap->alpha_moments_min;
#pragma omp parallel for simd schedule(static) num_threads(threads)
  for (size_t i = 0; i < n; i++) {
    const float A = age[i], L = low[i];
    const int take = L < A;
    const float invA = 1.0f / hush__select_bits(A > 1.0f, A, 1.0f);
    const float invL = 1.0f / hush__select_bits(L > 1.0f, L, 1.0f);
    const float a = hush__select_bits(alpha > invA, alpha, invA);
    const float a2 = hush__select_bits(alpha > invL, alpha, invL);
    const float am = hush__select_bits(alpha_m > invA, alpha_m, invA);
    const float am2 = hush__select_bits(alpha_m > invL, alpha_m, invL);
    const float k = (1.0f - a2) / hush__select_bits(1.0f - a > 1e-6f, 1.0f - a, 1.0f);
    const float km = (1.0f - am2) / hush__select_bits(1.0f - am > 1e-6f, 1.0f - am, 1.0f);
    const float r = k * (cr[i] - a * xr[i]) + a2 * xr[i];
    const float g = k * (cg[i] - a * xg[i]) + a2 * xg[i];
    const float b = k * (cb[i] - a * xb[i]) + a2 * xb[i];
    const float y = hush_luminance(xr[i], xg[i], xb[i]);
    const float m1 = km * (m1p[i] - am * y) + am2 * y;
    const float m2 = km * (m2p[i] - am * y * y) + am2 * y * y;
    cr[i] = hush__select_bits(take, r, cr[i]);
    cg[i] = hush__select_bits(take, g, cg[i]);
    cb[i] = hush__select_bits(take, b, cb[i]);
    m1p[i] = hush__select_bits(take, m1, m1p[i]);
    m2p[i] = hush__select_bits(take, m2, m2p[i]);
    const float v = m2 - m1 * m1;
    variance[i] = hush__select_bits(take, hush__select_bits(v > 0.0f, v, 0.0f), variance[i]);
    age[i] = hush__select_bits(take, L, A);
  }
}

void svgf_adaptive_history(svgf_adaptive *ad, hush_accum *acc, int had_history,
                           const float *const sample[3], const hush_accum_params *ap,
                           float *variance, int threads) {
  if (!had_history) return;
  const size_t n = hush__planar_pixels(&ad->lambda);
  const float *age = hush__accum_age(acc)->plane[0];
  if (!hush__gradient_lower_age(ad->lambda.plane[0], age, ad->lowered.plane[0], n, ad->rule,
                                ap->alpha_min, ap->max_age, threads))
    return;
  rescale(ad, acc, sample, ap, variance, n, threads);
}
