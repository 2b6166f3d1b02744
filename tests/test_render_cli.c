/*
 * test_render_cli.c — `hush render` end to end: usage errors (exit 2),
 * runtime errors (exit 1) with messages naming what failed, --list, and a
 * tiny render whose sequence reads back (cameras.json, motion source,
 * layers, render.json).
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

int main(void) {
  REQUIRE(system("rm -rf '" WORK "' && mkdir -p '" WORK "'") == 0);

  /* usage errors */
  expect("--out " WORK "/x", 2, "--scene is required");
  expect("--scene builtin:cornell", 2, "--out DIR is required");
  expect("--scene builtin:cornell --out " WORK "/x --spp 0", 2, "--spp");
  expect("--scene builtin:cornell --out " WORK "/x --size 10", 2, "--size");
  expect("--scene builtin:cornell --out " WORK "/x --sampler sobol", 2, "--sampler");
  expect("--scene builtin:cornell --out " WORK "/x --bounces 99", 2, "--bounces");
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
  CHECK(strstr(json, "\"spp\": 1") && strstr(json, "\"first_frame\": 2") &&
        strstr(json, "\"command\": [\"hush\", \"render\""));

  /* references: spp and variance layers; a static scene uses camera motion */
  expect("--scene builtin:cornell --size 16x12 --frames 1 --spp 4 --no-jitter --split --quiet "
         "--out " WORK "/ref",
         0, NULL);
  REQUIRE(hush__sequence_read(dev, WORK "/ref", &seq) == HUSH_OK);
  CHECK(seq.motion == HUSH_MOTION_CAMERA);
  CHECK(seq.cameras[0].jitter[0] == 0.0f && seq.cameras[0].jitter[1] == 0.0f);
  REQUIRE(hush__sequence_read_frame(dev, &seq, 0, &f) == HUSH_OK);
  CHECK(hush_frame_get_layer(f, "spp", NULL) == HUSH_OK);
  CHECK(hush_frame_get_layer(f, "variance", NULL) == HUSH_OK);
  CHECK(hush_frame_get_layer(f, "direct", NULL) == HUSH_OK);
  CHECK(hush_frame_get_layer(f, "indirect", NULL) == HUSH_OK);
  hush_frame_release(f);
  hush__sequence_free(&seq);
  hush_device_release(dev);
  return check_summary();
}
