/*
 * test_nca.c — the "nca" filter and its training (src/filters/nca/):
 * backpropagation against finite differences (W and bias, >= 2 iterations,
 * with and without the gradient loss), the float filter against the double
 * training model, all-zero weights adding exactly sigmoid(0) + bias per
 * iteration, determinism across thread counts, the weights file (round
 * trip, corrupt, truncated, wrong version) and finite output on extreme
 * input. Higginson 2023 §2.4.
 */
#include "hush.h"

#include "check.h"
#include "filters/nca/model.h"
#include "filters/nca/train.h"
#include "filters/nca/weights.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>

static uint32_t rng_state = 2463534242u;
static double rnd(void) { /* uniform in [0, 1), xorshift32 */
  rng_state ^= rng_state << 13;
  rng_state ^= rng_state >> 17;
  rng_state ^= rng_state << 5;
  return (double)(rng_state >> 8) / 16777216.0;
}

/* A random sample of w x h with plausible ranges: log colour 0..2, unit-ish
 * normals, albedo 0..1, target near the colour. */
typedef struct sample_data {
  float *planes; /* 12 planes */
  hush_nca_sample s;
} sample_data;

static void sample_make(sample_data *d, uint32_t w, uint32_t h) {
  const size_t n = (size_t)w * h;
  d->planes = malloc(12 * n * sizeof(float));
  REQUIRE(d->planes);
  for (size_t i = 0; i < 12 * n; i++) d->planes[i] = (float)(rnd() * 2.0 - (i >= 3 * n && i < 6 * n ? 1.0 : 0.0));
  d->s.width = w;
  d->s.height = h;
  for (int c = 0; c < HUSH_NCA_CHANNELS; c++) d->s.state[c] = d->planes + (size_t)c * n;
  for (int c = 0; c < 3; c++) d->s.target[c] = d->planes + (size_t)(9 + c) * n;
}

static void random_params(double *p, double scale) {
  for (int i = 0; i < HUSH_NCA_PARAM_COUNT; i++) p[i] = (rnd() * 2.0 - 1.0) * scale;
}

/* Central differences on every parameter; returns the number of parameters
 * whose analytic derivative is off by more than tol (absolute + relative). */
static int gradient_mismatches(const hush_nca_sample *s, int iterations,
                               const hush_nca_loss_weights *lw, double tol) {
  double p[HUSH_NCA_PARAM_COUNT], g[HUSH_NCA_PARAM_COUNT] = {0};
  random_params(p, 0.4);
  REQUIRE(hush__nca_loss(p, iterations, s, lw, g) >= 0.0);
  int bad = 0, nonzero_w = 0, nonzero_b = 0;
  const double eps = 1e-7;
  for (int i = 0; i < HUSH_NCA_PARAM_COUNT; i++) {
    const double keep = p[i];
    p[i] = keep + eps;
    const double lp = hush__nca_loss(p, iterations, s, lw, NULL);
    p[i] = keep - eps;
    const double lm = hush__nca_loss(p, iterations, s, lw, NULL);
    p[i] = keep;
    const double fd = (lp - lm) / (2.0 * eps);
    if (fabs(fd - g[i]) > tol * (1.0 + fabs(fd))) {
      if (bad < 3)
        fprintf(stderr, "  param %d (%s): analytic %.9g, finite difference %.9g\n", i,
                i < HUSH_NCA_P_BIAS ? "W" : "bias", g[i], fd);
      bad++;
    }
    if (fabs(g[i]) > 1e-6) *(i < HUSH_NCA_P_BIAS ? &nonzero_w : &nonzero_b) += 1;
  }
  /* the check means something only if the gradients are not all zero */
  CHECK(nonzero_w > HUSH_NCA_WEIGHT_COUNT / 2);
  CHECK(nonzero_b == HUSH_NCA_CHANNELS);
  return bad;
}

static void test_gradient_check(void) {
  sample_data d;
  sample_make(&d, 9, 7);
  /* MSE alone is smooth: every parameter must match */
  const hush_nca_loss_weights mse = {1.0, 0.0, HUSH_NCA_MSE_STATE, HUSH_NCA_LINEAR, NULL};
  CHECK_MSG(gradient_mismatches(&d.s, 2, &mse, 1e-5) == 0, "MSE, 2 iterations");
  CHECK_MSG(gradient_mismatches(&d.s, 3, &mse, 1e-5) == 0, "MSE, 3 iterations");
  /* with the L1 gradient term a +-1e-7 step may cross a kink of |.| for a
   * rare parameter; allow two of 360 */
  const hush_nca_loss_weights both = {1.0, 0.5, HUSH_NCA_MSE_STATE, HUSH_NCA_LINEAR, NULL};
  const int bad = gradient_mismatches(&d.s, 3, &both, 1e-5);
  CHECK_MSG(bad <= 2, "MSE + gradient loss, 3 iterations: %d mismatches", bad);
  /* gradient loss alone, so its derivative is really exercised */
  const hush_nca_loss_weights grad_only = {0.0, 1.0, HUSH_NCA_MSE_STATE, HUSH_NCA_LINEAR, NULL};
  const int bad2 = gradient_mismatches(&d.s, 2, &grad_only, 1e-5);
  CHECK_MSG(bad2 <= 2, "gradient loss, 2 iterations: %d mismatches", bad2);
  /* the MSE term in radiance (the colour leaves log space through expm1),
   * plain and relative to the reference */
  const hush_nca_loss_weights linear = {1.0, 0.0, HUSH_NCA_MSE_LINEAR, HUSH_NCA_LOG1P, NULL};
  CHECK_MSG(gradient_mismatches(&d.s, 2, &linear, 1e-5) == 0, "linear MSE, 2 iterations");
  const hush_nca_loss_weights relative = {1.0, 0.0, HUSH_NCA_MSE_RELATIVE, HUSH_NCA_LOG1P, NULL};
  CHECK_MSG(gradient_mismatches(&d.s, 2, &relative, 1e-5) == 0, "relative MSE, 2 iterations");
  const hush_nca_loss_weights rel_lin = {1.0, 0.0, HUSH_NCA_MSE_RELATIVE, HUSH_NCA_LINEAR, NULL};
  CHECK_MSG(gradient_mismatches(&d.s, 2, &rel_lin, 1e-5) == 0, "relative MSE, linear colour");
  free(d.planes);
}

