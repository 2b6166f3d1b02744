/*
 * test_taa.c — the TAA resolve (src/temporal/taa.h; Karis 2014 as
 * papers/NOTES.md summarises it) against a per-pixel statement of its
 * definition: the history gathered through the plan's taps, clamped or
 * clipped to the min/max box of the current 3x3 neighbourhood (clamped at
 * the image border) in YCoCg, blended with weight alpha, on tone-mapped
 * values when asked; no history -> the current frame. The plan mixes
 * bilinear, 3x3 and no-history pixels at random, so the vectorised rows,
 * the border columns and the 3x3 fix-up are all compared; a plan without
 * blocks (every pixel through its taps) must give the same image, and the
 * fused remodulation must equal resolving color * max(albedo, eps). A plan
 * of smooth motion exercises the contiguous-load chunks, and the thread
 * count (row bands) must not change a bit.
 */
#include "hush.h"

#include "check.h"
#include "core/image.h"
#include "filters/albedo.h"
#include "temporal/reproject.h"
#include "temporal/taa.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

static uint32_t rng_state = 12345u;
static float frand(void) {
  rng_state = rng_state * 1664525u + 1013904223u;
  return (float)(rng_state >> 8) * (1.0f / 16777216.0f);
}

static void ycocg(const float c[3], float v[3]) {
  v[0] = 0.25f * c[0] + 0.5f * c[1] + 0.25f * c[2];
  v[1] = 0.5f * c[0] - 0.5f * c[2];
  v[2] = -0.25f * c[0] + 0.5f * c[1] - 0.25f * c[2];
}
static float luma(const float c[3]) { return 0.2126f * c[0] + 0.7152f * c[1] + 0.0722f * c[2]; }

/* The definition, one pixel at a time, in double where it does not matter. */
static void reference(const hush_reproject_plan *plan, const float *const *color,
                      const float *const *hist, const hush_taa_params *p, int W, int H,
                      float *const *out) {
  for (int y = 0; y < H; y++)
    for (int x = 0; x < W; x++) {
      const size_t i = (size_t)y * W + x;
      float c[3], cur[3];
      for (int k = 0; k < 3; k++) c[k] = color[k][i];
      const float s = p->tonemap ? 1.0f / (1.0f + fmaxf(luma(c), 0.0f)) : 1.0f;
      for (int k = 0; k < 3; k++) c[k] *= s;
      ycocg(c, cur);
      float res[3] = {c[0], c[1], c[2]};
      int32_t idx[9];
      float w[9];
      const int n = plan ? hush__reproject_taps(plan, i, idx, w) : 0;
      if (n) {
        float h[3], hy[3], lo[3], hi[3];
        for (int k = 0; k < 3; k++) h[k] = hush__reproject_apply(hist[k], idx, w, n);
        const float hs = p->tonemap ? 1.0f / (1.0f + fmaxf(luma(h), 0.0f)) : 1.0f;
        for (int k = 0; k < 3; k++) h[k] *= hs;
        ycocg(h, hy);
        for (int k = 0; k < 3; k++) lo[k] = hi[k] = cur[k];
        for (int j = -1; j <= 1; j++)
          for (int l = -1; l <= 1; l++) {
            const int yy = y + j < 0 ? 0 : y + j >= H ? H - 1 : y + j;
            const int xx = x + l < 0 ? 0 : x + l >= W ? W - 1 : x + l;
            const size_t q = (size_t)yy * W + xx;
            float cq[3], v[3];
            for (int k = 0; k < 3; k++) cq[k] = color[k][q];
            const float sq = p->tonemap ? 1.0f / (1.0f + fmaxf(luma(cq), 0.0f)) : 1.0f;
            for (int k = 0; k < 3; k++) cq[k] *= sq;
            ycocg(cq, v);
            for (int k = 0; k < 3; k++) {
              lo[k] = fminf(lo[k], v[k]);
              hi[k] = fmaxf(hi[k], v[k]);
            }
          }
        if (p->box == HUSH_TAA_CLIP) {
          float t = 1.0f;
          for (int k = 0; k < 3; k++) {
            const float ctr = 0.5f * (lo[k] + hi[k]), e = 0.5f * (hi[k] - lo[k]) + 1e-7f;
            const float a = fabsf(hy[k] - ctr);
            if (a > e) t = fminf(t, e / a);
          }
          for (int k = 0; k < 3; k++) {
            const float ctr = 0.5f * (lo[k] + hi[k]);
            hy[k] = ctr + (hy[k] - ctr) * t;
          }
        } else {
          for (int k = 0; k < 3; k++) hy[k] = fminf(fmaxf(hy[k], lo[k]), hi[k]);
        }
        float m[3];
        for (int k = 0; k < 3; k++) m[k] = hy[k] + p->alpha * (cur[k] - hy[k]);
        res[0] = m[0] + m[1] - m[2];
        res[1] = m[0] + m[2];
        res[2] = m[0] - m[1] - m[2];
      }
      const float u = p->tonemap ? 1.0f / (1.0f - fminf(fmaxf(luma(res), 0.0f), 0.999999f)) : 1.0f;
      for (int k = 0; k < 3; k++) out[k][i] = res[k] * u;
    }
}

