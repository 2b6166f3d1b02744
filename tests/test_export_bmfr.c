/*
 * test_export_bmfr.c — `hush render --export bmfr` (io/export_bmfr.h): the
 * files the published BMFR code opens exist, each EXR has exactly the 3 float
 * channels R, G, B; colour * albedo gives the radiance back (also where the
 * albedo is 0), and sky pixels have colour 1 and their radiance as albedo; camera_matrices.h parses (and compiles, when a C compiler is
 * on the PATH), its matrices are those of cameras.json with clip y negated,
 * and projecting each pixel's world position with them by the code's own
 * formula, uv * size - (offset.x, 1 - offset.y), lands on that pixel; with
 * the previous frame's matrix it lands where the motion vector points.
 */
#include "check.h"

#include "hush.h"
#include "io/export_bmfr.h"
#include "io/frame.h"
#include "io/sequence.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>

#define WORK HUSH_BINARY_DIR "/test_export_bmfr"
#define W 40
#define H 30
#define FRAMES 3

static const float *layer3(hush_frame f, const char *name) {
  hush_layer *l = hush__frame_find(f, name);
  REQUIRE(l && l->channels == 3);
  return l->pixels;
}

/* Reads dir/<name><i>.exr and checks it is one RGB layer of W x H. */
static hush_frame read_rgb(hush_device dev, const char *name, int i) {
  char path[512];
  snprintf(path, sizeof path, WORK "/seq/bmfr/%s%d.exr", name, i);
  hush_frame f = NULL;
  REQUIRE(hush_frame_read_exr(dev, path, &f) == HUSH_OK);
  CHECK_MSG(hush_frame_layer_count(f) == 1 && strcmp(hush_frame_layer_name(f, 0), "color") == 0,
            "%s: expected exactly the channels R, G, B", path);
  CHECK(hush_frame_width(f) == W && hush_frame_height(f) == H);
  layer3(f, "color");
  return f;
}

/* The numbers of the declaration that starts with `decl` (up to its ;), comments skipped. */
static int parse_array(const char *text, const char *decl, float *out, int max) {
  const char *p = strstr(text, decl);
  if (!p) return -1;
  p = strchr(p, '=');
  if (!p) return -1;
  int n = 0;
  while (*p && *p != ';') {
    if (p[0] == '/' && p[1] == '*') {
      const char *end = strstr(p + 2, "*/");
      if (!end) return -1;
      p = end + 2;
    } else if (strchr("+-.0123456789", *p)) {
      char *end;
      const float v = strtof(p, &end);
      if (end == p) return -1;
      if (n < max) out[n] = v;
      n++;
      p = end;
    } else {
      p++;
    }
  }
  return n;
}

static void read_text(const char *path, char *buf, size_t size) {
  buf[0] = '\0';
  FILE *f = fopen(path, "rb");
  REQUIRE(f);
  const size_t n = fread(buf, 1, size - 1, f);
  buf[n] = '\0';
  fclose(f);
}

/* Pixel 0 and 1: surfaces, some albedo channels 0 (the guard); pixel 2: sky
 * (normal 0), demodulated by its own radiance, one channel below the guard. */
