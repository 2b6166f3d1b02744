/*
 * test_metrics.c — error metrics: identical images give RMSE 0 and infinite
 * PSNR; a known constant offset gives its exact RMSE; Gaussian noise of
 * standard deviation sigma gives RMSE ~ sigma and PSNR ~ -20 log10(sigma);
 * relative MSE divides by the reference; PSNR compares clamped values.
 */
#include "check.h"

#include "core/rng.h"
#include "eval/metrics.h"

#include <math.h>

#define N (256 * 256)

static float a[N * 3], b[N * 3];

int main(void) {
  for (int i = 0; i < N * 3; i++) a[i] = b[i] = 0.25f + 0.5f * hush_rng_float(1, 0, (uint32_t)i);
  hush_error_stats s = hush__error_stats(a, b, N, 3);
  CHECK(s.rmse == 0.0 && s.mse == 0.0 && s.rel_mse == 0.0 && isinf(s.psnr));

  for (int i = 0; i < N * 3; i++) b[i] = a[i] + 0.125f;
  s = hush__error_stats(b, a, N, 3);
  CHECK_NEAR(s.rmse, 0.125, 1e-6);
  CHECK_NEAR(s.psnr, -20.0 * log10(0.125), 1e-4);

  /* Box-Muller noise, sigma = 0.05: PSNR = -20 log10(sigma) = 26.02 dB. */
  const double sigma = 0.05;
  for (int i = 0; i < N * 3; i++) {
    const double u1 = 1.0 - hush_rng_float(2, 0, (uint32_t)i), u2 = hush_rng_float(2, 1, (uint32_t)i);
    b[i] = a[i] + (float)(sigma * sqrt(-2.0 * log(u1)) * cos(6.283185307179586 * u2));
  }
  s = hush__error_stats(b, a, N, 3);
  CHECK_NEAR(s.rmse, sigma, sigma * 0.01);
  CHECK_NEAR(s.psnr, -20.0 * log10(sigma), 0.1);
  CHECK(hush__error_stats(a, b, 0, 3).rmse == 0.0);

  /* relative MSE divides by the REFERENCE (the second argument): x = 0.75,
   * r = 0.5 gives 0.0625 / (0.25 + 0.01); swapped, 0.0625 / (0.5625 + 0.01). */
  for (int i = 0; i < N * 3; i++) {
    a[i] = 0.75f;
    b[i] = 0.5f;
  }
  CHECK_NEAR(hush__error_stats(a, b, N, 3).rel_mse, 0.0625 / 0.26, 1e-9);
  CHECK_NEAR(hush__error_stats(b, a, N, 3).rel_mse, 0.0625 / 0.5725, 1e-9);
  /* PSNR clamps to [0, 1]: values above 1 compare as 1 */
  for (int i = 0; i < N * 3; i++) a[i] = 3.0f + (float)(i % 2);
  for (int i = 0; i < N * 3; i++) b[i] = 1.0f;
  CHECK(isinf(hush__error_stats(a, b, N, 3).psnr));
  CHECK(hush__error_stats(a, b, N, 3).rmse > 2.0);
  return check_summary();
}
