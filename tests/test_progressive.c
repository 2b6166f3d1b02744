/*
 * test_progressive.c — fewer than one sample per pixel (render/progressive.h,
 * svgf-progressive-dundr-2018.md §4.2): the fraction's block and share; every
 * pixel traced exactly once per cycle; every k x k block traces exactly its
 * share each frame; consecutive frames spread over the block; a render with
 * holes (spp 0, features 0, vis -1) whose traced pixels equal a full render's.
 */
#include "check.h"
#include "holes_check.h"

#include "core/image.h"
#include "filters/holes.h"
#include "io/frame.h"
#include "render/camera.h"
#include "render/lights.h"
#include "render/progressive.h"
#include "render/render.h"
#include "render/scene.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

static void test_fractions(void) {
  const struct {
    double f;
    uint32_t k, m;
  } cases[] = {{1.0, 1, 1},          {0.5, 2, 2},   {0.25, 2, 1},  {0.75, 2, 3},
               {1.0 / 9.0, 3, 1},    {0.125, 4, 2}, {1.0 / 16, 4, 1}, {0.1, 10, 10},
               {0.3, 10, 30},        {1.0 / 256, 16, 1}, {0.1111, 3, 1}};
  for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
    hush_progressive p;
    CHECK_MSG(hush__progressive_init(&p, cases[i].f) && p.k == cases[i].k && p.m == cases[i].m,
              "fraction %g: k %u m %u, expected %u %u", cases[i].f, p.k, p.m, cases[i].k,
              cases[i].m);
  }
  const double bad[] = {0.0, -0.25, 1.5, 0.123, 1e-4, NAN};
  for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
    hush_progressive p;
    CHECK_MSG(!hush__progressive_init(&p, bad[i]), "fraction %g accepted", bad[i]);
  }
  hush_progressive p;
  CHECK(!hush__progressive_init_km(&p, 0, 1) && !hush__progressive_init_km(&p, 17, 1) &&
        !hush__progressive_init_km(&p, 2, 5) && !hush__progressive_init_km(&p, 2, 0));
}

/* The 2x2 pattern of the documentation: top-left, bottom-right, top-right,
 * bottom-left, then again. */
static void test_quarter_order(void) {
  hush_progressive p;
  REQUIRE(hush__progressive_init(&p, 0.25));
  const uint32_t expect[4][2] = {{0, 0}, {1, 1}, {1, 0}, {0, 1}};
  for (uint32_t f = 0; f < 8; f++)
    for (uint32_t y = 0; y < 2; y++)
      for (uint32_t x = 0; x < 2; x++)
        CHECK_MSG(hush__progressive_traced(&p, x, y, f) ==
                      (x == expect[f % 4][0] && y == expect[f % 4][1]),
                  "frame %u pixel %u,%u", f, x, y);
}

/* On a w x h image: per frame, every full block traces exactly m pixels;
 * over k^2 frames every pixel is traced m times; with a cycle, every window
 * of `cycle` consecutive frames traces every pixel exactly once. */
