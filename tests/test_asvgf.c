/*
 * test_asvgf.c — A-SVGF: the shared temporal-gradient module
 * (src/temporal/gradient.h) on synthetic gradient layers, and the "asvgf"
 * filter through the public API.
 */
#include "hush.h"

#include "check.h"
#include "core/hmath.h"
#include "io/frame.h"
#include "temporal/gradient.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>

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
  p.threshold = 0.0f;
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
      for (int sx = 0; sx < ws; sx++)
        put_sample(&g, sx, sy, 0.3f + 0.01f * sx, 0.3f + 0.01f * sx, (sx + sy) % 9);
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
    /* the noise floor: r = 0.5 with t = 0.2 is (0.5 - 0.2) / 0.8 = 0.375, squared; a gradient
     * below the floor is 0, a full one stays exactly 1 */
    p.threshold = 0.2f;
    compute(&g, &p, 2);
    CHECK_NEAR(lambda_at(&g, 25, 15), 0.140625f, 1e-4f);
    p.threshold = 0.6f;
    compute(&g, &p, 2);
    CHECK(lambda_at(&g, 25, 15) == 0.0f);
    for (int sy = 0; sy < hs; sy++)
      for (int sx = 0; sx < ws; sx++) put_sample(&g, sx, sy, 0.0f, 0.7f, 4);
    compute(&g, &p, 2);
    CHECK(lambda_at(&g, 25, 15) == 1.0f);
    p.threshold = 0.0f;
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


/* ---- the "asvgf" filter on synthetic frames ------------------------------- */

#define FW 48
#define FH 36
#define FN (FW * FH)

typedef struct fscene {
  float color[FN * 3];
  float depth[FN];
  float normal[FN * 3];
  float gradient[FN * 3];
  float output[FN * 3];
  float age[FN];
} fscene;

static uint32_t rng_state = 12345u;
static float rnd(void) { /* uniform in [0, 1), xorshift32 */
  rng_state ^= rng_state << 13;
  rng_state ^= rng_state >> 17;
  rng_state ^= rng_state << 5;
  return (float)(rng_state >> 8) / 16777216.0f;
}

/* A fronto-parallel wall, left half at depth 2, right half at depth 4. */
static void fscene_wall(fscene *s) {
  memset(s, 0, sizeof *s);
  for (int i = 0; i < FN; i++) {
    s->depth[i] = (i % FW) < FW / 2 ? 2.0f : 4.0f;
    s->normal[3 * i + 2] = 1.0f;
  }
}

/* Every stratum's sample: current and previous luminance, landing pixel 4
 * (the centre); the right half (x >= FW / 2) gets (c_right, p_right). */
static void fscene_gradient(fscene *s, float c, float p, float c_right, float p_right) {
  for (int y = 0; y < FH; y++)
    for (int x = 0; x < FW; x++) {
      const int i = y * FW + x, right = x >= FW / 2;
      s->gradient[3 * i + 0] = right ? c_right : c;
      s->gradient[3 * i + 1] = right ? p_right : p;
      s->gradient[3 * i + 2] = 4.0f;
    }
}

static hush_image_view fview(void *data, hush_format format) {
  hush_image_view v;
  memset(&v, 0, sizeof v);
  v.data = data;
  v.format = format;
  v.width = FW;
  v.height = FH;
  return v;
}

static void fframe_info(hush_frame_info *fi, uint64_t index) {
  hush_frame_info_init(fi);
  fi->frame_index = index;
  float w2v[16], v2c[16];
  hush_m4_look_at(w2v, hush_v3(0, 0, 5), hush_v3(0, 0, 0), hush_v3(0, 1, 0));
  hush_m4_perspective(v2c, 60.0f, (float)FW / FH, 0.1f, 100.0f);
  memcpy(fi->world_to_view, w2v, sizeof w2v);
  memcpy(fi->prev_world_to_view, w2v, sizeof w2v);
  memcpy(fi->view_to_clip, v2c, sizeof v2c);
  memcpy(fi->prev_view_to_clip, v2c, sizeof v2c);
}

