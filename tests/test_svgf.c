/*
 * test_svgf.c — the "svgf" filter (and "taa" when this build has it),
 * through the public API only, on synthetic G-buffers: a fronto-parallel
 * plane seen by a static camera (so all history is reused), with edges in
 * depth, normal or colour painted in.
 */
#include "hush.h"

#include "check.h"
#include "core/half.h"
#include "core/hmath.h"
#include "filters/svgf/atrous.h"
#include "filters/svgf/variance.h"
#include "filters/svgf/weights.h"

#include <float.h>

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define W 64
#define H 48
#define N (W * H)

typedef struct scene {
  float color[N * 3];
  float depth[N];
  float normal[N * 3];
  float albedo[N * 3];
  float output[N * 3];
} scene;

static uint32_t rng_state = 12345u;
static float rnd(void) { /* uniform in [0, 1), xorshift32 */
  rng_state ^= rng_state << 13;
  rng_state ^= rng_state >> 17;
  rng_state ^= rng_state << 5;
  return (float)(rng_state >> 8) / 16777216.0f;
}

static void flat(scene *s, float r, float g, float b, float z) {
  for (int i = 0; i < N; i++) {
    s->color[3 * i + 0] = r;
    s->color[3 * i + 1] = g;
    s->color[3 * i + 2] = b;
    s->depth[i] = z;
    s->normal[3 * i + 0] = 0.0f;
    s->normal[3 * i + 1] = 0.0f;
    s->normal[3 * i + 2] = 1.0f;
    for (int c = 0; c < 3; c++) s->albedo[3 * i + c] = 1.0f;
  }
}

static hush_image_view view_of(void *data, hush_format format) {
  hush_image_view v;
  memset(&v, 0, sizeof v);
  v.data = data;
  v.format = format;
  v.width = W;
  v.height = H;
  return v;
}

static void frame_info(hush_frame_info *fi, uint64_t index) {
  hush_frame_info_init(fi);
  fi->frame_index = index;
  float w2v[16], v2c[16];
  hush_m4_look_at(w2v, hush_v3(0, 0, 5), hush_v3(0, 0, 0), hush_v3(0, 1, 0));
  hush_m4_perspective(v2c, 60.0f, (float)W / H, 0.1f, 100.0f);
  memcpy(fi->world_to_view, w2v, sizeof w2v);
  memcpy(fi->prev_world_to_view, w2v, sizeof w2v);
  memcpy(fi->view_to_clip, v2c, sizeof v2c);
  memcpy(fi->prev_view_to_clip, v2c, sizeof v2c);
}

static int has_image(const char *cls, const char *name) {
  const hush_filter_class_info *c = hush_filter_class_find(cls);
  for (uint32_t i = 0; c && i < c->image_count; i++)
    if (strcmp(c->images[i].name, name) == 0) return 1;
  return 0;
}

static hush_filter make(hush_device dev, const char *cls, scene *s, int with_albedo) {
  hush_filter f = hush_filter_new(dev, cls);
  REQUIRE(f);
  hush_image_view v = view_of(s->color, HUSH_FORMAT_FLOAT3);
  REQUIRE(hush_filter_set_image(f, "color", &v) == HUSH_OK);
  if (has_image(cls, "depth")) {
    v = view_of(s->depth, HUSH_FORMAT_FLOAT);
    REQUIRE(hush_filter_set_image(f, "depth", &v) == HUSH_OK);
  }
  if (has_image(cls, "normal")) {
    v = view_of(s->normal, HUSH_FORMAT_FLOAT3);
    REQUIRE(hush_filter_set_image(f, "normal", &v) == HUSH_OK);
  }
  if (with_albedo) {
    v = view_of(s->albedo, HUSH_FORMAT_FLOAT3);
    REQUIRE(hush_filter_set_image(f, "albedo", &v) == HUSH_OK);
  }
  v = view_of(s->output, HUSH_FORMAT_FLOAT3);
  REQUIRE(hush_filter_set_image(f, "output", &v) == HUSH_OK);
  REQUIRE(hush_filter_commit(f) == HUSH_OK);
  return f;
}

static void run(hush_filter f, uint64_t index) {
  hush_frame_info fi;
  frame_info(&fi, index);
  REQUIRE(hush_filter_execute(f, &fi) == HUSH_OK);
}

static float max_abs_diff(const float *a, const float *b, int n) {
  float m = 0.0f;
  for (int i = 0; i < n; i++) {
    const float d = fabsf(a[i] - b[i]);
    m = d > m ? d : m;
  }
  return m;
}

static int all_finite(const float *a, int n) {
  for (int i = 0; i < n; i++)
    if (!isfinite(a[i])) return 0;
  return 1;
}

/* ---- svgf ---------------------------------------------------------------- */

static void test_constant(hush_device dev, int with_albedo) {
  static scene s;
  flat(&s, 0.5f, 0.3f, 0.2f, 3.0f);
  /* a textured wall under constant light: radiance = albedo * constant */
  if (with_albedo)
    for (int i = 0; i < N * 3; i++) {
      s.albedo[i] = 0.25f + 0.5f * (float)(i % 7) / 7.0f;
      s.color[i] = s.albedo[i] * 0.8f;
    }
  hush_filter f = make(dev, "svgf", &s, with_albedo);
  for (int k = 0; k < 6; k++) {
    run(f, (uint64_t)k);
    CHECK_MSG(max_abs_diff(s.output, s.color, N * 3) <= 1e-5f, "frame %d: %g", k,
              (double)max_abs_diff(s.output, s.color, N * 3));
  }
  hush_filter_release(f);
}

/* Two half-planes: left at depth zl with colour cl, right at zr with cr;
 * normals nl / nr. Checks the columns next to the edge keep their side's
 * value. Noise on both halves makes the luminance weight permissive. */
static void edge_case(hush_device dev, float zl, float zr, hush_vec3 nl, hush_vec3 nr,
                      const char *what) {
  static scene s;
  flat(&s, 0, 0, 0, 1);
  hush_filter f = make(dev, "svgf", &s, 0);
  /* the luminance weight alone would keep the edge: switch it off */
  REQUIRE(hush_filter_set_float(f, "sigma_l", 1e6f) == HUSH_OK);
  for (int k = 0; k < 5; k++) {
    for (int y = 0; y < H; y++)
      for (int x = 0; x < W; x++) {
        const int i = y * W + x, left = x < W / 2;
        const float v = left ? 1.0f : 0.1f;
        for (int c = 0; c < 3; c++) s.color[3 * i + c] = v;
        s.depth[i] = left ? zl : zr;
        const hush_vec3 n = left ? nl : nr;
        s.normal[3 * i + 0] = n.x;
        s.normal[3 * i + 1] = n.y;
        s.normal[3 * i + 2] = n.z;
      }
    run(f, (uint64_t)k);
  }
  float worst = 0.0f;
  for (int y = 0; y < H; y++)
    for (int x = W / 2 - 2; x < W / 2 + 2; x++) {
      const int i = y * W + x;
      const float d = fabsf(s.output[3 * i] - s.color[3 * i]);
      worst = d > worst ? d : worst;
    }
  CHECK_MSG(worst < 0.01f, "%s edge blurred: worst %g", what, (double)worst);
  CHECK(all_finite(s.output, N * 3));
  hush_filter_release(f);
}

static void test_edges(hush_device dev) {
  const hush_vec3 nz = hush_v3(0, 0, 1);
  edge_case(dev, 2.0f, 4.0f, nz, nz, "depth");
  const float r = sqrtf(0.5f);
  edge_case(dev, 3.0f, 3.0f, nz, hush_v3(r, 0, r), "normal");
}

/* A flat wall with white noise: the output is much less noisy, with the same
 * mean (energy preserved), and a variance estimate near the true one. */
static void test_noise(hush_device dev) {
  static scene s;
  flat(&s, 0.5f, 0.5f, 0.5f, 3.0f);
  hush_filter f = make(dev, "svgf", &s, 0);
  static float variance[N], age[N];
  hush_image_view v = view_of(variance, HUSH_FORMAT_FLOAT);
  REQUIRE(hush_filter_set_image(f, "variance_estimate", &v) == HUSH_OK);
  v = view_of(age, HUSH_FORMAT_FLOAT);
  REQUIRE(hush_filter_set_image(f, "history_length", &v) == HUSH_OK);
  double in_var = 0, out_var = 0, out_mean = 0, var_first = 0, var_last = 0;
  const int frames = 10;
  for (int k = 0; k < frames; k++) {
    for (int i = 0; i < N; i++) {
      const float x = 0.5f + 0.8f * (rnd() - 0.5f);
      for (int c = 0; c < 3; c++) s.color[3 * i + c] = x;
    }
    run(f, (uint64_t)k);
    double mean_v = 0;
    for (int i = 0; i < N; i++) mean_v += variance[i];
    mean_v /= N;
    if (k == 4) var_first = mean_v; /* the first temporal estimate */
    if (k == frames - 1) var_last = mean_v;
  }
  CHECK_NEAR(age[N / 2], (float)frames, 0.0f);
  for (int i = 0; i < N; i++) {
    in_var += (s.color[3 * i] - 0.5) * (s.color[3 * i] - 0.5);
    out_mean += s.output[3 * i];
  }
  out_mean /= N;
  for (int i = 0; i < N; i++) out_var += (s.output[3 * i] - out_mean) * (s.output[3 * i] - out_mean);
  in_var /= N;
  out_var /= N;
  CHECK_MSG(out_var < in_var / 50, "noise: in %g out %g", in_var, out_var);
  CHECK_MSG(fabs(out_mean - 0.5) < 0.005, "mean %g", out_mean);
  /* the moments estimate the per-frame sample variance (0.8^2 / 12): it
   * converges to it rather than shrinking */
  CHECK_MSG(fabs(var_last - 0.8 * 0.8 / 12) < 0.015, "variance %g -> %g", var_first, var_last);
  CHECK(all_finite(s.output, N * 3));
  hush_filter_release(f);
}

/* Bit-identical results with 1 and 2 threads, on noise with edges. */
static void fill_busy(scene *s, int k) {
  rng_state = 777u + (uint32_t)k;
  for (int y = 0; y < H; y++)
    for (int x = 0; x < W; x++) {
      const int i = y * W + x;
      for (int c = 0; c < 3; c++) s->color[3 * i + c] = (x < W / 3 ? 2.0f : 0.3f) * rnd();
      s->depth[i] = y < H / 2 ? 2.0f + 0.01f * (float)x : 6.0f;
      s->normal[3 * i + 0] = 0.0f;
      s->normal[3 * i + 1] = x > 2 * W / 3 ? 1.0f : 0.0f;
      s->normal[3 * i + 2] = x > 2 * W / 3 ? 0.0f : 1.0f;
    }
}