static void check_pattern(uint32_t k, uint32_t m, uint32_t w, uint32_t h, uint32_t first) {
  hush_progressive p;
  REQUIRE(hush__progressive_init_km(&p, k, m));
  const uint32_t n = k * k, cycle = hush__progressive_cycle(&p);
  CHECK(cycle == (n % m == 0 ? n / m : 0));
  uint32_t *count = calloc((size_t)w * h, sizeof *count);
  REQUIRE(count);
  int bad_share = 0, bad_window = 0;
  for (uint32_t f = first; f < first + n; f++) {
    for (uint32_t by = 0; by + k <= h; by += k)
      for (uint32_t bx = 0; bx + k <= w; bx += k) {
        uint32_t traced = 0;
        for (uint32_t y = by; y < by + k; y++)
          for (uint32_t x = bx; x < bx + k; x++) traced += hush__progressive_traced(&p, x, y, f);
        bad_share += traced != m;
      }
    for (uint32_t y = 0; y < h; y++)
      for (uint32_t x = 0; x < w; x++)
        count[(size_t)y * w + x] += hush__progressive_traced(&p, x, y, f);
  }
  int bad_total = 0;
  for (size_t i = 0; i < (size_t)w * h; i++) bad_total += count[i] != m;
  if (cycle) {
    for (uint32_t start = first; start < first + cycle; start++)
      for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++) {
          uint32_t c = 0;
          for (uint32_t f = start; f < start + cycle; f++)
            c += hush__progressive_traced(&p, x, y, f);
          bad_window += c != 1;
        }
  }
  CHECK_MSG(!bad_share && !bad_total && !bad_window,
            "k %u m %u on %ux%u from frame %u: %d blocks off their share, %d pixels not traced "
            "%u times in %u frames, %d pixel-windows not traced once",
            k, m, w, h, first, bad_share, bad_total, m, n, bad_window);
  free(count);
}

static void test_patterns(void) {
  for (uint32_t k = 1; k <= 6; k++)
    for (uint32_t m = 1; m <= k * k; m++) check_pattern(k, m, 3 * k + 1, 2 * k + 1, 5);
  check_pattern(16, 1, 35, 33, 0);
  check_pattern(16, 16, 32, 32, 1000003);
  check_pattern(10, 10, 21, 20, 7);
}

/* Bayer ranks spread consecutive frames: with 4x4 blocks and 4 pixels a
 * frame, each frame's pixels fall in the four different 2x2 quadrants, and
 * with 1 pixel a frame, frames 4j .. 4j+3 also do. */
static void test_stratified(void) {
  hush_progressive p;
  REQUIRE(hush__progressive_init_km(&p, 4, 4));
  int bad = 0;
  for (uint32_t f = 0; f < 4; f++) {
    int quadrant[4] = {0, 0, 0, 0};
    for (uint32_t y = 0; y < 4; y++)
      for (uint32_t x = 0; x < 4; x++)
        if (hush__progressive_traced(&p, x, y, f)) quadrant[(y / 2) * 2 + x / 2]++;
    for (int q = 0; q < 4; q++) bad += quadrant[q] != 1;
  }
  REQUIRE(hush__progressive_init_km(&p, 4, 1));
  for (uint32_t j = 0; j < 4; j++) {
    int quadrant[4] = {0, 0, 0, 0};
    for (uint32_t f = 4 * j; f < 4 * j + 4; f++)
      for (uint32_t y = 0; y < 4; y++)
        for (uint32_t x = 0; x < 4; x++)
          if (hush__progressive_traced(&p, x, y, f)) quadrant[(y / 2) * 2 + x / 2]++;
    for (int q = 0; q < 4; q++) bad += quadrant[q] != 1;
  }
  /* a non-power-of-two block: the corner of the 4x4 Bayer matrix, cycle 3 */
  REQUIRE(hush__progressive_init_km(&p, 3, 3));
  CHECK(hush__progressive_cycle(&p) == 3);
  CHECK_MSG(bad == 0, "%d quadrants without exactly one pixel", bad);
  /* deterministic: the same fraction gives the same table */
  hush_progressive a, b;
  REQUIRE(hush__progressive_init(&a, 0.1) && hush__progressive_init(&b, 0.1));
  CHECK(memcmp(&a, &b, sizeof a) == 0);
}

/* ---- a render with holes ------------------------------------------------------------ */

