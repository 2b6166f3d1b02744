/*
 * adaptive.c — the adaptive temporal stage of A-SVGF (adaptive.h):
 * gradient import, lambda, history lowered and blended again.
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
  hush__planar_free(&ad->color);
  hush__planar_free(&ad->moments);
  free(ad->scratch);
  ad->scratch = NULL;
}

hush_status svgf_adaptive_import(hush_filter f, svgf_adaptive *ad) {
  hush_status s;
  if ((s = hush__filter_scratch(f, &ad->gradient, 3)) || (s = hush__filter_scratch(f, &ad->lambda, 1)) ||
      (s = hush__filter_scratch(f, &ad->lum, 1)) || (s = hush__filter_scratch(f, &ad->lowered, 1)) ||
      (s = hush__filter_scratch(f, &ad->color, 3)) || (s = hush__filter_scratch(f, &ad->moments, 4)))
    return s;
  if (!ad->scratch) {
    ad->scratch = malloc(hush__gradient_scratch_floats(f->width, f->height) * sizeof(float));
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
    for (size_t i = 0; i < n; i++) lum[i] = hush_luminance(r[i] + r2[i], g[i] + g2[i], b[i] + b2[i]);
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

/* Where lowered < age: the blends again, the lowered age and the variance
 * replace the first blend's. */
static void take_lowered(const svgf_adaptive *ad, hush_accum *acc, float *variance, size_t n,
                         int threads) {
  float *age = hush__accum_age(acc)->plane[0];
  hush_planar *color = hush__accum_color(acc), *mom = hush__accum_moments(acc);
  const float *low = ad->lowered.plane[0];
#pragma omp parallel for simd schedule(static) num_threads(threads)
  for (size_t i = 0; i < n; i++) {
    const int take = low[i] < age[i];
    for (int c = 0; c < 3; c++)
      color->plane[c][i] = hush__select_bits(take, ad->color.plane[c][i], color->plane[c][i]);
    const float m1 = hush__select_bits(take, ad->moments.plane[0][i], mom->plane[0][i]);
    const float m2 = hush__select_bits(take, ad->moments.plane[1][i], mom->plane[1][i]);
    mom->plane[0][i] = m1;
    mom->plane[1][i] = m2;
    if (variance) {
      const float v = m2 - m1 * m1;
      variance[i] = hush__select_bits(take, v > 0.0f ? v : 0.0f, variance[i]);
    }
    age[i] = hush__select_bits(take, low[i], age[i]);
  }
}

void svgf_adaptive_history(svgf_adaptive *ad, hush_accum *acc, int had_history,
                           const hush_reproject_plan *plan, const float *const sample[3],
                           const hush_accum_params *ap, float *variance, int threads) {
  if (!had_history) return;
  const size_t n = hush__planar_pixels(&ad->lambda);
  const float *age = hush__accum_age(acc)->plane[0];
  if (!hush__gradient_lower_age(ad->lambda.plane[0], age, ad->lowered.plane[0], n, ad->rule,
                                ap->alpha_min, ap->max_age, threads))
    return;
  /* the set the blend read is still there: it writes the other one */
  const int prev = 1 - acc->latest;
  float *restrict l = ad->moments.plane[2], *restrict l2 = ad->moments.plane[3];
  const float *restrict r = sample[0], *restrict g = sample[1], *restrict b = sample[2];
#pragma omp parallel for simd schedule(static) num_threads(threads)
  for (size_t i = 0; i < n; i++) {
    const float y = hush_luminance(r[i], g[i], b[i]);
    l[i] = y;
    l2[i] = y * y;
  }
  hush__temporal_blend(plan, (const float *const *)acc->color[prev].plane, sample, 3,
                       ad->lowered.plane[0], ap->alpha_min, ad->color.plane, threads);
  const float *const smom[2] = {l, l2};
  float *const omom[2] = {ad->moments.plane[0], ad->moments.plane[1]};
  hush__temporal_blend(plan, (const float *const *)acc->moments[prev].plane, smom, 2,
                       ad->lowered.plane[0], ap->alpha_moments_min, omom, threads);
  take_lowered(ad, acc, variance, n, threads);
}