static void test_determinism(const char *cls) {
  static scene a, b;
  hush_device d1 = hush_device_new("threads=1"), d2 = hush_device_new("threads=2");
  REQUIRE(d1 && d2);
  flat(&a, 0, 0, 0, 1);
  flat(&b, 0, 0, 0, 1);
  hush_filter fa = make(d1, cls, &a, 0), fb = make(d2, cls, &b, 0);
  for (int k = 0; k < 4; k++) {
    fill_busy(&a, k);
    fill_busy(&b, k);
    run(fa, (uint64_t)k);
    run(fb, (uint64_t)k);
    CHECK_MSG(memcmp(a.output, b.output, sizeof a.output) == 0, "%s frame %d differs", cls, k);
  }
  hush_filter_release(fa);
  hush_filter_release(fb);
  hush_device_release(d1);
  hush_device_release(d2);
}

/* Half-precision colour gives (nearly) the float result. */
static void test_half(hush_device dev) {
  static scene a, b;
  static uint16_t half_color[N * 3];
  flat(&a, 0, 0, 0, 1);
  flat(&b, 0, 0, 0, 1);
  hush_filter fa = make(dev, "svgf", &a, 0), fb = make(dev, "svgf", &b, 0);
  hush_image_view v = view_of(half_color, HUSH_FORMAT_HALF3);
  v.data = half_color;
  REQUIRE(hush_filter_set_image(fb, "color", &v) == HUSH_OK);
  for (int k = 0; k < 3; k++) {
    fill_busy(&a, k);
    fill_busy(&b, k);
    for (int i = 0; i < N * 3; i++) {
      half_color[i] = hush__float_to_half(a.color[i]);
      a.color[i] = hush__half_to_float(half_color[i]);
    }
    run(fa, (uint64_t)k);
    run(fb, (uint64_t)k);
  }
  CHECK_MSG(max_abs_diff(a.output, b.output, N * 3) <= 1e-4f, "half vs float: %g",
            (double)max_abs_diff(a.output, b.output, N * 3));
  hush_filter_release(fa);
  hush_filter_release(fb);
}

static void test_misuse(hush_device dev) {
  static scene s;
  flat(&s, 1, 1, 1, 1);
  hush_filter f = hush_filter_new(dev, "svgf");
  REQUIRE(f);
  hush_image_view v = view_of(s.color, HUSH_FORMAT_FLOAT3);
  REQUIRE(hush_filter_set_image(f, "color", &v) == HUSH_OK);
  v = view_of(s.output, HUSH_FORMAT_FLOAT3);
  REQUIRE(hush_filter_set_image(f, "output", &v) == HUSH_OK);
  CHECK(hush_filter_commit(f) != HUSH_OK); /* no depth, no normal */
  hush_device_get_error(dev, NULL);
  hush_filter_release(f);

  f = make(dev, "svgf", &s, 0);
  hush_frame_info fi;
  frame_info(&fi, 0);
  fi.motion = HUSH_MOTION_VECTORS; /* without a 'motion' image */
  CHECK(hush_filter_execute(f, &fi) == HUSH_ERROR_INVALID_OPERATION);
  hush_device_get_error(dev, NULL);
  CHECK(hush_filter_set_float(f, "sigma_n", -1.0f) == HUSH_ERROR_OUT_OF_RANGE);
  hush_device_get_error(dev, NULL);
  s.color[5] = NAN;
  frame_info(&fi, 1);
  CHECK(hush_filter_execute(f, &fi) == HUSH_ERROR_NONFINITE);
  hush_device_get_error(dev, NULL);
  hush_filter_release(f);
}

/* A sigma_n that is no power of two takes the powf path: same result as a
 * close power of two on a flat wall (all normals equal). */
static void test_sigma_n_general(hush_device dev) {
  static scene s;
  flat(&s, 0.4f, 0.4f, 0.4f, 2.0f);
  hush_filter f = make(dev, "svgf", &s, 0);
  REQUIRE(hush_filter_set_float(f, "sigma_n", 100.0f) == HUSH_OK);
  run(f, 0);
  CHECK(max_abs_diff(s.output, s.color, N * 3) <= 1e-5f);
  hush_filter_release(f);
}

/* Every kernel and tap order keeps a constant image constant, and on a
 * noisy flat wall keeps the mean (energy) within 1 % while removing most of
 * the noise. */
static void test_variants(hush_device dev) {
  static const char *const kernels[] = {"5x5", "3x3"};
  static const char *const orders[] = {"increasing", "decreasing", "0-then-decreasing"};
  static scene s;
  for (int k = 0; k < 2; k++)
    for (int o = 0; o < 3; o++) {
      flat(&s, 0.6f, 0.25f, 0.1f, 2.5f);
      hush_filter f = make(dev, "svgf", &s, 0);
      REQUIRE(hush_filter_set_string(f, "kernel", kernels[k]) == HUSH_OK);
      REQUIRE(hush_filter_set_string(f, "order", orders[o]) == HUSH_OK);
      REQUIRE(hush_filter_set_int(f, "iterations", k ? 6 : 5) == HUSH_OK);
      for (int t = 0; t < 3; t++) {
        run(f, (uint64_t)t);
        CHECK_MSG(max_abs_diff(s.output, s.color, N * 3) <= 1e-5f, "%s %s constant: %g",
                  kernels[k], orders[o], (double)max_abs_diff(s.output, s.color, N * 3));
      }
      hush_filter_release(f);
      f = make(dev, "svgf", &s, 0);
      REQUIRE(hush_filter_set_string(f, "kernel", kernels[k]) == HUSH_OK);
      REQUIRE(hush_filter_set_string(f, "order", orders[o]) == HUSH_OK);
      REQUIRE(hush_filter_set_int(f, "iterations", k ? 6 : 5) == HUSH_OK);
      /* decreasing runs the coarsest level first, and feeding that back
       * compounds the luminance weight's bias frame after frame (measured:
       * +2 % after 8 frames; the reason for Dundr's 0-then-decreasing) */
      if (o == 1) REQUIRE(hush_filter_set_bool(f, "feedback_first_level", 0) == HUSH_OK);
      double in_var = 0, out_var = 0, out_mean = 0;
      for (int t = 0; t < 8; t++) {
        for (int i = 0; i < N; i++) {
          const float x = 0.5f + 0.8f * (rnd() - 0.5f);
          for (int c = 0; c < 3; c++) s.color[3 * i + c] = x;
        }
        run(f, (uint64_t)t);
      }
      for (int i = 0; i < N; i++) {
        out_mean += s.output[3 * i];
        in_var += (s.color[3 * i] - 0.5) * (s.color[3 * i] - 0.5);
        out_var += (s.output[3 * i] - 0.5) * (s.output[3 * i] - 0.5);
      }
      /* the true mean is 0.5 */
      CHECK_MSG(fabs(out_mean / N / 0.5 - 1.0) < 0.01, "%s %s mean %g", kernels[k], orders[o],
                out_mean / N);
      CHECK_MSG(out_var < in_var / 20, "%s %s noise: in %g out %g", kernels[k], orders[o],
                in_var / N, out_var / N);
      CHECK(all_finite(s.output, N * 3));
      hush_filter_release(f);
    }
}

/* The output noise shrinks as the history grows (temporal accumulation plus
 * the variance-guided filter): frame 8 is much cleaner than frame 0. */
static void test_history_shrinks_noise(hush_device dev) {
  static scene s;
  flat(&s, 0.5f, 0.5f, 0.5f, 3.0f);
  hush_filter f = make(dev, "svgf", &s, 0);
  double first = 0, last = 0;
  for (int k = 0; k < 9; k++) {
    for (int i = 0; i < N; i++) {
      const float x = 0.5f + 0.8f * (rnd() - 0.5f);
      for (int c = 0; c < 3; c++) s.color[3 * i + c] = x;
    }
    run(f, (uint64_t)k);
    double e = 0;
    for (int i = 0; i < N; i++) e += (s.output[3 * i] - 0.5) * (s.output[3 * i] - 0.5);
    if (k == 0) first = e / N;
    if (k == 8) last = e / N;
  }
  CHECK_MSG(last < first / 3, "output noise %g at frame 0, %g at frame 8", first, last);
  hush_filter_release(f);
}

/* depth_steep: on a plane seen at a grazing angle (relative depth slope
 * ln(1.3)/8 = 0.033 per pixel) a threshold below that slope switches the
 * depth weight off, which is what a huge sigma_z does. */
static void test_depth_steep(hush_device dev) {
  static scene a, b;
  flat(&a, 0, 0, 0, 1);
  flat(&b, 0, 0, 0, 1);
  hush_filter fa = make(dev, "svgf", &a, 0), fb = make(dev, "svgf", &b, 0);
  REQUIRE(hush_filter_set_float(fa, "depth_steep", 0.01f) == HUSH_OK);
  REQUIRE(hush_filter_set_float(fb, "sigma_z", 1e6f) == HUSH_OK);
  for (int k = 0; k < 3; k++) {
    for (int y = 0; y < H; y++)
      for (int x = 0; x < W; x++) {
        const int i = y * W + x;
        const float v = 0.5f + 0.8f * (rnd() - 0.5f);
        for (int c = 0; c < 3; c++) a.color[3 * i + c] = b.color[3 * i + c] = v;
        a.depth[i] = b.depth[i] = powf(1.3f, (float)x / 8.0f);
      }
    run(fa, (uint64_t)k);
    run(fb, (uint64_t)k);
  }
  CHECK_MSG(max_abs_diff(a.output, b.output, N * 3) < 1e-3f, "steep: %g",
            (double)max_abs_diff(a.output, b.output, N * 3));
  /* not steep enough for the default sigma_z to be switched off: differs */
  REQUIRE(hush_filter_set_float(fa, "depth_steep", 0.0f) == HUSH_OK);
  run(fa, 3);
  run(fb, 3);
  CHECK(max_abs_diff(a.output, b.output, N * 3) > 1e-3f);
  hush_filter_release(fa);
  hush_filter_release(fb);
}