/* A plan of random footprints: 70 % bilinear (random mask and fractions),
 * 15 % 3x3 (random mask), 15 % none. */
static void random_plan(hush_reproject_plan *plan, int W, int H) {
  for (size_t i = 0; i < (size_t)W * H; i++) {
    const float u = frand();
    plan->w[0][i] = plan->w[1][i] = plan->w[2][i] = plan->w[3][i] = 0.0f;
    if (u < 0.7f) {
      const int ox = (int)(frand() * (float)(W - 1)), oy = (int)(frand() * (float)(H - 1));
      plan->kind[i] = HUSH_FOOTPRINT_BILINEAR;
      plan->origin[i] = oy * W + ox;
      plan->mask[i] = (uint16_t)(1 + (int)(frand() * 15.0f));
      const float fx = 0.05f + 0.9f * frand();
      const float fy = 0.05f + 0.9f * frand();
      float w[4];
      hush__reproject_renormalised(plan->mask[i], fx, fy, w);
      for (int t = 0; t < 4; t++) plan->w[t][i] = w[t];
    } else if (u < 0.85f) {
      const int ox = (int)(frand() * (float)(W - 2)), oy = (int)(frand() * (float)(H - 2));
      plan->kind[i] = HUSH_FOOTPRINT_3X3;
      plan->origin[i] = oy * W + ox;
      plan->mask[i] = (uint16_t)(1 + (int)(frand() * 511.0f));
    } else {
      plan->kind[i] = HUSH_FOOTPRINT_NONE;
      plan->origin[i] = 0;
      plan->mask[i] = 0;
    }
  }
  plan->blocks = 1;
}

static float max_rel_diff(const hush_planar *a, float *const *b, size_t n) {
  float worst = 0.0f;
  for (int k = 0; k < 3; k++)
    for (size_t i = 0; i < n; i++) {
      const float d = fabsf(a->plane[k][i] - b[k][i]) / (1.0f + fabsf(b[k][i]));
      worst = d > worst || d != d ? d : worst;
    }
  return worst;
}

/* Two frames: the first without history (the output is the frame), the
 * second through a random plan, against reference(). */
