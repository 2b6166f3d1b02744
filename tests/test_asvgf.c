/*
 * test_asvgf.c — A-SVGF: the shared temporal-gradient module
 * (src/temporal/gradient.h) on synthetic gradient layers, and the "asvgf"
 * filter through the public API.
 */
#include "hush.h"

#include "check.h"
#include "temporal/gradient.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- synthetic frames for the gradient module ------------------------------ */

typedef struct gframe {
  uint32_t w, h;
  float *grad[3]; /* c, p, landing index */
  float *depth, *normal[3], *dgrad[2], *lum;
  float *lambda, *scratch;
} gframe;

static void gframe_init(gframe *g, uint32_t w, uint32_t h) {
  const size_t n = (size_t)w * h;
  g->w = w;
  g->h = h;
  for (int k = 0; k < 3; k++) g->grad[k] = calloc(n, sizeof(float));
  g->depth = calloc(n, sizeof(float));
  for (int k = 0; k < 3; k++) g->normal[k] = calloc(n, sizeof(float));
  for (int k = 0; k < 2; k++) g->dgrad[k] = calloc(n, sizeof(float));
  g->lum = calloc(n, sizeof(float));
  g->lambda = calloc(n, sizeof(float));
  g->scratch = calloc(hush__gradient_scratch_floats(w, h), sizeof(float));
  REQUIRE(g->grad[2] && g->normal[2] && g->dgrad[1] && g->lambda && g->scratch && g->lum);
  for (size_t i = 0; i < n; i++) {
    g->depth[i] = 2.0f;
    g->normal[2][i] = 1.0f;
    g->lum[i] = 0.5f;
  }
}

static void gframe_free(gframe *g) {
  for (int k = 0; k < 3; k++) free(g->grad[k]);
  free(g->depth);
  for (int k = 0; k < 3; k++) free(g->normal[k]);
  for (int k = 0; k < 2; k++) free(g->dgrad[k]);
  free(g->lum);
  free(g->lambda);
  free(g->scratch);
}

/* Stratum (sx, sy)'s sample: c, p at landing index k (-1: none), written
 * over the stratum's pixels as the renderer does. */
static void put_sample(gframe *g, int sx, int sy, float c, float p, int k) {
  for (int y = 3 * sy; y < 3 * sy + 3 && y < (int)g->h; y++)
    for (int x = 3 * sx; x < 3 * sx + 3 && x < (int)g->w; x++) {
      const size_t i = (size_t)y * g->w + x;
      g->grad[0][i] = k >= 0 ? c : 0.0f;
      g->grad[1][i] = k >= 0 ? p : 0.0f;
      g->grad[2][i] = (float)k;
    }
}

static hush_gradient_params default_params(void) {
  hush_gradient_params p;
  p.iterations = 3;
  p.sigma_z = 1.0f;
  p.sigma_n = 128.0f;
  p.sigma_l = 4.0f;
  p.exponent = 1.0f;
  return p;
}

static void compute(gframe *g, const hush_gradient_params *p, int threads) {
  hush_gradient_guides gd;
  gd.depth = g->depth;
  for (int k = 0; k < 3; k++) gd.normal[k] = g->normal[k];
  gd.depth_grad[0] = g->dgrad[0];
  gd.depth_grad[1] = g->dgrad[1];
  gd.luminance = g->lum;
  hush__gradient_lambda((const float *const *)g->grad, &gd, g->w, g->h, p, g->scratch, g->lambda,
                        threads);
}

static float lambda_at(const gframe *g, int x, int y) { return g->lambda[(size_t)y * g->w + x]; }