/* The loss relative to the prediction holds its weights constant in the
 * derivative: its gradient is the finite-difference gradient of the
 * weighted MSE with the weights frozen at the prediction of the same
 * parameters. */
static void test_gradient_relative_predicted(void) {
  sample_data d;
  sample_make(&d, 9, 7);
  const size_t n = 9 * 7;
  double p[HUSH_NCA_PARAM_COUNT], g[HUSH_NCA_PARAM_COUNT] = {0};
  random_params(p, 0.4);
  double *planes = malloc(HUSH_NCA_CHANNELS * n * sizeof(double));
  double *wplanes = malloc(3 * n * sizeof(double));
  REQUIRE(planes && wplanes);
  double *out[HUSH_NCA_CHANNELS];
  for (int c = 0; c < HUSH_NCA_CHANNELS; c++) out[c] = planes + c * n;
  REQUIRE(hush__nca_forward_double(p, 2, &d.s, out) == 0);
  const double *wp[3] = {wplanes, wplanes + n, wplanes + 2 * n};
  for (int c = 0; c < 3; c++)
    for (size_t i = 0; i < n; i++) {
      const double r = expm1(out[c][i]) > 0.0 ? expm1(out[c][i]) : 0.0;
      wplanes[c * n + i] = 1.0 / (r * r + 0.01);
    }
  const hush_nca_loss_weights pred = {1.0, 0.0, HUSH_NCA_MSE_RELATIVE_PREDICTED, HUSH_NCA_LOG1P,
                                      NULL};
  const hush_nca_loss_weights frozen = {1.0, 0.0, HUSH_NCA_MSE_WEIGHTED, HUSH_NCA_LOG1P, wp};
  const double l_pred = hush__nca_loss(p, 2, &d.s, &pred, g);
  CHECK_MSG(fabs(l_pred - hush__nca_loss(p, 2, &d.s, &frozen, NULL)) <= 1e-12 * (1.0 + l_pred),
            "the same loss value at the prediction");
  int bad = 0, nonzero = 0;
  const double eps = 1e-7;
  for (int i = 0; i < HUSH_NCA_PARAM_COUNT; i++) {
    const double keep = p[i];
    p[i] = keep + eps;
    const double lp = hush__nca_loss(p, 2, &d.s, &frozen, NULL);
    p[i] = keep - eps;
    const double lm = hush__nca_loss(p, 2, &d.s, &frozen, NULL);
    p[i] = keep;
    const double fd = (lp - lm) / (2.0 * eps);
    bad += fabs(fd - g[i]) > 1e-5 * (1.0 + fabs(fd));
    nonzero += fabs(g[i]) > 1e-6;
  }
  CHECK_MSG(bad == 0, "relative-to-prediction gradient vs frozen weights: %d mismatches", bad);
  CHECK(nonzero > HUSH_NCA_WEIGHT_COUNT / 2);
  free(planes);
  free(wplanes);
  free(d.planes);
}

/* The float step (blocked, separable, approximate sigmoid) computes the
 * same model as the double training code (plain 3x3 filters, exp). */
static void test_float_matches_double(void) {
  const uint32_t w = 37, h = 11; /* width not a multiple of 8: tail lanes */
  const size_t n = (size_t)w * h;
  sample_data d;
  sample_make(&d, w, h);
  double p[HUSH_NCA_PARAM_COUNT];
  random_params(p, 0.3);
  hush_nca_weights wt;
  hush__nca_weights_from_params(p, &wt);
  hush__nca_params_from_weights(&wt, p); /* the float-rounded values on both sides */
  const int K = 4;
  double *ref = malloc(9 * n * sizeof(double));
  float *a = malloc(9 * n * sizeof(float)), *b = malloc(9 * n * sizeof(float));
  float *scratch = calloc(hush__nca_scratch_floats(w, 2), sizeof(float));
  REQUIRE(ref && a && b && scratch);
  double *refp[9];
  float *ap[9], *bp[9];
  for (int c = 0; c < 9; c++) {
    refp[c] = ref + c * n;
    ap[c] = a + c * n;
    bp[c] = b + c * n;
    memcpy(ap[c], d.s.state[c], n * sizeof(float));
  }
  REQUIRE(hush__nca_forward_double(p, K, &d.s, refp) == 0);
  for (int it = 0; it < K; it++) {
    hush__nca_step(&wt, (const float *const *)(it & 1 ? bp : ap), it & 1 ? ap : bp, w, h, scratch, 2);
  }
  double worst = 0.0;
  for (size_t i = 0; i < 9 * n; i++) worst = fmax(worst, fabs((double)a[i] - ref[i]));
  CHECK_MSG(worst < 1e-4, "float vs double after %d iterations: max |diff| %g", K, worst);
  free(ref);
  free(a);
  free(b);
  free(scratch);
  free(d.planes);
}

