/*
 * test_core.c — the core module: device configuration and the error model,
 * half <-> float conversion, image views (formats, strides, offsets) through
 * import/export, NaN/Inf detection, matrices, the counter-based RNG, and
 * the streaming copy.
 */
#include "check.h"

#include "core/device.h"
#include "core/half.h"
#include "core/hmath.h"
#include "core/image.h"
#include "core/rng.h"
#include "core/stream.h"
#include "filters/albedo.h"

#include <float.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static void test_device_config(void) {
  hush_device d = hush_device_new(NULL);
  REQUIRE(d != NULL);
  CHECK(hush_device_threads(d) >= 1);
  hush_device_release(d);

  d = hush_device_new("threads=3, verbose=1");
  REQUIRE(d != NULL);
  CHECK(hush_device_threads(d) == 3);
  hush_device_release(d);

  const char *msg = NULL;
  CHECK(hush_device_new("threads=abc") == NULL);
  CHECK(hush_device_get_error(NULL, &msg) == HUSH_ERROR_INVALID_ARGUMENT);
  CHECK(msg && strstr(msg, "threads") != NULL);
  /* read-and-clear */
  CHECK(hush_device_get_error(NULL, &msg) == HUSH_OK);
  CHECK(msg && msg[0] == '\0');

  CHECK(hush_device_new("colour=red") == NULL);
  CHECK(hush_device_get_error(NULL, &msg) == HUSH_ERROR_NOT_FOUND);
  CHECK(msg && strstr(msg, "colour") != NULL);
  CHECK(hush_device_new("threads") == NULL);
  CHECK(hush_device_get_error(NULL, NULL) == HUSH_ERROR_INVALID_ARGUMENT);

  /* memory: MiB a commit may allocate; 0 is the machine's memory */
  d = hush_device_new("memory=64");
  REQUIRE(d != NULL);
  CHECK(hush__device_memory_limit(d) == (size_t)64 << 20);
  hush_device_release(d);
  d = hush_device_new("memory=0");
  REQUIRE(d != NULL);
  CHECK(hush__device_memory_limit(d) > (size_t)64 << 20);
  hush_device_release(d);
  CHECK(hush_device_new("memory=-5") == NULL);
  CHECK(hush_device_get_error(NULL, &msg) == HUSH_ERROR_INVALID_ARGUMENT);
  CHECK(msg && strstr(msg, "memory") != NULL);
  CHECK(hush_device_new("memory=1e9") == NULL);
  CHECK(hush_device_get_error(NULL, NULL) == HUSH_ERROR_INVALID_ARGUMENT);
}

static int callback_calls;
static hush_status callback_last;
static void on_error(void *user, hush_status s, const char *m) {
  (void)m;
  *(int *)user += 1;
  callback_calls++;
  callback_last = s;
}

static void test_first_error_kept(void) {
  hush_device d = hush_device_new(NULL);
  REQUIRE(d != NULL);
  int count = 0;
  hush_device_set_error_callback(d, on_error, &count);
  hush__fail(d, HUSH_ERROR_NOT_FOUND, "first %d", 1);
  hush__fail(d, HUSH_ERROR_IO, "second");
  CHECK(count == 2);
  CHECK(callback_last == HUSH_ERROR_IO);
  const char *msg;
  CHECK(hush_device_get_error(d, &msg) == HUSH_ERROR_NOT_FOUND);
  CHECK(strcmp(msg, "first 1") == 0);
  CHECK(hush_device_get_error(d, &msg) == HUSH_OK);
  CHECK(strcmp(hush_status_name(HUSH_ERROR_NONFINITE), "HUSH_ERROR_NONFINITE") == 0);
  hush_device_release(d);
}

static void test_half(void) {
  /* Every half value survives half -> float -> half exactly (NaN stays NaN). */
  int exact = 1;
  for (uint32_t h = 0; h < 65536; h++) {
    const float f = hush__half_to_float((uint16_t)h);
    const uint16_t back = hush__float_to_half(f);
    if (f != f) {
      if ((back & 0x7c00u) != 0x7c00u || (back & 0x3ffu) == 0) exact = 0;
    } else if (back != h) {
      exact = 0;
    }
  }
  CHECK(exact);
  CHECK(hush__half_to_float(0x3c00) == 1.0f);
  CHECK(hush__half_to_float(0x7bff) == 65504.0f);
  CHECK(hush__half_to_float(0x0001) == 5.9604644775390625e-8f);
  CHECK(hush__float_to_half(65520.0f) == 0x7c00); /* rounds to infinity */
  CHECK(hush__float_to_half(1.0f + 1.0f / 2048.0f) == 0x3c00); /* tie to even */
  CHECK(hush__float_to_half(1.0f + 3.0f / 2048.0f) == 0x3c02);
  CHECK(hush__float_to_half(-0.0f) == 0x8000);
}

