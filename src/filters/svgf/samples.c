/*
 * samples.c — the per-pixel sample variance of a > 1 spp renderer merged
 * into the SVGF moments (see samples.h; Dundr 2018 §4.3).
 */
#include "filters/svgf/samples.h"

#include "core/hmath.h"
#include "filters/albedo.h"
#include "temporal/reproject.h" /* hush__select_bits */

static inline float clamp_albedo(float a) { return a > HUSH_ALBEDO_EPS ? a : HUSH_ALBEDO_EPS; }

void svgf_merge_samples(const svgf_samples *s, hush_planar *moments, const float *age,
                        float *var, float *samples, int threads) {
  const int H = (int)moments->height, W = (int)moments->width;
  const float amin = s->alpha_moments_min;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < H; y++) {
    const size_t o = (size_t)y * W;
    const float *restrict spp = s->spp + o, *restrict a = age + o;
    const float *restrict m1 = moments->plane[0] + o;
    float *restrict m2 = moments->plane[1] + o, *restrict v = var + o, *restrict ns = samples + o;
    {
      const float *restrict sv = s->variance + o;
      const float *restrict c0 = s->color->plane[0] + o, *restrict c1 = s->color->plane[1] + o,
                            *restrict c2 = s->color->plane[2] + o;
      const float *a0 = s->albedo ? s->albedo->plane[0] + o : NULL;
      const float *a1 = s->albedo ? s->albedo->plane[1] + o : NULL;
      const float *a2 = s->albedo ? s->albedo->plane[2] + o : NULL;
      for (int x = 0; x < W; x++) {
        const float n = spp[x] > 1.0f ? spp[x] : 1.0f;
        /* the renderer's variance is of the luminance before demodulation:
         * scale by (demodulated / raw luminance)^2 of this pixel's mean */
        float k = 1.0f;
        if (a0) {
          const float ar = clamp_albedo(a0[x]), ag = clamp_albedo(a1[x]), ab = clamp_albedo(a2[x]);
          const float ld = hush_luminance(c0[x], c1[x], c2[x]);
          const float lr = hush_luminance(c0[x] * ar, c1[x] * ag, c2[x] * ab);
          k = lr > 1e-8f ? ld / lr : 1.0f / hush_luminance(ar, ag, ab);
        }
        const float within = k * k * (sv[x] > 0.0f ? sv[x] : 0.0f) * (n - 1.0f) / n;
        const float am = 1.0f / a[x] > amin ? 1.0f / a[x] : amin;
        m2[x] += am * within;
      }
    }
#pragma omp simd
    for (int x = 0; x < W; x++) {
      const float d = m2[x] - m1[x] * m1[x];
      v[x] = hush__select_bits(d > 0.0f, d, 0.0f);
      ns[x] = a[x] * (spp[x] > 1.0f ? spp[x] : 1.0f);
    }
  }
}

void svgf_variance_per_frame(const float *spp, float *var, size_t n, int threads) {
  const long long count = (long long)n;
#pragma omp parallel for simd schedule(static) num_threads(threads)
  for (long long i = 0; i < count; i++) var[i] /= spp[i] > 1.0f ? spp[i] : 1.0f;
}