/* §4.3, more than 1 spp: on a striped wall (texture, no geometry edge)
 * rendered at 64 spp with a small per-sample variance V, the 7x7 spatial
 * estimate of the first frames sees the stripes as variance; merging the
 * renderer's per-pixel variance gives about V / 64 instead, from frame 0. */
static double striped_variance(hush_device dev, int merge, int frames) {
  static scene s;
  static float spp[N], svar[N], est[N];
  const float V = 0.01f, n = 64.0f;
  flat(&s, 0, 0, 0, 2.0f);
  hush_filter f = make(dev, "svgf", &s, 0);
  hush_image_view v = view_of(spp, HUSH_FORMAT_FLOAT);
  REQUIRE(hush_filter_set_image(f, "spp", &v) == HUSH_OK);
  v = view_of(svar, HUSH_FORMAT_FLOAT);
  REQUIRE(hush_filter_set_image(f, "variance", &v) == HUSH_OK);
  v = view_of(est, HUSH_FORMAT_FLOAT);
  REQUIRE(hush_filter_set_image(f, "variance_estimate", &v) == HUSH_OK);
  REQUIRE(hush_filter_set_bool(f, "sample_variance", merge) == HUSH_OK);
  for (int k = 0; k < frames; k++) {
    for (int y = 0; y < H; y++)
      for (int x = 0; x < W; x++) {
        const int i = y * W + x;
        /* the mean of 64 samples of variance V: uniform noise of that variance */
        const float mean = (x / 2) % 2 ? 0.8f : 0.2f;
        const float noise = sqrtf(12.0f * V / n) * (rnd() - 0.5f);
        for (int c = 0; c < 3; c++) s.color[3 * i + c] = mean + noise;
        spp[i] = n;
        svar[i] = V;
      }
    run(f, (uint64_t)k);
  }
  double m = 0;
  for (int i = 0; i < N; i++) m += est[i];
  hush_filter_release(f);
  return m / N;
}

static void test_sample_variance(hush_device dev) {
  const double want = 0.01 / 64;
  for (int frames = 1; frames <= 6; frames += 5) {
    const double plain = striped_variance(dev, 0, frames), merged = striped_variance(dev, 1, frames);
    if (frames == 1)
      CHECK_MSG(merged < plain / 10, "frame 0: merged %g, spatial %g", merged, plain);
    CHECK_MSG(fabs(merged / want - 1.0) < 0.3, "%d frames: merged %g, want %g", frames, merged,
              want);
  }
  /* 'variance' without 'spp' is refused */
  static scene s;
  static float svar[N];
  flat(&s, 0.5f, 0.5f, 0.5f, 2.0f);
  hush_filter f = make(dev, "svgf", &s, 0);
  hush_image_view v = view_of(svar, HUSH_FORMAT_FLOAT);
  REQUIRE(hush_filter_set_image(f, "variance", &v) == HUSH_OK);
  hush_frame_info fi;
  frame_info(&fi, 0);
  CHECK(hush_filter_execute(f, &fi) == HUSH_ERROR_INVALID_OPERATION);
  hush_device_get_error(dev, NULL);
  hush_filter_release(f);
}

/* Direct and indirect bound: each is filtered on its own, so the output is
 * the sum of two svgf filters run on each as 'color' (up to rounding). */
static void test_split(hush_device dev) {
  static scene a, b, c;
  static float direct[N * 3], indirect[N * 3], sum[N * 3];
  flat(&a, 0, 0, 0, 1);
  flat(&b, 0, 0, 0, 1);
  flat(&c, 0, 0, 0, 1);
  hush_filter fs = make(dev, "svgf", &a, 0), fd = make(dev, "svgf", &b, 0),
              fi = make(dev, "svgf", &c, 0);
  hush_image_view v = view_of(direct, HUSH_FORMAT_FLOAT3);
  REQUIRE(hush_filter_set_image(fs, "direct", &v) == HUSH_OK);
  REQUIRE(hush_filter_set_image(fd, "color", &v) == HUSH_OK);
  v = view_of(indirect, HUSH_FORMAT_FLOAT3);
  REQUIRE(hush_filter_set_image(fs, "indirect", &v) == HUSH_OK);
  REQUIRE(hush_filter_set_image(fi, "color", &v) == HUSH_OK);
  float worst = 0.0f;
  for (int k = 0; k < 5; k++) {
    fill_busy(&a, k);
    for (int i = 0; i < N; i++) {
      for (int ch = 0; ch < 3; ch++) {
        direct[3 * i + ch] = a.color[3 * i + ch] * (a.depth[i] > 5.0f ? 0.0f : 1.0f);
        indirect[3 * i + ch] = 0.3f * rnd();
      }
      b.depth[i] = c.depth[i] = a.depth[i];
      for (int ch = 0; ch < 3; ch++) b.normal[3 * i + ch] = c.normal[3 * i + ch] = a.normal[3 * i + ch];
    }
    run(fs, (uint64_t)k);
    run(fd, (uint64_t)k);
    run(fi, (uint64_t)k);
    for (int i = 0; i < N * 3; i++) sum[i] = b.output[i] + c.output[i];
    const float d = max_abs_diff(a.output, sum, N * 3);
    worst = d > worst ? d : worst;
  }
  CHECK_MSG(worst < 1e-5f, "split vs two filters: %g", (double)worst);
  CHECK(all_finite(a.output, N * 3));
  hush_filter_release(fs);
  hush_filter_release(fd);
  hush_filter_release(fi);
}

/* §4.2, fewer than 1 spp: a wall at depth 3 of constant radiance 0.5, a
 * quarter of the pixels traced per frame (each 2x2 block in turn, as
 * `hush render --spp-fraction 0.25`); the holes have spp 0 and every other
 * layer 0. The camera is static or moves sideways (cam_dx per frame). */
static void wall_frame(scene *s, float *spp, float *pos, int k, float cam_x, hush_frame_info *fi) {
  const float t = tanf(30.0f * 3.14159265f / 180.0f), aspect = (float)W / H, d = 3.0f;
  for (int y = 0; y < H; y++)
    for (int x = 0; x < W; x++) {
      const int i = y * W + x;
      const int traced = ((y % 2) * 2 + (x % 2)) == k % 4;
      const float nx = ((float)x + 0.5f) / W * 2.0f - 1.0f, ny = 1.0f - ((float)y + 0.5f) / H * 2.0f;
      spp[i] = traced ? 1.0f : 0.0f;
      s->depth[i] = traced ? d : 0.0f;
      for (int c = 0; c < 3; c++) {
        s->color[3 * i + c] = traced ? 0.5f : 0.0f;
        s->normal[3 * i + c] = traced && c == 2 ? 1.0f : 0.0f;
        s->albedo[3 * i + c] = traced ? 1.0f : 0.0f;
      }
      pos[3 * i + 0] = traced ? cam_x + nx * t * aspect * d : 0.0f;
      pos[3 * i + 1] = traced ? ny * t * d : 0.0f;
      pos[3 * i + 2] = traced ? 5.0f - d : 0.0f;
    }
  hush_frame_info_init(fi);
  fi->frame_index = (uint64_t)k;
  fi->history = k ? HUSH_HISTORY_CONTINUE : HUSH_HISTORY_RESET;
  float w2v[16], v2c[16];
  hush_m4_look_at(w2v, hush_v3(cam_x, 0, 5), hush_v3(cam_x, 0, 0), hush_v3(0, 1, 0));
  hush_m4_perspective(v2c, 60.0f, (float)W / H, 0.1f, 100.0f);
  memcpy(fi->world_to_view, w2v, sizeof w2v);
  memcpy(fi->view_to_clip, v2c, sizeof v2c);
  memcpy(fi->prev_view_to_clip, v2c, sizeof v2c);
}

static void progressive_case(hush_device dev, float cam_dx, const char *what, int on) {
  static scene s;
  static float spp[N], pos[N * 3], age[N];
  flat(&s, 0, 0, 0, 1);
  hush_filter f = make(dev, "svgf", &s, 1);
  hush_image_view v = view_of(spp, HUSH_FORMAT_FLOAT);
  REQUIRE(hush_filter_set_image(f, "spp", &v) == HUSH_OK);
  v = view_of(pos, HUSH_FORMAT_FLOAT3);
  REQUIRE(hush_filter_set_image(f, "position", &v) == HUSH_OK);
  v = view_of(age, HUSH_FORMAT_FLOAT);
  REQUIRE(hush_filter_set_image(f, "history_length", &v) == HUSH_OK);
  REQUIRE(hush_filter_set_bool(f, "progressive", on) == HUSH_OK);
  float prev_w2v[16] = {0};
  for (int k = 0; k < 8; k++) {
    hush_frame_info fi;
    wall_frame(&s, spp, pos, k, cam_dx * (float)k, &fi);
    if (k == 0) memcpy(prev_w2v, fi.world_to_view, sizeof prev_w2v);
    memcpy(fi.prev_world_to_view, prev_w2v, sizeof prev_w2v);
    memcpy(prev_w2v, fi.world_to_view, sizeof prev_w2v);
    REQUIRE(hush_filter_execute(f, &fi) == HUSH_OK);
    /* no hole in the output, and the constant radiance kept */
    float worst = 0.0f;
    for (int i = 0; i < N * 3; i++) {
      const float d = fabsf(s.output[i] - 0.5f);
      worst = d > worst || !(d == d) ? d : worst;
    }
    if (!on) { /* the 1 spp pipeline takes the holes for black samples */
      CHECK_MSG(worst > 0.1f, "%s without progressive: off by only %g", what, (double)worst);
      hush_filter_release(f);
      return;
    }
    CHECK_MSG(worst < 1e-4f, "%s frame %d: output off by %g", what, k, (double)worst);
  }
  /* every pixel has its own history by frame 8 (away from the border the
   * moving camera uncovers) */
  int empty = 0;
  for (int y = 0; y < H; y++)
    for (int x = 4; x < W - 4; x++) empty += !(age[y * W + x] >= 1.0f);
  CHECK_MSG(empty == 0, "%s: %d pixels without history at frame 8", what, empty);
  hush_filter_release(f);
}

/* The progressive path (scatter with atomics) is bit-identical with 1 and
 * 2 threads: noisy radiance, moving camera. */