/* Writes a gradient through an arbitrary view (format, strides, offset) and
 * reads it back through import: the planes must equal the source. */
static void roundtrip_view(hush_format format, size_t offset, size_t pixel_pad, size_t row_pad) {
  const uint32_t w = 13, h = 7;
  const int ch = hush_format_channels(format);
  hush_planar src, dst;
  REQUIRE(hush__planar_init(NULL, &src, ch, w, h) == HUSH_OK);
  REQUIRE(hush__planar_init(NULL, &dst, ch, w, h) == HUSH_OK);
  for (int c = 0; c < ch; c++)
    for (size_t i = 0; i < (size_t)w * h; i++) src.plane[c][i] = (float)(i * 0.25 + c); /* exact in half */
  const size_t ps = hush_format_pixel_size(format) + pixel_pad;
  const size_t rs = ps * w + row_pad;
  unsigned char *mem = calloc(1, offset + rs * h + 64);
  hush_image_view v = {mem, format, w, h, offset, pixel_pad ? ps : 0, row_pad ? rs : 0};
  CHECK(hush__view_validate(NULL, &v, "test", ch, 1) == HUSH_OK);
  hush__view_export(&src, &v, 2);
  CHECK(hush__view_import(NULL, &v, "test", &dst, HUSH_NONFINITE_ERROR, NULL) == HUSH_OK);
  int same = 1;
  for (int c = 0; c < ch; c++)
    if (memcmp(src.plane[c], dst.plane[c], sizeof(float) * w * h)) same = 0;
  CHECK_MSG(same, "format %d offset %zu pixel pad %zu row pad %zu", format, offset, pixel_pad,
            row_pad);
  free(mem);
  hush__planar_free(&src);
  hush__planar_free(&dst);
}

/* A HALF output view gets finite values beyond the half range as +-65504,
 * not Inf; Inf and NaN stay, and values in range round as IEEE's
 * conversion does. */
static void half_export_saturates(void) {
  const float in[] = {70000.0f, -1e30f, 65519.0f, 65520.0f, INFINITY, -INFINITY, NAN, 1.5f,
                      -3.0e38f, 0.0f, FLT_MAX, 65504.0f, 1e-8f};
  const uint16_t want[] = {0x7bff, 0xfbff, 0x7bff, 0x7bff, 0x7c00, 0xfc00, 0, 0x3e00,
                           0xfbff, 0x0000, 0x7bff, 0x7bff, 0x0000};
  enum { N = sizeof in / sizeof in[0] };
  hush_planar src;
  REQUIRE(hush__planar_init(NULL, &src, 1, N, 1) == HUSH_OK);
  memcpy(src.plane[0], in, sizeof in);
  uint16_t out[N];
  hush_image_view v = {out, HUSH_FORMAT_HALF, N, 1, 0, 0, 0};
  hush__view_export(&src, &v, 1);
  for (int i = 0; i < N; i++) {
    const int ok = isnan(in[i]) ? (out[i] & 0x7c00) == 0x7c00 && (out[i] & 0x3ff) != 0
                                : out[i] == want[i];
    CHECK_MSG(ok, "%g exported as half 0x%04x, want 0x%04x", (double)in[i], out[i], want[i]);
  }
  hush__planar_free(&src);
}

/* Planes of fewer channels than the view's pixels (3 planes in FLOAT4,
 * 1 or 2 planes in a padded FLOAT2/FLOAT3/FLOAT4 pixel): export writes only
 * those channels, leaving the rest of each pixel as it was, and import reads
 * them back exactly. */
static void partial_channels(hush_format format, int planes) {
  const uint32_t w = 37, h = 3; /* not a multiple of any vector width */
  const size_t sf = (size_t)hush_format_channels(format);
  hush_planar src, dst;
  REQUIRE(hush__planar_init(NULL, &src, planes, w, h) == HUSH_OK);
  REQUIRE(hush__planar_init(NULL, &dst, planes, w, h) == HUSH_OK);
  for (int c = 0; c < planes; c++)
    for (size_t i = 0; i < (size_t)w * h; i++) src.plane[c][i] = (float)i * 0.5f - (float)c;
  const size_t n = (size_t)w * h * sf;
  float *mem = malloc(n * sizeof *mem);
  REQUIRE(mem != NULL);
  for (size_t k = 0; k < n; k++) mem[k] = -7.0f;
  hush_image_view v = {mem, format, w, h, 0, 0, 0};
  hush__view_export(&src, &v, 1);
  CHECK(hush__view_import(NULL, &v, "test", &dst, HUSH_NONFINITE_ERROR, NULL) == HUSH_OK);
  int same = 1, kept = 1;
  for (int c = 0; c < planes; c++)
    if (memcmp(src.plane[c], dst.plane[c], sizeof(float) * w * h)) same = 0;
  for (size_t k = 0; k < n; k++)
    if (k % sf >= (size_t)planes && mem[k] != -7.0f) kept = 0;
  CHECK_MSG(same && kept, "format %d with %d plane(s): same %d, rest kept %d", format, planes,
            same, kept);
  free(mem);
  hush__planar_free(&src);
  hush__planar_free(&dst);
}