static void test_resolve(hush_device dev, hush_taa_box box, int tonemap, int threads) {
  const int W = 37, H = 23; /* odd: vector tails and both border columns */
  const size_t n = (size_t)W * H;
  hush_planar color[2], albedo, expect, modulated;
  for (int f = 0; f < 2; f++) REQUIRE(hush__planar_init(dev, &color[f], 3, W, H) == HUSH_OK);
  REQUIRE(hush__planar_init(dev, &albedo, 3, W, H) == HUSH_OK);
  REQUIRE(hush__planar_init(dev, &expect, 3, W, H) == HUSH_OK);
  REQUIRE(hush__planar_init(dev, &modulated, 3, W, H) == HUSH_OK);
  for (int f = 0; f < 2; f++)
    for (int k = 0; k < 3; k++)
      for (size_t i = 0; i < n; i++) color[f].plane[k][i] = 3.0f * frand() * frand();
  for (int k = 0; k < 3; k++)
    for (size_t i = 0; i < n; i++) {
      albedo.plane[k][i] = frand() < 0.1f ? 0.0f : frand(); /* some below eps */
      modulated.plane[k][i] = color[1].plane[k][i] * fmaxf(albedo.plane[k][i], HUSH_ALBEDO_EPS);
    }
  hush_reproject_plan plan;
  REQUIRE(hush__reproject_plan_init(dev, &plan, (uint32_t)W, (uint32_t)H) == HUSH_OK);
  random_plan(&plan, W, H);
  hush_taa_params p = {0.2f, box, tonemap, NULL};

  hush_taa taa, taa3;
  REQUIRE(hush__taa_init(dev, &taa, W, H) == HUSH_OK);
  /* frame 0: no history anywhere, through the plan or without one */
  hush__taa_resolve(&taa, &plan, (const float *const *)color[0].plane, &p, threads);
  reference(NULL, (const float *const *)color[0].plane, NULL, &p, W, H, expect.plane);
  CHECK_MSG(max_rel_diff(hush__taa_output(&taa), expect.plane, n) < 1e-5f, "frame 0: %g",
            (double)max_rel_diff(hush__taa_output(&taa), expect.plane, n));
  REQUIRE(hush__taa_init(dev, &taa3, W, H) == HUSH_OK);
  hush__taa_resolve(&taa3, NULL, (const float *const *)color[0].plane, &p, threads);

  /* frame 1: the history through the plan */
  const hush_planar *hist = hush__taa_output(&taa);
  reference(&plan, (const float *const *)color[1].plane, (const float *const *)hist->plane, &p, W,
            H, expect.plane);
  hush__taa_resolve(&taa, &plan, (const float *const *)color[1].plane, &p, threads);
  const float d = max_rel_diff(hush__taa_output(&taa), expect.plane, n);
  CHECK_MSG(d < 2e-5f, "box %d tonemap %d threads %d: max relative difference %g", (int)box,
            tonemap, threads, (double)d);
  /* the history made a difference (the test is not vacuous) */
  float moved = 0.0f;
  for (size_t i = 0; i < n; i++)
    moved = fmaxf(moved, fabsf(hush__taa_output(&taa)->plane[1][i] - color[1].plane[1][i]));
  CHECK(moved > 1e-2f);

  /* every pixel through its taps (no blocks): the same image */
  plan.blocks = 0;
  hush__taa_resolve(&taa3, &plan, (const float *const *)color[1].plane, &p, threads);
  plan.blocks = 1;
  CHECK(max_rel_diff(hush__taa_output(&taa3), hush__taa_output(&taa)->plane, n) < 1e-6f);

  /* fused remodulation == resolving the remodulated colour */
  {
    hush_taa a, b;
    REQUIRE(hush__taa_init(dev, &a, W, H) == HUSH_OK);
    REQUIRE(hush__taa_init(dev, &b, W, H) == HUSH_OK);
    hush__taa_resolve(&a, NULL, (const float *const *)color[0].plane, &p, threads);
    hush__taa_resolve(&b, NULL, (const float *const *)color[0].plane, &p, threads);
    hush__taa_resolve_modulated(&a, &plan, (const float *const *)color[1].plane,
                                (const float *const *)albedo.plane, &p, threads);
    hush__taa_resolve(&b, &plan, (const float *const *)modulated.plane, &p, threads);
    CHECK(max_rel_diff(hush__taa_output(&a), hush__taa_output(&b)->plane, n) == 0.0f);
    hush__taa_free(&a);
    hush__taa_free(&b);
  }

  hush__taa_free(&taa);
  hush__taa_free(&taa3);
  hush__reproject_plan_free(&plan);
  for (int f = 0; f < 2; f++) hush__planar_free(&color[f]);
  hush__planar_free(&albedo);
  hush__planar_free(&expect);
  hush__planar_free(&modulated);
}