static void test_progressive_determinism(void) {
  static scene a, b;
  static float spp[N], pos[N * 3];
  hush_device d1 = hush_device_new("threads=1"), d2 = hush_device_new("threads=2");
  REQUIRE(d1 && d2);
  flat(&a, 0, 0, 0, 1);
  flat(&b, 0, 0, 0, 1);
  hush_filter fa = make(d1, "svgf", &a, 1), fb = make(d2, "svgf", &b, 1);
  hush_image_view v = view_of(spp, HUSH_FORMAT_FLOAT);
  REQUIRE(hush_filter_set_image(fa, "spp", &v) == HUSH_OK);
  REQUIRE(hush_filter_set_image(fb, "spp", &v) == HUSH_OK);
  v = view_of(pos, HUSH_FORMAT_FLOAT3);
  REQUIRE(hush_filter_set_image(fa, "position", &v) == HUSH_OK);
  REQUIRE(hush_filter_set_image(fb, "position", &v) == HUSH_OK);
  float prev_w2v[16] = {0};
  for (int k = 0; k < 5; k++) {
    hush_frame_info fi;
    wall_frame(&a, spp, pos, k, 0.1f * (float)k, &fi);
    for (int i = 0; i < N * 3; i++) a.color[i] *= 2.0f * rnd();
    memcpy(b.color, a.color, sizeof a.color);
    memcpy(b.depth, a.depth, sizeof a.depth);
    memcpy(b.normal, a.normal, sizeof a.normal);
    memcpy(b.albedo, a.albedo, sizeof a.albedo);
    if (k == 0) memcpy(prev_w2v, fi.world_to_view, sizeof prev_w2v);
    memcpy(fi.prev_world_to_view, prev_w2v, sizeof prev_w2v);
    memcpy(prev_w2v, fi.world_to_view, sizeof prev_w2v);
    REQUIRE(hush_filter_execute(fa, &fi) == HUSH_OK);
    REQUIRE(hush_filter_execute(fb, &fi) == HUSH_OK);
    CHECK_MSG(memcmp(a.output, b.output, sizeof a.output) == 0, "progressive frame %d differs",
              k);
    CHECK(all_finite(a.output, N * 3));
  }
  hush_filter_release(fa);
  hush_filter_release(fb);
  hush_device_release(d1);
  hush_device_release(d2);
}

static void test_progressive(hush_device dev) {
  progressive_case(dev, 0.0f, "static", 1);
  progressive_case(dev, 0.1f, "moving", 1);
  progressive_case(dev, 0.0f, "static", 0);
  /* holes without 'position' are refused */
  static scene s;
  static float spp[N];
  flat(&s, 0.5f, 0.5f, 0.5f, 2.0f);
  for (int i = 0; i < N; i++) spp[i] = (float)(i % 2);
  hush_filter f = make(dev, "svgf", &s, 0);
  hush_image_view v = view_of(spp, HUSH_FORMAT_FLOAT);
  REQUIRE(hush_filter_set_image(f, "spp", &v) == HUSH_OK);
  hush_frame_info fi;
  frame_info(&fi, 0);
  CHECK(hush_filter_execute(f, &fi) == HUSH_ERROR_INVALID_OPERATION);
  hush_device_get_error(dev, NULL);
  hush_filter_release(f);
}

/* ---- taa ------------------------------------------------------------------ */

static void test_taa_constant(hush_device dev, const char *cls) {
  static scene s;
  flat(&s, 0.7f, 0.2f, 3.0f, 2.5f);
  hush_filter f = make(dev, cls, &s, 0);
  if (strcmp(cls, "svgf") == 0) REQUIRE(hush_filter_set_bool(f, "taa", 1) == HUSH_OK);
  for (int k = 0; k < 6; k++) {
    run(f, (uint64_t)k);
    CHECK_MSG(max_abs_diff(s.output, s.color, N * 3) <= 1e-5f, "%s frame %d: %g", cls, k,
              (double)max_abs_diff(s.output, s.color, N * 3));
  }
  hush_filter_release(f);
}

/* A bright half-plane whose edge moves 4 pixels a frame over a static
 * background (the history stays where it was): away from the edge the 3x3
 * box holds only the current value, so no trail of the old position may
 * survive the clamp. */
static void test_taa_ghosting(hush_device dev, const char *box) {
  static scene s;
  flat(&s, 0, 0, 0, 2.0f);
  hush_filter f = make(dev, "taa", &s, 0);
  REQUIRE(hush_filter_set_string(f, "box", box) == HUSH_OK);
  float worst = 0.0f;
  for (int k = 0; k < 8; k++) {
    const int edge = 40 - 4 * k;
    for (int y = 0; y < H; y++)
      for (int x = 0; x < W; x++)
        for (int c = 0; c < 3; c++) s.color[3 * (y * W + x) + c] = x < edge ? 1.0f : 0.0f;
    run(f, (uint64_t)k);
    for (int y = 0; y < H; y++)
      for (int x = 0; x < W; x++) {
        if (x == edge - 1 || x == edge) continue; /* the box there holds both values */
        const int i = 3 * (y * W + x);
        const float d = fabsf(s.output[i] - s.color[i]);
        worst = d > worst ? d : worst;
      }
  }
  CHECK_MSG(worst <= 1e-5f, "taa (%s) ghosts: %g", box, (double)worst);
  hush_filter_release(f);
}

/* Noise (a jittered signal) is smoothed over time: the output of a static
 * noisy image converges towards the box-limited mean. */
static void test_taa_smooths(hush_device dev) {
  static scene s;
  flat(&s, 0.5f, 0.5f, 0.5f, 2.0f);
  hush_filter f = make(dev, "taa", &s, 0);
  REQUIRE(hush_filter_set_bool(f, "tonemap", 0) == HUSH_OK);
  double in_var = 0, out_var = 0;
  for (int k = 0; k < 20; k++) {
    for (int i = 0; i < N; i++) {
      const float x = 0.5f + 0.2f * (rnd() - 0.5f);
      for (int c = 0; c < 3; c++) s.color[3 * i + c] = x;
    }
    run(f, (uint64_t)k);
  }
  for (int i = 0; i < N; i++) {
    in_var += (s.color[3 * i] - 0.5) * (s.color[3 * i] - 0.5);
    out_var += (s.output[3 * i] - 0.5) * (s.output[3 * i] - 0.5);
  }
  CHECK_MSG(out_var < in_var / 3, "taa: in %g out %g", in_var / N, out_var / N);
  hush_filter_release(f);
}

/* The vectorisable math of the a-trous taps (filters/svgf/weights.h)
 * against libm in double: the Newton reciprocal, h 2^-s with its clamp,
 * and the whole tap weight: exactly 0 at or below h e^-20, else accurate,
 * and never with a subnormal square. */
/* The fast weight's model (weights.h, svgf_exp2_neg_fast) in double:
 * 2^floor(u) (1 + frac(u)), u = t + SVGF_FAST_EXP_SHIFT. */
static double fast_exp2_model(double t) {
  const double u = t + (double)SVGF_FAST_EXP_SHIFT, fl = floor(u);
  return ldexp(1.0 + (u - fl), (int)fl);
}

static void test_weight_math(void) {
  double worst = 0.0;
  for (int i = 0; i <= 20000; i++) { /* 1e-30 .. 1e30, log-spaced */
    const float x = (float)pow(10.0, -30.0 + 60.0 * i / 20000.0);
    const double e = fabs((double)svgf_rcp_pos(x) * x - 1.0);
    worst = e > worst ? e : worst;
  }
  CHECK_MSG(worst < 2e-7, "rcp: worst relative error %g", worst);

  const float hs[3] = {1.0f, 0.375f * 0.375f, 1.0f / 256};
  for (int k = 0; k < 3; k++) {
    const svgf_exp2_poly p = svgf_exp2_poly_scaled(hs[k]);
    worst = 0.0;
    for (int i = 0; i <= 26000; i++) {
      const float si = (float)i * (SVGF_S_MAX / 26000.0f);
      const float s = si < SVGF_S_MAX ? si : SVGF_S_MAX; /* no rounding past the clamp */
      const double ref = hs[k] * exp2(-(double)s);
      const double e = fabs(svgf_exp2_neg_h(s, SVGF_S_MAX, &p) / ref - 1.0);
      worst = e > worst ? e : worst;
    }
    CHECK_MSG(worst < 1e-6, "exp2: worst relative error %g (h %g)", worst, hs[k]);
    /* beyond the clamp, and NaN, give the clamp's value */
    const float at_max = svgf_exp2_neg_h(SVGF_S_MAX, SVGF_S_MAX, &p);
    CHECK(svgf_exp2_neg_h(1e30f, SVGF_S_MAX, &p) == at_max);
    CHECK(svgf_exp2_neg_h(NAN, SVGF_S_MAX, &p) == at_max);
    CHECK(svgf_exp2_neg_h(INFINITY, SVGF_S_MAX, &p) == at_max);
  }

  /* the fast weight (weight_exp=fast): its model to float rounding (the
   * fused multiply-add rounds (t + 127) 2^23 to 64 at most: 8e-6 of the
   * mantissa), within 2.98 % of 2^-s, and never increasing with s (a
   * weight must not grow as a tap differs more) */
  {
    double worst_model = 0.0, worst_exp = 0.0;
    float prev = INFINITY;
    int monotone = 1;
    for (int i = 0; i <= 64000; i++) {
      const float s = -2.0f + (float)i * (32.0f / 64000.0f);
      const float w = svgf_exp2_neg_fast(s);
      const double em = fabs(w / fast_exp2_model(-(double)s) - 1.0);
      const double ee = fabs(w / exp2(-(double)s) - 1.0);
      worst_model = em > worst_model ? em : worst_model;
      worst_exp = ee > worst_exp ? ee : worst_exp;
      monotone &= w <= prev;
      prev = w;
    }
    CHECK_MSG(worst_model < 1e-5, "fast exp2: %g from its model", worst_model);
    CHECK_MSG(worst_exp < 0.0299 && worst_exp > 0.029, "fast exp2: worst relative error %g",
              worst_exp);
    CHECK(monotone);
    /* the vector loops' floor compares these bits (svgf_avx2_exp2_fast) */
    int bits_same = 1;
    for (int i = 0; i <= 6400; i++) {
      const float t = -60.0f + (float)i * (62.0f / 6400.0f);
      const float w = svgf_exp2_neg_fast(-t);
      int32_t b;
      memcpy(&b, &w, sizeof b);
      bits_same &= b == svgf_fast_exp_bits(t);
    }
    CHECK(bits_same);
    /* out of range and NaN: clamped, finite, not negative */
    const float odd[5] = {NAN, INFINITY, -INFINITY, 1e30f, -1e30f};
    for (int k = 0; k < 5; k++) {
      const float w = svgf_exp2_neg_fast(odd[k]);
      CHECK(isfinite(w) && w >= 0.0f);
    }
  }

  /* the tap weight: h dot^sigma_n 2^-s for both ways of raising the dot */
  const float sigmas[2] = {128.0f, 100.0f};
  for (int k = 0; k < 2; k++) {
    const svgf_normal_power np = svgf_normal_power_of(sigmas[k]);
    CHECK(np.squarings == (k == 0 ? 7 : -1));
    const float h = 1.0f / 16;
    const svgf_exp2_poly p = svgf_exp2_poly_scaled(h);
    worst = 0.0;
    float smallest_sq = FLT_MAX;
    for (int i = 0; i <= 400; i++)
      for (int j = 0; j <= 100; j++) {
        const float dot = -1.0f + 2.0f * (float)i / 400.0f, s = 0.4f * (float)j;
        const float w = k == 0 ? svgf_tap_weight(s, dot, 7, np.sigma_n_log2e, np.dot_floor, &p)
                               : svgf_tap_weight(s, dot, -1, np.sigma_n_log2e, np.dot_floor, &p);
        CHECK(isfinite(w) && w >= 0.0f && w <= h * 1.0001f);
        if (w > 0.0f) smallest_sq = w * w < smallest_sq ? w * w : smallest_sq;
        const double ref = h * pow(dot > 0.0f ? dot : 0.0, sigmas[k]) * exp2(-(double)s);
        if (ref > h * exp(-19.99)) { /* above the floor */
          const double e = fabs(w / ref - 1.0);
          worst = e > worst ? e : worst;
        } else if (ref < h * exp(-20.01)) {
          CHECK(w == 0.0f); /* below: exactly 0 */
        }
      }
    /* 7 squarings double the float rounding of the dot's power each time:
     * up to 2^7 x 6e-8 (as before this exp; inherent to the squarings) */
    CHECK_MSG(worst < 1e-5, "tap weight: worst relative error %g (sigma_n %g)", worst,
              sigmas[k]);
    CHECK_MSG(smallest_sq >= FLT_MIN, "tap weight squared %g is subnormal", smallest_sq);
  }
}

