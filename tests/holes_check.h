/*
 * holes_check.h — a temporal filter fed frames with holes (`hush render
 * --spp-fraction 0.25`: the rotating 2x2 pattern of docs/renderer.md, spp 0
 * and every other layer 0 at a hole), through the public API only, on an
 * analytic scene: a plane facing the camera whose radiance is a known
 * linear function of the world position (so the truth of every pixel is
 * known exactly and noise-free). Shared by test_accumulate.c, test_taa.c,
 * test_bmfr.c and test_progressive.c (docs/holes.md).
 *
 * A run renders `frames` frames (camera panning `pan` world units a frame,
 * 0: still) with one of the patterns below and compares the last output
 * with the truth. Header-only (static functions): include it once.
 */
#ifndef HUSH_TESTS_HOLES_CHECK_H
#define HUSH_TESTS_HOLES_CHECK_H

#include "hush.h"

#include "check.h"
#include "core/hmath.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

typedef enum holes_pattern {
  HOLES_FULL = 0,     /* every pixel traced, no 'spp' image bound */
  HOLES_FULL_SPP = 1, /* every pixel traced, 'spp' bound (all 1) */
  HOLES_QUARTER = 2   /* 1/4 spp: one pixel of each 2x2 block a frame */
} holes_pattern;

typedef struct holes_result {
  float *out;          /* W x H x 3, the last output (caller frees) */
  float *extra;        /* W x H, the last extra output (caller frees; NULL: none) */
  double mean;         /* of the output's luminance */
  double truth_mean;   /* of the truth's */
  double mean_rel_err; /* mean |out - truth| / truth (luminance) */
  double max_rel_err;
  int black;     /* pixels whose luminance is below half the truth's */
  int nonfinite; /* NaN or Inf values */
  int trail;     /* sky scene: sky pixels 3+ pixels from the object, brighter than 1 */
} holes_result;

/* Radiance of the world point (X, Y, 0): linear, positive over the view. */
static void holes_truth(float X, float Y, float c[3]) {
  c[0] = 0.5f + 0.1f * X;
  c[1] = 0.4f + 0.08f * Y;
  c[2] = 0.3f + 0.03f * (X + Y);
}

static float holes_luma(const float *c) { return 0.2126f * c[0] + 0.7152f * c[1] + 0.0722f * c[2]; }

/* The 2x2 rotation of docs/renderer.md: top-left, bottom-right, top-right,
 * bottom-left. */
static int holes_traced(holes_pattern p, int x, int y, int frame) {
  static const int order[4][2] = {{0, 0}, {1, 1}, {1, 0}, {0, 1}};
  if (p != HOLES_QUARTER) return 1;
  return (x & 1) == order[frame & 3][0] && (y & 1) == order[frame & 3][1];
}

typedef struct holes_cam {
  float w2v[16], v2c[16], v2w[16];
  hush_vec3 eye;
} holes_cam;

static void holes_cam_at(holes_cam *c, float ex, int W, int H) {
  c->eye = hush_v3(ex, 0.0f, 5.0f);
  hush_m4_look_at(c->w2v, c->eye, hush_v3(ex, 0.0f, 0.0f), hush_v3(0.0f, 1.0f, 0.0f));
  hush_m4_perspective(c->v2c, 60.0f, (float)W / (float)H, 0.1f, 100.0f);
  REQUIRE(hush_m4_invert(c->v2w, c->w2v));
}

static void holes_bind(hush_filter f, const char *name, void *data, hush_format fmt, int W, int H) {
  hush_image_view v;
  memset(&v, 0, sizeof v);
  v.data = data;
  v.format = fmt;
  v.width = (uint32_t)W;
  v.height = (uint32_t)H;
  const hush_status s = hush_filter_set_image(f, name, &v);
  CHECK_MSG(s == HUSH_OK, "binding %s: %s", name, hush_status_name(s));
}

/* A lamp on the plane: first-hit emission (4, 3.5, 3) in a rectangle. */
static float holes_lamp(float X, float Y) {
  return X > -1.2f && X < 0.8f && Y > -0.6f && Y < 0.5f ? 1.0f : 0.0f;
}

/*
 * Runs filter `name` (sets: "param=value" strings, NULL-terminated, may be
 * NULL) on `frames` frames of W x H. Binds color, depth, normal, position,
 * albedo (0.8) and, unless HOLES_FULL, spp; and the 1-channel output
 * `extra` unless NULL. With lamp 1, the plane has a lamp (holes_lamp) and
 * 'emission' is bound; with lamp 2 only the lamp's rectangle is there, a
 * bright object (radiance + 20) against the sky (depth 0, radiance 0.05);
 * with either `r->black` counts the rectangle's inner pixels only.
 */