static void test_demodulation_guard(hush_device dev) {
  hush_frame f = hush_frame_new(dev, 3, 1);
  REQUIRE(f);
  const char *names[] = {"color", "albedo", "normal", "position"};
  const float values[4][9] = {{0.5f, 0.2f, 0.3f, 4.0f, 0.0f, 1.0f, 20.0f, 0.5f, 1e-5f},
                              {0.5f, 0.0f, 1e-4f, 1.0f, 0.25f, 0.0f, 1.0f, 1.0f, 1.0f},
                              {0, 0, 1, 0, 1, 0, 0, 0, 0},
                              {1, 2, 3, 4, 5, 6, 0, 0, 0}};
  for (int l = 0; l < 4; l++) {
    hush_image_view v;
    REQUIRE(hush_frame_add_layer(f, names[l], 3, &v) == HUSH_OK);
    memcpy(v.data, values[l], sizeof values[l]);
  }
  REQUIRE(system("mkdir -p '" WORK "/guard'") == 0);
  REQUIRE(hush__bmfr_write_frame(dev, WORK "/guard", 7, f) == HUSH_OK);
  hush_frame c = NULL, a = NULL;
  REQUIRE(hush_frame_read_exr(dev, WORK "/guard/color7.exr", &c) == HUSH_OK);
  REQUIRE(hush_frame_read_exr(dev, WORK "/guard/albedo7.exr", &a) == HUSH_OK);
  const float *cc = layer3(c, "color"), *aa = layer3(a, "color");
  const float expect_c[9] = {1.0f, 0.2f, 0.3f, 4.0f, 0.0f, 1.0f, 1.0f, 1.0f, 1e-5f};
  const float expect_a[9] = {0.5f, 1.0f, 1.0f, 1.0f, 0.25f, 1.0f, 20.0f, 0.5f, 1.0f};
  for (int i = 0; i < 9; i++) {
    CHECK_NEAR(cc[i], expect_c[i], 1e-6);
    CHECK_NEAR(aa[i], expect_a[i], 1e-6);
  }
  hush_frame_release(c);
  hush_frame_release(a);
  /* a frame without the layers is an error, not a crash */
  hush_frame empty = hush_frame_new(dev, 2, 1);
  CHECK(hush__bmfr_write_frame(dev, WORK "/guard", 0, empty) == HUSH_ERROR_NOT_FOUND);
  const char *msg = NULL;
  CHECK(hush_device_get_error(dev, &msg) == HUSH_ERROR_NOT_FOUND && msg && strstr(msg, "color"));
  hush_frame_release(empty);
  hush_frame_release(f);
}