/* ---- one a-trous level against the formula ------------------------------- */

#define LW 53 /* 32 + 16 + 5: two vectors at once, one, and a row tail */
#define LH 23

/* A level computed in double straight from the formulas of atrous.h and
 * weights.h (rows and columns clamped at the border). */
static void level_reference(const svgf_guide *g, const svgf_padded *in, const svgf_kernel *k,
                            int step, float sigma_l, const float *eps, int normal_exp, int fast,
                            int validity, double *out /* LW * LH * 4: r g b var */) {
  const int r = k->radius;
#define AT(P, C, X, Y) ((double)(P)->plane[C][(size_t)(Y) * (P)->stride + (size_t)(X)])
  for (int y = 0; y < LH; y++)
    for (int x = 0; x < LW; x++) {
      double g3 = 0.0;
      for (int j = -1; j <= 1; j++)
        for (int i = -1; i <= 1; i++) {
          const int xx = x + i < 0 ? 0 : x + i >= LW ? LW - 1 : x + i;
          const int yy = y + j < 0 ? 0 : y + j >= LH ? LH - 1 : y + j;
          g3 += (i ? 0.25 : 0.5) * (j ? 0.25 : 0.5) * AT(in, SVGF_VAR, xx, yy);
        }
      const size_t pi = (size_t)y * LW + x;
      const double okp = validity ? AT(in, SVGF_VALID, x, y) : 1.0;
      const double dl_den = sigma_l * sqrt(g3) + (eps ? eps[pi] : SVGF_EPS_L);
      double sw = 0, s0 = 0, s1 = 0, s2 = 0, sv = 0;
      for (int j = -r; j <= r; j++)
        for (int i = -r; i <= r; i++) {
          const int qx = x + i * step < 0 ? 0 : x + i * step >= LW ? LW - 1 : x + i * step;
          const int qy = y + j * step < 0 ? 0 : y + j * step >= LH ? LH - 1 : y + j * step;
          const double h = (double)k->h[r + i] * k->h[r + j];
          double w = h;
          if (i || j) {
            const double sz = g->sigma_z * fabs(g->gx[pi] * i * step + g->gy[pi] * j * step);
            const double ez = g->zon[pi] * fabs(AT(g->zn, 0, x, y) - AT(g->zn, 0, qx, qy)) /
                              (sz + SVGF_EPS_Z);
            const double el = okp * fabs(AT(in, SVGF_LUM, x, y) - AT(in, SVGF_LUM, qx, qy)) / dl_den;
            double dot = 0.0;
            for (int c = 1; c <= 3; c++) dot += AT(g->zn, c, x, y) * AT(g->zn, c, qx, qy);
            const double sn = g->np.sigma_n;
            const double wn = normal_exp ? exp(-sn * (1.0 - dot)) : pow(dot > 0 ? dot : 0, sn);
            w = h * wn * exp(-ez - el);
            if (w <= h * exp(-20.0))
              w = 0.0;
            else if (fast)
              w = fast_exp2_model(log2(w));
            if (validity) w *= AT(in, SVGF_VALID, qx, qy);
          } else {
            w *= okp;
          }
          sw += w;
          s0 += w * AT(in, SVGF_R, qx, qy);
          s1 += w * AT(in, SVGF_G, qx, qy);
          s2 += w * AT(in, SVGF_B, qx, qy);
          sv += w * w * AT(in, SVGF_VAR, qx, qy);
        }
      double *o = out + 4 * pi;
      if (sw > 0) {
        o[0] = s0 / sw;
        o[1] = s1 / sw;
        o[2] = s2 / sw;
        o[3] = sv / (sw * sw);
      } else {
        o[0] = o[1] = o[2] = o[3] = 0.0;
      }
    }
#undef AT
}

/* The guide of the level and wavefront tests: a w x h frame's zn and
 * gradient planes, sigma_z 1, sigma_n 128. */
static svgf_guide test_guide(const svgf_padded *zn, const float *gx, const float *gy,
                             const float *zon, int w, int h) {
  svgf_guide g;
  g.width = w;
  g.height = h;
  g.zn = zn;
  g.gx = gx;
  g.gy = gy;
  g.zon = zon;
  g.sigma_z = 1.0f;
  g.np = svgf_normal_power_of(128.0f);
  return g;
}

/* A level's input at index si of the signal planes p: noisy colour
 * (darker on the right-hand surface), variance, its luminance, and no data
 * at a rate of hole_rate. */
static void random_signal(svgf_padded *p, size_t si, int right, float hole_rate) {
  const float base = right ? 0.2f : 0.7f;
  for (int c = 0; c < 3; c++) p->plane[c][si] = base * (1.0f + 0.3f * (float)c) * (0.5f + rnd());
  p->plane[SVGF_VAR][si] = 0.05f * rnd();
  p->plane[SVGF_LUM][si] = hush_luminance(p->plane[0][si], p->plane[1][si], p->plane[2][si]);
  p->plane[SVGF_VALID][si] = rnd() < hole_rate ? 0.0f : 1.0f;
}

/* Every variant of svgf_atrous_level (the AVX-512 loop where built, the
 * portable loop, exp and pow normal weights, with and without validity,
 * both kernels, with tap steps past the frame) computes the formula within
 * float rounding of the weights (1e-4 relative of the value range). */