static hush_filter fmake(hush_device dev, const char *cls, fscene *s, int bind_gradient) {
  hush_filter f = hush_filter_new(dev, cls);
  REQUIRE(f);
  hush_image_view v = fview(s->color, HUSH_FORMAT_FLOAT3);
  REQUIRE(hush_filter_set_image(f, "color", &v) == HUSH_OK);
  v = fview(s->depth, HUSH_FORMAT_FLOAT);
  REQUIRE(hush_filter_set_image(f, "depth", &v) == HUSH_OK);
  v = fview(s->normal, HUSH_FORMAT_FLOAT3);
  REQUIRE(hush_filter_set_image(f, "normal", &v) == HUSH_OK);
  if (bind_gradient) {
    v = fview(s->gradient, HUSH_FORMAT_FLOAT3);
    REQUIRE(hush_filter_set_image(f, "gradient", &v) == HUSH_OK);
  }
  v = fview(s->output, HUSH_FORMAT_FLOAT3);
  REQUIRE(hush_filter_set_image(f, "output", &v) == HUSH_OK);
  v = fview(s->age, HUSH_FORMAT_FLOAT);
  REQUIRE(hush_filter_set_image(f, "history_length", &v) == HUSH_OK);
  return f;
}

static hush_status frun(hush_filter f, uint64_t index) {
  hush_frame_info fi;
  fframe_info(&fi, index);
  return hush_filter_execute(f, &fi);
}

static void noisy_color(fscene *s, float mean) {
  for (int i = 0; i < FN * 3; i++) s->color[i] = mean * 2.0f * rnd();
}

/* c = p everywhere: asvgf is svgf bit for bit (colour and history length),
 * also with the direct/indirect split off; and the "gradient" stage is timed. */
static void test_same_as_svgf(hush_device dev) {
  static fscene a, b;
  fscene_wall(&a);
  fscene_wall(&b);
  fscene_gradient(&a, 0.3f, 0.3f, 0.8f, 0.8f);
  hush_filter fa = fmake(dev, "asvgf", &a, 1), fb = fmake(dev, "svgf", &b, 0);
  REQUIRE(hush_filter_commit(fa) == HUSH_OK);
  REQUIRE(hush_filter_commit(fb) == HUSH_OK);
  int same = 1;
  for (int k = 0; k < 8; k++) {
    noisy_color(&a, 0.5f);
    memcpy(b.color, a.color, sizeof a.color);
    REQUIRE(frun(fa, (uint64_t)k) == HUSH_OK);
    REQUIRE(frun(fb, (uint64_t)k) == HUSH_OK);
    same &= memcmp(a.output, b.output, sizeof a.output) == 0;
    same &= memcmp(a.age, b.age, sizeof a.age) == 0;
  }
  CHECK_MSG(same, "asvgf with a zero gradient differs from svgf");
  const char *const *names;
  const double *ms;
  uint32_t count = 0;
  REQUIRE(hush_filter_get_timings(fa, &names, &ms, &count) == HUSH_OK);
  int has = 0;
  for (uint32_t i = 0; i < count; i++) has |= strcmp(names[i], "gradient") == 0;
  CHECK(has);
  hush_filter_release(fa);
  hush_filter_release(fb);
}

/* After 5 unchanged frames the right half goes dark (c = 0 < p): its
 * history length drops to 1 and the output is exactly this frame's colour
 * there; the left half keeps its history. A constant image stays constant
 * through all of it, whatever lambda. */