static void test_sigmoid(void) {
  double worst = 0.0;
  for (int i = -2000; i <= 2000; i++) {
    const float x = (float)i * 0.01f;
    const double exact = 1.0 / (1.0 + exp(-(double)x));
    worst = fmax(worst, fabs(hush__nca_sigmoid(x) - exact) / exact);
  }
  CHECK_MSG(worst < 2e-6, "sigmoid relative error %g", worst);
  CHECK(hush__nca_sigmoid(0.0f) == 0.5f);
  /* the colour transform and its inverse */
  double worst_log = 0.0, worst_exp = 0.0;
  for (int i = 0; i <= 4000; i++) {
    const float v = (float)(pow(10.0, (i - 2000) * 0.005)); /* 1e-10 .. 1e10 */
    const double exact = log1p((double)v);
    /* 1 + v rounds to float first: absolute error ~6e-8 near 0, relative above */
    worst_log = fmax(worst_log, fabs(hush__nca_log1p(v) - exact) / (exact + 0.05));
    const float s = (float)(i - 2000) * 0.015f; /* -30 .. 30 */
    worst_exp = fmax(worst_exp, fabs(hush__nca_exp(s) - exp((double)s)) / exp((double)s));
  }
  CHECK_MSG(worst_log < 2e-6, "log1p error / (value + 0.05) %g", worst_log);
  CHECK_MSG(worst_exp < 2e-6, "exp relative error %g", worst_exp);
  CHECK(hush__nca_log1p(0.0f) == 0.0f);
  CHECK(isfinite(hush__nca_log1p(3.4e38f)));
  CHECK(hush__nca_sigmoid(1e30f) == 1.0f);
  CHECK(hush__nca_sigmoid(-1e30f) >= 0.0f && hush__nca_sigmoid(-1e30f) < 1e-30f);
}

/* W = 0: every iteration adds exactly sigmoid(0) + bias = 0.5 + bias to
 * every channel, whatever the neighbourhood. */
static void test_zero_weights_step(void) {
  const uint32_t w = 19, h = 6;
  const size_t n = (size_t)w * h;
  hush_nca_weights wt;
  memset(&wt, 0, sizeof wt);
  for (int c = 0; c < 9; c++) wt.bias[c] = 0.125f * (float)(c - 4); /* exact in binary */
  wt.iterations = 1;
  float *a = malloc(9 * n * sizeof(float)), *b = malloc(9 * n * sizeof(float));
  float *scratch = calloc(hush__nca_scratch_floats(w, 2), sizeof(float));
  REQUIRE(a && b && scratch);
  float *ap[9], *bp[9];
  for (int c = 0; c < 9; c++) {
    ap[c] = a + c * n;
    bp[c] = b + c * n;
  }
  for (size_t i = 0; i < 9 * n; i++) a[i] = (float)((int)(rnd() * 64.0) - 32) * 0.25f;
  int bad = 0;
  for (int it = 0; it < 3; it++) {
    float **src = it & 1 ? bp : ap, **dst = it & 1 ? ap : bp;
    hush__nca_step(&wt, (const float *const *)src, dst, w, h, scratch, 2);
    for (int c = 0; c < 9; c++)
      for (size_t i = 0; i < n; i++)
        if (dst[c][i] != src[c][i] + 0.5f + wt.bias[c]) bad++;
  }
  CHECK_MSG(bad == 0, "%d values differ from s + 0.5 + bias", bad);
  free(a);
  free(b);
  free(scratch);
}

/* ---- the filter through the public API ---------------------------------- */

#define FW 45
#define FH 23
#define FN (FW * FH)

typedef struct frame_data {
  float color[FN * 3], normal[FN * 3], albedo[FN * 3], output[FN * 3];
} frame_data;

static void frame_random(frame_data *f) {
  for (int i = 0; i < FN * 3; i++) {
    f->color[i] = (float)(rnd() * rnd() * 4.0);
    f->normal[i] = (float)(rnd() * 2.0 - 1.0);
    f->albedo[i] = (float)rnd();
  }
}

static hush_image_view view3(float *data) {
  hush_image_view v;
  memset(&v, 0, sizeof v);
  v.data = data;
  v.format = HUSH_FORMAT_FLOAT3;
  v.width = FW;
  v.height = FH;
  return v;
}

static hush_filter make_nca(hush_device dev, frame_data *f) {
  hush_filter flt = hush_filter_new(dev, "nca");
  REQUIRE(flt);
  hush_image_view v = view3(f->color);
  CHECK(hush_filter_set_image(flt, "color", &v) == HUSH_OK);
  v = view3(f->normal);
  CHECK(hush_filter_set_image(flt, "normal", &v) == HUSH_OK);
  v = view3(f->albedo);
  CHECK(hush_filter_set_image(flt, "albedo", &v) == HUSH_OK);
  v = view3(f->output);
  CHECK(hush_filter_set_image(flt, "output", &v) == HUSH_OK);
  CHECK(hush_filter_commit(flt) == HUSH_OK);
  return flt;
}