/*
 * Smooth motion: rows whose block origins run consecutively (a whole-pixel
 * shift: the contiguous-load chunks), rows whose shift steps by one pixel
 * part-way (chunks whose taps form a window, read with permutes where
 * AVX-512 is built, else from two diagonals), a band of 3x3 and no-history
 * pixels; on
 * a frame of odd size, against reference(); the result is the same bit for
 * bit whatever the thread count (each thread resolves its own band of
 * rows), down to a frame too short for one band per thread.
 */
static void test_resolve_smooth(hush_device dev, int H) {
  const int W = 70;
  const size_t n = (size_t)W * H;
  hush_planar color[2], expect;
  for (int f = 0; f < 2; f++) REQUIRE(hush__planar_init(dev, &color[f], 3, W, H) == HUSH_OK);
  REQUIRE(hush__planar_init(dev, &expect, 3, W, H) == HUSH_OK);
  for (int f = 0; f < 2; f++)
    for (int k = 0; k < 3; k++)
      for (size_t i = 0; i < n; i++) color[f].plane[k][i] = 2.0f * frand() * frand();
  hush_reproject_plan plan;
  REQUIRE(hush__reproject_plan_init(dev, &plan, (uint32_t)W, (uint32_t)H) == HUSH_OK);
  int runs = 0;
  for (int y = 0; y < H; y++)
    for (int x = 0; x < W; x++) {
      const size_t i = (size_t)y * W + x;
      const int dx = y % 3 == 0 ? (x < W / 3 ? 1 : 2) : 1, dy = y % 2; /* steps on rows 0 mod 3 */
      const int ox = x + dx < W - 1 ? x + dx : W - 2, oy = y + dy < H - 1 ? y + dy : H - 2;
      plan.w[0][i] = plan.w[1][i] = plan.w[2][i] = plan.w[3][i] = 0.0f;
      if (y == H / 2 && x % 7 == 3) {
        plan.kind[i] = x % 2 ? HUSH_FOOTPRINT_3X3 : HUSH_FOOTPRINT_NONE;
        plan.origin[i] = oy > 0 ? (oy - 1) * W + (ox > 0 ? ox - 1 : 0) : 0;
        plan.mask[i] = plan.kind[i] == HUSH_FOOTPRINT_NONE ? 0 : 0x1ff;
        continue;
      }
      plan.kind[i] = HUSH_FOOTPRINT_BILINEAR;
      plan.origin[i] = oy * W + ox;
      plan.mask[i] = frand() < 0.9f ? 15 : (uint16_t)(1 + (int)(frand() * 14.0f));
      const float fx = 0.05f + 0.9f * frand();
      const float fy = 0.05f + 0.9f * frand();
      float w[4];
      hush__reproject_renormalised(plan.mask[i], fx, fy, w);
      for (int t = 0; t < 4; t++) plan.w[t][i] = w[t];
      runs += ox == x + 1 && plan.kind[i] == HUSH_FOOTPRINT_BILINEAR;
    }
  plan.blocks = 1;
  CHECK(runs > (int)n / 3);
  hush_taa_params p = {0.2f, HUSH_TAA_CLAMP, 1, NULL};
  hush_planar outs[4];
  for (int threads = 1; threads <= 4; threads++) {
    hush_taa taa;
    REQUIRE(hush__taa_init(dev, &taa, W, H) == HUSH_OK);
    hush__taa_resolve(&taa, NULL, (const float *const *)color[0].plane, &p, threads);
    const hush_planar *hist = hush__taa_output(&taa);
    if (threads == 1)
      reference(&plan, (const float *const *)color[1].plane, (const float *const *)hist->plane,
                &p, W, H, expect.plane);
    hush__taa_resolve(&taa, &plan, (const float *const *)color[1].plane, &p, threads);
    const float d = max_rel_diff(hush__taa_output(&taa), expect.plane, n);
    CHECK_MSG(d < 2e-5f, "smooth motion, H %d, threads %d: max relative difference %g", H,
              threads, (double)d);
    REQUIRE(hush__planar_init(dev, &outs[threads - 1], 3, W, H) == HUSH_OK);
    for (int k = 0; k < 3; k++)
      memcpy(outs[threads - 1].plane[k], hush__taa_output(&taa)->plane[k], n * sizeof(float));
    hush__taa_free(&taa);
  }
  for (int t = 1; t < 4; t++)
    for (int k = 0; k < 3; k++)
      CHECK_MSG(memcmp(outs[t].plane[k], outs[0].plane[k], n * sizeof(float)) == 0,
                "H %d: %d threads differ from 1", H, t + 1);
  for (int t = 0; t < 4; t++) hush__planar_free(&outs[t]);
  hush__reproject_plan_free(&plan);
  for (int f = 0; f < 2; f++) hush__planar_free(&color[f]);
  hush__planar_free(&expect);
}

