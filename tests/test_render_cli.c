/*
 * test_render_cli.c — `hush render` end to end: usage errors (exit 2),
 * runtime errors (exit 1) with messages naming what failed, --list, and a
 * tiny render whose sequence reads back (cameras.json, motion source,
 * layers, render.json). Bad scenes (issue 3, "Bad input"): a missing mesh or
 * texture, malformed JSON, an unsupported material or light type name the
 * file and the field; a scene without light renders black with a warning;
 * degenerate and NaN triangles are skipped with a count. --spp-fraction
 * holes, and progress on stderr.
 */
#include "check.h"

#include "hush.h"
#include "io/frame.h"
#include "io/sequence.h"

#include <stdio.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>

#define WORK HUSH_BINARY_DIR "/test_render_cli"

typedef struct result {
  int status;
  char out[16384];
  char err[4096];
} result;

static void read_file(const char *path, char *buf, size_t size) {
  buf[0] = '\0';
  FILE *f = fopen(path, "rb");
  if (!f) return;
  const size_t n = fread(buf, 1, size - 1, f);
  buf[n] = '\0';
  fclose(f);
}

static void hush(result *r, const char *args) {
  char cmd[4096];
  snprintf(cmd, sizeof cmd, "'%s' render %s > '%s/stdout.txt' 2> '%s/stderr.txt'", HUSH_CLI, args,
           WORK, WORK);
  const int s = system(cmd);
  r->status = (s != -1 && WIFEXITED(s)) ? WEXITSTATUS(s) : -1;
  read_file(WORK "/stdout.txt", r->out, sizeof r->out);
  read_file(WORK "/stderr.txt", r->err, sizeof r->err);
}

static void expect(const char *args, int status, const char *needle) {
  result r;
  hush(&r, args);
  CHECK_MSG(r.status == status, "hush render %s: exit %d, expected %d (%s)", args, r.status, status,
            r.err);
  if (needle)
    CHECK_MSG(strstr(r.err, needle) || strstr(r.out, needle), "hush render %s: no '%s' in '%s'",
              args, needle, r.err);
}

/* Like expect, with a second string the message must contain. */
static void expect2(const char *args, int status, const char *needle, const char *needle2) {
  expect(args, status, needle);
  result r;
  hush(&r, args);
  CHECK_MSG(strstr(r.err, needle2) != NULL, "hush render %s: no '%s' in '%s'", args, needle2,
            r.err);
}

static void write_file(const char *path, const char *text) {
  FILE *f = fopen(path, "wb");
  REQUIRE(f);
  fputs(text, f);
  fclose(f);
}

/* A floor quad lit by nothing, a degenerate triangle (three collinear
 * points), one with a NaN vertex and one with an infinite vertex:
 * WORK/bad/scene.json and variants. */
static void write_bad_scenes(void) {
  REQUIRE(system("mkdir -p '" WORK "/bad'") == 0);
  const char *obj = "mtllib %s.mtl\n"
                    "v -1 0 -1\nv 1 0 -1\nv 1 0 1\nv -1 0 1\nv 0 1 0\nv nan 0 0\nv 2 0 -1\n"
                    "v 0 0 inf\n"
                    "usemtl floor\nf 1 2 3\nf 1 3 4\nf 1 2 7\nf 1 5 6\nf 2 3 8\n";
  const char *manifest =
      "{\"format\": \"hush-scene/1\", \"name\": \"bad\", \"mesh\": \"%s\",\n"
      " \"camera\": {\"position\": [0, 2, 3], \"target\": [0, 0, 0], \"up\": [0, 1, 0],\n"
      "            \"fov_deg\": 45, \"fov_axis\": \"x\"},\n"
      " \"resolution\": [16, 12]%s}\n";
  const struct {
    const char *name, *mtl, *mesh, *extra;
  } v[] = {
      {"scene", "# mitsuba: diffuse\nnewmtl floor\nKd 0.5 0.5 0.5\n", "scene.obj", ""},
      {"nomesh", NULL, "nope.obj", ""},
      {"tex", "# mitsuba: diffuse\nnewmtl floor\nmap_Kd textures/missing.png\n", "tex.obj", ""},
      {"mat", "# mitsuba: twosided > hair\nnewmtl floor\nKd 0.5 0.5 0.5\n", "mat.obj", ""},
      {"light", NULL, "scene.obj", ", \"lights\": [{\"type\": \"area\"}]"},
      {"json", NULL, "scene.obj", ",,"},
  };
  for (size_t i = 0; i < sizeof v / sizeof v[0]; i++) {
    char path[512], text[2048];
    if (v[i].mtl) {
      snprintf(path, sizeof path, WORK "/bad/%s.mtl", v[i].name);
      write_file(path, v[i].mtl);
      snprintf(path, sizeof path, WORK "/bad/%s.obj", v[i].name);
      snprintf(text, sizeof text, obj, v[i].name);
      write_file(path, text);
    }
    snprintf(path, sizeof path, WORK "/bad/%s.json", v[i].name);
    snprintf(text, sizeof text, manifest, v[i].mesh, v[i].extra);
    write_file(path, text);
  }
}

