/*
 * metrics.h — image error metrics against a reference, on planar or
 * interleaved float RGB: RMSE, relative MSE (Rousselle et al.: mean of
 * (x - r)^2 / (r^2 + eps)) and PSNR (peak 1, on clamped values). Computed in
 * double over the whole image; all channels weigh the same.
 */
#ifndef HUSH_EVAL_METRICS_H
#define HUSH_EVAL_METRICS_H

#include <stddef.h>

typedef struct hush_error_stats {
  double mse;     /* mean over pixels and channels of (x - r)^2 */
  double rmse;    /* sqrt(mse) */
  double rel_mse; /* mean of (x - r)^2 / (r^2 + 0.01) */
  double psnr;    /* 10 log10(1 / mse) on values clamped to [0, 1]; +inf when equal */
} hush_error_stats;

/* x and ref: `count` interleaved pixels of `channels` floats each. */
hush_error_stats hush__error_stats(const float *x, const float *ref, size_t count, int channels);

#endif