static hush_status run_frame(hush_filter flt) {
  hush_frame_info info;
  hush_frame_info_init(&info);
  return hush_filter_execute(flt, &info);
}

static void test_filter_deterministic(void) {
  static frame_data f1, f2;
  frame_random(&f1);
  f2 = f1;
  hush_device d1 = hush_device_new("threads=1"), d2 = hush_device_new("threads=2");
  REQUIRE(d1 && d2);
  hush_filter a = make_nca(d1, &f1), b = make_nca(d2, &f2);
  CHECK(run_frame(a) == HUSH_OK);
  CHECK(run_frame(b) == HUSH_OK);
  CHECK_MSG(memcmp(f1.output, f2.output, sizeof f1.output) == 0, "1 vs 2 threads differ");
  float first[FN * 3];
  memcpy(first, f1.output, sizeof first);
  CHECK(run_frame(a) == HUSH_OK); /* no history: the same frame again */
  CHECK(memcmp(first, f1.output, sizeof first) == 0);
  int finite = 1, changed = 0;
  for (int i = 0; i < FN * 3; i++) {
    finite &= isfinite(f1.output[i]) && f1.output[i] >= 0.0f;
    changed |= f1.output[i] != f1.color[i];
  }
  CHECK(finite);
  CHECK_MSG(changed, "the built-in weights do nothing");
  hush_filter_release(a);
  hush_filter_release(b);
  hush_device_release(d1);
  hush_device_release(d2);
}

static void test_filter_extreme_input(void) {
  static frame_data f;
  frame_random(&f);
  f.color[0] = 1e30f;
  f.color[5] = 3e38f;
  f.color[7] = -1e30f;
  f.normal[3] = 1e20f;
  f.albedo[9] = -1e20f;
  f.color[11] = NAN;
  hush_device dev = hush_device_new("threads=2");
  REQUIRE(dev);
  hush_filter flt = make_nca(dev, &f);
  CHECK(run_frame(flt) == HUSH_ERROR_NONFINITE);
  CHECK(hush_filter_set_string(flt, "nonfinite", "replace") == HUSH_OK);
  CHECK(hush_filter_set_int(flt, "iterations", 20) == HUSH_OK);
  CHECK(run_frame(flt) == HUSH_OK);
  int finite = 1;
  for (int i = 0; i < FN * 3; i++) finite &= isfinite(f.output[i]) && f.output[i] >= 0.0f;
  CHECK_MSG(finite, "NaN, Inf or negative output");
  hush_filter_release(flt);
  hush_device_release(dev);
}

/* With 'emission' bound the automaton sees color - emission and the
 * emission is added back: the output is exactly that of the same filter
 * run on max(color - emission, 0) plus the emission, and a lamp keeps its
 * radiance. emission_bypass=false ignores the bound image. */
static void test_filter_emission_bypass(void) {
  static frame_data lit, off, plain;
  static float emission[FN * 3], lit_color[FN * 3];
  frame_random(&lit);
  memset(emission, 0, sizeof emission);
  for (int y = 10; y < 13; y++) /* a 3x3 lamp of radiance 50 */
    for (int x = 20; x < 23; x++)
      for (int c = 0; c < 3; c++) {
        emission[3 * (y * FW + x) + c] = 50.0f;
        lit.color[3 * (y * FW + x) + c] = 50.0f + 0.25f * (float)c;
      }
  emission[3 * 40 + 1] = 2.0f * lit.color[3 * 40 + 1]; /* more than the colour: clamped at 0 */
  memcpy(lit_color, lit.color, sizeof lit_color);
  off = lit;
  for (int i = 0; i < FN * 3; i++) {
    const float r = lit.color[i] - emission[i];
    off.color[i] = r > 0.0f ? r : 0.0f;
  }
  plain = lit;
  hush_device dev = hush_device_new("threads=2");
  REQUIRE(dev);
  hush_filter a = make_nca(dev, &lit), b = make_nca(dev, &off), c = make_nca(dev, &plain);
  hush_image_view v = view3(emission);
  CHECK(hush_filter_set_image(a, "emission", &v) == HUSH_OK);
  CHECK(hush_filter_commit(a) == HUSH_OK);
  CHECK(run_frame(a) == HUSH_OK);
  CHECK(run_frame(b) == HUSH_OK);
  CHECK(run_frame(c) == HUSH_OK);
  int same = 1, lamp = 1, input_kept = 1;
  for (int i = 0; i < FN * 3; i++) {
    same &= lit.output[i] == off.output[i] + emission[i];
    input_kept &= lit.color[i] == lit_color[i];
  }
  for (int y = 10; y < 13; y++)
    for (int x = 20; x < 23; x++)
      for (int k = 0; k < 3; k++) lamp &= lit.output[3 * (y * FW + x) + k] >= 50.0f;
  CHECK_MSG(same, "output is not nca(color - emission) + emission");
  CHECK_MSG(lamp, "the lamp lost radiance");
  CHECK_MSG(input_kept, "the caller's color image was written");
  /* the bypass off: the emission image is bound but not used */
  CHECK(hush_filter_set_bool(a, "emission_bypass", 0) == HUSH_OK);
  CHECK(run_frame(a) == HUSH_OK);
  CHECK_MSG(memcmp(lit.output, plain.output, sizeof plain.output) == 0,
            "emission_bypass=false still uses the emission");
  hush_filter_release(a);
  hush_filter_release(b);
  hush_filter_release(c);
  hush_device_release(dev);
}