static void test_bad_scenes(hush_device dev) {
  write_bad_scenes();
  expect2("--scene " WORK "/bad/nomesh.json --out " WORK "/x", 1, "nomesh.json", "mesh: ");
  expect2("--scene " WORK "/bad/nomesh.json --out " WORK "/x", 1, "nope.obj", "not found");
  expect2("--scene " WORK "/bad/tex.json --out " WORK "/x", 1, "tex.mtl", "map_Kd");
  expect2("--scene " WORK "/bad/tex.json --out " WORK "/x", 1, "missing.png", "not found");
  expect2("--scene " WORK "/bad/mat.json --out " WORK "/x", 1, "mat.mtl", "type 'hair'");
  expect2("--scene " WORK "/bad/light.json --out " WORK "/x", 1, "light.json",
          "lights[0].type: unknown light type 'area'");
  expect2("--scene " WORK "/bad/json.json --out " WORK "/x", 1, "json.json", "malformed JSON");

  /* no light: a warning (also with --quiet), and a black frame; the three
   * bad triangles are counted */
  result r;
  hush(&r, "--scene " WORK "/bad/scene.json --frames 1 --out " WORK "/dark");
  CHECK_MSG(r.status == 0, "no-light scene: exit %d (%s)", r.status, r.err);
  CHECK_MSG(strstr(r.err, "warning: scene 'bad' has no light"), "no warning in '%s'", r.err);
  CHECK_MSG(strstr(r.err, "skipped 3 triangles"), "no skipped count in '%s'", r.err);
  hush(&r, "--scene " WORK "/bad/scene.json --frames 1 --quiet --out " WORK "/dark");
  CHECK_MSG(strstr(r.err, "warning: scene 'bad' has no light") && !strstr(r.err, "frame 1/1"),
            "--quiet: '%s'", r.err);
  hush_frame f = NULL;
  REQUIRE(hush_frame_read_exr(dev, WORK "/dark/frame_0000.exr", &f) == HUSH_OK);
  hush_layer *color = hush__frame_find(f, "color"), *depth = hush__frame_find(f, "depth");
  REQUIRE(color && depth);
  int nonzero = 0, seen = 0;
  for (size_t i = 0; i < (size_t)16 * 12; i++) {
    nonzero += color->pixels[3 * i] != 0.0f || color->pixels[3 * i + 1] != 0.0f ||
               color->pixels[3 * i + 2] != 0.0f;
    seen += depth->pixels[i] > 0.0f;
  }
  CHECK_MSG(nonzero == 0, "%d lit pixels without a light", nonzero);
  CHECK(seen > 0); /* the floor is there, only black */
  hush_frame_release(f);
  char json[8192];
  read_file(WORK "/dark/render.json", json, sizeof json);
  CHECK(strstr(json, "\"skipped_triangles\": 3") != NULL);
}

/* --spp-fraction: usage errors, and a sequence whose frames have holes in
 * the documented rotation (0.25: one pixel of each 2x2 block per frame). */
