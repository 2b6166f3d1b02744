/*
 * samples.h — more than one sample per pixel (Dundr 2018 §4.3): "the path
 * tracer computes the variance for us while blending the samples in a
 * single pixel. Later, we will mix this variance with previous frame's one
 * according to the sample count: all this time using the two-component
 * representation."
 *
 * A pixel of n samples with mean luminance mu and unbiased per-sample
 * variance s2 (the renderer's `spp` and `variance` layers, of the radiance's
 * luminance) has the per-sample second moment mu^2 + s2 (n-1)/n. The
 * temporal blend (accumulation.h) put mu^2 into the new frame's share of
 * m2; the merge adds the within-pixel part with the same weight,
 * max(alpha_moments, 1/age). The variance of one frame's pixel value, which
 * guides the luminance weight, is then (m2 - m1^2) / n, and a pixel counts
 * as having a temporal estimate once age * n samples reach the spatial
 * estimate's threshold (§4.4: "fall back to the default variance
 * calculation when two or more samples are available").
 */
#ifndef HUSH_FILTERS_SVGF_SAMPLES_H
#define HUSH_FILTERS_SVGF_SAMPLES_H

#include "core/image.h"

typedef struct svgf_samples {
  const float *spp;      /* samples per pixel (values below 1 count as 1) */
  const float *variance; /* per-sample luminance variance of the raw radiance */
  const hush_planar *color;  /* this frame, demodulated (3 planes) */
  const hush_planar *albedo; /* the demodulating albedo (3 planes), or NULL */
  float alpha_moments_min;
} svgf_samples;

/*
 * Merges the within-pixel variance into moments[1] (m2), rescaled from raw to demodulated luminance by the pixel's ratio of
 * the two; then var = max(0, m2 - m1^2) and samples = age * n (the sample
 * count behind the estimate). All planes unpadded, width x height.
 */
void svgf_merge_samples(const svgf_samples *s, hush_planar *moments, const float *age,
                        float *var, float *samples, int threads);

/* var /= n (the variance of one frame's pixel value). */
void svgf_variance_per_frame(const float *spp, float *var, size_t n, int threads);

#endif