/* ---- weights file -------------------------------------------------------- */

static void write_bytes(const char *path, const unsigned char *buf, size_t n) {
  FILE *fp = fopen(path, "wb");
  REQUIRE(fp);
  REQUIRE(fwrite(buf, 1, n, fp) == n);
  fclose(fp);
}

/* What K iterations with W = 0 and bias -0.25 make of a colour (linear):
 * K additions of sigmoid(0) + bias, in the filter's order. */
static float zero_weights_output(float c, int k) {
  float v = c;
  for (int i = 0; i < k; i++) v = v + 0.5f + -0.25f;
  return v;
}

static void test_weights_file(void) {
  hush_device dev = hush_device_new("threads=2");
  REQUIRE(dev);
  hush_nca_weights w, r;
  memset(&w, 0, sizeof w);
  for (int i = 0; i < HUSH_NCA_WEIGHT_COUNT; i++) w.w[i] = (float)(rnd() - 0.5);
  for (int i = 0; i < 9; i++) w.bias[i] = (float)(rnd() - 0.5);
  w.iterations = 7;
  w.color_transform = HUSH_NCA_LOG1P;
  const char *path = HUSH_BINARY_DIR "/test_nca_weights.bin";
  CHECK(hush__nca_weights_save(dev, path, &w) == HUSH_OK);
  memset(&r, 0, sizeof r);
  CHECK(hush__nca_weights_load(dev, path, &r) == HUSH_OK);
  CHECK(memcmp(&w, &r, sizeof w) == 0);

  unsigned char buf[HUSH_NCA_FILE_SIZE + 8];
  hush__nca_weights_encode(&w, buf);
  const char *msg = NULL;
  /* truncated */
  CHECK(hush__nca_weights_decode(dev, buf, HUSH_NCA_FILE_SIZE - 5, "t", &r) == HUSH_ERROR_CORRUPT);
  hush_device_get_error(dev, &msg);
  CHECK_MSG(msg && strstr(msg, "truncated"), "message: %s", msg ? msg : "(none)");
  /* trailing bytes */
  CHECK(hush__nca_weights_decode(dev, buf, HUSH_NCA_FILE_SIZE + 8, "t", &r) == HUSH_ERROR_CORRUPT);
  hush_device_get_error(dev, &msg);
  /* one flipped bit in a weight: the checksum catches it */
  buf[HUSH_NCA_FILE_HEADER + 100] ^= 0x10;
  CHECK(hush__nca_weights_decode(dev, buf, HUSH_NCA_FILE_SIZE, "t", &r) == HUSH_ERROR_CORRUPT);
  hush_device_get_error(dev, &msg);
  CHECK_MSG(msg && strstr(msg, "checksum"), "message: %s", msg ? msg : "(none)");
  buf[HUSH_NCA_FILE_HEADER + 100] ^= 0x10;
  CHECK(hush__nca_weights_decode(dev, buf, HUSH_NCA_FILE_SIZE, "t", &r) == HUSH_OK);
  /* another version */
  buf[8] = 2;
  CHECK(hush__nca_weights_decode(dev, buf, HUSH_NCA_FILE_SIZE, "t", &r) == HUSH_ERROR_UNSUPPORTED);
  hush_device_get_error(dev, &msg);
  CHECK_MSG(msg && strstr(msg, "version 2"), "message: %s", msg ? msg : "(none)");
  buf[8] = 1;
  /* wrong magic, wrong dimensions (with a valid checksum) */
  buf[0] = 'X';
  CHECK(hush__nca_weights_decode(dev, buf, HUSH_NCA_FILE_SIZE, "t", &r) == HUSH_ERROR_CORRUPT);
  buf[0] = 'H';
  /* NaN weight with a valid checksum: refused on its value */
  hush_nca_weights bad = w;
  bad.w[3] = NAN;
  CHECK(hush__nca_weights_check(dev, &bad, "t") == HUSH_ERROR_CORRUPT);
  CHECK(hush__nca_weights_save(dev, path, &bad) == HUSH_ERROR_CORRUPT);

  /* through the public API */
  static frame_data f;
  frame_random(&f);
  hush_filter flt = make_nca(dev, &f);
  CHECK(hush_nca_load_weights(flt, HUSH_BINARY_DIR "/no/such/file.bin") == HUSH_ERROR_IO);
  write_bytes(HUSH_BINARY_DIR "/test_nca_truncated.bin", buf, 100);
  CHECK(hush_nca_load_weights(flt, HUSH_BINARY_DIR "/test_nca_truncated.bin") == HUSH_ERROR_CORRUPT);
  hush_filter acc = hush_filter_new(dev, "accumulate");
  CHECK(hush_nca_load_weights(acc, path) == HUSH_ERROR_INVALID_ARGUMENT);
  hush_filter_release(acc);

  /* W = 0, bias b, linear transform, K = 3: output = colour + 3 (0.5 + b) */
  hush_nca_weights z;
  memset(&z, 0, sizeof z);
  for (int c = 0; c < 9; c++) z.bias[c] = -0.25f;
  z.iterations = 3;
  z.color_transform = HUSH_NCA_LINEAR;
  CHECK(hush__nca_weights_save(dev, path, &z) == HUSH_OK);
  CHECK(hush_nca_load_weights(flt, path) == HUSH_OK);
  CHECK(hush_filter_commit(flt) == HUSH_OK); /* loaded weights survive a commit */
  CHECK(run_frame(flt) == HUSH_OK);
  int exact = 1;
  for (int i = 0; i < FN * 3; i++) exact &= f.output[i] == zero_weights_output(f.color[i], 3);
  CHECK_MSG(exact, "zero weights through the filter: output != colour + K (0.5 + bias)");
  CHECK(hush_filter_set_int(flt, "iterations", 5) == HUSH_OK);
  CHECK(run_frame(flt) == HUSH_OK);
  exact = 1;
  for (int i = 0; i < FN * 3; i++) exact &= f.output[i] == zero_weights_output(f.color[i], 5);
  CHECK(exact);
  /* back to the built-in weights */
  CHECK(hush_nca_load_weights(flt, NULL) == HUSH_OK);
  CHECK(run_frame(flt) == HUSH_OK);
  hush_filter_release(flt);
  hush_device_release(dev);
}