static void holes_run_lamp(const char *name, const char *const *sets, holes_pattern pattern,
                           int W, int H, int frames, float pan, const char *extra, int lamp,
                           holes_result *r) {
  memset(r, 0, sizeof *r);
  const size_t n = (size_t)W * H;
  float *color = calloc(3 * n, sizeof(float)), *depth = calloc(n, sizeof(float));
  float *normal = calloc(3 * n, sizeof(float)), *position = calloc(3 * n, sizeof(float));
  float *albedo = calloc(3 * n, sizeof(float)), *spp = calloc(n, sizeof(float));
  float *truth = calloc(3 * n, sizeof(float)), *emission = calloc(3 * n, sizeof(float));
  float *on_lamp = calloc(n, sizeof(float));
  r->out = calloc(3 * n, sizeof(float));
  r->extra = extra ? calloc(n, sizeof(float)) : NULL;
  REQUIRE(color && depth && normal && position && albedo && spp && truth && emission && on_lamp &&
          r->out);
  hush_device dev = hush_device_new("threads=2");
  REQUIRE(dev);
  hush_filter f = hush_filter_new(dev, name);
  REQUIRE(f);
  for (int k = 0; sets && sets[k]; k++) {
    char key[64];
    const char *eq = strchr(sets[k], '=');
    REQUIRE(eq && (size_t)(eq - sets[k]) < sizeof key);
    memcpy(key, sets[k], (size_t)(eq - sets[k]));
    key[eq - sets[k]] = 0;
    CHECK_MSG(hush_filter_set_string(f, key, eq + 1) == HUSH_OK, "%s: %s", name, sets[k]);
  }
  holes_bind(f, "color", color, HUSH_FORMAT_FLOAT3, W, H);
  holes_bind(f, "depth", depth, HUSH_FORMAT_FLOAT, W, H);
  holes_bind(f, "normal", normal, HUSH_FORMAT_FLOAT3, W, H);
  holes_bind(f, "position", position, HUSH_FORMAT_FLOAT3, W, H);
  if (strcmp(name, "taa") != 0) holes_bind(f, "albedo", albedo, HUSH_FORMAT_FLOAT3, W, H);
  if (pattern != HOLES_FULL) holes_bind(f, "spp", spp, HUSH_FORMAT_FLOAT, W, H);
  holes_bind(f, "output", r->out, HUSH_FORMAT_FLOAT3, W, H);
  if (extra) holes_bind(f, extra, r->extra, HUSH_FORMAT_FLOAT, W, H);
  if (lamp == 1) holes_bind(f, "emission", emission, HUSH_FORMAT_FLOAT3, W, H);
  const int sky = lamp == 2;
  static const float sky_radiance[3] = {0.05f, 0.05f, 0.07f};
  REQUIRE(hush_filter_commit(f) == HUSH_OK);

  holes_cam prev, cur;
  holes_cam_at(&prev, 0.0f, W, H);
  const float th = tanf(30.0f * 3.14159265358979f / 180.0f), aspect = (float)W / (float)H;
  for (int fr = 0; fr < frames; fr++) {
    holes_cam_at(&cur, pan * (float)fr, W, H);
    for (int y = 0; y < H; y++)
      for (int x = 0; x < W; x++) {
        const size_t i = (size_t)y * W + x;
        const float nx = 2.0f * ((float)x + 0.5f) / (float)W - 1.0f;
        const float ny = 1.0f - 2.0f * ((float)y + 0.5f) / (float)H;
        const hush_vec4 d = hush_m4_mul_v4(cur.v2w, nx * th * aspect, ny * th, -1.0f, 0.0f);
        const float t = -cur.eye.z / d.z; /* the plane z = 0 */
        const float X = cur.eye.x + t * d.x, Y = cur.eye.y + t * d.y;
        holes_truth(X, Y, truth + 3 * i);
        on_lamp[i] = lamp ? holes_lamp(X, Y) : 0.0f;
        const int traced = holes_traced(pattern, x, y, fr);
        const int hit = traced && (!sky || on_lamp[i] > 0.0f); /* else a hole or the sky */
        spp[i] = traced ? 1.0f : 0.0f;
        depth[i] = hit ? cur.eye.z : 0.0f; /* the view axis is -z */
        for (int c = 0; c < 3; c++) {
          /* the lamp's emission, or the sky scene's bright object */
          const float e = on_lamp[i] * (sky ? 20.0f : 4.0f - 0.5f * (float)c);
          emission[3 * i + c] = traced && !sky ? e : 0.0f;
          /* albedo x irradiance (+ emission), or the sky */
          color[3 * i + c] = hit ? truth[3 * i + c] * 0.8f + e : traced ? sky_radiance[c] : 0.0f;
          albedo[3 * i + c] = hit ? 0.8f : traced ? 1.0f : 0.0f;
          normal[3 * i + c] = hit && c == 2 ? 1.0f : 0.0f;
          truth[3 * i + c] = !sky || on_lamp[i] > 0.0f ? truth[3 * i + c] * 0.8f + e : sky_radiance[c];
        }
        position[3 * i] = hit ? X : 0.0f;
        position[3 * i + 1] = hit ? Y : 0.0f;
        position[3 * i + 2] = 0.0f;
      }
    hush_frame_info info;
    hush_frame_info_init(&info);
    info.frame_index = (uint64_t)fr;
    memcpy(info.world_to_view, cur.w2v, sizeof info.world_to_view);
    memcpy(info.view_to_clip, cur.v2c, sizeof info.view_to_clip);
    memcpy(info.prev_world_to_view, prev.w2v, sizeof info.prev_world_to_view);
    memcpy(info.prev_view_to_clip, prev.v2c, sizeof info.prev_view_to_clip);
    info.motion = HUSH_MOTION_CAMERA;
    info.history = fr == 0 ? HUSH_HISTORY_RESET : HUSH_HISTORY_CONTINUE;
    const hush_status s = hush_filter_execute(f, &info);
    if (s != HUSH_OK) {
      const char *msg = NULL;
      hush_device_get_error(dev, &msg);
      CHECK_MSG(0, "%s frame %d: %s", name, fr, msg ? msg : "?");
      break;
    }
    prev = cur;
  }
  double sum = 0.0, tsum = 0.0, err = 0.0;
  for (size_t i = 0; i < n; i++) {
    for (int c = 0; c < 3; c++) r->nonfinite += !isfinite(r->out[3 * i + c]);
    const float l = holes_luma(r->out + 3 * i), lt = holes_luma(truth + 3 * i);
    sum += l;
    tsum += lt;
    const double e = fabs((double)l - lt) / lt;
    err += e;
    if (e > r->max_rel_err && getenv("HUSH_HOLES_VERBOSE") && e > 0.1)
      printf("  %s: pixel %d,%d: %.4f vs truth %.4f\n", name, (int)(i % W), (int)(i / W), l, lt);
    r->max_rel_err = e > r->max_rel_err ? e : r->max_rel_err;
    /* with a lamp: its pixels at least one pixel inside its edge (an edge
     * moving a third of a pixel a frame is soft by about one pixel) */
    int inside = 1;
    for (int j = -1; lamp && j <= 1; j++)
      for (int k = -1; k <= 1; k++) {
        const int xx = (int)(i % W) + k, yy = (int)(i / W) + j;
        inside &= xx >= 0 && yy >= 0 && xx < W && yy < H && on_lamp[(size_t)yy * W + xx] > 0.0f;
      }
    r->black += inside && !(l >= 0.5f * lt);
    int far_sky = sky;
    for (int j = -3; sky && j <= 3; j++)
      for (int k = -3; k <= 3; k++) {
        const int xx = (int)(i % W) + k, yy = (int)(i / W) + j;
        far_sky &= !(xx >= 0 && yy >= 0 && xx < W && yy < H && on_lamp[(size_t)yy * W + xx] > 0.0f);
      }
    r->trail += far_sky && !(l <= 1.0f);
    if (far_sky && !(l <= 1.0f) && getenv("HUSH_HOLES_VERBOSE"))
      printf("  %s: trail at %d,%d: %.3f\n", name, (int)(i % W), (int)(i / W), l);
  }
  r->mean = sum / (double)n;
  r->truth_mean = tsum / (double)n;
  r->mean_rel_err = err / (double)n;
  hush_filter_release(f);
  hush_device_release(dev);
  free(color);
  free(depth);
  free(normal);
  free(position);
  free(albedo);
  free(spp);
  free(truth);
  free(emission);
  free(on_lamp);
}

