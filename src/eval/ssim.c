/*
 * ssim.c — SSIM (Wang et al. 2004) and the temporal error of Schied et al.
 * 2017 on display luminance (definitions in ssim.h), the perceptual columns
 * of bmfr-koskela-2019.md Tables 2-3 and
 * realtime-denoising-comparison-higginson-2023.md Table 3.1.
 *
 * SSIM needs five Gaussian-weighted local moments (mean of x, y, x^2, y^2,
 * xy). The window is separable, so a horizontal pass writes the five
 * row-filtered rows over the valid columns into a per-thread ring of 11
 * rows, and a vertical pass finishes the moments of one output row at a
 * time into a scratch row, where the SSIM of the row is summed. Both inner loops run over x, so they
 * vectorise. The moments are accumulated in double: the variances are
 * differences of nearly equal numbers (E[x^2] - E[x]^2) that float would
 * get wrong by ~1e-7, which is 1e-4 of C2. Sums of the SSIM map are kept per row and added in row order
 * so the result does not depend on the thread count.
 */
#include "eval/ssim.h"

#include "io/tonemap.h"

#include <math.h>
#include <omp.h>
#include <stdlib.h>
#include <string.h>

enum { MOMENTS = 5 }; /* x, y, x^2, y^2, x*y */

float hush__display_luma(float r, float g, float b) {
  const float y = 0.2126f * r + 0.7152f * g + 0.0722f * b;
  if (!(y > 0.0f)) return 0.0f; /* also NaN */
  return hush__srgb_encode(y < 1.0f ? y : 1.0f);
}

void hush__display_luma_plane(const float *rgb, int channels, size_t count, float *luma) {
  for (size_t i = 0; i < count; i++) {
    const float *p = rgb + i * (size_t)channels;
    luma[i] = hush__display_luma(p[0], p[1], p[2]);
  }
}

/* Taps of the window along an axis of n pixels: 11, or the largest odd
 * count that fits, so a small image still has one centred window. */
static uint32_t window_taps(uint32_t n) {
  if (n >= HUSH_SSIM_WINDOW) return HUSH_SSIM_WINDOW;
  return n % 2 ? n : n - 1;
}

/* The 1-D Gaussian of `taps` weights, centred, summing to 1. The 2-D
 * window is its outer product, which then also sums to 1. */
static void gaussian(uint32_t taps, double *g) {
  const double r = 0.5 * (double)(taps - 1);
  double w[HUSH_SSIM_WINDOW], sum = 0.0;
  for (uint32_t i = 0; i < taps; i++) {
    const double d = (double)i - r;
    w[i] = exp(-d * d / (2.0 * HUSH_SSIM_SIGMA * HUSH_SSIM_SIGMA));
    sum += w[i];
  }
  for (uint32_t i = 0; i < taps; i++) g[i] = w[i] / sum;
}

/* Row `row` of x and y filtered horizontally: the five moments over the ow
 * valid columns, into out (five arrays of ow doubles). */
static void horizontal_row(const float *restrict x, const float *restrict y, uint32_t width,
                           uint32_t row, const double *g, uint32_t taps, uint32_t ow,
                           double *restrict out) {
  const float *xr = x + (size_t)row * width, *yr = y + (size_t)row * width;
  double *restrict mx = out, *restrict my = mx + ow, *restrict mxx = my + ow,
                   *restrict myy = mxx + ow, *restrict mxy = myy + ow;
  memset(out, 0, (size_t)MOMENTS * ow * sizeof *out);
  for (uint32_t t = 0; t < taps; t++) {
    const double w = g[t];
    const float *xs = xr + t, *ys = yr + t;
    for (uint32_t i = 0; i < ow; i++) {
      const double a = xs[i], b = ys[i];
      mx[i] += w * a;
      my[i] += w * b;
      mxx[i] += w * a * a;
      myy[i] += w * b * b;
      mxy[i] += w * a * b;
    }
  }
}

/* Output row oy from the ring of the `taps` horizontal rows oy .. oy+taps-1
 * (row r in slot r % taps): the vertical pass into the scratch row m (five
 * arrays of ow doubles), then the SSIM of each window, summed. */
