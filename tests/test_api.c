/*
 * test_api.c — the public API contract, through hush.h only: class tables
 * are well formed, and every kind of misuse returns the documented status
 * with a message that names the culprit (NULL handles, unknown names, type
 * and range errors, missing or mismatched images, execute before commit,
 * bad frame info, overlapping output), and what every filter makes of odd
 * but finite input (normals not of unit length, values up to the limit).
 */
#include "check.h"

#include "hush.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define W 16
#define H 8

static hush_device dev;

/* Reads the device error and checks its status and a word of its message. */
static int expect_error(hush_device d, hush_status want, const char *word) {
  const char *msg = NULL;
  const hush_status got = hush_device_get_error(d, &msg);
  if (got != want || !msg || (word && !strstr(msg, word))) {
    fprintf(stderr, "  expected %s with '%s', got %s: %s\n", hush_status_name(want),
            word ? word : "", hush_status_name(got), msg ? msg : "(null)");
    return 0;
  }
  return 1;
}

static void test_class_tables(void) {
  const uint32_t n = hush_filter_class_count();
  CHECK(n >= 1);
  CHECK(hush_filter_class_at(n) == NULL);
  CHECK(hush_filter_class_find("accumulate") != NULL);
  CHECK(hush_filter_class_find("no-such-filter") == NULL);
  CHECK(hush_filter_class_find(NULL) == NULL);
  for (uint32_t i = 0; i < n; i++) {
    const hush_filter_class_info *c = hush_filter_class_at(i);
    REQUIRE(c && c->name && c->doc && c->paper);
    CHECK(c->param_count >= 1 && strcmp(c->params[0].name, "nonfinite") == 0);
    int has_output = 0;
    for (uint32_t k = 0; k < c->image_count; k++) {
      const hush_image_info *im = &c->images[k];
      CHECK(im->name && im->doc && im->doc[0] && im->channels >= 1 && im->channels <= 4);
      if (!strcmp(im->name, "output") && im->role == HUSH_IMAGE_OUTPUT && im->required) has_output = 1;
      for (uint32_t j = 0; j < k; j++) CHECK(strcmp(c->images[j].name, im->name) != 0);
    }
    CHECK_MSG(has_output, "%s has no required 'output'", c->name);
    for (uint32_t k = 0; k < c->param_count; k++) {
      const hush_param_info *p = &c->params[k];
      CHECK(p->name && p->doc && p->doc[0]);
      for (uint32_t j = 0; j < k; j++) CHECK(strcmp(c->params[j].name, p->name) != 0);
      if (p->type != HUSH_PARAM_BOOL)
        CHECK_MSG(p->default_value >= p->min_value && p->default_value <= p->max_value,
                  "%s.%s default outside its range", c->name, p->name);
      if (p->type == HUSH_PARAM_ENUM) {
        CHECK(p->enum_names != NULL && p->min_value == 0);
        for (int e = 0; p->enum_names && e <= (int)p->max_value; e++) CHECK(p->enum_names[e] != NULL);
      }
      if (p->type == HUSH_PARAM_INT || p->type == HUSH_PARAM_ENUM)
        CHECK(p->default_value == (double)(int)p->default_value);
    }
  }
}