static void test_level_formula(hush_device dev) {
  static svgf_padded zn, in, out;
  const int pad = 32;
  REQUIRE(svgf_padded_ensure(dev, &zn, 4, LW, LH, pad) == HUSH_OK);
  REQUIRE(svgf_padded_ensure(dev, &in, SVGF_SIGNAL_CHANNELS, LW, LH, pad) == HUSH_OK);
  REQUIRE(svgf_padded_ensure(dev, &out, SVGF_SIGNAL_CHANNELS, LW, LH, pad) == HUSH_OK);
  static float gx[LW * LH], gy[LW * LH], zon[LW * LH], eps[LW * LH];
  for (int y = 0; y < LH; y++) {
    for (int x = 0; x < LW; x++) {
      const size_t i = (size_t)y * zn.stride + x, pi = (size_t)y * LW + x;
      /* two planes meeting at a depth and normal edge, plus noise */
      const int right = x > LW / 2;
      zn.plane[0][i] = (right ? 3.0f : 2.0f) + 0.02f * (float)y + 0.01f * rnd();
      float n[3] = {right ? 0.6f : 0.05f * rnd(), 0.05f * rnd(), right ? 0.8f : 1.0f};
      const float len = sqrtf(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
      for (int c = 0; c < 3; c++) zn.plane[1 + c][i] = n[c] / len;
      if (y == 1 || (y == LH / 2 && x < 40) || (y == 3 && x >= 16 && x < 20) ||
          (y == 5 && x >= 32 && x < 48) || (y == 7 && x < 16)) {
        /* sky (no surface: depth and normal 0): whole vectors and a part of one */
        for (int c = 0; c < 4; c++) zn.plane[c][i] = 0.0f;
      }
      random_signal(&in, (size_t)y * in.stride + x, right, 0.2f);
      gx[pi] = 0.01f * (rnd() - 0.5f);
      gy[pi] = 0.02f + 0.01f * rnd();
      zon[pi] = rnd() < 0.1f ? 0.0f : 1.0f;
      eps[pi] = 1e-4f + 0.05f * rnd();
    }
    for (int c = 0; c < 4; c++) svgf_pad_row(svgf_padded_row(&zn, c, y), LW, zn.pad);
    for (int c = 0; c < SVGF_SIGNAL_CHANNELS; c++)
      svgf_pad_row(svgf_padded_row(&in, c, y), LW, in.pad);
  }
  static double ref[LW * LH * 4];
  const svgf_kernel *kernels[2] = {&svgf_kernel_5x5, &svgf_kernel_3x3};
  for (int kk = 0; kk < 2; kk++)
    for (int step = 1; step <= 16; step *= 4)
      for (int form = 0; form < 3; form++) /* pow, exp, exp with the fast weight */
        for (int valid = 0; valid <= 1; valid++)
          for (int loop = 0; loop < 3; loop++) {
            const int nexp = form > 0, fast = form == 2;
            /* loop 0, 1: the AVX-512 loop (where built) with one and two
             * vectors at a time, the same bits; 2: the portable loop */
            const int portable = loop == 2;
            const svgf_guide g = test_guide(&zn, gx, gy, zon, LW, LH);
            svgf_level_params lp;
            lp.kernel = kernels[kk];
            lp.step = step;
            lp.sigma_l = 4.0f;
            lp.eps_l = valid ? eps : NULL;
            lp.validity = valid;
            lp.normal_exp = nexp;
            lp.fast_exp = fast;
            lp.portable = portable;
            lp.vectors = loop == 1 ? 2 : 1;
            const svgf_level_out o = svgf_level_out_padded(&out);
            svgf_atrous_level(&g, &lp, &in, &o, 2);
            static float one[SVGF_SIGNAL_CHANNELS][LW * LH];
            int same = 1;
            for (int c = 0; c < SVGF_SIGNAL_CHANNELS; c++)
              for (int y = 0; y < LH; y++) {
                const float *row = out.plane[c] + (size_t)y * out.stride;
                if (c == SVGF_VALID && !valid) continue;
                if (loop == 0) memcpy(one[c] + y * LW, row, LW * sizeof(float));
                if (loop == 1) same &= !memcmp(one[c] + y * LW, row, LW * sizeof(float));
              }
            CHECK_MSG(same, "level %s step %d: two vectors at a time differ from one",
                      kk ? "3x3" : "5x5", step);
            level_reference(&g, &in, kernels[kk], step, 4.0f, lp.eps_l, nexp, fast, valid, ref);
            double worst = 0.0;
            int holes_ok = 1;
            for (int y = 0; y < LH; y++)
              for (int x = 0; x < LW; x++) {
                const size_t i = (size_t)y * out.stride + x, pi = (size_t)y * LW + x;
                for (int c = 0; c < 3; c++) {
                  const double e = fabs(out.plane[c][i] - ref[4 * pi + c]);
                  worst = e > worst ? e : worst;
                }
                /* the variance relative to its own size */
                const double ev = fabs(out.plane[SVGF_VAR][i] - ref[4 * pi + 3]) /
                                  (ref[4 * pi + 3] + 1e-6);
                worst = ev > worst ? ev : worst;
                if (valid && !(out.plane[SVGF_VALID][i] == 1.0f || ref[4 * pi] == 0.0))
                  holes_ok = 0;
              }
            /* the AVX-512 loop's 2^t is within 7.5e-5 relative (weights.h), and
             * the variance sums squared weights: up to twice that */
            CHECK_MSG(worst < 2.5e-4, "level %s step %d %s%s%s: worst difference %g",
                      kk ? "3x3" : "5x5", step, fast ? "fast exp" : nexp ? "exp" : "pow",
                      valid ? " validity" : "", portable ? " portable" : "", worst);
            CHECK(holes_ok);
          }

  /* the 7x7 spatial variance (Dundr §4.4) against its formula: depth and
   * normal weights, pixels without data (age 0) not counted, kept where the
   * history is long; moments unpadded (another stride than the guide's),
   * read through clamped windows at the borders */
  static float mom1[LW * LH], mom2[LW * LH];
  const float *const mom[2] = {mom1, mom2};
  static float age[LW * LH], var[LW * LH];
  for (int holes = 0; holes <= 1; holes++)
    for (int form = 0; form < 3; form++) { /* pow, exp, exp with the fast weight */
      const int nexp = form > 0, fast = form == 2;
      for (int y = 0; y < LH; y++) {
        for (int x = 0; x < LW; x++) {
          const size_t pi = (size_t)y * LW + x;
          const float l = 0.3f + 0.5f * rnd();
          mom1[pi] = l;
          mom2[pi] = l * l + 0.1f * rnd();
          const float u = rnd();
          age[pi] = u < 0.4f ? 1.0f + (float)(int)(3.0f * rnd()) : 10.0f;
          if (holes && u > 0.85f) age[pi] = 0.0f;
          var[pi] = -1.0f; /* kept where age >= 4 */
        }
      }
      const svgf_guide g = test_guide(&zn, gx, gy, zon, LW, LH);
      svgf_spatial_variance(&g, mom, age, 4.0f, var, nexp, fast, holes, 2);
      double worst = 0.0;
      int kept = 1;
      const int R = SVGF_SPATIAL_VARIANCE_RADIUS;
      for (int y = 0; y < LH; y++)
        for (int x = 0; x < LW; x++) {
          const size_t pi = (size_t)y * LW + x;
          if (!(age[pi] < 4.0f)) {
            kept &= var[pi] == -1.0f;
            continue;
          }
          double sw = 0, s1 = 0, s2 = 0;
          for (int j = -R; j <= R; j++)
            for (int i = -R; i <= R; i++) {
              const int qx = x + i < 0 ? 0 : x + i >= LW ? LW - 1 : x + i;
              const int qy = y + j < 0 ? 0 : y + j >= LH ? LH - 1 : y + j;
              if (!(age[(size_t)qy * LW + qx] > 0.0f)) continue;
              const size_t gp = (size_t)y * zn.stride + x, gq = (size_t)qy * zn.stride + qx;
              double w = 1.0;
              if (i || j) {
                const double ez = zon[pi] * fabs((double)zn.plane[0][gp] - zn.plane[0][gq]) /
                                  (fabs((double)gx[pi] * i + (double)gy[pi] * j) + SVGF_EPS_Z);
                double dot = 0.0;
                for (int c = 1; c <= 3; c++) dot += (double)zn.plane[c][gp] * zn.plane[c][gq];
                const double wn = nexp ? exp(-128.0 * (1.0 - dot)) : pow(dot > 0 ? dot : 0, 128.0);
                w = wn * exp(-ez);
                if (w <= exp(-20.0))
                  w = 0.0;
                else if (fast)
                  w = fast_exp2_model(log2(w));
              }
              const size_t mq = (size_t)qy * LW + qx;
              sw += w;
              s1 += w * mom1[mq];
              s2 += w * mom2[mq];
            }
          double est = sw > 0 ? s2 / sw - (s1 / sw) * (s1 / sw) : 0.0;
          est = est > 0 ? est : 0.0;
          const double e = fabs(var[pi] - est);
          worst = e > worst ? e : worst;
        }
      CHECK_MSG(worst < 1e-5 && kept, "spatial variance %s%s: worst difference %g, kept %d",
                fast ? "fast exp" : nexp ? "exp" : "pow", holes ? " holes" : "", worst, kept);
    }
  svgf_padded_free(&zn);
  svgf_padded_free(&in);
  svgf_padded_free(&out);
}

/* ---- emission ------------------------------------------------------------ */

/* A dark wall (radiance `wall`) with a lamp on it: a 6 x 6 patch whose
 * colour is the lamp's emission E, plus `lamp_reflects` times the wall's
 * radiance. The lamp shares the wall's depth and normal, so no G-buffer
 * edge separates them: only the emission input does. */
#define LAMP_X0 20
#define LAMP_Y0 18
#define LAMP_E 20.0f
static int in_lamp(int i) {
  const int x = i % W, y = i / W;
  return x >= LAMP_X0 && x < LAMP_X0 + 6 && y >= LAMP_Y0 && y < LAMP_Y0 + 6;
}

static void lamp_scene(scene *s, float *emission, float wall, int lamp_reflects) {
  flat(s, wall, wall, wall, 3.0f);
  for (int i = 0; i < N; i++)
    for (int c = 0; c < 3; c++) {
      emission[3 * i + c] = in_lamp(i) ? LAMP_E : 0.0f;
      s->color[3 * i + c] = in_lamp(i) ? LAMP_E + (lamp_reflects ? wall : 0.0f) : wall;
    }
}

/* make() with 'emission' bound too (NULL: unbound). */
static hush_filter make_emission(hush_device dev, const char *cls, scene *s, float *emission) {
  hush_filter f = hush_filter_new(dev, cls);
  REQUIRE(f);
  hush_image_view v = view_of(s->color, HUSH_FORMAT_FLOAT3);
  REQUIRE(hush_filter_set_image(f, "color", &v) == HUSH_OK);
  v = view_of(s->depth, HUSH_FORMAT_FLOAT);
  REQUIRE(hush_filter_set_image(f, "depth", &v) == HUSH_OK);
  v = view_of(s->normal, HUSH_FORMAT_FLOAT3);
  REQUIRE(hush_filter_set_image(f, "normal", &v) == HUSH_OK);
  v = view_of(s->albedo, HUSH_FORMAT_FLOAT3);
  REQUIRE(hush_filter_set_image(f, "albedo", &v) == HUSH_OK);
  if (emission) {
    v = view_of(emission, HUSH_FORMAT_FLOAT3);
    REQUIRE(hush_filter_set_image(f, "emission", &v) == HUSH_OK);
    if (strcmp(cls, "svgf") == 0) /* opt-in there (its lamp edges stay aliased) */
      REQUIRE(hush_filter_set_bool(f, "emission_bypass", 1) == HUSH_OK);
  }
  v = view_of(s->output, HUSH_FORMAT_FLOAT3);
  REQUIRE(hush_filter_set_image(f, "output", &v) == HUSH_OK);
  REQUIRE(hush_filter_commit(f) == HUSH_OK);
  return f;
}


/*
 * The wavefront gives the bits of the levels run one at a time, through the
 * same ping-pong buffers as svgf.c (level k writes what level k-2 read
 * from): a lag too short lets a level read a row the level before has not
 * written yet, or overwrite one it still reads, and the bits differ.
 */
#define WFW 520
#define WFH 400
static svgf_padded wf_zn, wf_init, wf_buf[2];
static float wf_gx[WFW * WFH], wf_gy[WFW * WFH], wf_zon[WFW * WFH];
static float wf_last[2][3][WFW * WFH], wf_also[2][3][WFW * WFH];
static float wf_ring[3][SVGF_WAVEFRONT_RING * WFW];

/* The last level into wf_ring, each part of a row copied out to wf_last
 * as it is finished (svgf.c's export): a ring too short for the threads'
 * distance, or a split that moves under a row, shows as wrong bits. */
typedef struct ring_export {
  int slot, width;
} ring_export;

static void ring_span_done(void *ctx, int y, int xa, int xb) {
  const ring_export *e = ctx;
  const size_t r = (size_t)(y % SVGF_WAVEFRONT_RING) * e->width + xa;
  for (int c = 0; c < 3; c++)
    memcpy(wf_last[e->slot][c] + (size_t)y * e->width + xa, wf_ring[c] + r,
           (size_t)(xb - xa) * sizeof(float));
}

/* A w x h frame (guide and first signal): two surfaces meeting at a
 * slanted depth and normal edge, sky in a corner, noisy colour, 30 % of
 * the pixels without data. */
static svgf_guide wavefront_frame(hush_device dev, int w, int h) {
  const int pad = 2 << 5; /* 5x5 at step 32 (6 levels) */
  svgf_padded_free(&wf_zn);
  svgf_padded_free(&wf_init);
  REQUIRE(svgf_padded_ensure(dev, &wf_zn, 4, w, h, pad) == HUSH_OK);
  REQUIRE(svgf_padded_ensure(dev, &wf_init, SVGF_SIGNAL_CHANNELS, w, h, pad) == HUSH_OK);
  for (int b = 0; b < 2; b++) {
    svgf_padded_free(&wf_buf[b]);
    REQUIRE(svgf_padded_ensure(dev, &wf_buf[b], SVGF_SIGNAL_CHANNELS, w, h, pad) == HUSH_OK);
  }
  for (int y = 0; y < h; y++) {
    for (int x = 0; x < w; x++) {
      const size_t i = (size_t)y * wf_zn.stride + x, pi = (size_t)y * w + x;
      const int right = x > w / 3 + y / 4;
      wf_zn.plane[0][i] = (right ? 3.0f : 2.0f) + 0.01f * (float)y + 0.01f * rnd();
      float n[3] = {right ? 0.6f : 0.05f * rnd(), 0.05f * rnd(), right ? 0.8f : 1.0f};
      const float len = sqrtf(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
      for (int c = 0; c < 3; c++) wf_zn.plane[1 + c][i] = n[c] / len;
      if (y > h - h / 10 && x < w / 5) /* sky */
        for (int c = 0; c < 4; c++) wf_zn.plane[c][i] = 0.0f;
      random_signal(&wf_init, (size_t)y * wf_init.stride + x, right, 0.3f);
      wf_gx[pi] = 0.01f * (rnd() - 0.5f);
      wf_gy[pi] = 0.01f + 0.01f * rnd();
      wf_zon[pi] = 1.0f;
    }
    for (int c = 0; c < 4; c++) svgf_pad_row(svgf_padded_row(&wf_zn, c, y), w, wf_zn.pad);
    for (int c = 0; c < SVGF_SIGNAL_CHANNELS; c++)
      svgf_pad_row(svgf_padded_row(&wf_init, c, y), w, wf_init.pad);
  }
  return test_guide(&wf_zn, wf_gx, wf_gy, wf_zon, w, h);
}

/* Levels of a tap order on the frame of wavefront_frame, the last one into
 * wf_last[slot] (unpadded, as svgf.c's result; ring: through wf_ring) and
 * the first one's colour also into wf_also[slot]. how: 0 one level at a
 * time, 1 svgf_atrous_wavefront (with jitter), 2 svgf_atrous_levels. */
static void wavefront_run(const svgf_guide *g, int order, int valid, int portable, int how,
                          int threads, int slot, unsigned jitter, int ring) {
  /* steps per level: increasing, decreasing, 0-then-decreasing (5x5), and
   * the thesis's 6 levels of 3x3 */
  static const int steps[4][6] = {
      {1, 2, 4, 8, 16}, {16, 8, 4, 2, 1}, {1, 16, 8, 4, 2}, {1, 2, 4, 8, 16, 32}};
  const int n = order == 3 ? 6 : 5, w = g->width, h = g->height;
  for (int c = 0; c < SVGF_SIGNAL_CHANNELS; c++)
    memcpy(wf_buf[0].mem[c], wf_init.mem[c], wf_buf[0].stride * (size_t)h * sizeof(float));
  svgf_level_params lp[6];
  svgf_level_out out[6];
  const svgf_padded *in[6];
  const svgf_level_out *outp[6];
  ring_export rx = {slot, w};
  for (int k = 0; k < n; k++) {
    lp[k].kernel = order == 3 ? &svgf_kernel_3x3 : &svgf_kernel_5x5;
    lp[k].step = steps[order][k];
    lp[k].sigma_l = 4.0f;
    lp[k].eps_l = NULL;
    lp[k].validity = valid;
    lp[k].normal_exp = 1;
    lp[k].fast_exp = order >= 2; /* both weights through the wavefront */
    lp[k].portable = portable;
    lp[k].vectors = 1 + ((order + valid) & 1);
    in[k] = &wf_buf[k & 1];
    out[k] = svgf_level_out_padded(&wf_buf[1 - (k & 1)]);
    if (k == 0)
      for (int c = 0; c < 3; c++) out[k].also[c] = wf_also[slot][c];
    if (k == n - 1) {
      for (int c = 0; c < SVGF_SIGNAL_CHANNELS; c++) out[k].plane[c] = NULL;
      for (int c = 0; c < 3; c++) out[k].plane[c] = wf_last[slot][c];
      out[k].stride = (size_t)w;
      out[k].pad = 0;
      if (ring) {
        for (int c = 0; c < 3; c++) out[k].plane[c] = wf_ring[c];
        out[k].ring = SVGF_WAVEFRONT_RING;
        out[k].span_done = ring_span_done;
        out[k].span_ctx = &rx;
      }
    }
    outp[k] = &out[k];
  }
  if (how == 0)
    for (int k = 0; k < n; k++) svgf_atrous_level(g, &lp[k], in[k], outp[k], threads);
  else if (how == 1)
    svgf_atrous_wavefront(g, lp, in, outp, n, threads, jitter);
  else
    svgf_atrous_levels(g, lp, in, outp, n, threads);
}

static int wavefront_same(int w, int h) {
  const size_t bytes = (size_t)w * h * sizeof(float);
  for (int c = 0; c < 3; c++)
    if (memcmp(wf_last[0][c], wf_last[1][c], bytes) || memcmp(wf_also[0][c], wf_also[1][c], bytes))
      return 0;
  return 1;
}

/* Every tap order, both kernels, with and without validity, both loops, 2
 * and 3 threads (rows split in parts: as svgf_atrous_levels splits them,
 * and split at random, with the last level into wf_ring or not) on a small
 * frame whose width is no multiple of 32 (taps past every border); then
 * svgf_atrous_levels above SVGF_WAVEFRONT_MIN_PIXELS, where it takes the
 * wavefront. */
static void test_wavefront(hush_device dev) {
  const int w = 150, h = 100;
  svgf_guide g = wavefront_frame(dev, w, h);
  for (int order = 0; order < 4; order++)
    for (int valid = 0; valid <= 1; valid++)
      for (int portable = 0; portable <= 1; portable++) {
        wavefront_run(&g, order, valid, portable, 0, 2, 0, 0, 0);
        for (int threads = 2; threads <= 3; threads++)
          for (unsigned jitter = 0; jitter <= 2; jitter++) {
            const int ring = (int)jitter == 1 + (order & 1);
            wavefront_run(&g, order, valid, portable, 1, threads, 1, jitter, ring);
            CHECK_MSG(wavefront_same(w, h),
                      "wavefront order %d%s%s, %d threads, split %s%s: not the bits of one level "
                      "at a time",
                      order, valid ? " validity" : "", portable ? " portable" : "", threads,
                      jitter ? "at random" : "adaptive", ring ? ", ring" : "");
          }
      }
  REQUIRE((long long)WFW * WFH >= SVGF_WAVEFRONT_MIN_PIXELS);
  g = wavefront_frame(dev, WFW, WFH);
  wavefront_run(&g, 0, 0, 0, 0, 2, 0, 0, 0);
  wavefront_run(&g, 0, 0, 0, 2, 2, 1, 0, 1);
  CHECK_MSG(wavefront_same(WFW, WFH), "svgf_atrous_levels at %dx%d: not the bits of one level at a time",
            WFW, WFH);
  svgf_padded_free(&wf_zn);
  svgf_padded_free(&wf_init);
  for (int b = 0; b < 2; b++) svgf_padded_free(&wf_buf[b]);
}
/* A lamp's edge at 1 spp: the column just right of the lamp sees the lamp
 * (its emission and its id) on even frames and the wall on odd ones, as a
 * jittered sample on a pixel the lamp's edge crosses. The lamp and wall
 * have ids: without the emission input the id test keeps their histories
 * apart, so the edge keeps flipping between E and the wall; with it, the
 * lamp's pixels match any id (hush__emission_wildcard_ids) and the edge's
 * accumulated emission averages its coverage, about E / 2 in both phases,
 * while the wall a pixel further on gets none. */
static void test_emission_edge(hush_device dev, const char *cls) {
  static scene s;
  static float emission[N * 3], id[N];
  const float wall = 0.05f;
  const int edge = LAMP_X0 + 6;
  for (int bound = 0; bound <= 1; bound++) {
    lamp_scene(&s, emission, wall, 0);
    hush_filter f = make_emission(dev, cls, &s, bound ? emission : NULL);
    hush_image_view v = view_of(id, HUSH_FORMAT_FLOAT);
    REQUIRE(hush_filter_set_image(f, "id", &v) == HUSH_OK);
    REQUIRE(hush_filter_commit(f) == HUSH_OK);
    float lo = INFINITY, hi = -INFINITY, beyond = 0.0f;
    for (int k = 0; k < 16; k++) {
      for (int i = 0; i < N; i++) {
        const int x = i % W, y = i / W;
        const int lit = in_lamp(i) || (k % 2 == 0 && x == edge && y >= LAMP_Y0 && y < LAMP_Y0 + 6);
        id[i] = lit ? 1.0f : 2.0f;
        for (int c = 0; c < 3; c++) {
          emission[3 * i + c] = lit ? LAMP_E : 0.0f;
          s.color[3 * i + c] = lit ? LAMP_E : wall;
        }
      }
      run(f, (uint64_t)k);
      if (k < 8) continue;
      for (int y = LAMP_Y0; y < LAMP_Y0 + 6; y++) {
        const float o = s.output[3 * (y * W + edge)];
        lo = o < lo ? o : lo;
        hi = o > hi ? o : hi;
        const float b = s.output[3 * (y * W + edge + 2)];
        beyond = b > beyond ? b : beyond;
      }
    }
    printf("edge %s bound %d: %g .. %g beyond %g\n", cls, bound, (double)lo, (double)hi, (double)beyond);
    if (bound) {
      CHECK_MSG(lo > 0.3f * LAMP_E && hi < 0.7f * LAMP_E,
                "%s: lamp edge not averaged over frames: %g .. %g (E %g)", cls, (double)lo,
                (double)hi, (double)LAMP_E);
      CHECK_MSG(beyond <= wall + 1e-4f, "%s: the lamp's emission reaches 2 pixels out: %g", cls,
                (double)beyond);
    } else {
      /* without the emission input the lamp is colour like any other,
       * and the ids keep the edge's two histories apart */
      CHECK_MSG(hi > 0.9f * LAMP_E && lo < 0.1f * LAMP_E, "%s: edge without emission %g .. %g",
                cls, (double)lo, (double)hi);
    }
    hush_filter_release(f);
  }
}

/* With 'emission' bound, the lamp's output is its emission (plus at most
 * the wall's radiance the filter may spread onto it) and none of the
 * lamp's radiance reaches the wall; a lamp that also reflects the wall's
 * light comes out exactly; zero emission changes nothing, bit for bit. */
static void test_emission(hush_device dev, const char *cls) {
  static scene s;
  static float emission[N * 3], plain[N * 3];
  const float wall = 0.05f;
  lamp_scene(&s, emission, wall, 0);
  hush_filter f = make_emission(dev, cls, &s, emission);
  for (int k = 0; k < 6; k++) run(f, (uint64_t)k);
  float lamp_dev = 0.0f, wall_max = 0.0f;
  for (int i = 0; i < N; i++)
    for (int c = 0; c < 3; c++) {
      const float o = s.output[3 * i + c];
      if (in_lamp(i)) {
        const float d = o < LAMP_E ? LAMP_E - o : o - LAMP_E - wall;
        lamp_dev = d > lamp_dev ? d : lamp_dev;
      } else {
        wall_max = o > wall_max ? o : wall_max;
      }
    }
  CHECK_MSG(lamp_dev <= 1e-4f * LAMP_E, "%s: lamp output off its emission by %g", cls,
            (double)lamp_dev);
  CHECK_MSG(wall_max <= wall + 1e-5f, "%s: lamp leaks into the wall: %g (wall %g)", cls,
            (double)wall_max, (double)wall);
  CHECK(all_finite(s.output, N * 3));
  hush_filter_release(f);

  lamp_scene(&s, emission, wall, 1);
  f = make_emission(dev, cls, &s, emission);
  for (int k = 0; k < 6; k++) run(f, (uint64_t)k);
  CHECK_MSG(max_abs_diff(s.output, s.color, N * 3) <= 1e-5f * LAMP_E,
            "%s: reflecting lamp off by %g", cls, (double)max_abs_diff(s.output, s.color, N * 3));
  hush_filter_release(f);

  /* noisy frames, emission 0: the same output as without the input */
  memset(emission, 0, sizeof emission);
  for (int pass = 0; pass < 2; pass++) {
    rng_state = 777u;
    flat(&s, 0, 0, 0, 3.0f);
    f = make_emission(dev, cls, &s, pass ? emission : NULL);
    for (int k = 0; k < 4; k++) {
      for (int i = 0; i < N * 3; i++) s.color[i] = 0.5f * rnd();
      run(f, (uint64_t)k);
    }
    if (pass == 0) memcpy(plain, s.output, sizeof plain);
    hush_filter_release(f);
  }
  CHECK_MSG(memcmp(plain, s.output, sizeof plain) == 0, "%s: zero emission changed the output",
            cls);

  /* a light's edge pixel at 1 spp: the jittered ray sees the light every
   * other frame; the emission added back is accumulated, so the output
   * settles near the coverage (E / 2) instead of flipping between 0 and E */
  lamp_scene(&s, emission, wall, 0);
  f = make_emission(dev, cls, &s, emission);
  const int edge = 3 * (LAMP_Y0 * W + LAMP_X0 + 6); /* right of the lamp */
  float worst = 0.0f;
  for (int k = 0; k < 16; k++) {
    const float e = k % 2 ? LAMP_E : 0.0f;
    for (int c = 0; c < 3; c++) {
      emission[edge + c] = e;
      s.color[edge + c] = e + wall;
    }
    run(f, (uint64_t)k);
    const float d = fabsf(s.output[edge] - 0.5f * LAMP_E);
    if (k >= 8) worst = d > worst ? d : worst;
  }
  CHECK_MSG(worst <= 0.15f * LAMP_E, "%s: edge pixel %g away from its coverage", cls,
            (double)worst);
  hush_filter_release(f);
}

/* On a frame large enough for the a-trous wavefront, svgf writes the
 * output row by row as its last level finishes them (svgf.c, span_done),
 * with the accumulated emission added there; with the light split into
 * 'direct' (the colour) and 'indirect' (zeros, which filter to exactly 0)
 * it filters the same signal and exports the whole frame after the a-trous
 * instead. Both must give the same bits (x + 0 is x for the non-negative
 * radiance here), frame after frame, with textured albedo, noise and a
 * lamp in some rows (others without emission: their rows' flags), so a
 * row or column put in the wrong place, a part not exported or an
 * emission not added shows. */
static void test_row_export(hush_device dev) {
  enum { BW = 640, BH = 360, BN = BW * BH };
  REQUIRE(svgf_atrous_levels_wavefront(BW, BH));
  float *color = malloc(sizeof(float) * BN * 3), *albedo = malloc(sizeof(float) * BN * 3);
  float *normal = malloc(sizeof(float) * BN * 3), *depth = malloc(sizeof(float) * BN);
  float *zero = calloc((size_t)BN * 3, sizeof(float)), *lamp = malloc(sizeof(float) * BN * 3);
  float *out[2] = {malloc(sizeof(float) * BN * 3), malloc(sizeof(float) * BN * 3)};
  REQUIRE(color && albedo && normal && depth && zero && lamp && out[0] && out[1]);
  for (int i = 0; i < BN; i++) {
    const int x = i % BW, y = i / BW;
    depth[i] = x < BW / 3 ? 2.0f : 3.0f + 0.002f * (float)y;
    normal[3 * i + 0] = 0.0f;
    normal[3 * i + 1] = y < BH / 2 ? 0.0f : 0.6f;
    normal[3 * i + 2] = y < BH / 2 ? 1.0f : 0.8f;
    const int lit = x >= 200 && x < 260 && y >= 100 && y < 140;
    for (int c = 0; c < 3; c++) {
      albedo[3 * i + c] = 0.1f + 0.8f * (float)((x * 7 + y * 3 + c) % 11) / 11.0f;
      lamp[3 * i + c] = lit ? 3.0f + (float)c : 0.0f;
    }
  }
  hush_filter f[2];
  for (int k = 0; k < 2; k++) {
    f[k] = hush_filter_new(dev, "svgf");
    REQUIRE(f[k]);
    hush_image_view v;
    memset(&v, 0, sizeof v);
    v.width = BW;
    v.height = BH;
    const struct { const char *name; void *data; hush_format format; } img[] = {
        {"depth", depth, HUSH_FORMAT_FLOAT},    {"normal", normal, HUSH_FORMAT_FLOAT3},
        {"albedo", albedo, HUSH_FORMAT_FLOAT3}, {"output", out[k], HUSH_FORMAT_FLOAT3},
        {"emission", lamp, HUSH_FORMAT_FLOAT3}, {"color", color, HUSH_FORMAT_FLOAT3},
        {"direct", color, HUSH_FORMAT_FLOAT3},  {"indirect", zero, HUSH_FORMAT_FLOAT3}};
    for (int j = 0; j < (k ? 8 : 6); j++) {
      v.data = img[j].data;
      v.format = img[j].format;
      REQUIRE(hush_filter_set_image(f[k], img[j].name, &v) == HUSH_OK);
    }
    REQUIRE(hush_filter_commit(f[k]) == HUSH_OK);
  }
  for (int frame = 0; frame < 3; frame++) {
    for (int i = 0; i < BN * 3; i++) color[i] = lamp[i] + albedo[i] * (0.2f + 1.6f * rnd());
    hush_frame_info fi;
    hush_frame_info_init(&fi);
    fi.frame_index = (uint64_t)frame;
    float w2v[16], v2c[16];
    hush_m4_look_at(w2v, hush_v3(0, 0, 5), hush_v3(0, 0, 0), hush_v3(0, 1, 0));
    hush_m4_perspective(v2c, 60.0f, (float)BW / BH, 0.1f, 100.0f);
    memcpy(fi.world_to_view, w2v, sizeof w2v);
    memcpy(fi.prev_world_to_view, w2v, sizeof w2v);
    memcpy(fi.view_to_clip, v2c, sizeof v2c);
    memcpy(fi.prev_view_to_clip, v2c, sizeof v2c);
    for (int k = 0; k < 2; k++) REQUIRE(hush_filter_execute(f[k], &fi) == HUSH_OK);
    CHECK_MSG(memcmp(out[0], out[1], sizeof(float) * BN * 3) == 0,
              "frame %d: the row-by-row export differs from the export pass", frame);
  }
  CHECK(all_finite(out[0], BN * 3));
  /* the lamp's own pixels come out as its emission (plus a little wall) */
  const size_t at = 3 * ((size_t)120 * BW + 230);
  CHECK_MSG(out[0][at] >= 3.0f && out[0][at + 2] >= 5.0f, "lamp pixel %g %g", (double)out[0][at],
            (double)out[0][at + 2]);
  for (int k = 0; k < 2; k++) {
    hush_filter_release(f[k]);
    free(out[k]);
  }
  free(color);
  free(albedo);
  free(normal);
  free(depth);
  free(zero);
  free(lamp);
}

int main(void) {
  hush_device dev = hush_device_new("threads=2");
  REQUIRE(dev);
  test_weight_math();
  test_level_formula(dev);
  test_wavefront(dev);
  test_constant(dev, 0);
  test_constant(dev, 1);
  test_edges(dev);
  test_noise(dev);
  test_determinism("svgf");
  test_half(dev);
  test_misuse(dev);
  test_sigma_n_general(dev);
  test_variants(dev);
  test_history_shrinks_noise(dev);
  test_depth_steep(dev);
  test_sample_variance(dev);
  test_split(dev);
  test_progressive(dev);
  test_progressive_determinism();
  test_taa_constant(dev, "taa");
  test_taa_constant(dev, "svgf");
  test_taa_ghosting(dev, "clamp");
  test_taa_ghosting(dev, "clip");
  test_taa_smooths(dev);
  test_determinism("taa");
  test_emission(dev, "svgf");
  test_emission(dev, "accumulate");
  test_emission_edge(dev, "svgf");
  test_emission_edge(dev, "accumulate");
  test_row_export(dev);
  hush_device_release(dev);
  return check_summary();
}