/* c = p everywhere: lambda exactly 0; c = 0 < p everywhere: exactly 1. */
static void test_lambda_extremes(void) {
  gframe g;
  gframe_init(&g, 50, 31); /* partial strata at the right and bottom */
  const int ws = (50 + 2) / 3, hs = (31 + 2) / 3;
  for (int iters = 0; iters <= HUSH_GRADIENT_MAX_ITERATIONS; iters++) {
    hush_gradient_params p = default_params();
    p.iterations = iters;
    for (int sy = 0; sy < hs; sy++)
      for (int sx = 0; sx < ws; sx++) put_sample(&g, sx, sy, 0.3f + 0.01f * sx, 0.3f + 0.01f * sx, (sx + sy) % 9);
    compute(&g, &p, 2);
    int zero = 1;
    for (size_t i = 0; i < (size_t)g.w * g.h; i++) zero &= g.lambda[i] == 0.0f;
    CHECK_MSG(zero, "c = p: lambda not 0 (iterations %d)", iters);
    for (int sy = 0; sy < hs; sy++)
      for (int sx = 0; sx < ws; sx++) put_sample(&g, sx, sy, 0.0f, 0.7f, 4);
    compute(&g, &p, 2);
    int one = 1;
    for (size_t i = 0; i < (size_t)g.w * g.h; i++) one &= g.lambda[i] == 1.0f;
    CHECK_MSG(one, "c = 0 < p: lambda not 1 (iterations %d)", iters);
    /* half the light: |delta| / max = 0.5, squared with exponent 2 */
    for (int sy = 0; sy < hs; sy++)
      for (int sx = 0; sx < ws; sx++) put_sample(&g, sx, sy, 0.2f, 0.4f, 0);
    p.exponent = 2.0f;
    compute(&g, &p, 1);
    CHECK_NEAR(lambda_at(&g, 25, 15), 0.25f, 1e-4f);
    CHECK_NEAR(lambda_at(&g, 49, 30), 0.25f, 1e-4f);
  }
  /* no sample anywhere: no evidence of change */
  for (int sy = 0; sy < hs; sy++)
    for (int sx = 0; sx < ws; sx++) put_sample(&g, sx, sy, 0.0f, 0.0f, -1);
  hush_gradient_params p = default_params();
  compute(&g, &p, 2);
  int zero = 1;
  for (size_t i = 0; i < (size_t)g.w * g.h; i++) zero &= g.lambda[i] == 0.0f;
  CHECK(zero);
  gframe_free(&g);
}

/* Left half at depth 2 unchanged, right half at depth 5 went dark: the
 * reconstruction keeps each side's lambda up to the edge. Also: a lone
 * changed stratum in an unchanged region is spread out and diluted (an
 * illumination change is never seen on a single stratum), a stratum without
 * sample takes its neighbours' lambda, and the result does not depend on
 * the thread count. */
static void test_depth_edge(void) {
  gframe g;
  gframe_init(&g, 60, 30);
  const int ws = 20, hs = 10;
  for (int y = 0; y < 30; y++)
    for (int x = 0; x < 60; x++) g.depth[y * 60 + x] = x < 30 ? 2.0f : 5.0f;
  for (int sy = 0; sy < hs; sy++)
    for (int sx = 0; sx < ws; sx++) {
      const int right = sx >= 10;
      put_sample(&g, sx, sy, right ? 0.0f : 0.5f, 0.5f, (sx * 7 + sy) % 9);
    }
  put_sample(&g, 3, 4, 0.0f, 0.0f, -1); /* no sample */
  put_sample(&g, 15, 4, 0.0f, 0.0f, -1);
  hush_gradient_params p = default_params();
  p.iterations = 5;
  compute(&g, &p, 2);
  float left_max = 0.0f, right_min = 1.0f;
  for (int y = 0; y < 30; y++)
    for (int x = 0; x < 60; x++) {
      const float l = lambda_at(&g, x, y);
      if (x < 30) left_max = l > left_max ? l : left_max;
      else right_min = l < right_min ? l : right_min;
    }
  CHECK_MSG(left_max < 1e-6f, "leak into the unchanged side: %g", (double)left_max);
  CHECK_MSG(right_min > 1.0f - 1e-6f, "leak into the changed side: %g", (double)right_min);

  /* one stratum changed in a flat unchanged wall */
  for (int y = 0; y < 30; y++)
    for (int x = 0; x < 60; x++) g.depth[y * 60 + x] = 2.0f;
  for (int sy = 0; sy < hs; sy++)
    for (int sx = 0; sx < ws; sx++) put_sample(&g, sx, sy, 0.5f, 0.5f, 4);
  put_sample(&g, 10, 5, 0.0f, 0.5f, 4);
  p.iterations = 0;
  compute(&g, &p, 2);
  CHECK(lambda_at(&g, 31, 16) == 1.0f);
  CHECK(lambda_at(&g, 34, 16) == 0.0f);
  p.iterations = 3;
  compute(&g, &p, 1);
  const float centre = lambda_at(&g, 31, 16), next = lambda_at(&g, 34, 16);
  CHECK_MSG(centre > 0.0f && centre < 0.5f, "centre %g", (double)centre);
  CHECK_MSG(next > 0.0f && next < centre, "neighbour %g", (double)next);
  const size_t n = (size_t)g.w * g.h;
  float *one = malloc(n * sizeof(float));
  REQUIRE(one);
  memcpy(one, g.lambda, n * sizeof(float));
  compute(&g, &p, 3);
  CHECK(memcmp(one, g.lambda, n * sizeof(float)) == 0);
  free(one);
  gframe_free(&g);
}