static void test_params(void) {
  CHECK(hush_filter_new(NULL, "accumulate") == NULL);
  CHECK(expect_error(NULL, HUSH_ERROR_INVALID_ARGUMENT, "device"));
  CHECK(hush_filter_new(dev, "nope") == NULL);
  CHECK(expect_error(dev, HUSH_ERROR_NOT_FOUND, "accumulate")); /* lists the known ones */
  CHECK(hush_filter_new(dev, NULL) == NULL);
  CHECK(expect_error(dev, HUSH_ERROR_NOT_FOUND, NULL));

  hush_filter f = hush_filter_new(dev, "accumulate");
  REQUIRE(f != NULL);
  CHECK(strcmp(hush_filter_get_class(f)->name, "accumulate") == 0);

  /* Defaults read back as the table says. */
  const hush_filter_class_info *c = hush_filter_get_class(f);
  for (uint32_t k = 0; k < c->param_count; k++) {
    const hush_param_info *p = &c->params[k];
    if (p->type == HUSH_PARAM_FLOAT) {
      float v = -1;
      CHECK(hush_filter_get_float(f, p->name, &v) == HUSH_OK && v == (float)p->default_value);
    } else {
      int v = -1;
      CHECK(hush_filter_get_int(f, p->name, &v) == HUSH_OK && v == (int)p->default_value);
    }
  }

  CHECK(hush_filter_set_float(f, "no_such_param", 1.0f) == HUSH_ERROR_NOT_FOUND);
  CHECK(expect_error(dev, HUSH_ERROR_NOT_FOUND, "no_such_param"));
  CHECK(hush_filter_set_float(f, "alpha_min", 1.5f) == HUSH_ERROR_OUT_OF_RANGE);
  CHECK(expect_error(dev, HUSH_ERROR_OUT_OF_RANGE, "alpha_min"));
  CHECK(hush_filter_set_float(f, "alpha_min", NAN) == HUSH_ERROR_OUT_OF_RANGE);
  CHECK(expect_error(dev, HUSH_ERROR_OUT_OF_RANGE, "finite"));
  CHECK(hush_filter_set_bool(f, "alpha_min", 1) == HUSH_ERROR_TYPE_MISMATCH);
  CHECK(expect_error(dev, HUSH_ERROR_TYPE_MISMATCH, "float"));
  CHECK(hush_filter_set_float(f, "alpha_min", 0.25f) == HUSH_OK);
  float a = 0;
  CHECK(hush_filter_get_float(f, "alpha_min", &a) == HUSH_OK && a == 0.25f);
  CHECK(hush_filter_set_string(f, "alpha_min", "0.5") == HUSH_OK);
  CHECK(hush_filter_get_float(f, "alpha_min", &a) == HUSH_OK && a == 0.5f);
  CHECK(hush_filter_set_string(f, "alpha_min", "half") == HUSH_ERROR_TYPE_MISMATCH);
  CHECK(expect_error(dev, HUSH_ERROR_TYPE_MISMATCH, "half"));
  CHECK(hush_filter_set_string(f, "max_age", "2.5") == HUSH_ERROR_TYPE_MISMATCH);
  CHECK(expect_error(dev, HUSH_ERROR_TYPE_MISMATCH, "max_age"));
  CHECK(hush_filter_set_float(f, "max_age", 2.5f) == HUSH_ERROR_TYPE_MISMATCH);
  CHECK(expect_error(dev, HUSH_ERROR_TYPE_MISMATCH, "int"));
  CHECK(hush_filter_set_int(f, "max_age", 0) == HUSH_ERROR_OUT_OF_RANGE);
  CHECK(expect_error(dev, HUSH_ERROR_OUT_OF_RANGE, "max_age"));
  CHECK(hush_filter_set_string(f, "nonfinite", "replace") == HUSH_OK);
  int e = -1;
  CHECK(hush_filter_get_int(f, "nonfinite", &e) == HUSH_OK && e == 1);
  CHECK(hush_filter_set_string(f, "nonfinite", "ignore") == HUSH_ERROR_OUT_OF_RANGE);
  CHECK(expect_error(dev, HUSH_ERROR_OUT_OF_RANGE, "error, replace"));
  CHECK(hush_filter_set_int(f, "nonfinite", 2) == HUSH_ERROR_OUT_OF_RANGE);
  CHECK(expect_error(dev, HUSH_ERROR_OUT_OF_RANGE, NULL));
  CHECK(hush_filter_set_string(f, "use_id", "maybe") == HUSH_ERROR_TYPE_MISMATCH);
  CHECK(expect_error(dev, HUSH_ERROR_TYPE_MISMATCH, "bool"));
  CHECK(hush_filter_set_string(f, "use_id", "false") == HUSH_OK);
  CHECK(hush_filter_set_string(f, "use_id", NULL) == HUSH_ERROR_INVALID_ARGUMENT);
  CHECK(expect_error(dev, HUSH_ERROR_INVALID_ARGUMENT, NULL));
  CHECK(hush_filter_get_float(f, "alpha_min", NULL) == HUSH_ERROR_INVALID_ARGUMENT);
  CHECK(expect_error(dev, HUSH_ERROR_INVALID_ARGUMENT, NULL));

  /* NULL filter handles: an error, never a crash. */
  CHECK(hush_filter_set_float(NULL, "alpha_min", 0.1f) == HUSH_ERROR_INVALID_ARGUMENT);
  CHECK(hush_filter_commit(NULL) == HUSH_ERROR_INVALID_ARGUMENT);
  CHECK(hush_filter_execute(NULL, NULL) == HUSH_ERROR_INVALID_ARGUMENT);
  CHECK(hush_filter_set_image(NULL, "color", NULL) == HUSH_ERROR_INVALID_ARGUMENT);
  hush_device_get_error(NULL, NULL);
  hush_filter_release(NULL);
  hush_filter_retain(NULL);
  hush_device_release(NULL);
  hush_filter_release(f);
}

