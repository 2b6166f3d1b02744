/*
 * adaptive.c — adaptive BMFR (adaptive.h): the gradient layer imported,
 * lambda, phase I's history lowered and its colour blended again.
 * Schied, Peters, Dachsbacher 2018 §4.3-4.4; docs/asvgf.md.
 */
#include "filters/bmfr/adaptive.h"

#include "core/hmath.h"

#include <stdlib.h>

void bmfr_adaptive_free(bmfr_adaptive *ad) {
  hush__planar_free(&ad->gradient);
  hush__planar_free(&ad->lambda);
  hush__planar_free(&ad->lowered);
  hush__planar_free(&ad->color);
  free(ad->scratch);
  ad->scratch = NULL;
}

hush_status bmfr_adaptive_import(hush_filter f, bmfr_adaptive *ad, int image) {
  if (!hush__filter_view(f, image))
    return hush__fail(f->device, HUSH_ERROR_INVALID_OPERATION,
                      "bmfr: temporal_gradients is on but the image 'gradient' (hush render "
                      "--gradients) is not bound");
  hush_status s;
  if ((s = hush__filter_scratch(f, &ad->gradient, 3)) ||
      (s = hush__filter_scratch(f, &ad->lambda, 1)) ||
      (s = hush__filter_scratch(f, &ad->lowered, 1)) ||
      (s = hush__filter_scratch(f, &ad->color, 3)))
    return s;
  if (!ad->scratch) {
    ad->scratch =
        hush__alloc_counted(hush__gradient_scratch_floats(f->width, f->height), sizeof(float));
    if (!ad->scratch) return hush__fail(f->device, HUSH_ERROR_OUT_OF_MEMORY, "bmfr: out of memory");
  }
  return hush__filter_import(f, image, &ad->gradient);
}

/* Where lowered < age: the colour blended again and the lowered age
 * replace the first blend's (selected without a branch). */
static void take_lowered(const bmfr_adaptive *ad, hush_accum *acc, size_t n, int threads) {
  float *restrict age = hush__accum_age(acc)->plane[0];
  hush_planar *color = hush__accum_color(acc);
  const float *restrict low = ad->lowered.plane[0];
  float *restrict r = color->plane[0], *restrict g = color->plane[1], *restrict b = color->plane[2];
  const float *restrict nr = ad->color.plane[0], *restrict ng = ad->color.plane[1],
                        *restrict nb = ad->color.plane[2];
#pragma omp parallel for simd schedule(static) num_threads(threads)
  for (size_t i = 0; i < n; i++) {
    const int take = low[i] < age[i];
    r[i] = hush__select_bits(take, nr[i], r[i]);
    g[i] = hush__select_bits(take, ng[i], g[i]);
    b[i] = hush__select_bits(take, nb[i], b[i]);
    age[i] = hush__select_bits(take, low[i], age[i]);
  }
}

size_t bmfr_adaptive_history(bmfr_adaptive *ad, hush_accum *acc, int had_history,
                             const hush_reproject_plan *plan, const float *const sample[3],
                             const hush_accum_params *ap, const float *depth,
                             const float *const normal[3], int threads) {
  const uint32_t W = ad->lambda.width, H = ad->lambda.height;
  hush_gradient_guides gd;
  gd.depth = depth;
  for (int k = 0; k < 3; k++) gd.normal[k] = normal[k];
  gd.depth_grad[0] = gd.depth_grad[1] = NULL; /* bmfr takes no depth gradient: flat */
  gd.luminance = NULL;                        /* the samples' own luminance */
  hush__gradient_lambda((const float *const *)ad->gradient.plane, &gd, W, H, &ad->params,
                        ad->scratch, ad->lambda.plane[0], threads);
  if (!had_history) return 0;
  const size_t n = (size_t)W * H;
  const size_t lowered = hush__gradient_lower_age(ad->lambda.plane[0], hush__accum_age(acc)->plane[0],
                                                  ad->lowered.plane[0], n, ad->rule, ap->alpha_min,
                                                  ap->max_age, threads);
  if (!lowered) return 0;
  /* the set the blend read is still there: it wrote the other one */
  const int prev = 1 - acc->latest;
  hush__temporal_blend(plan, (const float *const *)acc->color[prev].plane, sample, 3,
                       ad->lowered.plane[0], ap->alpha_min, ad->color.plane, threads);
  take_lowered(ad, acc, n, threads);
  return lowered;
}