/* A normal edge (same depth) keeps lambda apart too. */
static void test_normal_edge(void) {
  gframe g;
  gframe_init(&g, 30, 30);
  const float r = sqrtf(0.5f);
  for (int y = 0; y < 30; y++)
    for (int x = 0; x < 30; x++)
      if (y >= 15) {
        g.normal[0][y * 30 + x] = r;
        g.normal[2][y * 30 + x] = r;
      }
  for (int sy = 0; sy < 10; sy++)
    for (int sx = 0; sx < 10; sx++) put_sample(&g, sx, sy, sy >= 5 ? 1.0f : 0.5f, 0.5f, 8);
  hush_gradient_params p = default_params();
  compute(&g, &p, 2);
  CHECK(lambda_at(&g, 10, 14) < 1e-6f);
  CHECK_NEAR(lambda_at(&g, 10, 15), 0.5f, 1e-5f);
  gframe_free(&g);
}

/* The history rules: lambda 0 keeps the age, lambda 1 gives 1, in between
 * the new frame's weight max(alpha, 1/lowered) is the rule's. */
static void test_lower_age(void) {
  enum { n = 6 };
  const float lambda[n] = {0.0f, 1.0f, 0.5f, 0.5f, 0.05f, 1.0f};
  const float age[n] = {32.0f, 32.0f, 32.0f, 2.0f, 32.0f, 1.0f};
  float out[n];
  size_t c = hush__gradient_lower_age(lambda, age, out, n, HUSH_HISTORY_SCHIED, 0.2f, 32, 1);
  CHECK(out[0] == 32.0f);
  CHECK(out[1] == 1.0f);
  CHECK_NEAR(1.0f / out[2], 0.5f * 0.2f + 0.5f, 1e-6f);
  CHECK_NEAR(1.0f / out[3], 0.5f * 0.5f + 0.5f, 1e-6f);
  CHECK_NEAR(1.0f / out[4], 0.95f * 0.2f + 0.05f, 1e-6f);
  CHECK(out[5] == 1.0f);
  CHECK(c == 4);
  c = hush__gradient_lower_age(lambda, age, out, n, HUSH_HISTORY_HIGGINSON, 0.2f, 32, 2);
  CHECK(out[0] == 32.0f);
  CHECK(out[1] == 1.0f);
  const float np = 31.0f / 1024.0f + 1.0f;
  CHECK_NEAR(1.0f / out[2], 0.5f / np + 0.5f, 1e-6f);
  /* a small change leaves the alpha floor in charge: no change */
  CHECK(out[4] == 32.0f);
  CHECK(c == 3);
  /* in place, and no change at all for lambda 0 */
  float same[n];
  memcpy(same, age, sizeof same);
  const float none[n] = {0};
  CHECK(hush__gradient_lower_age(none, same, same, n, HUSH_HISTORY_SCHIED, 0.2f, 32, 2) == 0);
  CHECK(memcmp(same, age, sizeof same) == 0);
}

int main(void) {
  test_lambda_extremes();
  test_depth_edge();
  test_normal_edge();
  test_lower_age();
  return check_summary();
}