static float color[W * H * 3], depth[W * H], normal[W * H * 3], out[W * H * 3];
static float small[4 * 4 * 3];

static hush_image_view view(void *p, hush_format fmt, uint32_t w, uint32_t h) {
  hush_image_view v = {p, fmt, w, h, 0, 0, 0};
  return v;
}

static void test_images_and_commit(void) {
  for (int i = 0; i < W * H; i++) {
    depth[i] = 2.0f;
    normal[3 * i + 2] = 1.0f;
    color[3 * i] = color[3 * i + 1] = color[3 * i + 2] = 0.5f;
  }
  hush_filter f = hush_filter_new(dev, "accumulate");
  REQUIRE(f != NULL);
  hush_image_view vc = view(color, HUSH_FORMAT_FLOAT3, W, H);
  hush_image_view vd = view(depth, HUSH_FORMAT_FLOAT, W, H);
  hush_image_view vn = view(normal, HUSH_FORMAT_FLOAT3, W, H);
  hush_image_view vo = view(out, HUSH_FORMAT_FLOAT3, W, H);

  CHECK(hush_filter_set_image(f, "colour", &vc) == HUSH_ERROR_NOT_FOUND);
  CHECK(expect_error(dev, HUSH_ERROR_NOT_FOUND, "colour"));
  CHECK(hush_filter_set_image(f, "color", NULL) == HUSH_ERROR_INVALID_ARGUMENT);
  CHECK(expect_error(dev, HUSH_ERROR_INVALID_ARGUMENT, "color"));
  CHECK(hush_filter_set_image(f, "color", &vd) == HUSH_ERROR_INVALID_ARGUMENT); /* 1 channel */
  CHECK(expect_error(dev, HUSH_ERROR_INVALID_ARGUMENT, "channel"));
  hush_image_view v4 = view(out, HUSH_FORMAT_FLOAT4, W, H / 2);
  CHECK(hush_filter_set_image(f, "output", &v4) == HUSH_ERROR_INVALID_ARGUMENT); /* exactly 3 */
  CHECK(expect_error(dev, HUSH_ERROR_INVALID_ARGUMENT, "exactly"));

  CHECK(hush_filter_execute(f, NULL) == HUSH_ERROR_INVALID_OPERATION);
  CHECK(expect_error(dev, HUSH_ERROR_INVALID_OPERATION, "commit"));
  CHECK(hush_filter_commit(f) == HUSH_ERROR_INVALID_OPERATION); /* nothing bound */
  CHECK(expect_error(dev, HUSH_ERROR_INVALID_OPERATION, NULL));

  CHECK(hush_filter_set_image(f, "color", &vc) == HUSH_OK);
  CHECK(hush_filter_set_image(f, "depth", &vd) == HUSH_OK);
  CHECK(hush_filter_set_image(f, "output", &vo) == HUSH_OK);
  CHECK(hush_filter_commit(f) == HUSH_ERROR_INVALID_OPERATION); /* normal missing */
  CHECK(expect_error(dev, HUSH_ERROR_INVALID_OPERATION, "normal"));

  hush_image_view vs = view(small, HUSH_FORMAT_FLOAT3, 4, 4);
  CHECK(hush_filter_set_image(f, "normal", &vs) == HUSH_OK);
  CHECK(hush_filter_commit(f) == HUSH_ERROR_INVALID_ARGUMENT); /* sizes differ */
  CHECK(expect_error(dev, HUSH_ERROR_INVALID_ARGUMENT, "4x4"));

  CHECK(hush_filter_set_image(f, "normal", &vn) == HUSH_OK);
  hush_image_view overlap = view(color, HUSH_FORMAT_FLOAT3, W, H);
  CHECK(hush_filter_set_image(f, "output", &overlap) == HUSH_OK);
  CHECK(hush_filter_commit(f) == HUSH_ERROR_INVALID_ARGUMENT);
  CHECK(expect_error(dev, HUSH_ERROR_INVALID_ARGUMENT, "overlaps"));
  CHECK(hush_filter_set_image(f, "output", &vo) == HUSH_OK);
  CHECK(hush_filter_commit(f) == HUSH_OK);

  hush_frame_info info;
  hush_frame_info_init(&info);
  CHECK(info.size == sizeof info && info.motion == HUSH_MOTION_CAMERA);
  CHECK(hush_filter_execute(f, &info) == HUSH_OK);
  CHECK(out[0] == 0.5f);

  const char *const *names;
  const double *ms;
  uint32_t count = 0;
  CHECK(hush_filter_get_timings(f, &names, &ms, &count) == HUSH_OK);
  CHECK(count >= 1 && names[0] != NULL && ms[0] >= 0.0);

  hush_frame_info bad = info;
  bad.size = 3;
  CHECK(hush_filter_execute(f, &bad) == HUSH_ERROR_INVALID_ARGUMENT);
  CHECK(expect_error(dev, HUSH_ERROR_INVALID_ARGUMENT, "size"));
  bad = info;
  bad.world_to_view[5] = INFINITY;
  CHECK(hush_filter_execute(f, &bad) == HUSH_ERROR_NONFINITE);
  CHECK(expect_error(dev, HUSH_ERROR_NONFINITE, "matrix"));
  bad = info;
  bad.motion = (hush_motion_source)7;
  CHECK(hush_filter_execute(f, &bad) == HUSH_ERROR_INVALID_ARGUMENT);
  CHECK(expect_error(dev, HUSH_ERROR_INVALID_ARGUMENT, "motion"));

  /* A binding of another size invalidates the commit. */
  CHECK(hush_filter_set_image(f, "color", &vs) == HUSH_OK);
  CHECK(hush_filter_execute(f, &info) == HUSH_ERROR_INVALID_OPERATION);
  CHECK(expect_error(dev, HUSH_ERROR_INVALID_OPERATION, NULL));
  CHECK(hush_filter_set_image(f, "color", &vc) == HUSH_OK);
  CHECK(hush_filter_commit(f) == HUSH_OK);

  /* Unsetting a required image makes execute fail, not crash. */
  CHECK(hush_filter_unset_image(f, "depth") == HUSH_OK);
  CHECK(hush_filter_execute(f, &info) == HUSH_ERROR_INVALID_OPERATION);
  CHECK(expect_error(dev, HUSH_ERROR_INVALID_OPERATION, "depth"));
  CHECK(hush_filter_unset_image(f, "bogus") == HUSH_ERROR_NOT_FOUND);
  CHECK(expect_error(dev, HUSH_ERROR_NOT_FOUND, "bogus"));
  hush_filter_release(f);
}