static void test_history_and_constant(hush_device dev) {
  static fscene s;
  fscene_wall(&s);
  hush_filter f = fmake(dev, "asvgf", &s, 1);
  REQUIRE(hush_filter_commit(f) == HUSH_OK);
  for (int i = 0; i < FN * 3; i++) s.color[i] = 0.4f;
  fscene_gradient(&s, 0.4f, 0.4f, 0.4f, 0.4f);
  int constant = 1;
  for (int k = 0; k < 5; k++) {
    REQUIRE(frun(f, (uint64_t)k) == HUSH_OK);
    for (int i = 0; i < FN * 3; i++) constant &= fabsf(s.output[i] - 0.4f) <= 1e-5f;
  }
  fscene_gradient(&s, 0.4f, 0.4f, 0.0f, 0.4f);
  for (int i = 0; i < FN; i++)
    if (i % FW >= FW / 2)
      for (int c = 0; c < 3; c++) s.color[3 * i + c] = 0.1f;
  REQUIRE(frun(f, 5) == HUSH_OK);
  int left_kept = 1, right_reset = 1, right_now = 1;
  for (int y = 0; y < FH; y++)
    for (int x = 0; x < FW; x++) {
      const int i = y * FW + x;
      if (x < FW / 2) {
        left_kept &= s.age[i] == 6.0f;
        for (int c = 0; c < 3; c++) constant &= fabsf(s.output[3 * i + c] - 0.4f) <= 1e-5f;
      } else {
        right_reset &= s.age[i] == 1.0f;
        for (int c = 0; c < 3; c++) right_now &= fabsf(s.output[3 * i + c] - 0.1f) <= 1e-5f;
      }
    }
  CHECK_MSG(constant, "a constant image did not stay constant");
  CHECK_MSG(left_kept, "unchanged half lost its history");
  CHECK_MSG(right_reset, "changed half kept its history");
  CHECK_MSG(right_now, "changed half lags");
  /* svgf lags there: 0.8 of the old value is kept */
  hush_filter_release(f);
}

static int error_names(hush_device dev, const char *what) {
  const char *msg = NULL;
  hush_device_get_error(dev, &msg);
  return msg && strstr(msg, what) != NULL;
}

/* No gradient layer: a clear error naming it. NaN in it: an error naming
 * it with nonfinite=error, a finite output with nonfinite=replace. */
static void test_bad_gradient(hush_device dev) {
  static fscene s;
  fscene_wall(&s);
  noisy_color(&s, 0.5f);
  hush_filter f = fmake(dev, "asvgf", &s, 0);
  CHECK(hush_filter_commit(f) != HUSH_OK);
  CHECK(error_names(dev, "'gradient'"));
  hush_filter_release(f);

  fscene_gradient(&s, 0.5f, 0.5f, 0.5f, 0.5f);
  s.gradient[3 * (10 * FW + 30) + 0] = NAN;
  s.gradient[3 * (20 * FW + 3) + 1] = INFINITY;
  f = fmake(dev, "asvgf", &s, 1);
  REQUIRE(hush_filter_commit(f) == HUSH_OK);
  CHECK(frun(f, 0) != HUSH_OK);
  CHECK(error_names(dev, "gradient"));
  REQUIRE(hush_filter_set_string(f, "nonfinite", "replace") == HUSH_OK);
  int finite = 1;
  for (int k = 0; k < 3; k++) {
    CHECK(frun(f, (uint64_t)k) == HUSH_OK);
    for (int i = 0; i < FN * 3; i++) finite &= isfinite(s.output[i]) != 0;
  }
  CHECK(finite);
  hush_device_get_error(dev, NULL);
  hush_filter_release(f);
}

/* ---- builtin:light-off, rendered with gradients ---------------------------- */

#define WORK HUSH_BINARY_DIR "/test_asvgf"
#define LW 160
#define LH 90
#define LN (LW * LH)

static int cli(const char *args) {
  char cmd[2048];
  snprintf(cmd, sizeof cmd, "'%s' %s >> '%s/out.txt' 2>&1", HUSH_CLI, args, WORK);
  const int s = system(cmd);
  return (s != -1 && WIFEXITED(s)) ? WEXITSTATUS(s) : -1;
}

/* Channel c of layer `name` of a sequence frame into dst (LN floats). */
static void read_layer(hush_device dev, const char *dir, int frame, const char *name, int c,
                       float *dst) {
  char path[512];
  snprintf(path, sizeof path, "%s/frame_%04d.exr", dir, frame);
  hush_frame fr;
  REQUIRE(hush_frame_read_exr(dev, path, &fr) == HUSH_OK);
  const hush_layer *l = hush__frame_find(fr, name);
  REQUIRE(l && c < l->channels && fr->width == LW && fr->height == LH);
  for (int i = 0; i < LN; i++) dst[i] = l->pixels[(size_t)i * l->channels + c];
  hush_frame_release(fr);
}

static void read_lum(hush_device dev, const char *dir, int frame, float *dst) {
  static float r[LN], g[LN], b[LN];
  read_layer(dev, dir, frame, "color", 0, r);
  read_layer(dev, dir, frame, "color", 1, g);
  read_layer(dev, dir, frame, "color", 2, b);
  for (int i = 0; i < LN; i++) dst[i] = hush_luminance(r[i], g[i], b[i]);
}