/* Frames of 1 and 2 rows (fewer than the three rows of a thread's ring),
 * with more threads than rows: against reference(), without and with a
 * plan (2 rows: random bilinear and no-history footprints). */
static void test_resolve_tiny(hush_device dev) {
  for (int H = 1; H <= 2; H++) {
    const int W = 19;
    const size_t n = (size_t)W * H;
    hush_planar color[2], expect;
    for (int f = 0; f < 2; f++) REQUIRE(hush__planar_init(dev, &color[f], 3, W, H) == HUSH_OK);
    REQUIRE(hush__planar_init(dev, &expect, 3, W, H) == HUSH_OK);
    for (int f = 0; f < 2; f++)
      for (int k = 0; k < 3; k++)
        for (size_t i = 0; i < n; i++) color[f].plane[k][i] = 2.0f * frand();
    hush_reproject_plan plan;
    REQUIRE(hush__reproject_plan_init(dev, &plan, (uint32_t)W, (uint32_t)H) == HUSH_OK);
    if (H == 2) { /* bilinear footprints (all inside two rows) and no-history pixels */
      random_plan(&plan, W, H);
      for (size_t i = 0; i < n; i++)
        if (plan.kind[i] == HUSH_FOOTPRINT_3X3) {
          plan.kind[i] = HUSH_FOOTPRINT_NONE;
          plan.origin[i] = 0;
          plan.mask[i] = 0;
        }
    }
    hush_taa_params p = {0.2f, HUSH_TAA_CLAMP, 1, NULL};
    hush_taa taa;
    REQUIRE(hush__taa_init(dev, &taa, W, H) == HUSH_OK);
    hush__taa_resolve(&taa, NULL, (const float *const *)color[0].plane, &p, 4);
    reference(NULL, (const float *const *)color[0].plane, NULL, &p, W, H, expect.plane);
    CHECK_MSG(max_rel_diff(hush__taa_output(&taa), expect.plane, n) < 1e-5f, "H %d, frame 0", H);
    if (H == 2) {
      reference(&plan, (const float *const *)color[1].plane,
                (const float *const *)hush__taa_output(&taa)->plane, &p, W, H, expect.plane);
      hush__taa_resolve(&taa, &plan, (const float *const *)color[1].plane, &p, 4);
      CHECK_MSG(max_rel_diff(hush__taa_output(&taa), expect.plane, n) < 2e-5f, "H 2, frame 1");
    }
    hush__taa_free(&taa);
    hush__reproject_plan_free(&plan);
    for (int f = 0; f < 2; f++) hush__planar_free(&color[f]);
    hush__planar_free(&expect);
  }
}