static void test_frames(void) {
  hush_frame fr = hush_frame_new(dev, 8, 4);
  REQUIRE(fr != NULL);
  hush_image_view v;
  CHECK(hush_frame_add_layer(fr, "color", 3, &v) == HUSH_OK);
  CHECK(v.width == 8 && v.height == 4 && v.format == HUSH_FORMAT_FLOAT3);
  CHECK(hush_frame_add_layer(fr, "bad", 5, NULL) == HUSH_ERROR_INVALID_ARGUMENT);
  CHECK(expect_error(dev, HUSH_ERROR_INVALID_ARGUMENT, NULL));
  CHECK(hush_frame_add_layer(fr, "", 1, NULL) == HUSH_ERROR_INVALID_ARGUMENT);
  CHECK(expect_error(dev, HUSH_ERROR_INVALID_ARGUMENT, NULL));
  CHECK(hush_frame_get_layer(fr, "normal", &v) == HUSH_ERROR_NOT_FOUND);
  CHECK(expect_error(dev, HUSH_ERROR_NOT_FOUND, "normal"));
  CHECK(hush_frame_layer_count(fr) == 1);
  CHECK(strcmp(hush_frame_layer_name(fr, 0), "color") == 0);
  CHECK(hush_frame_layer_name(fr, 1) == NULL);
  CHECK(hush_frame_new(dev, 0, 4) == NULL);
  CHECK(expect_error(dev, HUSH_ERROR_INVALID_ARGUMENT, NULL));
  hush_frame_release(fr);
  hush_frame f2 = NULL;
  CHECK(hush_frame_read_exr(dev, "/nonexistent/dir/x.exr", &f2) == HUSH_ERROR_IO);
  CHECK(expect_error(dev, HUSH_ERROR_IO, "/nonexistent/dir/x.exr"));
  CHECK(f2 == NULL);
}