static void test_views(void) {
  const hush_format formats[] = {HUSH_FORMAT_FLOAT,  HUSH_FORMAT_FLOAT2, HUSH_FORMAT_FLOAT3,
                                 HUSH_FORMAT_FLOAT4, HUSH_FORMAT_HALF,   HUSH_FORMAT_HALF2,
                                 HUSH_FORMAT_HALF3,  HUSH_FORMAT_HALF4};
  for (size_t i = 0; i < sizeof formats / sizeof formats[0]; i++) {
    roundtrip_view(formats[i], 0, 0, 0);
    roundtrip_view(formats[i], 8, 4, 12);
    roundtrip_view(formats[i], 2 * (formats[i] >= HUSH_FORMAT_HALF ? 1 : 2), 8, 0);
  }
  for (int planes = 1; planes <= 3; planes++) {
    if (planes < 2) partial_channels(HUSH_FORMAT_FLOAT2, planes);
    if (planes < 3) partial_channels(HUSH_FORMAT_FLOAT3, planes);
    partial_channels(HUSH_FORMAT_FLOAT4, planes);
  }
  half_export_saturates();
  CHECK(hush_format_pixel_size(HUSH_FORMAT_HALF3) == 6);
  CHECK(hush_format_pixel_size(HUSH_FORMAT_FLOAT4) == 16);
  CHECK(hush_format_channels((hush_format)99) == 0);

  float buf[64] = {0};
  hush_device d = hush_device_new(NULL);
  const char *msg;
  hush_image_view v = {buf, HUSH_FORMAT_FLOAT3, 4, 4, 0, 0, 0};
  CHECK(hush__view_validate(d, &v, "color", 3, 0) == HUSH_OK);
  v.pixel_stride = 6; /* not a multiple of 4 */
  CHECK(hush__view_validate(d, &v, "color", 3, 0) == HUSH_ERROR_INVALID_ARGUMENT);
  CHECK(hush_device_get_error(d, &msg) && strstr(msg, "color") != NULL);
  v.pixel_stride = 4; /* smaller than a pixel */
  CHECK(hush__view_validate(d, &v, "color", 3, 0) == HUSH_ERROR_INVALID_ARGUMENT);
  CHECK(hush_device_get_error(d, &msg) && strstr(msg, "smaller than a pixel") != NULL);
  v.pixel_stride = 0;
  v.row_stride = 16; /* rows overlap */
  CHECK(hush__view_validate(d, &v, "color", 3, 0) == HUSH_ERROR_INVALID_ARGUMENT);
  CHECK(hush_device_get_error(d, &msg) && strstr(msg, "overlap") != NULL);
  v.row_stride = 0;
  CHECK(hush__view_validate(d, &v, "normal", 4, 0) == HUSH_ERROR_INVALID_ARGUMENT);
  CHECK(hush_device_get_error(d, &msg) && strstr(msg, "at least 4") != NULL);
  v.width = 0;
  CHECK(hush__view_validate(d, &v, "color", 3, 0) == HUSH_ERROR_INVALID_ARGUMENT);
  v.width = 4;
  v.data = NULL;
  CHECK(hush__view_validate(d, &v, "color", 3, 0) == HUSH_ERROR_INVALID_ARGUMENT);
  hush_device_get_error(d, NULL);

  /* NaN detection names the first pixel; replace policy zeroes and counts. */
  v.data = buf;
  buf[3 * (2 * 4 + 1) + 1] = NAN; /* pixel (1, 2), green */
  buf[3 * (3 * 4 + 3)] = INFINITY;
  hush_planar p;
  REQUIRE(hush__planar_init(d, &p, 3, 4, 4) == HUSH_OK);
  CHECK(hush__view_import(d, &v, "color", &p, HUSH_NONFINITE_ERROR, NULL) == HUSH_ERROR_NONFINITE);
  CHECK(hush_device_get_error(d, &msg) == HUSH_ERROR_NONFINITE);
  CHECK_MSG(strstr(msg, "(1, 2)") != NULL, "message: %s", msg);
  size_t replaced = 0;
  CHECK(hush__view_import(d, &v, "color", &p, HUSH_NONFINITE_REPLACE, &replaced) == HUSH_OK);
  CHECK(replaced == 2);
  CHECK(p.plane[1][2 * 4 + 1] == 0.0f && p.plane[0][3 * 4 + 3] == 0.0f);
  hush__planar_free(&p);
  hush_device_release(d);
}

