/*
 * metrics.c — RMSE, relative MSE and PSNR of an image against a reference
 * (the per-frame error measures of bmfr-koskela-2019.md §7.1 and
 * realtime-denoising-comparison-higginson-2023.md §3.5).
 */
#include "eval/metrics.h"

#include <math.h>

static inline double clamp01(double v) { return v < 0.0 ? 0.0 : v > 1.0 ? 1.0 : v; }

hush_error_stats hush__error_stats(const float *x, const float *ref, size_t count, int channels) {
  hush_error_stats s = {0, 0, 0, INFINITY};
  const size_t n = count * (size_t)channels;
  if (n == 0) return s;
  double se = 0.0, rel = 0.0, se_clamped = 0.0;
  for (size_t i = 0; i < n; i++) {
    const double d = (double)x[i] - (double)ref[i];
    const double dc = clamp01(x[i]) - clamp01(ref[i]);
    se += d * d;
    rel += d * d / ((double)ref[i] * ref[i] + 0.01);
    se_clamped += dc * dc;
  }
  s.mse = se / (double)n;
  s.rmse = sqrt(s.mse);
  s.rel_mse = rel / (double)n;
  s.psnr = se_clamped > 0.0 ? 10.0 * log10((double)n / se_clamped) : INFINITY;
  return s;
}