/* ---- what every filter makes of odd but finite input ----------------- */

#define BW 40
#define BH 24
#define BN (BW * BH)

/* A frame every filter takes: a wall with a step in depth and a crease in
 * its normal, a noisy colour, a grey albedo. */
typedef struct bench_frame {
  float color[BN * 3], depth[BN], normal[BN * 3], albedo[BN * 3], position[BN * 3];
  float motion[BN * 2]; /* 0: a static scene, each pixel its own history */
  float out[BN * 3];
} bench_frame;

static float hash01(uint32_t i) {
  i = i * 0x9e3779b9u ^ (i >> 15);
  i *= 0x85ebca6bu;
  i ^= i >> 13;
  return (float)(i >> 8) / 16777216.0f;
}

static void bench_fill(bench_frame *b, int k) {
  for (int i = 0; i < BN; i++) {
    const int x = i % BW;
    b->depth[i] = x < BW / 2 ? 3.0f : 5.0f;
    b->position[3 * i + 0] = 0.1f * (float)x;
    b->position[3 * i + 1] = 0.1f * (float)(i / BW);
    b->position[3 * i + 2] = -b->depth[i];
    b->normal[3 * i + 0] = x < BW / 3 ? 1.0f : 0.0f;
    b->normal[3 * i + 1] = 0.0f;
    b->normal[3 * i + 2] = x < BW / 3 ? 0.0f : 1.0f;
    for (int c = 0; c < 3; c++) {
      b->color[3 * i + c] = 0.4f + 0.5f * hash01((uint32_t)(i * 3 + c + k * BN * 3));
      b->albedo[3 * i + c] = 0.5f;
    }
  }
}

/* The planes of a w x h frame that bind_frame binds by image name. */
typedef struct frame_planes {
  float *color, *depth, *normal, *albedo, *position, *motion, *out;
} frame_planes;

/* Binds every image of f's class that planes has (others stay unbound). */
static void bind_frame(hush_filter f, const frame_planes *p, uint32_t w, uint32_t h) {
  const hush_filter_class_info *ci = hush_filter_get_class(f);
  for (uint32_t k = 0; k < ci->image_count; k++) {
    const char *name = ci->images[k].name;
    hush_image_view v = {0};
    if (!strcmp(name, "color")) v = view(p->color, HUSH_FORMAT_FLOAT3, w, h);
    else if (!strcmp(name, "depth")) v = view(p->depth, HUSH_FORMAT_FLOAT, w, h);
    else if (!strcmp(name, "normal")) v = view(p->normal, HUSH_FORMAT_FLOAT3, w, h);
    else if (!strcmp(name, "albedo")) v = view(p->albedo, HUSH_FORMAT_FLOAT3, w, h);
    else if (!strcmp(name, "position")) v = view(p->position, HUSH_FORMAT_FLOAT3, w, h);
    else if (!strcmp(name, "motion")) v = view(p->motion, HUSH_FORMAT_FLOAT2, w, h);
    else if (!strcmp(name, "output")) v = view(p->out, HUSH_FORMAT_FLOAT3, w, h);
    else continue;
    CHECK(hush_filter_set_image(f, name, &v) == HUSH_OK);
  }
}

static hush_filter bench_filter(const char *cls, bench_frame *b) {
  hush_filter f = hush_filter_new(dev, cls);
  REQUIRE(f != NULL);
  const frame_planes p = {b->color,    b->depth,  b->normal, b->albedo,
                          b->position, b->motion, b->out};
  bind_frame(f, &p, BW, BH);
  CHECK(hush_filter_commit(f) == HUSH_OK);
  return f;
}

