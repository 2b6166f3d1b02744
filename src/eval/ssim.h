/*
 * ssim.h — the perceptual and temporal measures of hush eval, on display
 * luminance:
 *
 *   display luminance  Y = 0.2126 R + 0.7152 G + 0.0722 B of the LINEAR
 *                      radiance (Rec. 709 / sRGB primaries), clamped to
 *                      [0, 1], then sRGB-encoded (IEC 61966-2-1). NaN
 *                      counts as 0. No exposure, no tone curve: radiance 1
 *                      is display white, as in `hush render --png` without
 *                      --exposure.
 *   SSIM               Wang et al. 2004 on display luminance: an 11x11
 *                      Gaussian window of sigma 1.5 (normalised to sum 1),
 *                      K1 = 0.01, K2 = 0.03, L = 1 (C1 = (K1 L)^2,
 *                      C2 = (K2 L)^2), averaged over the VALID window
 *                      positions only (no padding: (W-10) x (H-10) values,
 *                      like Wang's reference MATLAB code). An image
 *                      narrower or lower than 11 pixels uses the centred
 *                      taps that fit, renormalised.
 *   temporal error     Schied et al. 2017: the mean absolute difference of
 *                      the display luminance of two consecutive frames.
 *                      hush eval computes it for each filter's output and
 *                      for the reference on the same pairs.
 *
 * Every function is deterministic: the same inputs give the same bits for
 * any thread count (partial sums are per row, added in order).
 */
#ifndef HUSH_EVAL_SSIM_H
#define HUSH_EVAL_SSIM_H

#include "hush.h"

#include <stddef.h>
#include <stdint.h>

#define HUSH_SSIM_WINDOW 11
#define HUSH_SSIM_SIGMA 1.5
#define HUSH_SSIM_K1 0.01
#define HUSH_SSIM_K2 0.03

/* Display luminance of one linear RGB value, as defined above. */
float hush__display_luma(float r, float g, float b);

/* Display luminance of `count` interleaved pixels of `channels` (>= 3)
 * floats into the plane `luma` (count floats). */
void hush__display_luma_plane(const float *rgb, int channels, size_t count, float *luma);

/*
 * Mean SSIM of two planar images (display luminance, values in [0, 1]) of
 * width x height. threads: OpenMP threads, 0 for the default.
 * Returns HUSH_ERROR_INVALID_ARGUMENT for an empty image and
 * HUSH_ERROR_OUT_OF_MEMORY if its work buffers cannot be allocated.
 */
hush_status hush__ssim(const float *x, const float *y, uint32_t width, uint32_t height,
                       int threads, double *ssim);

/* Mean absolute difference of two planes of `count` floats (0 for none). */
double hush__temporal_error(const float *prev, const float *cur, size_t count);

#endif
