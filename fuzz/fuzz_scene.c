/*
 * fuzz_scene.c — libFuzzer target for hush's text inputs: a sequence's
 * cameras.json (hush__sequence_read), a camera path file of `hush render
 * --path FILE.json` (hush__camera_path_load), and a scene folder's
 * scene.json, MTL, camera path and OBJ (hush__scene_load; the OBJ through
 * assimp). The first
 * byte picks the file the rest of the input becomes; the other files of a
 * small valid scene stay as they are, so the loader gets past them. Seeds:
 * fuzz/scene_seeds/ (one per kind).
 *
 * assimp leaks a little when it rejects an OBJ (inside libassimp, not
 * hush's to free): fuzz/lsan-assimp.supp suppresses those reports only.
 */
#include "hush.h"
#include "io/sequence.h"
#include "render/camera.h"
#include "render/scene.h"

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

enum { KIND_CAMERAS, KIND_SCENE, KIND_MTL, KIND_PATH, KIND_OBJ, KIND_PATH_FILE, KINDS };

static const char OBJ[] = "mtllib s.mtl\n"
                          "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvn 0 0 1\nvt 0 0\nvt 1 0\nvt 0 1\n"
                          "usemtl a\nf 1/1/1 2/2/1 3/3/1\nusemtl b\nf 2/2/1 4/3/1 3/1/1\n";
static const char MTL[] = "newmtl a\n# mitsuba: twosided > diffuse\nKd 0.5 0.5 0.5\n"
                          "newmtl b\nKe 1 1 1\nKd 0 0 0\n";
static const char SCENE[] =
    "{\"format\": \"hush-scene/1\", \"mesh\": \"s.obj\",\n"
    " \"camera\": {\"position\": [0, 0, 3], \"target\": [0, 0, 0], \"up\": [0, 1, 0],"
    " \"fov_deg\": 40},\n"
    " \"resolution\": [32, 16], \"camera_path\": \"p.json\",\n"
    " \"lights\": [{\"type\": \"sphere\", \"center\": [0, 0, 1], \"radius\": 0.1,"
    " \"radiance\": [1, 1, 1]}]}\n";
static const char PATH[] =
    "{\"fov_axis\": \"y\", \"resolution\": [32, 16], \"frames\": [{\"position\": [0, 0, 3],"
    " \"target\": [0, 0, 0], \"up\": [0, 1, 0], \"fov_deg\": 40}]}\n";

static char dir[64];

static void remove_files(void) {
  static const char *const names[] = {"s.obj", "s.mtl", "scene.json", "p.json", "cameras.json",
                                      "frame_0000.exr", "frame_0001.exr"};
  char p[128];
  for (size_t i = 0; i < sizeof names / sizeof names[0]; i++) {
    snprintf(p, sizeof p, "%s/%s", dir, names[i]);
    unlink(p);
  }
  rmdir(dir);
}

static void put(const char *name, const void *bytes, size_t n) {
  char p[128];
  snprintf(p, sizeof p, "%s/%s", dir, name);
  FILE *f = fopen(p, "wb");
  if (!f) abort();
  if (n && fwrite(bytes, 1, n, f) != n) abort();
  fclose(f);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  if (!dir[0]) {
    const char *tmp = getenv("TMPDIR");
    snprintf(dir, sizeof dir, "%s/hush-fuzz-XXXXXX", tmp && strlen(tmp) < 40 ? tmp : "/tmp");
    if (!mkdtemp(dir)) abort();
    atexit(remove_files);
  }
  if (size < 1) return 0;
  const int kind = data[0] % KINDS;
  data++, size--;
  put("s.obj", OBJ, sizeof OBJ - 1);
  put("s.mtl", MTL, sizeof MTL - 1);
  put("scene.json", SCENE, sizeof SCENE - 1);
  put("p.json", PATH, sizeof PATH - 1);
  /* cameras.json names frame files; they only need to exist */
  put("frame_0000.exr", "", 0);
  put("frame_0001.exr", "", 0);
  hush_device device = hush_device_new("threads=1");
  if (!device) return 0;
  if (kind == KIND_CAMERAS) {
    put("cameras.json", data, size);
    hush_sequence seq;
    memset(&seq, 0, sizeof seq);
    if (hush__sequence_read(device, dir, &seq) == HUSH_OK) hush__sequence_free(&seq);
  } else if (kind == KIND_PATH_FILE) {
    put("p.json", data, size);
    char p[128];
    snprintf(p, sizeof p, "%s/p.json", dir);
    hush_camera_path path;
    memset(&path, 0, sizeof path);
    if (hush__camera_path_load(device, p, &path) == HUSH_OK) free(path.frames);
  } else {
    static const char *const file[KINDS] = {NULL, "scene.json", "s.mtl", "p.json", "s.obj", NULL};
    put(file[kind], data, size);
    hush_scene scene;
    char p[128];
    snprintf(p, sizeof p, "%s/scene.json", dir);
    if (hush__scene_load(device, p, &scene) == HUSH_OK) hush__scene_commit(device, &scene);
    hush__scene_free(&scene); /* safe after a failed load too */
  }
  hush_device_get_error(device, NULL);
  hush_device_release(device);
  return 0;
}