static int bench_finite(const bench_frame *b) {
  for (int i = 0; i < BN * 3; i++)
    if (!isfinite(b->out[i])) return 0;
  return 1;
}

/* The filters that take this frame (asvgf needs gradient samples). */
static const char *const bench_classes[] = {"accumulate", "svgf", "taa", "bmfr", "nca"};
#define BENCH_CLASSES (sizeof bench_classes / sizeof bench_classes[0])

/*
 * Normals of any length are taken as their directions: the output of the
 * unit normals, within the rescaling's rounding. Lengths of 0.9 used to
 * fail the reprojection's normal test (no history); lengths of 3 made
 * svgf's normal weight overflow (NaN); 1e-20 and 1e14 do not square in
 * float.
 */
static void test_normal_length(void) {
  static const float scales[] = {0.5f, 0.9f, 3.0f, 1e-20f, 1e14f, 1.0f};
  static bench_frame unit, scaled;
  for (size_t c = 0; c < BENCH_CLASSES; c++) {
    hush_filter fu = bench_filter(bench_classes[c], &unit);
    hush_filter fs = bench_filter(bench_classes[c], &scaled);
    hush_frame_info info;
    hush_frame_info_init(&info);
    info.motion = HUSH_MOTION_VECTORS;
    int same = 1, finite = 1;
    for (int k = 0; k < 4; k++) {
      bench_fill(&unit, k);
      bench_fill(&scaled, k);
      for (int i = 0; i < BN; i++)
        for (int j = 0; j < 3; j++) scaled.normal[3 * i + j] *= scales[(i * 7) % 6];
      info.frame_index = (uint64_t)k;
      CHECK(hush_filter_execute(fu, &info) == HUSH_OK);
      CHECK(hush_filter_execute(fs, &info) == HUSH_OK);
      for (int i = 0; i < BN * 3; i++)
        same &= fabsf(unit.out[i] - scaled.out[i]) <= 1e-4f * (fabsf(unit.out[i]) + 0.1f);
      finite &= bench_finite(&scaled);
    }
    CHECK_MSG(same && finite, "%s: normals not of unit length change the output (finite %d)",
              bench_classes[c], finite);
    hush_filter_release(fu);
    hush_filter_release(fs);
  }
}

/*
 * Input values are accepted up to 1e15 in magnitude, and the output of
 * values that large is finite; beyond, the frame fails like NaN/Inf do (the
 * filters' squares and sums would overflow into NaN), or with
 * nonfinite=replace they become 0.
 */
static void test_input_range(void) {
  static bench_frame b;
  for (size_t c = 0; c < BENCH_CLASSES; c++) {
    hush_filter f = bench_filter(bench_classes[c], &b);
    hush_frame_info info;
    hush_frame_info_init(&info);
    info.motion = HUSH_MOTION_VECTORS;
    for (int k = 0; k < 3; k++) {
      bench_fill(&b, k);
      info.frame_index = (uint64_t)k;
      /* large but accepted, in every image */
      for (int i = 5; i < BN; i += 37) {
        b.color[3 * i] = 9e14f;
        b.albedo[3 * i + 1] = 9e14f;
        b.normal[3 * i + 2] = -9e14f;
        if (i % 2) b.depth[i] = 9e14f;
      }
      CHECK_MSG(hush_filter_execute(f, &info) == HUSH_OK, "%s: 9e14 refused", bench_classes[c]);
      CHECK_MSG(bench_finite(&b), "%s: 9e14 in, NaN/Inf out", bench_classes[c]);
    }
    b.color[3 * 17 + 2] = 2e15f;
    CHECK(hush_filter_execute(f, &info) == HUSH_ERROR_NONFINITE);
    CHECK(expect_error(dev, HUSH_ERROR_NONFINITE, "beyond"));
    b.color[3 * 17 + 2] = 0.5f;
    b.normal[3 * 17] = -3e38f; /* every class here reads the normal */
    CHECK(hush_filter_execute(f, &info) == HUSH_ERROR_NONFINITE);
    CHECK(expect_error(dev, HUSH_ERROR_NONFINITE, "(17, 0)"));
    b.normal[3 * 17] = 0.0f;
    CHECK(hush_filter_set_string(f, "nonfinite", "replace") == HUSH_OK);
    b.color[3 * 18] = 1e30f;
    CHECK(hush_filter_execute(f, &info) == HUSH_OK);
    CHECK(bench_finite(&b));
    hush_filter_release(f);
  }
}