static void test_fraction(hush_device dev) {
  expect("--scene builtin:cornell --out " WORK "/x --spp-fraction 0", 2, "--spp-fraction");
  expect("--scene builtin:cornell --out " WORK "/x --spp-fraction 1.5", 2, "--spp-fraction");
  expect("--scene builtin:cornell --out " WORK "/x --spp-fraction 0.123", 2, "m/k^2");
  expect("--scene builtin:cornell --out " WORK "/x --spp-fraction 1/0", 2, "--spp-fraction");
  expect("--scene builtin:cornell --out " WORK "/x --export exr", 2, "--export");
  result r;
  hush(&r, "--scene builtin:cornell --size 8x6 --frames 4 --spp-fraction 1/4 --out " WORK
           "/frac");
  CHECK_MSG(r.status == 0, "exit %d (%s)", r.status, r.err);
  /* progress for every run: a line per frame with the time left (stderr is
   * not a terminal here, so plain lines) */
  CHECK_MSG(strstr(r.err, "frame 1/4") && strstr(r.err, "frame 4/4") && strstr(r.err, "left") &&
                strstr(r.err, "Mrays/s") && !strchr(r.err, '\r'),
            "progress: '%s'", r.err);
  hush_sequence seq;
  REQUIRE(hush__sequence_read(dev, WORK "/frac", &seq) == HUSH_OK);
  const uint32_t order[4][2] = {{0, 0}, {1, 1}, {1, 0}, {0, 1}};
  int bad = 0;
  for (uint32_t i = 0; i < 4; i++) {
    hush_frame f;
    REQUIRE(hush__sequence_read_frame(dev, &seq, i, &f) == HUSH_OK);
    hush_layer *spp = hush__frame_find(f, "spp"), *vis = hush__frame_find(f, "vis");
    REQUIRE(spp && vis);
    for (uint32_t y = 0; y < 6; y++)
      for (uint32_t x = 0; x < 8; x++) {
        const int traced = x % 2 == order[i][0] && y % 2 == order[i][1];
        const size_t j = (size_t)y * 8 + x;
        bad += spp->pixels[j] != (traced ? 1.0f : 0.0f);
        if (!traced) bad += vis->pixels[3 * j] != -1.0f;
      }
    hush_frame_release(f);
  }
  CHECK_MSG(bad == 0, "%d pixels off the 2x2 rotation", bad);
  hush__sequence_free(&seq);
  char json[8192];
  read_file(WORK "/frac/render.json", json, sizeof json);
  CHECK(strstr(json, "\"spp_fraction\": 0.25") && strstr(json, "\"progressive_block\": [2, 1]"));
}