/* The compiled-in weights are those of the committed weights file. */
static void test_default_weights_match_file(void) {
  hush_device dev = hush_device_new(NULL);
  REQUIRE(dev);
  hush_nca_weights r;
  const hush_status s = hush__nca_weights_load(dev, HUSH_SOURCE_DIR "/data/nca/weights-v1.bin", &r);
  CHECK(s == HUSH_OK);
  if (s == HUSH_OK) {
    CHECK(hush__nca_weights_check(dev, &hush__nca_default_weights, "built-in") == HUSH_OK);
    CHECK_MSG(memcmp(&r, &hush__nca_default_weights, sizeof r) == 0,
              "src/filters/nca/default_weights.c is not data/nca/weights-v1.bin: regenerate it "
              "(docs/nca.md)");
  }
  hush_device_release(dev);
}

/* ---- hush train-nca end to end ------------------------------------------- */

#define TWORK HUSH_BINARY_DIR "/test_nca_train"
#define TS 40

static int run_cli(const char *args, char *err, size_t err_size) {
  char cmd[4096];
  snprintf(cmd, sizeof cmd, "'%s' %s > '%s/out.txt' 2> '%s/err.txt'", HUSH_CLI, args, TWORK, TWORK);
  const int s = system(cmd);
  err[0] = '\0';
  FILE *f = fopen(TWORK "/err.txt", "rb");
  if (f) {
    const size_t n = fread(err, 1, err_size - 1, f);
    err[n] = '\0';
    fclose(f);
  }
  return (s != -1 && WIFEXITED(s)) ? WEXITSTATUS(s) : -1;
}

/* Writes view v: a smooth reference and a noisy input with fireflies, with
 * normals and albedo, in the layout `hush render` gives train-nca. */
/* A training view DATA/v<v>; emission 1: the input also has an 'emission'
 * layer equal to its colour (all lamp), 2: the reference too. */
static void write_view_in(hush_device dev, const char *data, int v, int emission) {
  char path[1024];
  snprintf(path, sizeof path, "mkdir -p '%s/%s/v%d/noisy' '%s/%s/v%d/ref'", TWORK, data, v, TWORK,
           data, v);
  REQUIRE(system(path) == 0);
  hush_frame noisy = hush_frame_new(dev, TS, TS), ref = hush_frame_new(dev, TS, TS);
  REQUIRE(noisy && ref);
  hush_image_view c, n, a, r;
  REQUIRE(hush_frame_add_layer(noisy, "color", 3, &c) == HUSH_OK);
  REQUIRE(hush_frame_add_layer(noisy, "normal", 3, &n) == HUSH_OK);
  REQUIRE(hush_frame_add_layer(noisy, "albedo", 3, &a) == HUSH_OK);
  REQUIRE(hush_frame_add_layer(ref, "color", 3, &r) == HUSH_OK);
  float *cp = c.data, *np = n.data, *ap = a.data, *rp = r.data;
  for (int i = 0; i < TS * TS; i++) {
    const int x = i % TS, y = i / TS;
    const float left = (float)(x < TS / 2 + v);
    for (int k = 0; k < 3; k++) {
      const float truth = 0.2f + 0.5f * left + 0.01f * (float)(y + k);
      rp[3 * i + k] = truth;
      /* 1 spp-like: mostly dark, sometimes 4x bright */
      cp[3 * i + k] = rnd() < 0.25 ? 4.0f * truth : 0.0f;
      np[3 * i + k] = k == 2 ? 1.0f : 0.0f;
      ap[3 * i + k] = 0.3f + 0.5f * left;
    }
  }
  hush_image_view e;
  if (emission >= 1) {
    REQUIRE(hush_frame_add_layer(noisy, "emission", 3, &e) == HUSH_OK);
    memcpy(e.data, cp, sizeof(float) * 3 * TS * TS);
  }
  if (emission >= 2) {
    REQUIRE(hush_frame_add_layer(ref, "emission", 3, &e) == HUSH_OK);
    memcpy(e.data, rp, sizeof(float) * 3 * TS * TS);
  }
  snprintf(path, sizeof path, "%s/%s/v%d/noisy/frame_0000.exr", TWORK, data, v);
  CHECK(hush_frame_write_exr(noisy, path, HUSH_EXR_FLOAT) == HUSH_OK);
  snprintf(path, sizeof path, "%s/%s/v%d/ref/frame_0000.exr", TWORK, data, v);
  CHECK(hush_frame_write_exr(ref, path, HUSH_EXR_FLOAT) == HUSH_OK);
  hush_frame_release(noisy);
  hush_frame_release(ref);
}