/* v <- its 3x3 box average (the references' noise out of the masks). */
static void box3(float *v) {
  static float t[LN];
  for (int y = 0; y < LH; y++)
    for (int x = 0; x < LW; x++) {
      float sum = 0.0f;
      int n = 0;
      for (int dy = -1; dy <= 1; dy++)
        for (int dx = -1; dx <= 1; dx++) {
          const int yy = y + dy, xx = x + dx;
          if (yy < 0 || yy >= LH || xx < 0 || xx >= LW) continue;
          sum += v[yy * LW + xx];
          n++;
        }
      t[y * LW + x] = sum / (float)n;
    }
  memcpy(v, t, sizeof t);
}

static float region_mean(const float *v, const unsigned char *mask) {
  double sum = 0.0;
  int n = 0;
  for (int i = 0; i < LN; i++)
    if (mask[i]) {
      sum += v[i];
      n++;
    }
  return n ? (float)(sum / n) : 0.0f;
}

/* The sphere light of light-off goes out at frame 8 (the camera orbits):
 * lambda at frame 8 is near 1 where it lit and near 0 where nothing
 * changed; asvgf's mean luminance in the lit region is within 15% of the
 * truth (32 spp) at most 2 frames after the change (frame 8, 9 or 10: the
 * issue's lag of at most 2), svgf's is not. */