static double ssim_row(const double *ring, uint32_t ow, uint32_t oy, const double *g,
                       uint32_t taps, double *restrict m) {
  double *restrict mx = m, *restrict my = m + ow, *restrict mxx = my + ow,
                   *restrict myy = mxx + ow, *restrict mxy = myy + ow;
  memset(m, 0, (size_t)MOMENTS * ow * sizeof *m);
  for (uint32_t t = 0; t < taps; t++) {
    const double w = g[t];
    const double *restrict hx = ring + (size_t)((oy + t) % taps) * MOMENTS * ow;
    const double *restrict hy = hx + ow, *restrict hxx = hy + ow, *restrict hyy = hxx + ow,
                           *restrict hxy = hyy + ow;
    for (uint32_t i = 0; i < ow; i++) {
      mx[i] += w * hx[i];
      my[i] += w * hy[i];
      mxx[i] += w * hxx[i];
      myy[i] += w * hyy[i];
      mxy[i] += w * hxy[i];
    }
  }
  const double c1 = HUSH_SSIM_K1 * HUSH_SSIM_K1, c2 = HUSH_SSIM_K2 * HUSH_SSIM_K2;
  double sum = 0.0;
  for (uint32_t i = 0; i < ow; i++) {
    /* Written so that x == y gives numerator == denominator bit for bit,
     * also where the compiler contracts a*b + c into an FMA: ab + ab has
     * the shape of aa + bb, and sxy + sxy that of sxx + syy. */
    const double a = mx[i], b = my[i];
    const double sxx = mxx[i] - a * a, syy = myy[i] - b * b, sxy = mxy[i] - a * b;
    const double num = (a * b + a * b + c1) * (sxy + sxy + c2);
    const double den = (a * a + b * b + c1) * (sxx + syy + c2);
    sum += num / den;
  }
  return sum;
}

/* One thread's band of output rows [first, last): the horizontal rows
 * go through a ring of `ky` rows that stays in cache, and each is made
 * once per band (bands overlap by ky - 1 input rows). */
static void ssim_band(const float *x, const float *y, uint32_t width, const double *gx,
                      uint32_t kx, const double *gy, uint32_t ky, uint32_t ow, uint32_t first,
                      uint32_t last, double *ring, double *m, double *row_sum) {
  const size_t slot = (size_t)MOMENTS * ow;
  if (first >= last) return;
  for (uint32_t r = first; r + 1 < first + ky; r++)
    horizontal_row(x, y, width, r, gx, kx, ow, ring + (r % ky) * slot);
  for (uint32_t oy = first; oy < last; oy++) {
    const uint32_t r = oy + ky - 1; /* the newest row this output needs */
    horizontal_row(x, y, width, r, gx, kx, ow, ring + (r % ky) * slot);
    row_sum[oy] = ssim_row(ring, ow, oy, gy, ky, m);
  }
}

hush_status hush__ssim(const float *x, const float *y, uint32_t width, uint32_t height,
                       int threads, double *ssim) {
  *ssim = 0.0;
  if (!x || !y || width == 0 || height == 0) return HUSH_ERROR_INVALID_ARGUMENT;
  const uint32_t kx = window_taps(width), ky = window_taps(height);
  const uint32_t ow = width - kx + 1, oh = height - ky + 1;
  double gx[HUSH_SSIM_WINDOW], gy[HUSH_SSIM_WINDOW];
  gaussian(kx, gx);
  gaussian(ky, gy);
  int nt = threads > 0 ? threads : omp_get_max_threads();
  if ((uint32_t)nt > oh) nt = (int)oh;
  /* per thread: the ring of ky horizontal rows and one scratch row */
  const size_t per_thread = (size_t)(ky + 1) * MOMENTS * ow;
  double *work = malloc((size_t)nt * per_thread * sizeof *work);
  double *row_sum = malloc((size_t)oh * sizeof *row_sum);
  if (!work || !row_sum) {
    free(work);
    free(row_sum);
    return HUSH_ERROR_OUT_OF_MEMORY;
  }
#pragma omp parallel num_threads(nt)
  {
    /* contiguous bands; each output row is computed the same way whichever
     * band holds it, so the sums do not depend on the thread count */
    const uint32_t t = (uint32_t)omp_get_thread_num(), n = (uint32_t)omp_get_num_threads();
    const uint32_t band = (oh + n - 1) / n;
    const uint32_t first = t * band < oh ? t * band : oh;
    const uint32_t last = first + band < oh ? first + band : oh;
    double *ring = work + (size_t)t * per_thread;
    ssim_band(x, y, width, gx, kx, gy, ky, ow, first, last, ring, ring + (size_t)ky * MOMENTS * ow,
              row_sum);
  }
  double sum = 0.0;
  for (uint32_t oy = 0; oy < oh; oy++) sum += row_sum[oy];
  *ssim = sum / ((double)ow * (double)oh);
  free(work);
  free(row_sum);
  return HUSH_OK;
}

double hush__temporal_error(const float *prev, const float *cur, size_t count) {
  if (count == 0) return 0.0;
  double sum = 0.0;
  for (size_t i = 0; i < count; i++) sum += fabs((double)cur[i] - (double)prev[i]);
  return sum / (double)count;
}