static void write_view(hush_device dev, int v) { write_view_in(dev, "data", v, 0); }

/* The noisy input's validation loss that train-nca prints (-1: none). */
static double noisy_loss(const char *err) {
  const char *a = strstr(err, "noisy input: ");
  double loss = -1.0;
  if (a) sscanf(a + strlen("noisy input: "), "%lf", &loss);
  return loss;
}

/* With 'emission' layers train-nca takes them off both colours, as the
 * filter's emission_bypass does: views that are all lamp leave nothing to
 * learn (loss 0); --keep-emission trains on the colour as it is; an
 * emission layer in only one of the two frames is an error. */
static void test_train_emission(void) {
  hush_device dev = hush_device_new("threads=1");
  REQUIRE(dev);
  for (int v = 0; v < 4; v++) write_view_in(dev, "lamps", v, 2);
  write_view_in(dev, "half", 0, 1);
  char err[8192];
  const char *common = "--iterations 3 --steps 0 --crop 32 --threads 1";
  char cmd[2048];
  snprintf(cmd, sizeof cmd, "train-nca --data '%s/lamps' --out '%s/l.bin' %s", TWORK, TWORK,
           common);
  int rc = run_cli(cmd, err, sizeof err);
  CHECK_MSG(rc == 0 && noisy_loss(err) == 0.0, "exit %d, loss %g: %s", rc, noisy_loss(err), err);
  snprintf(cmd, sizeof cmd, "train-nca --data '%s/lamps' --out '%s/l.bin' %s --keep-emission",
           TWORK, TWORK, common);
  rc = run_cli(cmd, err, sizeof err);
  CHECK_MSG(rc == 0 && noisy_loss(err) > 0.0, "exit %d, loss %g: %s", rc, noisy_loss(err), err);
  snprintf(cmd, sizeof cmd, "train-nca --data '%s/half' --out '%s/h.bin' %s", TWORK, TWORK, common);
  CHECK(run_cli(cmd, err, sizeof err) == 1 && strstr(err, "only the input has an 'emission'"));
  hush_device_release(dev);
}

static void test_train_cli(void) {
  REQUIRE(system("rm -rf '" TWORK "' && mkdir -p '" TWORK "'") == 0);
  hush_device dev = hush_device_new("threads=1");
  REQUIRE(dev);
  for (int v = 0; v < 4; v++) write_view(dev, v);
  char err[8192];
  /* usage errors exit 2, runtime errors 1, each with a message */
  CHECK(run_cli("train-nca --out x.bin", err, sizeof err) == 2 && strstr(err, "--data"));
  CHECK(run_cli("train-nca --data '" TWORK "/none' --out x.bin", err, sizeof err) == 1 &&
        strstr(err, "none"));
  CHECK(run_cli("train-nca --data '" TWORK "/data' --out '" TWORK "/w.bin' --crop 64", err,
                sizeof err) == 1 &&
        strstr(err, "smaller than the crop"));
  CHECK(run_cli("train-nca --data '" TWORK "/data' --out '" TWORK "/w.bin' "
                "--min-iterations 5 --max-iterations 2",
                err, sizeof err) == 2);
  CHECK(run_cli("train-nca --data '" TWORK "/data' --out '" TWORK "/w.bin' --mse-space cubic", err,
                sizeof err) == 2 &&
        strstr(err, "cubic"));
  /* a short run learns: the held-out loss falls below the noisy input's */
  const int rc = run_cli("train-nca --data '" TWORK "/data' --out '" TWORK "/w.bin' --c-out '" TWORK
                         "/w.c' --iterations 3 --steps 60 --crop 32 --batch 2 --lr 0.01 "
                         "--threads 2 --log 1000",
                         err, sizeof err);
  CHECK_MSG(rc == 0, "train-nca exit %d: %s", rc, err);
  const char *a = strstr(err, "noisy input: "), *b = strstr(err, "after training, K = 3: ");
  double before = -1.0, after = -1.0;
  if (a) sscanf(a + strlen("noisy input: "), "%lf", &before);
  if (b) sscanf(b + strlen("after training, K = 3: "), "%lf", &after);
  CHECK_MSG(before > 0.0 && after >= 0.0 && after < 0.9 * before,
            "validation loss %g before, %g after training", before, after);
  hush_nca_weights w;
  CHECK(hush__nca_weights_load(dev, TWORK "/w.bin", &w) == HUSH_OK);
  CHECK(w.iterations == 3 && w.color_transform == HUSH_NCA_LOG1P);
  FILE *f = fopen(TWORK "/w.c", "rb");
  CHECK(f != NULL);
  if (f) fclose(f);
  hush_device_release(dev);
}

/* The "color" layer of an EXR as floats (w x h x 3; the caller frees), or
 * NULL. */