static void test_light_off(hush_device dev) {
  REQUIRE(system("rm -rf '" WORK "' && mkdir -p '" WORK "'") == 0);
  REQUIRE(cli("render --scene builtin:light-off --out " WORK
              "/seq --gradients --quiet --size 160x90 "
              "--frames 11 --path static") == 0);
  REQUIRE(cli("render --scene builtin:light-off --out " WORK "/ref --quiet --size 160x90 --first 7 "
              "--frames 4 --spp 32 --path static") == 0);
  REQUIRE(cli("denoise --filter asvgf --in " WORK "/seq --out " WORK "/asvgf --quiet") == 0);
  REQUIRE(cli("denoise --filter svgf --in " WORK "/seq --out " WORK "/svgf --quiet") == 0);
  REQUIRE(cli("denoise --filter asvgf --in " WORK "/seq --out " WORK "/schied --set "
              "history_rule=schied --quiet") == 0);
  static float on[LN], off[LN];
  static unsigned char lit[LN], same[LN];
  read_lum(dev, WORK "/ref", 0, on);  /* frame 7 */
  read_lum(dev, WORK "/ref", 1, off); /* frame 8 */
  box3(on);
  box3(off);
  int n_lit = 0, n_same = 0;
  for (int i = 0; i < LN; i++) {
    lit[i] = on[i] > 0.02f && off[i] < 0.25f * on[i];
    same[i] = on[i] > 0.002f && fabsf(on[i] - off[i]) < 0.05f * on[i];
    n_lit += lit[i];
    n_same += same[i];
  }
  printf("light-off: %d lit pixels, %d unchanged\n", n_lit, n_same);
  REQUIRE(n_lit > LN / 20 && n_same > LN / 50);

  /* lambda of frame 8 from its layers */
  static float grad[3][LN], depth[LN], normal[3][LN], dgrad[2][LN], lum[LN], lambda[LN];
  for (int c = 0; c < 3; c++) read_layer(dev, WORK "/seq", 8, "gradient", c, grad[c]);
  for (int c = 0; c < 3; c++) read_layer(dev, WORK "/seq", 8, "normal", c, normal[c]);
  for (int c = 0; c < 2; c++) read_layer(dev, WORK "/seq", 8, "depth_gradient", c, dgrad[c]);
  read_layer(dev, WORK "/seq", 8, "depth", 0, depth);
  read_lum(dev, WORK "/seq", 8, lum);
  float *scratch = malloc(hush__gradient_scratch_floats(LW, LH) * sizeof(float));
  REQUIRE(scratch);
  hush_gradient_guides gd;
  gd.depth = depth;
  for (int c = 0; c < 3; c++) gd.normal[c] = normal[c];
  gd.depth_grad[0] = dgrad[0];
  gd.depth_grad[1] = dgrad[1];
  gd.luminance = lum;
  const hush_gradient_params p = default_params();
  const float *const gp[3] = {grad[0], grad[1], grad[2]};
  hush__gradient_lambda(gp, &gd, LW, LH, &p, scratch, lambda, 2);
  free(scratch);
  const float l_lit = region_mean(lambda, lit), l_same = region_mean(lambda, same);
  printf("light-off frame 8: mean lambda %.3f lit, %.3f unchanged\n", (double)l_lit,
         (double)l_same);
  int lit_high = 0, same_low = 0;
  for (int i = 0; i < LN; i++) {
    lit_high += lit[i] && lambda[i] > 0.8f;
    same_low += same[i] && lambda[i] < 0.1f;
  }
  printf("light-off frame 8: %.0f%% of the lit pixels have lambda > 0.8, %.0f%% of the unchanged "
         "ones lambda < 0.1\n", 100.0 * lit_high / n_lit, 100.0 * same_low / n_same);
  /* near 1, not 1: the reconstruction's luminance guide at a landing pixel
   * is its own fresh sample (the renderer's default landing mode), and a
   * lit stratum next to an unlit one shares some of its weight */
  CHECK_MSG(l_lit > 0.85f, "lambda in the lit region %g", (double)l_lit);
  CHECK_MSG(lit_high > 0.85 * n_lit, "lambda > 0.8 on %d of %d lit pixels", lit_high, n_lit);
  /* where nothing changed: mostly 0 (the mean is raised by strata whose
   * brightest sample saw the light indirectly) */
  CHECK_MSG(l_same < 0.25f, "lambda where nothing changed %g", (double)l_same);
  CHECK_MSG(same_low > 0.6 * n_same, "lambda < 0.1 on %d of %d unchanged pixels", same_low,
            n_same);
  /* and before the change: nothing */
  for (int c = 0; c < 3; c++) read_layer(dev, WORK "/seq", 6, "gradient", c, grad[c]);
  int zero = 1;
  for (int i = 0; i < LN; i++) zero &= grad[0][i] == grad[1][i];
  CHECK(zero);

  /* lag: frames 8, 9, 10 (ref frames 1, 2, 3) */
  static float out[LN];
  int asvgf_ok = 0, svgf_ok = 0;
  for (int k = 1; k <= 3; k++) {
    read_lum(dev, WORK "/ref", k, off);
    const float truth = region_mean(off, lit);
    read_lum(dev, WORK "/asvgf", 7 + k, out);
    const float ma = region_mean(out, lit);
    read_lum(dev, WORK "/svgf", 7 + k, out);
    const float ms = region_mean(out, lit);
    read_lum(dev, WORK "/schied", 7 + k, out);
    const float mh = region_mean(out, lit);
    read_lum(dev, WORK "/seq", 7 + k, out);
    const float mi = region_mean(out, lit);
    printf("light-off frame %d, lit region mean: truth %.4f asvgf %.4f (schied rule %.4f) svgf "
           "%.4f input %.4f\n",
           7 + k, (double)truth, (double)ma, (double)mh, (double)ms, (double)mi);
    /* 15%, not the 10%: at this size the region's edge takes light
     * from the unchanged (sky-lit) surroundings through the a-trous (about
     * +10% here); at 320x180, where `hush eval` measures the acceptance,
     * the lag is 0 (docs/results/asvgf-lag.md); svgf is 4-7x off */
    asvgf_ok |= fabsf(ma - truth) <= 0.15f * truth;
    svgf_ok |= fabsf(ms - truth) <= 0.15f * truth;
  }
  CHECK_MSG(asvgf_ok, "asvgf lags after the light went off");
  CHECK_MSG(!svgf_ok, "svgf does not lag: the test scene shows nothing");
}

int main(void) {
  test_lambda_extremes();
  test_depth_edge();
  test_normal_edge();
  test_lower_age();
  hush_device dev = hush_device_new("threads=2");
  REQUIRE(dev);
  test_same_as_svgf(dev);
  test_history_and_constant(dev);
  test_bad_gradient(dev);
  test_light_off(dev);
  hush_device_release(dev);
  return check_summary();
}