/* Rows of whole vectors (the streamed import path where the build has one):
 * every value lands in its plane, every NaN/Inf is counted (in each lane
 * and channel), and the cached variant agrees. Also a width that is not a
 * multiple of 16, which takes the plain path. */
static void streamed_rows(hush_format format, uint32_t W) {
  const uint32_t H = 3;
  const int nc = hush_format_channels(format);
  float *buf = malloc(sizeof(float) * W * H * (size_t)nc);
  REQUIRE(buf != NULL);
  for (size_t i = 0; i < (size_t)W * H * (size_t)nc; i++) buf[i] = (float)i * 0.25f - 7.0f;
  /* non-finite values in lanes 0, 5, 11, 15 of the first vector and in the
   * last pixel, in different channels */
  const size_t at[] = {0, 5, 11, 15, (size_t)W * H - 1};
  for (size_t k = 0; k < sizeof at / sizeof at[0]; k++)
    buf[at[k] * (size_t)nc + k % (size_t)nc] = k % 2 ? INFINITY : NAN;
  hush_image_view v = {buf, format, W, H, 0, 0, 0};
  hush_planar a, b;
  REQUIRE(hush__planar_init(NULL, &a, nc, W, H) == HUSH_OK);
  REQUIRE(hush__planar_init(NULL, &b, nc, W, H) == HUSH_OK);
  size_t bad_a = 0, bad_b = 0;
  for (uint32_t y = 0; y < H; y++) {
    bad_a += hush__view_import_row(&v, y, &a);
    bad_b += hush__view_import_row_cached(&v, y, &b);
  }
  CHECK_MSG(bad_a == 5 && bad_b == 5, "format %d width %u: %zu and %zu non-finite, want 5",
            (int)format, W, bad_a, bad_b);
  int same = 1;
  for (size_t i = 0; i < (size_t)W * H; i++)
    for (int c = 0; c < nc; c++) {
      const float want = buf[i * (size_t)nc + (size_t)c];
      const float got = a.plane[c][i], got_b = b.plane[c][i];
      if (memcmp(&want, &got, sizeof got) != 0 || memcmp(&want, &got_b, sizeof got) != 0)
        same = 0;
    }
  CHECK_MSG(same, "format %d width %u: planes differ from the view", (int)format, W);
  hush__planar_free(&a);
  hush__planar_free(&b);
  free(buf);
}

/* The normals' row flag of hush__view_import_row_normals against
 * hush__normals_odd on the imported planes: rows of unit normals and zeros
 * (not odd), then one normal of length 0.9, 1 + 3e-3 in its square, or a
 * NaN, at each lane of the first vector and at the last pixel (odd), on
 * the streamed path (a width of whole vectors) and the plain one. */
static void normal_rows(uint32_t W) {
  float *buf = malloc(sizeof(float) * W * 3);
  REQUIRE(buf != NULL);
  hush_planar a;
  REQUIRE(hush__planar_init(NULL, &a, 3, W, 1) == HUSH_OK);
  hush_image_view v = {buf, HUSH_FORMAT_FLOAT3, W, 1, 0, 0, 0};
  const float odd_values[][3] = {{0.9f, 0.0f, 0.0f}, {0.0f, 0.0f, sqrtf(1.003f)}, {NAN, 0.0f, 1.0f}};
  int ok = 1;
  for (int trial = -1; trial < 3 * 17; trial++) {
    for (uint32_t x = 0; x < W; x++) {
      const float t = 0.37f * (float)x;
      const float n[3] = {cosf(t) * 0.6f, sinf(t) * 0.6f, 0.8f};
      for (int c = 0; c < 3; c++) buf[3 * x + c] = x % 5 == 3 ? 0.0f : n[c];
    }
    if (trial >= 0) {
      const uint32_t x = trial % 17 == 16 ? W - 1 : (uint32_t)(trial % 17);
      for (int c = 0; c < 3; c++) buf[3 * x + c] = odd_values[trial / 17][c];
    }
    int odd = -1;
    hush__view_import_row_normals(&v, 0, &a, &odd);
    const int want = hush__normals_odd(a.plane[0], a.plane[1], a.plane[2], W);
    ok &= odd == want && want == (trial >= 0);
  }
  CHECK_MSG(ok, "width %u: the normals' row flag differs from hush__normals_odd", W);
  hush__planar_free(&a);
  free(buf);
}

/* The export of three planes into an interleaved float row, at every
 * start alignment of the output (the streamed path has a head, 64-byte
 * groups and a tail): every pixel of the span lands, nothing around it is
 * touched. */