static hush_frame render(hush_device dev, hush_scene *sc, hush_lights *li,
                         const hush_render_params *p, uint32_t f) {
  REQUIRE(hush__scene_set_frame(dev, sc, f) == HUSH_OK);
  hush__lights_set_frame(li, f);
  hush_camera_pose pose;
  int ax;
  float zn, zf;
  hush__camera_pose(sc, HUSH_MOVE_ORBIT, NULL, f, &pose, &ax);
  hush__camera_clip_range(sc, hush_v3(pose.position[0], pose.position[1], pose.position[2]), &zn,
                          &zf);
  hush_render_camera cam, prev;
  REQUIRE(hush__camera_setup(&cam, &pose, ax, p->width, p->height, zn, zf, f, p->jitter));
  hush__camera_pose(sc, HUSH_MOVE_ORBIT, NULL, f - 1, &pose, &ax);
  REQUIRE(hush__camera_setup(&prev, &pose, ax, p->width, p->height, zn, zf, f - 1, p->jitter));
  hush_render_ctx ctx;
  hush__render_ctx_init(&ctx, sc, li, p, &cam, &prev, f);
  hush_frame out = hush_frame_new(dev, p->width, p->height);
  REQUIRE(out);
  REQUIRE(hush__render_frame(dev, &ctx, out, NULL, NULL, NULL) == HUSH_OK);
  return out;
}

static const float *pixels(hush_frame f, const char *name, int *channels) {
  hush_layer *l = hush__frame_find(f, name);
  REQUIRE(l);
  *channels = l->channels;
  return l->pixels;
}

static void test_render_holes(void) {
  hush_device dev = hush_device_new("threads=2");
  REQUIRE(dev);
  hush_scene sc;
  hush_lights li;
  REQUIRE(hush__scene_builtin(dev, "cornell-moving", &sc) == HUSH_OK);
  REQUIRE(hush__scene_commit(dev, &sc) == HUSH_OK);
  REQUIRE(hush__lights_init(dev, &li, &sc) == HUSH_OK);
  hush_render_params p;
  hush__render_defaults(&p);
  p.width = 40;
  p.height = 30;
  hush_progressive prog;
  REQUIRE(hush__progressive_init(&prog, 0.25));
  const uint32_t f = 3;
  hush_frame full = render(dev, &sc, &li, &p, f);
  CHECK(hush__frame_find(full, "spp") == NULL);
  p.progressive = &prog;
  hush_frame part = render(dev, &sc, &li, &p, f);
  int ch;
  const float *spp = pixels(part, "spp", &ch);
  const char *names[] = {"color", "albedo", "normal", "position", "depth", "depth_gradient",
                         "motion", "id", "vis"};
  int bad_spp = 0, bad_hole = 0, bad_traced = 0, holes = 0;
  for (uint32_t y = 0; y < p.height; y++)
    for (uint32_t x = 0; x < p.width; x++) {
      const size_t i = (size_t)y * p.width + x;
      const int traced = hush__progressive_traced(&prog, x, y, f);
      bad_spp += spp[i] != (traced ? 1.0f : 0.0f);
      holes += !traced;
      for (size_t l = 0; l < sizeof names / sizeof names[0]; l++) {
        int c, c2;
        const float *a = pixels(part, names[l], &c);
        const float *b = pixels(full, names[l], &c2);
        for (int k = 0; k < c; k++) {
          const float v = a[i * c + k];
          if (traced) {
            bad_traced += memcmp(&v, &b[i * c + k], sizeof v) != 0;
          } else {
            const float hole = strcmp(names[l], "vis") == 0 && k == 0 ? -1.0f : 0.0f;
            bad_hole += v != hole;
          }
        }
      }
    }
  CHECK(holes == 40 * 30 * 3 / 4);
  CHECK_MSG(bad_spp == 0, "%d spp values wrong", bad_spp);
  CHECK_MSG(bad_hole == 0, "%d hole values not 0 (vis -1)", bad_hole);
  CHECK_MSG(bad_traced == 0, "%d traced values differ from the full render", bad_traced);
  /* with spp > 1 the traced pixels carry their sample count and a variance */
  p.spp = 4;
  hush_frame ref = render(dev, &sc, &li, &p, f);
  spp = pixels(ref, "spp", &ch);
  CHECK(hush__frame_find(ref, "variance") != NULL);
  bad_spp = 0;
  for (uint32_t y = 0; y < p.height; y++)
    for (uint32_t x = 0; x < p.width; x++) {
      const float want = hush__progressive_traced(&prog, x, y, f) ? 4.0f : 0.0f;
      bad_spp += spp[(size_t)y * p.width + x] != want;
    }
  CHECK_MSG(bad_spp == 0, "%d spp values wrong at 4 spp", bad_spp);
  hush_frame_release(ref);
  hush_frame_release(part);
  hush_frame_release(full);
  hush__lights_free(&li);
  hush__scene_free(&sc);
  hush_device_release(dev);
}