static void test_render_export(hush_device dev) {
  char cmd[1024];
  snprintf(cmd, sizeof cmd,
           "'%s' render --scene builtin:cornell-moving --size %dx%d --frames %d --first 1 --quiet "
           "--export bmfr --out '" WORK "/seq'",
           HUSH_CLI, W, H, FRAMES);
  REQUIRE(system(cmd) == 0);
  hush_sequence seq;
  REQUIRE(hush__sequence_read(dev, WORK "/seq", &seq) == HUSH_OK);
  REQUIRE(seq.frame_count == FRAMES);

  static char text[1 << 16];
  read_text(WORK "/seq/bmfr/camera_matrices.h", text, sizeof text);
  float mats[FRAMES * 16 + 1], offs[FRAMES * 2 + 1], lim[2];
  CHECK(parse_array(text, "const float camera_matrices[", mats, FRAMES * 16 + 1) == FRAMES * 16);
  CHECK(parse_array(text, "const float pixel_offsets[", offs, FRAMES * 2 + 1) == FRAMES * 2);
  CHECK(parse_array(text, "const float position_limit_squared", lim, 1) == 1 && lim[0] > 0.0f);
  CHECK(parse_array(text, "const float normal_limit_squared", lim + 1, 1) == 1 && lim[1] > 0.0f);
  CHECK(strstr(text, "const float camera_matrices[3][4][4]") != NULL);
  CHECK(strstr(text, "const float pixel_offsets[3][2]") != NULL);

  for (int i = 0; i < FRAMES; i++) {
    const hush_camera *cam = &seq.cameras[i];
    /* the header's matrix is cameras.json's view_to_clip * world_to_view, y negated */
    float vp[16];
    for (int c = 0; c < 4; c++)
      for (int r = 0; r < 4; r++) {
        double s = 0.0;
        for (int k = 0; k < 4; k++)
          s += (double)cam->view_to_clip[k * 4 + r] * cam->world_to_view[c * 4 + k];
        vp[c * 4 + r] = (float)(r == 1 ? -s : s);
      }
    int bad_m = 0;
    for (int k = 0; k < 16; k++)
      bad_m += fabsf(vp[k] - mats[i * 16 + k]) > 1e-5f * (1.0f + fabsf(vp[k]));
    CHECK_MSG(bad_m == 0, "frame %d: %d matrix elements differ from cameras.json", i, bad_m);
    CHECK_NEAR(offs[2 * i], 0.5f + cam->jitter[0], 1e-6);
    CHECK_NEAR(offs[2 * i + 1], 0.5f - cam->jitter[1], 1e-6);

    hush_frame seqf;
    REQUIRE(hush__sequence_read_frame(dev, &seq, (uint32_t)i, &seqf) == HUSH_OK);
    hush_frame color = read_rgb(dev, "color", i), albedo = read_rgb(dev, "albedo", i);
    hush_frame normal = read_rgb(dev, "shading_normal", i);
    hush_frame position = read_rgb(dev, "world_position", i);
    const float *c = layer3(color, "color"), *a = layer3(albedo, "color");
    const float *nn = layer3(normal, "color"), *pp = layer3(position, "color");
    const float *sc = layer3(seqf, "color"), *sn = layer3(seqf, "normal");
    const float *sp = layer3(seqf, "position");
    const float *m = mats + 16 * i, *o = offs + 2 * i;
    int bad_color = 0, bad_copy = 0, bad_proj = 0, surfaces = 0, top_ndc_neg = 1;
    for (int y = 0; y < H; y++)
      for (int x = 0; x < W; x++) {
        const size_t j = (size_t)y * W + x;
        for (int k = 0; k < 3; k++) {
          const float back = c[3 * j + k] * a[3 * j + k], want = sc[3 * j + k];
          bad_color += fabsf(back - want) > 1e-5f * (1.0f + fabsf(want));
          bad_copy += nn[3 * j + k] != sn[3 * j + k] || pp[3 * j + k] != sp[3 * j + k];
        }
        if (nn[3 * j] == 0.0f && nn[3 * j + 1] == 0.0f && nn[3 * j + 2] == 0.0f) continue; /* sky */
        surfaces++;
        /* the published code's reprojection, with this frame's matrix and offset */
        const float P[4] = {pp[3 * j], pp[3 * j + 1], pp[3 * j + 2], 1.0f};
        float clip[4];
        for (int r = 0; r < 4; r++)
          clip[r] = m[r] * P[0] + m[4 + r] * P[1] + m[8 + r] * P[2] + m[12 + r] * P[3];
        const float u = (clip[0] / clip[3] + 1.0f) * 0.5f, v = (clip[1] / clip[3] + 1.0f) * 0.5f;
        const float px = u * W - o[0], py = v * H - (1.0f - o[1]);
        bad_proj += fabsf(px - (float)x) > 2e-3f || fabsf(py - (float)y) > 2e-3f;
        if (y == 0 && !(clip[1] / clip[3] < -0.9f)) top_ndc_neg = 0;
      }
    CHECK(surfaces > W * H / 2);
    CHECK_MSG(bad_color == 0, "frame %d: %d channels where colour * albedo is not the radiance", i,
              bad_color);
    CHECK_MSG(bad_copy == 0, "frame %d: %d normal/position values differ", i, bad_copy);
    CHECK_MSG(bad_proj == 0, "frame %d: %d pixels do not reproject onto themselves", i, bad_proj);
    CHECK_MSG(top_ndc_neg, "frame %d: the top row is not at NDC y = -1", i);
    hush_frame_release(color);
    hush_frame_release(albedo);
    hush_frame_release(normal);
    hush_frame_release(position);
    hush_frame_release(seqf);
  }
  hush__sequence_free(&seq);

  /* the header compiles as the code includes it (C, and C++ when there is one) */
  if (system("command -v cc > /dev/null 2>&1") == 0)
    CHECK(system("cc -std=c99 -Wall -Werror -fsyntax-only -include '" WORK
                 "/seq/bmfr/camera_matrices.h' -x c /dev/null") == 0);
  if (system("command -v c++ > /dev/null 2>&1") == 0)
    CHECK(system("c++ -std=c++11 -Wall -Werror -fsyntax-only -include '" WORK
                 "/seq/bmfr/camera_matrices.h' -x c++ /dev/null") == 0);
}