static void export_spans(void) {
  enum { W = 101 };
  float p0[W], p1[W], p2[W];
  for (int x = 0; x < W; x++) {
    p0[x] = (float)x;
    p1[x] = 1000.0f + (float)x;
    p2[x] = -(float)x - 0.5f;
  }
  const float *const in[3] = {p0, p1, p2};
  enum { N = 3 * W + 64 };
  float *buf = aligned_alloc(64, (sizeof(float) * N + 63) / 64 * 64);
  REQUIRE(buf != NULL);
  int ok = 1;
  for (uint32_t shift = 0; shift < 16; shift++)
    for (uint32_t x0 = 0; x0 < 3; x0++) {
      const uint32_t w = W - 2 * x0 - 1;
      for (int i = 0; i < N; i++) buf[i] = 7.0f;
      const hush_image_view v = {buf + shift, HUSH_FORMAT_FLOAT3, W, 1, 0, 0, 0};
      hush__view_export_span(in, 3, &v, 0, x0, w);
      for (int i = 0; i < N; i++) {
        const int e = i - (int)shift, x = e / 3;
        const int inside = e >= 0 && x >= (int)x0 && x < (int)(x0 + w);
        const float want = inside ? in[e % 3][x - (int)x0] : 7.0f;
        if (buf[i] != want) ok = 0;
      }
    }
  CHECK_MSG(ok, "export of three planes into an interleaved row");
  free(buf);
}

/* The demodulating import (filters/albedo.c, streamed and divided in one
 * pass where it can) gives the bits of an import followed by the division,
 * also with NaN/Inf replaced, at widths with and without that pass. */
static void demodulated_import(uint32_t W, int with_bad) {
  const uint32_t H = 4;
  float *buf = malloc(sizeof(float) * W * H * 3);
  REQUIRE(buf != NULL);
  for (size_t i = 0; i < (size_t)W * H * 3; i++) buf[i] = (float)(i % 97) * 0.37f - 3.0f;
  if (with_bad) {
    buf[3 * (size_t)(W + 5) + 1] = NAN;
    buf[3 * (size_t)(2 * W + 15) + 2] = INFINITY;
  }
  hush_planar alb, a, b;
  REQUIRE(hush__planar_init(NULL, &alb, 3, W, H) == HUSH_OK);
  REQUIRE(hush__planar_init(NULL, &a, 3, W, H) == HUSH_OK);
  REQUIRE(hush__planar_init(NULL, &b, 3, W, H) == HUSH_OK);
  const float values[] = {0.0f, 1e-4f, HUSH_ALBEDO_EPS, 0.002f, 0.5f, 1.0f, 3.0f};
  for (int c = 0; c < 3; c++)
    for (size_t i = 0; i < (size_t)W * H; i++) alb.plane[c][i] = values[(i + (size_t)c) % 7];
  const hush_image_view v = {buf, HUSH_FORMAT_FLOAT3, W, H, 0, 0, 0};
  size_t ra = 0, rb = 0;
  CHECK(hush__import_demodulated(NULL, &v, "color", &a, &alb, HUSH_NONFINITE_REPLACE, &ra, 2) ==
        HUSH_OK);
  CHECK(hush__view_import(NULL, &v, "color", &b, HUSH_NONFINITE_REPLACE, &rb) == HUSH_OK);
  hush__demodulate(&b, &alb, 1);
  CHECK_MSG(ra == rb && ra == (with_bad ? 2u : 0u), "width %u: replaced %zu and %zu", W, ra, rb);
  int same = 1;
  for (int c = 0; c < 3; c++)
    same &= memcmp(a.plane[c], b.plane[c], sizeof(float) * W * H) == 0;
  CHECK_MSG(same, "width %u%s: demodulated import differs from import + division", W,
            with_bad ? " with NaN/Inf" : "");
  hush__planar_free(&alb);
  hush__planar_free(&a);
  hush__planar_free(&b);
  free(buf);
}

/* The albedo's import with the radiance's demodulated import in one pass
 * gives the bits, counts and errors of the two in turn (hush__view_import
 * of the albedo, then hush__import_demodulated): bad values in neither,
 * the radiance, the albedo (NaN, Inf, beyond HUSH_INPUT_MAX), or both,
 * under either policy; at a width of whole vectors (the paired streamed
 * rows) and one that is not. */
