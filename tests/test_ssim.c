/*
 * test_ssim.c — SSIM and temporal error (src/eval/ssim.c): identical images
 * give exactly 1; constant images a and b give (2ab + C1) / (a^2 + b^2 + C1);
 * images with structure match a direct double-precision evaluation of Wang's
 * formula over every valid window; SSIM falls as noise grows; results do not
 * depend on the thread count; display luminance clamps and encodes as
 * documented; the temporal error of a static sequence is 0 and that of an
 * alternating one is the known difference.
 */
#include "check.h"

#include "core/rng.h"
#include "eval/ssim.h"
#include "io/tonemap.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define C1 (HUSH_SSIM_K1 * HUSH_SSIM_K1)
#define C2 (HUSH_SSIM_K2 * HUSH_SSIM_K2)

static float *plane(uint32_t w, uint32_t h) {
  float *p = malloc((size_t)w * h * sizeof *p);
  REQUIRE(p);
  return p;
}

static void fill_random(float *p, size_t n, uint32_t seed) {
  for (size_t i = 0; i < n; i++) p[i] = hush_rng_float(seed, 0, (uint32_t)i);
}

/* A smooth image with edges: what a denoised frame looks like. */
static void fill_pattern(float *p, uint32_t w, uint32_t h) {
  for (uint32_t y = 0; y < h; y++)
    for (uint32_t x = 0; x < w; x++)
      p[y * w + x] = 0.5f + 0.3f * sinf(0.21f * (float)x) * cosf(0.13f * (float)y) +
                     ((x / 8 + y / 8) % 2 ? 0.1f : -0.1f);
}

/* Gaussian noise of standard deviation sigma added to src (Box-Muller). */
static void add_noise(const float *src, float *dst, size_t n, double sigma, uint32_t seed) {
  for (size_t i = 0; i < n; i++) {
    const double u1 = 1.0 - hush_rng_float(seed, 1, (uint32_t)i);
    const double u2 = hush_rng_float(seed, 2, (uint32_t)i);
    dst[i] = src[i] + (float)(sigma * sqrt(-2.0 * log(u1)) * cos(6.283185307179586 * u2));
  }
}

/* Wang et al.'s formula straight from the definition, in double: for each
 * valid 11x11 window the weighted means, variances and covariance. */
static double ssim_reference(const float *x, const float *y, uint32_t w, uint32_t h) {
  double g[11], sum = 0.0;
  for (int i = 0; i < 11; i++) {
    g[i] = exp(-(i - 5.0) * (i - 5.0) / (2.0 * 1.5 * 1.5));
    sum += g[i];
  }
  for (int i = 0; i < 11; i++) g[i] /= sum;
  double total = 0.0;
  for (uint32_t oy = 0; oy + 11 <= h; oy++) {
    for (uint32_t ox = 0; ox + 11 <= w; ox++) {
      double mx = 0, my = 0;
      for (int j = 0; j < 11; j++)
        for (int i = 0; i < 11; i++) {
          const size_t k = (size_t)(oy + j) * w + ox + i;
          mx += g[j] * g[i] * x[k];
          my += g[j] * g[i] * y[k];
        }
      double vx = 0, vy = 0, cxy = 0;
      for (int j = 0; j < 11; j++)
        for (int i = 0; i < 11; i++) {
          const size_t k = (size_t)(oy + j) * w + ox + i;
          const double dx = x[k] - mx, dy = y[k] - my;
          vx += g[j] * g[i] * dx * dx;
          vy += g[j] * g[i] * dy * dy;
          cxy += g[j] * g[i] * dx * dy;
        }
      total += (2 * mx * my + C1) * (2 * cxy + C2) / ((mx * mx + my * my + C1) * (vx + vy + C2));
    }
  }
  return total / ((double)(w - 10) * (h - 10));
}

static double ssim_of(const float *x, const float *y, uint32_t w, uint32_t h, int threads) {
  double s = -2.0;
  CHECK(hush__ssim(x, y, w, h, threads, &s) == HUSH_OK);
  return s;
}

static void test_identical(void) {
  const uint32_t w = 67, h = 45;
  float *a = plane(w, h);
  fill_random(a, (size_t)w * h, 1);
  CHECK(ssim_of(a, a, w, h, 0) == 1.0);
  fill_pattern(a, w, h);
  CHECK(ssim_of(a, a, w, h, 2) == 1.0);
  free(a);
}

static void test_constant(void) {
  const uint32_t w = 32, h = 24;
  float *a = plane(w, h), *b = plane(w, h);
  const double va = 0.3, vb = 0.6;
  for (size_t i = 0; i < (size_t)w * h; i++) {
    a[i] = (float)va;
    b[i] = (float)vb;
  }
  /* float inputs: use the values the images really hold */
  const double fa = (float)va, fb = (float)vb;
  CHECK_NEAR(ssim_of(a, b, w, h, 0), (2 * fa * fb + C1) / (fa * fa + fb * fb + C1), 1e-9);
  CHECK_NEAR(ssim_of(b, a, w, h, 0), (2 * fa * fb + C1) / (fa * fa + fb * fb + C1), 1e-9);
  free(a);
  free(b);
}