/* The published code's first kernel finds a pixel's history by projecting its
 * world position with the PREVIOUS frame's matrix and subtracting THIS frame's
 * offset (bmfr.cpp passes camera_matrices[frame - 1] and pixel_offsets[frame]).
 * With the export's matrices and offsets that must land where the renderer's
 * motion vectors say the point was (a static scene and a moving camera, so
 * the motion is the camera's alone), and the same in every frame. */
static void test_history_reprojection(hush_device dev) {
  char cmd[1024];
  snprintf(cmd, sizeof cmd,
           "'%s' render --scene builtin:cornell --path orbit --size %dx%d --frames %d --first 5 "
           "--quiet --export bmfr --out '" WORK "/orbit'",
           HUSH_CLI, W, H, FRAMES);
  REQUIRE(system(cmd) == 0);
  hush_sequence seq;
  REQUIRE(hush__sequence_read(dev, WORK "/orbit", &seq) == HUSH_OK);
  static char text[1 << 16];
  read_text(WORK "/orbit/bmfr/camera_matrices.h", text, sizeof text);
  float mats[FRAMES * 16 + 1], offs[FRAMES * 2 + 1];
  REQUIRE(parse_array(text, "const float camera_matrices[", mats, FRAMES * 16 + 1) == FRAMES * 16);
  REQUIRE(parse_array(text, "const float pixel_offsets[", offs, FRAMES * 2 + 1) == FRAMES * 2);
  for (int i = 1; i < FRAMES; i++) {
    hush_frame f;
    REQUIRE(hush__sequence_read_frame(dev, &seq, (uint32_t)i, &f) == HUSH_OK);
    hush_layer *ml = hush__frame_find(f, "motion");
    REQUIRE(ml && ml->channels == 2);
    const float *mv = ml->pixels, *nn = layer3(f, "normal"), *pp = layer3(f, "position");
    const float *m = mats + 16 * (i - 1), *o = offs + 2 * i;
    int surfaces = 0, bad = 0, moved = 0;
    for (int y = 0; y < H; y++)
      for (int x = 0; x < W; x++) {
        const size_t j = (size_t)y * W + x;
        if (nn[3 * j] == 0.0f && nn[3 * j + 1] == 0.0f && nn[3 * j + 2] == 0.0f) continue;
        surfaces++;
        const float P[4] = {pp[3 * j], pp[3 * j + 1], pp[3 * j + 2], 1.0f};
        float clip[4];
        for (int r = 0; r < 4; r++)
          clip[r] = m[r] * P[0] + m[4 + r] * P[1] + m[8 + r] * P[2] + m[12 + r] * P[3];
        const float u = (clip[0] / clip[3] + 1.0f) * 0.5f, v = (clip[1] / clip[3] + 1.0f) * 0.5f;
        const float px = u * W - o[0], py = v * H - (1.0f - o[1]);
        bad += fabsf(px - (x + mv[2 * j])) > 2e-3f || fabsf(py - (y + mv[2 * j + 1])) > 2e-3f;
        moved += fabsf(mv[2 * j]) > 0.05f;
      }
    CHECK(surfaces > W * H / 2);
    CHECK_MSG(moved > surfaces / 2, "frame %d: the camera does not move (%d of %d pixels)", i,
              moved, surfaces);
    CHECK_MSG(bad == 0, "frame %d: %d of %d pixels reproject elsewhere than their motion vector",
              i, bad, surfaces);
    hush_frame_release(f);
  }
  hush__sequence_free(&seq);
}

int main(void) {
  REQUIRE(system("rm -rf '" WORK "' && mkdir -p '" WORK "'") == 0);
  hush_device dev = hush_device_new(NULL);
  REQUIRE(dev);
  test_demodulation_guard(dev);
  test_render_export(dev);
  test_history_reprojection(dev);
  hush_device_release(dev);
  return check_summary();
}