/*
 * Frames with holes (hush__taa_resolve_holes; Dundr 2018 §4.2.6, docs/holes.md):
 * with every pixel traced it is the definition above; a hole never blends
 * its (absent) sample: it keeps its history, clamped to the box of its
 * traced neighbours, or takes their mean without history, or is flagged
 * (valid 0) with neither; the colour at a hole is never read.
 */
static void test_resolve_holes(hush_device dev, int threads) {
  const int W = 29, H = 17;
  const size_t n = (size_t)W * H;
  hush_planar color, garbage, expect, valid;
  REQUIRE(hush__planar_init(dev, &color, 3, W, H) == HUSH_OK);
  REQUIRE(hush__planar_init(dev, &garbage, 3, W, H) == HUSH_OK);
  REQUIRE(hush__planar_init(dev, &expect, 3, W, H) == HUSH_OK);
  REQUIRE(hush__planar_init(dev, &valid, 1, W, H) == HUSH_OK);
  float *spp = malloc(n * sizeof(float));
  REQUIRE(spp);
  for (int k = 0; k < 3; k++)
    for (size_t i = 0; i < n; i++) color.plane[k][i] = 0.1f + 2.0f * frand() * frand();
  hush_reproject_plan plan;
  REQUIRE(hush__reproject_plan_init(dev, &plan, (uint32_t)W, (uint32_t)H) == HUSH_OK);
  random_plan(&plan, W, H);
  for (int tonemap = 0; tonemap < 2; tonemap++) {
    /* every pixel traced: the definition */
    hush_taa_params p = {0.2f, HUSH_TAA_CLAMP, tonemap, NULL};
    hush_taa a;
    REQUIRE(hush__taa_init(dev, &a, W, H) == HUSH_OK);
    for (size_t i = 0; i < n; i++) spp[i] = 1.0f;
    hush__taa_resolve(&a, NULL, (const float *const *)color.plane, &p, threads);
    const hush_planar *hist = hush__taa_output(&a);
    reference(&plan, (const float *const *)color.plane, (const float *const *)hist->plane, &p, W,
              H, expect.plane);
    CHECK(hush__taa_resolve_holes(&a, &plan, (const float *const *)color.plane, spp, 0, &p,
                                  valid.plane[0], threads) == 0);
    CHECK_MSG(max_rel_diff(hush__taa_output(&a), expect.plane, n) < 2e-5f,
              "all traced, tonemap %d: %g", tonemap,
              (double)max_rel_diff(hush__taa_output(&a), expect.plane, n));
    hush__taa_free(&a);
  }
  /* one pixel in eight traced, linear values: the hole rules one by one */
  hush_taa_params p = {0.2f, HUSH_TAA_CLAMP, 0, NULL};
  for (size_t i = 0; i < n; i++) spp[i] = frand() < 0.125f ? 1.0f : 0.0f;
  for (int k = 0; k < 3; k++)
    for (size_t i = 0; i < n; i++) garbage.plane[k][i] = spp[i] > 0.0f ? color.plane[k][i] : 1e6f;
  hush_taa a, b;
  REQUIRE(hush__taa_init(dev, &a, W, H) == HUSH_OK);
  REQUIRE(hush__taa_init(dev, &b, W, H) == HUSH_OK);
  hush__taa_resolve(&a, NULL, (const float *const *)color.plane, &p, threads);
  hush__taa_resolve(&b, NULL, (const float *const *)color.plane, &p, threads);
  float *const *hist = hush__taa_output(&a)->plane; /* the history of both */
  for (int k = 0; k < 3; k++) memcpy(expect.plane[k], hist[k], n * sizeof(float));
  const int missing = hush__taa_resolve_holes(&a, &plan, (const float *const *)color.plane, spp, 0,
                                              &p, valid.plane[0], threads);
  hush__taa_resolve_holes(&b, &plan, (const float *const *)garbage.plane, spp, 0, &p, valid.plane[0],
                          threads);
  CHECK_MSG(max_rel_diff(hush__taa_output(&a), hush__taa_output(&b)->plane, n) == 0.0f,
            "the colour at a hole was read");
  const hush_planar *out = hush__taa_output(&a);
  int bad_keep = 0, bad_box = 0, bad_mean = 0, bad_flag = 0, flagged = 0, kept = 0;
  for (int y = 0; y < H; y++)
    for (int x = 0; x < W; x++) {
      const size_t i = (size_t)y * W + x;
      if (spp[i] > 0.0f) continue;
      float lo[3] = {1e30f, 1e30f, 1e30f}, hi[3] = {-1e30f, -1e30f, -1e30f}, sum[3] = {0, 0, 0};
      int m = 0;
      for (int j = y - 1; j <= y + 1; j++)
        for (int q = x - 1; q <= x + 1; q++) {
          if (j < 0 || q < 0 || j >= H || q >= W || !(spp[(size_t)j * W + q] > 0.0f)) continue;
          float c[3], v[3];
          for (int k = 0; k < 3; k++) c[k] = color.plane[k][(size_t)j * W + q];
          ycocg(c, v);
          for (int k = 0; k < 3; k++) {
            lo[k] = fminf(lo[k], v[k]);
            hi[k] = fmaxf(hi[k], v[k]);
            sum[k] += c[k];
          }
          m++;
        }
      int32_t idx[9];
      float w[9];
      const int taps = hush__reproject_taps(&plan, i, idx, w);
      float o[3], ov[3], h[3];
      for (int k = 0; k < 3; k++) o[k] = out->plane[k][i];
      ycocg(o, ov);
      if (taps) {
        for (int k = 0; k < 3; k++) h[k] = hush__reproject_apply(expect.plane[k], idx, w, taps);
        if (!m) {
          kept++;
          for (int k = 0; k < 3; k++) bad_keep += fabsf(o[k] - h[k]) > 1e-5f * (1.0f + h[k]);
        } else {
          for (int k = 0; k < 3; k++) bad_box += ov[k] < lo[k] - 1e-5f || ov[k] > hi[k] + 1e-5f;
        }
      } else if (m) {
        for (int k = 0; k < 3; k++) bad_mean += fabsf(o[k] - sum[k] / (float)m) > 1e-5f;
      } else {
        flagged++;
        bad_flag += valid.plane[0][i] != 0.0f;
      }
    }
  CHECK_MSG(!bad_keep && !bad_box && !bad_mean && !bad_flag,
            "holes: %d kept wrong (of %d), %d outside the traced box, %d not the traced mean, "
            "%d not flagged",
            bad_keep, kept, bad_box, bad_mean, bad_flag);
  CHECK(kept > 0 && flagged > 0 && missing == 1);
  hush__taa_free(&a);
  hush__taa_free(&b);
  hush__reproject_plan_free(&plan);
  hush__planar_free(&color);
  hush__planar_free(&garbage);
  hush__planar_free(&expect);
  hush__planar_free(&valid);
  free(spp);
}

int main(void) {
  hush_device dev = hush_device_new(NULL);
  REQUIRE(dev != NULL);
  for (int box = 0; box < 2; box++)
    for (int tonemap = 0; tonemap < 2; tonemap++)
      for (int threads = 1; threads <= 2; threads++)
        test_resolve(dev, (hush_taa_box)box, tonemap, threads);
  test_resolve_smooth(dev, 29);
  test_resolve_smooth(dev, 7); /* two bands of three rows at most */
  test_resolve_tiny(dev);
  test_resolve_holes(dev, 1);
  test_resolve_holes(dev, 2);
  hush_device_release(dev);
  return check_summary();
}