static void albedo_demodulated_import(uint32_t W, int bad_color, int bad_albedo,
                                      hush_nonfinite_policy policy) {
  const uint32_t H = 4;
  float *buf = malloc(sizeof(float) * W * H * 3), *abuf = malloc(sizeof(float) * W * H * 3);
  REQUIRE(buf != NULL && abuf != NULL);
  const float values[] = {0.0f, 1e-4f, HUSH_ALBEDO_EPS, 0.002f, 0.5f, 1.0f, 3.0f};
  for (size_t i = 0; i < (size_t)W * H * 3; i++) {
    buf[i] = (float)(i % 97) * 0.37f - 3.0f;
    abuf[i] = values[(i + i / 3) % 7];
  }
  if (bad_color) buf[3 * (size_t)(W + 5) + 1] = NAN;
  if (bad_albedo) {
    abuf[3 * (size_t)(2 * W + 15) + 2] = INFINITY;
    abuf[3 * (size_t)(W + 5)] = NAN;
    abuf[7] = 2e15f;
  }
  const hush_image_view v = {buf, HUSH_FORMAT_FLOAT3, W, H, 0, 0, 0};
  const hush_image_view av = {abuf, HUSH_FORMAT_FLOAT3, W, H, 0, 0, 0};
  hush_device d = hush_device_new(NULL);
  REQUIRE(d != NULL);
  hush_planar alb_a, alb_b, a, b;
  REQUIRE(hush__planar_init(NULL, &alb_a, 3, W, H) == HUSH_OK);
  REQUIRE(hush__planar_init(NULL, &alb_b, 3, W, H) == HUSH_OK);
  REQUIRE(hush__planar_init(NULL, &a, 3, W, H) == HUSH_OK);
  REQUIRE(hush__planar_init(NULL, &b, 3, W, H) == HUSH_OK);
  size_t ra = 0, raa = 0, rb = 0, rab = 0;
  const hush_status sa = hush__import_albedo_demodulated(d, &v, "color", &a, &av, "albedo",
                                                         &alb_a, policy, &ra, &raa, 2);
  const char *msg = NULL;
  hush_device_get_error(d, &msg);
  char msg_a[256];
  snprintf(msg_a, sizeof msg_a, "%s", msg ? msg : "");
  hush_status sb = hush__view_import(d, &av, "albedo", &alb_b, policy, &rab);
  if (!sb) sb = hush__import_demodulated(d, &v, "color", &b, &alb_b, policy, &rb, 2);
  hush_device_get_error(d, &msg);
  CHECK_MSG(sa == sb && strcmp(msg_a, msg ? msg : "") == 0,
            "width %u bad %d/%d: status %d '%s' against %d '%s'", W, bad_color, bad_albedo,
            (int)sa, msg_a, (int)sb, msg ? msg : "");
  CHECK(sa != HUSH_OK || (raa == (bad_albedo ? 3u : 0u) && ra == (bad_color ? 1u : 0u)));
  if (sa == HUSH_OK && sb == HUSH_OK) {
    int same = 1;
    for (int c = 0; c < 3; c++)
      same &= memcmp(a.plane[c], b.plane[c], sizeof(float) * W * H) == 0 &&
              memcmp(alb_a.plane[c], alb_b.plane[c], sizeof(float) * W * H) == 0;
    CHECK_MSG(same, "width %u bad %d/%d: the paired import differs from the two in turn", W,
              bad_color, bad_albedo);
  }
  hush__planar_free(&alb_a);
  hush__planar_free(&alb_b);
  hush__planar_free(&a);
  hush__planar_free(&b);
  hush_device_release(d);
  free(buf);
  free(abuf);
}

/* The remodulating export (filters/albedo.c) gives the bits of the
 * separate passes: remodulate, add the emission (filters/emission.c does
 * o = filtered + emission), export; with the albedo or the addition left
 * out, at widths that are and are not a multiple of its span; and with
 * the addition's all-zero middle row flagged as such (not read), also
 * where the filtered value is -0 (+0 out, as the addition gives). */