static void holes_run_extra(const char *name, const char *const *sets, holes_pattern pattern,
                            int W, int H, int frames, float pan, const char *extra,
                            holes_result *r) {
  holes_run_lamp(name, sets, pattern, W, H, frames, pan, extra, 0, r);
}

static void holes_run(const char *name, const char *const *sets, holes_pattern pattern, int W,
                      int H, int frames, float pan, holes_result *r) {
  holes_run_extra(name, sets, pattern, W, H, frames, pan, NULL, r);
}

/*
 * The properties every hole-aware temporal filter must have (docs/holes.md):
 *  - 'spp' bound and all 1: the output is bit-identical to 'spp' unbound;
 *  - still camera, 1/4 spp, after `frames` (>= 4) frames: no pixel black
 *    (below half the truth), nothing non-finite, the mean within mean_tol
 *    (relative) of the 1 spp run's mean;
 *  - panning camera at 1/4 spp: no pixel black, nothing non-finite, mean
 *    relative error below err_tol and no pixel off by more than max_tol
 *    (a streak, a smear of old values or of holes, would be).
 */
static void holes_check_filter(const char *name, const char *const *sets, int frames,
                               double mean_tol, double err_tol, double max_tol) {
  const int W = 40, H = 24;
  holes_result full, full_spp, quarter, moving;
  holes_run(name, sets, HOLES_FULL, W, H, frames, 0.0f, &full);
  holes_run(name, sets, HOLES_FULL_SPP, W, H, frames, 0.0f, &full_spp);
  CHECK_MSG(memcmp(full.out, full_spp.out, 3 * sizeof(float) * W * H) == 0,
            "%s: 'spp' all 1 is not bit-identical to no 'spp'", name);
  holes_run(name, sets, HOLES_QUARTER, W, H, frames, 0.0f, &quarter);
  CHECK_MSG(quarter.nonfinite == 0 && quarter.black == 0,
            "%s, still camera, 1/4 spp, %d frames: %d black pixels, %d non-finite values", name,
            frames, quarter.black, quarter.nonfinite);
  CHECK_MSG(fabs(quarter.mean - full.mean) <= mean_tol * full.mean,
            "%s, still camera: mean %.5f at 1/4 spp, %.5f at 1 spp (truth %.5f)", name,
            quarter.mean, full.mean, full.truth_mean);
  holes_run(name, sets, HOLES_QUARTER, W, H, frames, 0.05f, &moving);
  CHECK_MSG(moving.nonfinite == 0 && moving.black == 0,
            "%s, moving camera, 1/4 spp: %d black pixels, %d non-finite values", name,
            moving.black, moving.nonfinite);
  CHECK_MSG(moving.mean_rel_err <= err_tol && moving.max_rel_err <= max_tol,
            "%s, moving camera, 1/4 spp: relative error mean %.4f (max %.4f), largest %.4f "
            "(max %.4f)",
            name, moving.mean_rel_err, err_tol, moving.max_rel_err, max_tol);
  if (getenv("HUSH_HOLES_VERBOSE"))
    printf("%s: still mean %.5f / %.5f (truth %.5f), rel err %.4f max %.4f; moving rel err %.4f "
           "max %.4f\n",
           name, quarter.mean, full.mean, full.truth_mean, quarter.mean_rel_err,
           quarter.max_rel_err, moving.mean_rel_err, moving.max_rel_err);
  free(full.out);
  free(full_spp.out);
  free(quarter.out);
  free(moving.out);
}