static void test_formula(void) {
  /* one window exactly (11x11), then many */
  const uint32_t sizes[][2] = {{11, 11}, {29, 17}};
  for (int s = 0; s < 2; s++) {
    const uint32_t w = sizes[s][0], h = sizes[s][1];
    float *a = plane(w, h), *b = plane(w, h);
    fill_pattern(a, w, h);
    add_noise(a, b, (size_t)w * h, 0.1, 7);
    const double want = ssim_reference(a, b, w, h);
    CHECK(want > 0.1 && want < 0.99);
    CHECK_NEAR(ssim_of(a, b, w, h, 0), want, 1e-9);
    /* a structural change of known sign: the negated image correlates -1 */
    for (size_t i = 0; i < (size_t)w * h; i++) b[i] = 1.0f - a[i];
    CHECK_NEAR(ssim_of(a, b, w, h, 0), ssim_reference(a, b, w, h), 1e-9);
    CHECK(ssim_of(a, b, w, h, 0) < 0.0);
    free(a);
    free(b);
  }
}

static void test_noise_and_threads(void) {
  const uint32_t w = 160, h = 90;
  float *a = plane(w, h), *b = plane(w, h);
  fill_pattern(a, w, h);
  double last = 1.0;
  const double sigmas[] = {0.01, 0.03, 0.1, 0.3};
  for (int i = 0; i < 4; i++) {
    add_noise(a, b, (size_t)w * h, sigmas[i], 3);
    const double s = ssim_of(a, b, w, h, 0);
    CHECK_MSG(s < last, "sigma %g: SSIM %g, not below %g", sigmas[i], s, last);
    last = s;
    CHECK(ssim_of(a, b, w, h, 1) == ssim_of(a, b, w, h, 3));
  }
  free(a);
  free(b);
}

static void test_small_and_bad(void) {
  /* smaller than the window: the centred taps that fit, still 1 and finite */
  float a[5 * 7], b[5 * 7];
  fill_random(a, 35, 4);
  fill_random(b, 35, 5);
  CHECK(ssim_of(a, a, 5, 7, 0) == 1.0);
  const double s = ssim_of(a, b, 5, 7, 0);
  CHECK(isfinite(s) && s < 1.0);
  CHECK(ssim_of(a, b, 1, 1, 0) <= 1.0);
  double out = 5.0;
  CHECK(hush__ssim(a, b, 0, 7, 0, &out) == HUSH_ERROR_INVALID_ARGUMENT && out == 0.0);
}

static void test_display_luma(void) {
  CHECK(hush__display_luma(0, 0, 0) == 0.0f);
  CHECK_NEAR(hush__display_luma(1, 1, 1), 1.0, 1e-6);
  CHECK(hush__display_luma(8, 9, 10) == hush__display_luma(1, 1, 1)); /* clamped */
  CHECK(hush__display_luma(-1, -1, -1) == 0.0f);
  CHECK(hush__display_luma(NAN, 0, 0) == 0.0f);
  CHECK_NEAR(hush__display_luma(0.2f, 0.2f, 0.2f), hush__srgb_encode(0.2f), 1e-6);
  /* Rec. 709 weights of the linear values, then sRGB */
  CHECK_NEAR(hush__display_luma(1, 0, 0), hush__srgb_encode(0.2126f), 1e-6);
  CHECK_NEAR(hush__display_luma(0, 1, 0), hush__srgb_encode(0.7152f), 1e-6);
  const float rgba[8] = {0.5f, 0.5f, 0.5f, 9.0f, 0, 0, 1, 9.0f};
  float y[2];
  hush__display_luma_plane(rgba, 4, 2, y);
  CHECK_NEAR(y[0], hush__srgb_encode(0.5f), 1e-6);
  CHECK_NEAR(y[1], hush__srgb_encode(0.0722f), 1e-6);
}

static void test_temporal(void) {
  enum { N = 1000 };
  float f0[N], f1[N];
  fill_random(f0, N, 9);
  CHECK(hush__temporal_error(f0, f0, N) == 0.0);
  /* a sequence alternating between 0.25 and 0.75 (or 0.75 and 0.25): 0.5 */
  for (int i = 0; i < N; i++) {
    f0[i] = i % 2 ? 0.25f : 0.75f;
    f1[i] = i % 2 ? 0.75f : 0.25f;
  }
  CHECK(hush__temporal_error(f0, f1, N) == 0.5);
  CHECK(hush__temporal_error(f1, f0, N) == 0.5);
  /* half the pixels change by 0.2: 0.1 */
  memcpy(f1, f0, sizeof f0);
  for (int i = 0; i < N / 2; i++) f1[i] += 0.2f;
  CHECK_NEAR(hush__temporal_error(f0, f1, N), 0.1, 1e-7);
  CHECK(hush__temporal_error(f0, f1, 0) == 0.0);
}

int main(void) {
  test_identical();
  test_constant();
  test_formula();
  test_noise_and_threads();
  test_small_and_bad();
  test_display_luma();
  test_temporal();
  return check_summary();
}