/* ---- the pyramid fill and the background/surface split ------------------------------ */

/* An object (depth 5, normal +z, motion (1, 0.5)) on the left and in a
 * disc, the background (depth 0, normal 0, motion (-2, 0)) elsewhere, one
 * pixel in four traced: every hole ends up exactly the object's or exactly
 * the background's (never a depth or motion in between), the ones far
 * from the boundary the right one, and traced pixels unchanged. */
static void test_split_background(void) {
  const uint32_t W = 37, H = 23;
  const size_t n = (size_t)W * H;
  float *valid = malloc(n * sizeof(float)), *g[6], *sc[3], *truth = malloc(n * sizeof(float));
  float *pyr = malloc(hush__holes_pyramid_floats(W, H, 6) * sizeof(float));
  REQUIRE(valid && truth && pyr);
  for (int k = 0; k < 6; k++) REQUIRE((g[k] = malloc(n * sizeof(float))) != NULL);
  for (int k = 0; k < 3; k++) REQUIRE((sc[k] = malloc(n * sizeof(float))) != NULL);
  for (uint32_t y = 0; y < H; y++)
    for (uint32_t x = 0; x < W; x++) {
      const size_t i = (size_t)y * W + x;
      const float dx = (float)x - 27.0f, dy = (float)y - 11.0f;
      const int obj = x < 12 || dx * dx + dy * dy < 36.0f;
      truth[i] = (float)obj;
      valid[i] = (x % 2 == 1 && y % 2 == 0) ? 1.0f : 0.0f;
      const float v[6] = {obj ? 5.0f : 0.0f, 0.0f, 0.0f, obj ? 1.0f : 0.0f, obj ? 1.0f : -2.0f,
                          obj ? 0.5f : 0.0f};
      for (int k = 0; k < 6; k++) g[k][i] = valid[i] > 0.0f ? v[k] : 0.0f;
    }
  hush__holes_fill(pyr, W, H, valid, g, 6, 2);
  float *const geometry[4] = {g[0], g[1], g[2], g[3]}, *const motion[2] = {g[4], g[5]};
  hush__holes_split_background(pyr, W, H, valid, sc, geometry, 4, motion, 2);
  int mixed = 0, wrong_far = 0;
  for (uint32_t y = 0; y < H; y++)
    for (uint32_t x = 0; x < W; x++) {
      const size_t i = (size_t)y * W + x;
      const int obj = fabsf(g[0][i] - 5.0f) < 1e-5f * 5.0f && fabsf(g[3][i] - 1.0f) < 1e-5f &&
                      fabsf(g[4][i] - 1.0f) < 1e-5f &&
                      fabsf(g[5][i] - 0.5f) < 1e-5f;
      const int bg = g[0][i] == 0.0f && g[3][i] == 0.0f && fabsf(g[4][i] + 2.0f) < 1e-5f &&
                     fabsf(g[5][i]) < 1e-5f;
      mixed += !obj && !bg;
      int same = 1; /* the 7x7 around is all object or all background */
      for (int j = -3; j <= 3; j++)
        for (int k = -3; k <= 3; k++) {
          const int xx = (int)x + k, yy = (int)y + j;
          if (xx >= 0 && yy >= 0 && xx < (int)W && yy < (int)H)
            same &= truth[(size_t)yy * W + xx] == truth[i];
        }
      wrong_far += same && (truth[i] > 0.0f ? !obj : !bg);
    }
  CHECK_MSG(mixed == 0 && wrong_far == 0,
            "split: %d pixels neither object nor background, %d far from the boundary on the "
            "wrong side",
            mixed, wrong_far);
  for (int k = 0; k < 6; k++) free(g[k]);
  for (int k = 0; k < 3; k++) free(sc[k]);
  free(valid);
  free(truth);
  free(pyr);
}