static float *read_color(hush_device dev, const char *path, uint32_t *w, uint32_t *h) {
  hush_frame fr = NULL;
  if (hush_frame_read_exr(dev, path, &fr) != HUSH_OK) return NULL;
  hush_image_view v;
  float *out = NULL;
  if (hush_frame_get_layer(fr, "color", &v) == HUSH_OK && v.format == HUSH_FORMAT_FLOAT3) {
    *w = v.width;
    *h = v.height;
    out = malloc(sizeof(float) * 3 * v.width * v.height);
    const size_t row = sizeof(float) * 3 * v.width;
    const size_t stride = v.row_stride ? v.row_stride : row;
    if (out && (v.pixel_stride == 0 || v.pixel_stride == 3 * sizeof(float)))
      for (uint32_t y = 0; y < v.height; y++)
        memcpy(out + (size_t)y * v.width * 3, (const char *)v.data + v.byte_offset + y * stride,
               row);
  }
  hush_frame_release(fr);
  return out;
}

/* --set weights=FILE loads nca weights in denoise, eval and bench: zero
 * weights with bias b give colour + K (0.5 + b) exactly (emission bypass off:
 * the synthetic frames are all lit surfaces anyway); a file that cannot be
 * read is an error naming it; other filters have no such parameter. */
static void test_weights_cli(void) {
  REQUIRE(system("mkdir -p '" TWORK "'") == 0);
  hush_device dev = hush_device_new("threads=1");
  REQUIRE(dev);
  char err[8192];
  int rc = run_cli("synth --out '" TWORK "/seq' --size 40x24 --frames 2 --quiet", err, sizeof err);
  REQUIRE(rc == 0);
  hush_nca_weights z;
  memset(&z, 0, sizeof z);
  for (int c = 0; c < 9; c++) z.bias[c] = -0.25f;
  z.iterations = 3;
  z.color_transform = HUSH_NCA_LINEAR;
  REQUIRE(hush__nca_weights_save(dev, TWORK "/zero.bin", &z) == HUSH_OK);
  rc = run_cli("denoise --filter nca --in '" TWORK "/seq' --out '" TWORK "/zout' --set "
               "emission_bypass=0 --set weights='" TWORK "/zero.bin'",
               err, sizeof err);
  CHECK_MSG(rc == 0, "denoise exit %d: %s", rc, err);
  uint32_t w0 = 0, h0 = 0, w1 = 0, h1 = 0;
  float *in = read_color(dev, TWORK "/seq/frame_0001.exr", &w0, &h0);
  float *out = read_color(dev, TWORK "/zout/frame_0001.exr", &w1, &h1);
  CHECK(in && out && w0 == 40 && h0 == 24 && w1 == w0 && h1 == h0);
  if (in && out && w1 == w0 && h1 == h0) {
    int exact = 1;
    for (uint32_t i = 0; i < 3 * w0 * h0; i++) exact &= out[i] == zero_weights_output(in[i], 3);
    CHECK_MSG(exact, "denoise --set weights=zero.bin: output != colour + K (0.5 + bias)");
  }
  /* and back to the built-in weights, which do not add a constant */
  rc = run_cli("denoise --filter nca --in '" TWORK "/seq' --out '" TWORK "/bout' --set "
               "emission_bypass=0 --set weights=builtin",
               err, sizeof err);
  CHECK_MSG(rc == 0, "denoise exit %d: %s", rc, err);
  float *bout = read_color(dev, TWORK "/bout/frame_0001.exr", &w1, &h1);
  CHECK(bout && out && memcmp(bout, out, sizeof(float) * 3 * w0 * h0) != 0);
  free(in);
  free(out);
  free(bout);
  REQUIRE(system("head -c 100 '" TWORK "/zero.bin' > '" TWORK "/short.bin'") == 0);
  rc = run_cli("denoise --filter nca --in '" TWORK "/seq' --out '" TWORK "/sout' --set "
               "weights='" TWORK "/short.bin'",
               err, sizeof err);
  CHECK_MSG(rc == 1 && strstr(err, "short.bin") && strstr(err, "truncated"), "exit %d: %s", rc,
            err);
  rc = run_cli("denoise --filter svgf --in '" TWORK "/seq' --out '" TWORK "/sout' --set "
               "weights='" TWORK "/zero.bin'",
               err, sizeof err);
  CHECK_MSG(rc == 1 && strstr(err, "no parameter 'weights'"), "exit %d: %s", rc, err);
  rc = run_cli("bench --filters nca,accumulate --size 40x24 --frames 2 --warmup 0 --threads 1 "
               "--set weights='" TWORK "/zero.bin'",
               err, sizeof err);
  CHECK_MSG(rc == 0, "bench exit %d: %s", rc, err);
  rc = run_cli("bench --filters nca --size 40x24 --frames 2 --warmup 0 --threads 1 --set "
               "weights='" TWORK "/missing.bin'",
               err, sizeof err);
  CHECK_MSG(rc == 1 && strstr(err, "missing.bin"), "bench exit %d: %s", rc, err);
  rc = run_cli("eval --seq '" TWORK "/seq' --out '" TWORK "/rep' --filters nca --threads 1 "
               "--set nca.weights='" TWORK "/short.bin'",
               err, sizeof err);
  CHECK_MSG(rc == 1 && strstr(err, "short.bin"), "eval exit %d: %s", rc, err);
  hush_device_release(dev);
}

int main(void) {
  test_sigmoid();
  test_zero_weights_step();
  test_float_matches_double();
  test_gradient_check();
  test_gradient_relative_predicted();
  test_filter_deterministic();
  test_filter_extreme_input();
  test_filter_emission_bypass();
  test_weights_file();
  test_default_weights_match_file();
  test_train_cli();
  test_train_emission();
  test_weights_cli();
  return check_summary();
}