int main(void) {
  REQUIRE(system("rm -rf '" WORK "' && mkdir -p '" WORK "'") == 0);

  /* usage errors */
  expect("--out " WORK "/x", 2, "--scene is required");
  expect("--scene builtin:cornell", 2, "--out DIR is required");
  expect("--scene builtin:cornell --out " WORK "/x --spp 0", 2, "--spp");
  expect("--scene builtin:cornell --out " WORK "/x --size 10", 2, "--size");
  expect("--scene builtin:cornell --out " WORK "/x --sampler sobol", 2, "--sampler");
  expect("--scene builtin:cornell --out " WORK "/x --bounces 99", 2, "--bounces");
  expect2("--scene builtin:cornell --out " WORK "/x --mirror-depth 4", 2, "--mirror-depth",
          "[0, 3]");
  expect("--scene builtin:cornell --out " WORK "/x --mirror-depth -1", 2, "--mirror-depth");
  expect("--scene builtin:cornell --out " WORK "/x --path spiral", 2, "--path");
  expect("--scene builtin:cornell --out " WORK "/x --frobnicate", 2, "--frobnicate");
  expect("--scene builtin:cornell --out " WORK "/x extra", 2, "extra");

  /* runtime errors name what failed */
  expect("--scene " WORK "/missing/scene.json --out " WORK "/x", 1, "missing");
  expect("--scene builtin:nope --out " WORK "/x", 1, "nope");
  expect("--scene builtin:cornell --path " WORK "/none.json --out " WORK "/x", 1, "none.json");
  expect("--scene builtin:cornell --path path --out " WORK "/x", 1, "no camera path");

  expect("--list", 0, "cornell");
  expect("--help", 0, "usage: hush render");

  /* a tiny render reads back as a sequence */
  expect("--scene builtin:cornell-moving --size 24x16 --frames 3 --first 2 --quiet --out " WORK
         "/seq",
         0, NULL);
  hush_device dev = hush_device_new(NULL);
  REQUIRE(dev);
  hush_sequence seq;
  REQUIRE(hush__sequence_read(dev, WORK "/seq", &seq) == HUSH_OK);
  CHECK(seq.width == 24 && seq.height == 16 && seq.frame_count == 3);
  CHECK(seq.motion == HUSH_MOTION_VECTORS);
  CHECK(seq.cameras[0].jitter[0] != seq.cameras[1].jitter[0]);
  hush_frame f;
  REQUIRE(hush__sequence_read_frame(dev, &seq, 1, &f) == HUSH_OK);
  const char *layers[] = {"color", "albedo", "normal", "position", "depth", "depth_gradient",
                          "motion", "id", "vis"};
  for (size_t i = 0; i < sizeof layers / sizeof layers[0]; i++)
    CHECK_MSG(hush_frame_get_layer(f, layers[i], NULL) == HUSH_OK, "layer %s missing", layers[i]);
  CHECK(hush_frame_get_layer(f, "spp", NULL) == HUSH_ERROR_NOT_FOUND);
  hush_frame_release(f);
  hush__sequence_free(&seq);
  char json[8192];
  read_file(WORK "/seq/render.json", json, sizeof json);
  CHECK(strstr(json, "\"mirror_depth\": 3") != NULL);
  CHECK(strstr(json, "\"spp\": 1") && strstr(json, "\"first_frame\": 2") &&
        strstr(json, "\"command\": [\"hush\", \"render\""));

  /* references: spp and variance layers; a static scene uses camera motion */
  expect("--scene builtin:cornell --size 16x12 --frames 1 --spp 4 --no-jitter --split "
         "--split-lobes --quiet --out " WORK "/ref",
         0, NULL);
  REQUIRE(hush__sequence_read(dev, WORK "/ref", &seq) == HUSH_OK);
  CHECK(seq.motion == HUSH_MOTION_CAMERA);
  CHECK(seq.cameras[0].jitter[0] == 0.0f && seq.cameras[0].jitter[1] == 0.0f);
  REQUIRE(hush__sequence_read_frame(dev, &seq, 0, &f) == HUSH_OK);
  CHECK(hush_frame_get_layer(f, "spp", NULL) == HUSH_OK);
  CHECK(hush_frame_get_layer(f, "variance", NULL) == HUSH_OK);
  CHECK(hush_frame_get_layer(f, "direct", NULL) == HUSH_OK);
  CHECK(hush_frame_get_layer(f, "indirect", NULL) == HUSH_OK);
  hush_image_view dv, sv, cv;
  REQUIRE(hush_frame_get_layer(f, "diffuse", &dv) == HUSH_OK);
  REQUIRE(hush_frame_get_layer(f, "specular", &sv) == HUSH_OK);
  REQUIRE(hush_frame_get_layer(f, "color", &cv) == HUSH_OK);
  /* written as float: the sum still holds bit for bit after the EXR */
  int inexact = 0;
  for (uint32_t i = 0; i < 16 * 12 * 3; i++) {
    const float sum = ((const float *)dv.data)[i] + ((const float *)sv.data)[i];
    if (sum != ((const float *)cv.data)[i]) inexact++;
  }
  CHECK_MSG(inexact == 0, "%d colours are not diffuse + specular", inexact);
  read_file(WORK "/ref/render.json", json, sizeof json);
  CHECK(strstr(json, "\"split_lobes\": true") != NULL);
  hush_frame_release(f);
  hush__sequence_free(&seq);
  test_bad_scenes(dev);
  test_fraction(dev);
  hush_device_release(dev);
  return check_summary();
}