/*
 * Lights seen directly at 1/4 spp (docs/holes.md): with 'emission' bound
 * and the filter's emission bypass on, no pixel inside a lamp is darker
 * than half its truth after `frames` frames, still or moving: the emission
 * of the holes is filled like the G-buffer, not taken as 0, and a hole
 * keeps the emission it had.
 */
static void holes_check_lamp(const char *name, const char *const *sets, int frames) {
  const int W = 40, H = 24;
  holes_result still, moving;
  holes_run_lamp(name, sets, HOLES_QUARTER, W, H, frames, 0.0f, NULL, 1, &still);
  holes_run_lamp(name, sets, HOLES_QUARTER, W, H, frames, 0.05f, NULL, 1, &moving);
  CHECK_MSG(still.black == 0 && still.nonfinite == 0 && moving.black == 0 &&
                moving.nonfinite == 0,
            "%s, lamp at 1/4 spp: %d (still) and %d (moving) lamp pixels below half the truth, "
            "%d non-finite values",
            name, still.black, moving.black, still.nonfinite + moving.nonfinite);
  free(still.out);
  free(moving.out);
}

/*
 * A bright object against the sky (depth 0) at 1/4 spp, the camera panning
 * about a pixel a frame (the object moves, the sky at infinity does not):
 * no sky pixel three pixels or more from the object brighter than 1 (a
 * trail: holes between the object and the sky that took the object's
 * depth or state along; nearer, the fill's first level, 3x3 blocks looked
 * up bilinearly, may see the object), and no pixel inside the object
 * darker than half its truth.
 */
static void holes_check_sky(const char *name, const char *const *sets, int frames) {
  holes_result r;
  holes_run_lamp(name, sets, HOLES_QUARTER, 48, 32, frames, 0.15f, NULL, 2, &r);
  CHECK_MSG(r.trail == 0 && r.black == 0 && r.nonfinite == 0,
            "%s, object against the sky at 1/4 spp, panning: %d sky pixels in its trail, %d "
            "object pixels below half the truth, %d non-finite values",
            name, r.trail, r.black, r.nonfinite);
  free(r.out);
}

#endif