static void remodulated_export(uint32_t W) {
  const uint32_t H = 3;
  const size_t n = (size_t)W * H;
  hush_planar flt, alb, add, want;
  REQUIRE(hush__planar_init(NULL, &flt, 3, W, H) == HUSH_OK);
  REQUIRE(hush__planar_init(NULL, &alb, 3, W, H) == HUSH_OK);
  REQUIRE(hush__planar_init(NULL, &add, 3, W, H) == HUSH_OK);
  REQUIRE(hush__planar_init(NULL, &want, 3, W, H) == HUSH_OK);
  float *got = malloc(sizeof(float) * n * 3), *ref = malloc(sizeof(float) * n * 3);
  REQUIRE(got && ref);
  const hush_image_view gv = {got, HUSH_FORMAT_FLOAT3, W, H, 0, 0, 0};
  const hush_image_view rv = {ref, HUSH_FORMAT_FLOAT3, W, H, 0, 0, 0};
  const float add_rows[3] = {1.0f, 0.0f, 1.0f};
  for (int mode = 0; mode < 6; mode++) {
    const int with_alb = mode & 1, with_add = mode & 2 || mode >= 4, with_rows = mode >= 4;
    for (int c = 0; c < 3; c++)
      for (size_t i = 0; i < n; i++) {
        flt.plane[c][i] = (float)((i * 7 + (size_t)c) % 53) * 0.731f;
        if (i % 13 == 0) flt.plane[c][i] = -0.0f;
        alb.plane[c][i] = (float)((i + 3 * (size_t)c) % 11) * 0.093f; /* 0 too: the floor */
        add.plane[c][i] = i / W == 1 && with_rows ? 0.0f : (float)((i * 5 + (size_t)c) % 17) * 1.37f;
        want.plane[c][i] = flt.plane[c][i];
      }
    if (with_alb) {
      hush__remodulate(&alb, &flt, 2); /* alb <- flt * max(alb, eps) */
      for (int c = 0; c < 3; c++) memcpy(want.plane[c], alb.plane[c], sizeof(float) * n);
      for (int c = 0; c < 3; c++)
        for (size_t i = 0; i < n; i++) alb.plane[c][i] = (float)((i + 3 * (size_t)c) % 11) * 0.093f;
    }
    if (with_add)
      for (int c = 0; c < 3; c++)
        for (size_t i = 0; i < n; i++) want.plane[c][i] = want.plane[c][i] + add.plane[c][i];
    hush__view_export(&want, &rv, 1);
    if (with_rows) /* the flagged row is not read: what it holds must not matter */
      for (int c = 0; c < 3; c++) add.plane[c][W + 1] = 1.0f;
    hush__export_remodulated(&flt, with_alb ? &alb : NULL, with_add ? &add : NULL,
                             with_rows ? add_rows : NULL, &gv, 2);
    CHECK_MSG(memcmp(got, ref, sizeof(float) * n * 3) == 0,
              "width %u, albedo %d, add %d, rows %d: the fused export differs from the passes", W,
              with_alb, with_add != 0, with_rows);
  }
  free(got);
  free(ref);
  hush__planar_free(&flt);
  hush__planar_free(&alb);
  hush__planar_free(&add);
  hush__planar_free(&want);
}

static void test_math(void) {
  float v[16], pr[16], m[16], inv[16], id[16];
  hush_m4_look_at(v, hush_v3(1, 2, 3), hush_v3(0, 0, -4), hush_v3(0, 1, 0));
  hush_m4_perspective(pr, 60.0f, 16.0f / 9.0f, 0.1f, 100.0f);
  hush_m4_mul(m, pr, v);
  CHECK(hush_m4_invert(inv, m));
  hush_m4_mul(id, m, inv);
  double err = 0;
  for (int i = 0; i < 16; i++) err = fmax(err, fabs(id[i] - (i % 5 == 0 ? 1.0 : 0.0)));
  CHECK(err < 1e-4);
  /* The eye maps to the view origin; the target lies on -Z. */
  hush_vec4 e = hush_m4_mul_v4(v, 1, 2, 3, 1);
  CHECK_NEAR(e.x, 0, 1e-5);
  CHECK_NEAR(e.y, 0, 1e-5);
  CHECK_NEAR(e.z, 0, 1e-5);
  hush_vec4 t = hush_m4_mul_v4(v, 0, 0, -4, 1);
  CHECK(t.z < 0 && fabsf(t.x) < 1e-5f && fabsf(t.y) < 1e-5f);
  float zero[16] = {0};
  CHECK(!hush_m4_invert(inv, zero));
}

static void test_rng(void) {
  /* Pure function of its inputs; roughly uniform; streams decorrelated. */
  CHECK(hush_rng_u32(1, 2, 3) == hush_rng_u32(1, 2, 3));
  CHECK(hush_rng_u32(1, 2, 3) != hush_rng_u32(1, 2, 4));
  CHECK(hush_rng_u32(1, 2, 3) != hush_rng_u32(1, 3, 3));
  const int n = 1 << 16;
  double sum = 0, sum2 = 0, cross = 0;
  int buckets[16] = {0};
  for (int i = 0; i < n; i++) {
    const float a = hush_rng_float(7, 0, (uint32_t)i), b = hush_rng_float(7, 1, (uint32_t)i);
    CHECK(a >= 0.0f && a < 1.0f);
    sum += a;
    sum2 += a * a;
    cross += (a - 0.5) * (b - 0.5);
    buckets[(int)(a * 16)]++;
  }
  CHECK_NEAR(sum / n, 0.5, 0.01);
  CHECK_NEAR(sum2 / n - (sum / n) * (sum / n), 1.0 / 12.0, 0.003);
  CHECK_NEAR(cross / n, 0.0, 0.003);
  int flat = 1;
  for (int k = 0; k < 16; k++)
    if (abs(buckets[k] - n / 16) > n / 16 / 10) flat = 0;
  CHECK(flat);
}

/* hush__stream_copy copies every byte for any alignment of either end
 * and any length (whole lines streamed, the partial ones at the ends
 * copied), and writes nothing outside dst. */