/*
 * A filter committed with less memory than it needs (the device's memory
 * option) fails with HUSH_ERROR_OUT_OF_MEMORY, at whichever allocation the
 * cap is reached, and frees what it had (the sanitizer builds check the
 * leaks); with enough it commits and runs. The cap is what keeps a commit
 * at a size the machine cannot hold from being killed by the kernel.
 */
static void test_memory_cap(void) {
  enum { MW = 512, MH = 512, MN = MW * MH };
  float *buf = calloc((size_t)MN * 18, sizeof(float));
  REQUIRE(buf != NULL);
  frame_planes p;
  p.color = buf;
  p.depth = p.color + 3 * MN;
  p.normal = p.depth + MN;
  p.albedo = p.normal + 3 * MN;
  p.position = p.albedo + 3 * MN;
  p.motion = p.position + 3 * MN;
  p.out = p.motion + 2 * MN;
  for (int i = 0; i < MN; i++) {
    p.depth[i] = 2.0f;
    p.normal[3 * i + 2] = 1.0f;
    p.position[3 * i + 2] = -2.0f;
    for (int c = 0; c < 3; c++) p.color[3 * i + c] = p.albedo[3 * i + c] = 0.5f;
  }
  for (size_t k = 0; k < BENCH_CLASSES; k++) {
    int refused = 0, ran = 0;
    for (int mib = 1; mib <= 256 && !ran; mib++) {
      char config[64];
      snprintf(config, sizeof config, "threads=2, memory=%d", mib);
      hush_device d = hush_device_new(config);
      REQUIRE(d != NULL);
      hush_filter f = hush_filter_new(d, bench_classes[k]);
      REQUIRE(f != NULL);
      bind_frame(f, &p, MW, MH);
      const hush_status s = hush_filter_commit(f);
      if (s == HUSH_OK) {
        /* the first execute allocates the buffers of images first used
         * then (svgf's albedo): counted against what commit left */
        hush_frame_info info;
        hush_frame_info_init(&info);
        const hush_status e = hush_filter_execute(f, &info);
        ran = e == HUSH_OK;
        const int capped =
            e == HUSH_ERROR_OUT_OF_MEMORY && expect_error(d, e, "MiB it may allocate");
        CHECK_MSG(ran || capped, "%s at memory=%d: %s", bench_classes[k], mib, hush_status_name(e));
        /* a flat grey wall stays grey (nca, a learned filter, within 0.1) */
        const float tol = strcmp(bench_classes[k], "nca") ? 1e-3f : 0.1f;
        CHECK_MSG(!ran || (isfinite(p.out[0]) && fabsf(p.out[3 * (MN / 2)] - 0.5f) < tol),
                  "%s: %g", bench_classes[k], p.out[3 * (MN / 2)]);
      } else {
        refused++;
        CHECK_MSG(s == HUSH_ERROR_OUT_OF_MEMORY && expect_error(d, s, "MiB it may allocate"),
                  "%s at memory=%d: %s", bench_classes[k], mib, hush_status_name(s));
        CHECK(hush_filter_execute(f, NULL) == HUSH_ERROR_INVALID_OPERATION);
      }
      hush_filter_release(f);
      hush_device_release(d);
    }
    /* 512x512 planes are 1 MiB each: every filter needs 19-64 MiB to run a frame */
    CHECK_MSG(ran && refused >= 10, "%s: ran %d after %d refusals", bench_classes[k], ran,
              refused);
  }
  free(buf);
}

int main(void) {
  dev = hush_device_new("threads=2");
  REQUIRE(dev != NULL);
  CHECK(strcmp(hush_version(), "0.1.0") == 0);
  test_class_tables();
  test_params();
  test_images_and_commit();
  test_frames();
  test_normal_length();
  test_input_range();
  test_memory_cap();
  hush_device_release(dev);
  return check_summary();
}