/* ---- every temporal filter at 1/4 spp (docs/holes.md) -------------------------------- */

/* The acceptance: at 1/4 spp with a still camera every pixel is
 * filled by frame 8; with a moving camera no holes and no streaks; no NaN;
 * 'spp' all 1 changes nothing. */
static void test_filters_with_holes(void) {
  holes_check_filter("accumulate", NULL, 8, 0.01, 0.02, 0.10);
  static const char *const taa[] = {"alpha=0.1", NULL};
  holes_check_filter("taa", taa, 8, 0.01, 0.03, 0.15);
  holes_check_filter("bmfr", NULL, 8, 0.01, 0.02, 0.10);
  holes_check_filter("svgf", NULL, 8, 0.01, 0.03, 0.35); /* a-trous: the ramp's corners blur */
  /* §4.2.6: only traced pixels blend into svgf's TAA history */
  static const char *const ptaa[] = {"taa=true", "progressive_taa=true", NULL};
  holes_result r; /* the moving camera only: the still one is the same as without */
  holes_run("svgf", ptaa, HOLES_QUARTER, 40, 24, 8, 0.05f, &r);
  CHECK_MSG(r.black == 0 && r.nonfinite == 0 && r.mean_rel_err <= 0.03 && r.max_rel_err <= 0.3,
            "svgf progressive_taa, moving camera, 1/4 spp: %d black, %d non-finite, relative "
            "error mean %.4f, largest %.4f",
            r.black, r.nonfinite, r.mean_rel_err, r.max_rel_err);
  free(r.out);
  static const char *const bypass[] = {"emission_bypass=true", NULL};
  holes_check_lamp("accumulate", bypass, 8);
  holes_check_lamp("bmfr", bypass, 8);
  holes_check_lamp("svgf", bypass, 8);
  /* the first frame: odd rows are all holes, their lamp emission is only
   * what the fill gives them (after svgf noted the lit rows) */
  holes_check_lamp("accumulate", bypass, 1);
  holes_check_lamp("bmfr", bypass, 1);
  holes_check_lamp("svgf", bypass, 1);
  holes_check_sky("accumulate", NULL, 12);
  holes_check_sky("taa", NULL, 12);
  holes_check_sky("bmfr", NULL, 12);
  holes_check_sky("svgf", NULL, 12);
}

/* svgf's 7x7 spatial variance (Dundr §4.4) counts only pixels with data: on
 * the first frame at 1/4 spp the smooth ramp has a tiny variance; counting
 * the empty pixels (moments 0) as samples made it about l^2 p (1 - p),
 * ~0.02 here. */
static void test_svgf_spatial_variance_holes(void) {
  holes_result r;
  holes_run_extra("svgf", NULL, HOLES_QUARTER, 48, 32, 1, 0.0f, "variance_estimate", &r);
  float worst = 0.0f;
  int nonfinite = 0;
  for (size_t i = 0; i < 48 * 32; i++) {
    worst = r.extra[i] > worst ? r.extra[i] : worst;
    nonfinite += !isfinite(r.extra[i]);
  }
  CHECK_MSG(worst < 1e-3f && nonfinite == 0,
            "svgf, 1/4 spp, frame 0: spatial variance up to %g (%d non-finite): empty pixels "
            "counted",
            (double)worst, nonfinite);
  free(r.out);
  free(r.extra);
}

int main(void) {
  test_split_background();
  test_svgf_spatial_variance_holes();
  test_filters_with_holes();
  test_fractions();
  test_quarter_order();
  test_patterns();
  test_stratified();
  test_render_holes();
  return check_summary();
}