static void test_stream_copy(void) {
  enum { MAXLEN = 300, PAD = 64 };
  unsigned char src[MAXLEN + 64], buf[PAD + MAXLEN + 64 + PAD] __attribute__((aligned(64)));
  for (int i = 0; i < (int)sizeof src; i++) src[i] = (unsigned char)(i * 37 + 11);
  int bad = 0;
  for (int off = 0; off < 64; off++)
    for (int soff = 0; soff < 64; soff += 5)
      for (int len = 0; len <= MAXLEN; len += len < 140 ? 1 : 7) {
        memset(buf, 0xA5, sizeof buf);
        unsigned char *d = buf + PAD + off;
        hush__stream_copy(d, src + soff, (size_t)len);
        hush__stream_fence();
        bad += memcmp(d, src + soff, (size_t)len) != 0;
        for (int i = 0; i < (int)sizeof buf; i++)
          if (buf + i < d || buf + i >= d + len) bad += buf[i] != 0xA5;
      }
  CHECK(bad == 0);
}

/* The allocation cap: refuses what would pass it, before allocating, and
 * only while open; the planes it grants are zeroed and aligned. */
static void test_alloc_cap(void) {
  const char *msg = NULL;
  hush__alloc_cap_open(NULL, (size_t)1 << 20, "the test's cap");
  float *a = hush__alloc_floats(150000); /* 600 KB */
  float *b = hush__alloc_floats(150000); /* past 1 MiB */
  float *c = hush__alloc_floats(10000);  /* 40 KB still fits */
  CHECK(hush__alloc_cap_close() == 1);
  CHECK(a != NULL && b == NULL && c != NULL);
  CHECK(hush_device_get_error(NULL, &msg) == HUSH_ERROR_OUT_OF_MEMORY && msg &&
        strcmp(msg, "the test's cap") == 0);
  float *d = hush__alloc_floats(150000); /* closed: no cap */
  CHECK(d != NULL);
  hush__alloc_cap_open(NULL, (size_t)1 << 20, "unused");
  CHECK(hush__alloc_cap_close() == 0);
  CHECK(hush_device_get_error(NULL, &msg) == HUSH_OK);
  int zero = 1;
  for (int i = 0; a && d && i < 150000; i++) zero = zero && a[i] == 0.0f && d[i] == 0.0f;
  CHECK(zero);
  CHECK(((uintptr_t)a % HUSH_ALIGN) == 0 && ((uintptr_t)c % HUSH_ALIGN) == 0 &&
        ((uintptr_t)d % HUSH_ALIGN) == 0);
  hush__free_floats(a);
  hush__free_floats(c);
  hush__free_floats(d);

  /* the other per-pixel arrays count against the same cap */
  hush__alloc_cap_open(NULL, (size_t)1 << 20, "the counted cap");
  unsigned char *e = hush__alloc_counted(700000, 1);
  uint32_t *g = hush__alloc_counted(100000, sizeof *g); /* 400 KB: past 1 MiB */
  float *k = hush__alloc_floats(10000);
  CHECK(hush__alloc_cap_close() == 1);
  CHECK(e != NULL && g == NULL && k != NULL);
  CHECK(hush_device_get_error(NULL, &msg) == HUSH_ERROR_OUT_OF_MEMORY && msg &&
        strcmp(msg, "the counted cap") == 0);
  int zeroed = 1;
  for (int i = 0; e && i < 700000; i++) zeroed = zeroed && e[i] == 0;
  CHECK(zeroed);
  CHECK(hush__alloc_counted(0, 4) == NULL && hush__alloc_counted(4, 0) == NULL);
  CHECK(hush__alloc_counted(SIZE_MAX / 2, 4) == NULL); /* count * size overflows */
  free(e);
  hush__free_floats(k);
}

int main(void) {
  test_alloc_cap();
  test_device_config();
  test_first_error_kept();
  test_half();
  test_views();
  streamed_rows(HUSH_FORMAT_FLOAT3, 48);
  streamed_rows(HUSH_FORMAT_FLOAT, 32);
  streamed_rows(HUSH_FORMAT_FLOAT2, 64);
  streamed_rows(HUSH_FORMAT_FLOAT3, 37);
  normal_rows(48);
  normal_rows(37);
  export_spans();
  for (int bad = 0; bad < 2; bad++) {
    demodulated_import(48, bad);
    demodulated_import(37, bad);
  }
  for (int k = 0; k < 8; k++)
    albedo_demodulated_import(k & 1 ? 37 : 48, (k >> 1) & 1, (k >> 2) & 1,
                              HUSH_NONFINITE_REPLACE);
  albedo_demodulated_import(48, 1, 0, HUSH_NONFINITE_ERROR);
  albedo_demodulated_import(48, 0, 1, HUSH_NONFINITE_ERROR);
  albedo_demodulated_import(48, 1, 1, HUSH_NONFINITE_ERROR);
  remodulated_export(37);
  remodulated_export(1100);
  test_math();
  test_rng();
  test_stream_copy();
  CHECK(callback_calls == 2);
  return check_summary();
}
