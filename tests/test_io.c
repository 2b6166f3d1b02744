/*
 * test_io.c — the I/O module: the frame object; EXR, PNG and PFM round
 * trips (EXR files written by OpenEXR itself too: tiled, every common
 * compression, uint channels); sequences and cameras.json; and the status
 * and message of every kind of bad input. A failed write must leave neither
 * a temporary file nor a damaged old file. Scratch files go to
 * HUSH_BINARY_DIR/test_io_tmp/.
 */
#include "check.h"
#include "core/half.h"
#include "hush.h"
#include "io/atomic_file.h"
#include "io/exr.h"
#include "io/frame.h"
#include "io/sequence.h"
#include "io/tonemap.h"

#include <openexr.h>
#include <png.h>

#include <dirent.h>
#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#define TMP HUSH_BINARY_DIR "/test_io_tmp"

/* ------------------------------------------------------------------------ */
/* Helpers                                                                  */
/* ------------------------------------------------------------------------ */

static uint32_t rng_state = 12345u;
static float rnd(void) { /* [0, 1) */
  rng_state = rng_state * 1664525u + 1013904223u;
  return (float)(rng_state >> 8) / 16777216.0f;
}

/* Reads the device's error and checks its status and that the message
 * contains needle (and, for errors, is not empty). */
static int expect(hush_device dev, hush_status got, hush_status want, const char *needle) {
  const char *msg = "";
  const hush_status err = hush_device_get_error(dev, &msg);
  const int ok = got == want && err == want && (want == HUSH_OK || (msg[0] && strstr(msg, needle)));
  if (!ok)
    fprintf(stderr, "  expected %s with '%s'; got %s, device has %s: %s\n", hush_status_name(want),
            needle, hush_status_name(got), hush_status_name(err), msg);
  return ok;
}
#define CHECK_STATUS(dev, expr, want, needle) CHECK(expect((dev), (expr), (want), (needle)))

static void remove_tree(const char *dir) {
  DIR *d = opendir(dir);
  if (!d) return;
  struct dirent *e;
  char path[1024];
  while ((e = readdir(d))) {
    if (!strcmp(e->d_name, ".") || !strcmp(e->d_name, "..")) continue;
    snprintf(path, sizeof path, "%s/%s", dir, e->d_name);
    struct stat st;
    if (lstat(path, &st) == 0 && S_ISDIR(st.st_mode))
      remove_tree(path);
    else
      unlink(path);
  }
  closedir(d);
  rmdir(dir);
}

static int count_temp_files(const char *dir) {
  DIR *d = opendir(dir);
  if (!d) return -1;
  int n = 0;
  struct dirent *e;
  while ((e = readdir(d)))
    if (strstr(e->d_name, ".tmp-")) n++;
  closedir(d);
  return n;
}

static void write_bytes(const char *path, const void *data, size_t n) {
  FILE *f = fopen(path, "wb");
  REQUIRE(f);
  REQUIRE(fwrite(data, 1, n, f) == n);
  fclose(f);
}

static void write_text(const char *path, const char *text) {
  write_bytes(path, text, strlen(text));
}

/* The whole file; the caller frees it. */
static uint8_t *read_bytes(const char *path, size_t *n) {
  FILE *f = fopen(path, "rb");
  if (!f) return NULL;
  fseek(f, 0, SEEK_END);
  const long size = ftell(f);
  fseek(f, 0, SEEK_SET);
  uint8_t *buf = malloc((size_t)size + 1);
  REQUIRE(buf && fread(buf, 1, (size_t)size, f) == (size_t)size);
  fclose(f);
  *n = (size_t)size;
  return buf;
}

static long file_size(const char *path) {
  struct stat st;
  return stat(path, &st) == 0 ? (long)st.st_size : -1;
}

static float *layer_pixels(hush_frame frame, const char *name, int *channels) {
  hush_image_view v;
  if (hush_frame_get_layer(frame, name, &v) != HUSH_OK) return NULL;
  if (channels) *channels = hush_format_channels(v.format);
  return v.data;
}

/* Same size, same layers (in any order), bit-identical pixels. */
static int frames_identical(hush_frame a, hush_frame b) {
  if (hush_frame_width(a) != hush_frame_width(b) || hush_frame_height(a) != hush_frame_height(b) ||
      hush_frame_layer_count(a) != hush_frame_layer_count(b))
    return 0;
  const size_t pixels = (size_t)hush_frame_width(a) * hush_frame_height(a);
  for (uint32_t i = 0; i < hush_frame_layer_count(a); i++) {
    const char *name = hush_frame_layer_name(a, i);
    int ca = 0, cb = 0;
    const float *pa = layer_pixels(a, name, &ca), *pb = layer_pixels(b, name, &cb);
    if (!pb || ca != cb || memcmp(pa, pb, pixels * (size_t)ca * sizeof(float)) != 0) {
      fprintf(stderr, "  layer '%s' differs\n", name);
      return 0;
    }
  }
  return 1;
}

static hush_frame make_frame(hush_device dev, uint32_t w, uint32_t h, const char *const *names,
                             const int *channels, int n) {
  hush_frame f = hush_frame_new(dev, w, h);
  REQUIRE(f);
  for (int l = 0; l < n; l++) {
    hush_image_view v;
    REQUIRE(hush_frame_add_layer(f, names[l], channels[l], &v) == HUSH_OK);
    float *p = v.data;
    for (size_t i = 0; i < (size_t)w * h * (size_t)channels[l]; i++)
      p[i] = (rnd() - 0.3f) * (float)(1 << (l % 8)) * 3.0f;
  }
  return f;
}

/* ------------------------------------------------------------------------ */
/* Frames                                                                   */
/* ------------------------------------------------------------------------ */

static void test_frame_api(hush_device dev) {
  CHECK(hush_frame_new(dev, 0, 4) == NULL);
  CHECK_STATUS(dev, HUSH_ERROR_INVALID_ARGUMENT, HUSH_ERROR_INVALID_ARGUMENT, "size");
  CHECK(hush_frame_new(dev, 70000, 4) == NULL);
  CHECK_STATUS(dev, HUSH_ERROR_INVALID_ARGUMENT, HUSH_ERROR_INVALID_ARGUMENT, "70000");

  hush_frame f = hush_frame_new(dev, 5, 3);
  REQUIRE(f);
  CHECK(hush_frame_width(f) == 5 && hush_frame_height(f) == 3);
  CHECK(hush_frame_layer_count(f) == 0);
  hush_image_view v;
  CHECK_STATUS(dev, hush_frame_add_layer(f, "color", 3, &v), HUSH_OK, "");
  CHECK(v.format == HUSH_FORMAT_FLOAT3 && v.width == 5 && v.height == 3 && v.data);
  CHECK(v.pixel_stride == 12 && v.row_stride == 60 && v.byte_offset == 0);
  CHECK(((const float *)v.data)[14] == 0.0f); /* zero-filled */
  CHECK(((uintptr_t)v.data & 63) == 0);
  CHECK_STATUS(dev, hush_frame_add_layer(f, "", 1, NULL), HUSH_ERROR_INVALID_ARGUMENT, "empty");
  CHECK_STATUS(dev, hush_frame_add_layer(f, NULL, 1, NULL), HUSH_ERROR_INVALID_ARGUMENT, "NULL");
  char long_name[80];
  memset(long_name, 'x', 64);
  long_name[64] = '\0';
  CHECK_STATUS(dev, hush_frame_add_layer(f, long_name, 1, NULL), HUSH_ERROR_INVALID_ARGUMENT, "63");
  long_name[63] = '\0';
  CHECK_STATUS(dev, hush_frame_add_layer(f, long_name, 1, NULL), HUSH_OK, "");
  CHECK_STATUS(dev, hush_frame_add_layer(f, "depth", 0, NULL), HUSH_ERROR_INVALID_ARGUMENT,
               "depth");
  CHECK_STATUS(dev, hush_frame_add_layer(f, "depth", 5, NULL), HUSH_ERROR_INVALID_ARGUMENT,
               "1 to 4");
  CHECK(hush_frame_add_layer(NULL, "depth", 1, NULL) == HUSH_ERROR_INVALID_ARGUMENT);
  CHECK(hush_device_get_error(NULL, NULL) ==
        HUSH_ERROR_INVALID_ARGUMENT); /* no device: thread slot */
  CHECK_STATUS(dev, hush_frame_get_layer(f, "albedo", &v), HUSH_ERROR_NOT_FOUND, "albedo");
  CHECK_STATUS(dev, hush_frame_get_layer(f, "color", NULL), HUSH_OK, "");
  /* replacing keeps the position and changes the channel count */
  CHECK_STATUS(dev, hush_frame_add_layer(f, "color", 4, &v), HUSH_OK, "");
  CHECK(hush_frame_layer_count(f) == 2 && v.format == HUSH_FORMAT_FLOAT4);
  CHECK(strcmp(hush_frame_layer_name(f, 0), "color") == 0);
  CHECK(hush_frame_layer_name(f, 2) == NULL);
  CHECK(hush__frame_find(f, "color") == &f->layers[0]);
  char name[16];
  for (int i = 2; i < HUSH_MAX_LAYERS; i++) {
    snprintf(name, sizeof name, "l%d", i);
    REQUIRE(hush_frame_add_layer(f, name, 1, NULL) == HUSH_OK);
  }
  CHECK_STATUS(dev, hush_frame_add_layer(f, "one_too_many", 1, NULL), HUSH_ERROR_UNSUPPORTED, "32");
  hush_frame_retain(f);
  hush_frame_release(f);
  CHECK(hush_frame_layer_count(f) == HUSH_MAX_LAYERS);
  hush_frame_release(f);
  hush_frame_release(NULL);
  CHECK(hush_frame_width(NULL) == 0 && hush_frame_layer_count(NULL) == 0);
}

/* ------------------------------------------------------------------------ */
/* EXR written by hush                                                      */
/* ------------------------------------------------------------------------ */

static const char *const all_layers[] = {"color", "albedo", "normal", "position", "depth", "motion",
                                         "id",    "ref",    "spp",    "variance", "foo",   "mask"};
static const int all_channels[] = {3, 3, 3, 3, 1, 2, 1, 3, 1, 1, 4, 1};
#define ALL_LAYERS 12

static void test_exr_float_round_trip(hush_device dev) {
  hush_frame f = make_frame(dev, 37, 23, all_layers, all_channels, ALL_LAYERS);
  float *color = layer_pixels(f, "color", NULL);
  color[0] = NAN;
  color[1] = INFINITY;
  color[2] = -0.0f;
  color[3] = 1e-40f; /* a float subnormal */
  color[4] = 3.4e38f;
  float *id = layer_pixels(f, "id", NULL);
  id[5] = 16777216.0f;
  CHECK_STATUS(dev, hush_frame_write_exr(f, TMP "/float.exr", HUSH_EXR_FLOAT), HUSH_OK, "");
  hush_frame g = NULL;
  CHECK_STATUS(dev, hush_frame_read_exr(dev, TMP "/float.exr", &g), HUSH_OK, "");
  REQUIRE(g);
  CHECK(frames_identical(f, g));
  /* layers come back in the order of their first (sorted) channel */
  CHECK(strcmp(hush_frame_layer_name(g, 0), "B") != 0);
  hush_frame_release(g);

  /* the same bytes read from memory give the same frame */
  size_t n = 0;
  uint8_t *bytes = read_bytes(TMP "/float.exr", &n);
  REQUIRE(bytes);
  CHECK_STATUS(dev, hush__exr_read_memory(dev, "mem.exr", bytes, n, 0, &g), HUSH_OK, "");
  CHECK(g && frames_identical(f, g));
  hush_frame_release(g);
  g = NULL;
  CHECK_STATUS(dev, hush__exr_read_memory(dev, "mem.exr", bytes, n, 100, &g),
               HUSH_ERROR_UNSUPPORTED, "mem.exr");
  CHECK(g == NULL);
  free(bytes);
  hush_frame_release(f);
}

/* Tiny frames, partly compressible: some of their chunks deflate to
 * exactly their raw size, which OpenEXR 3.1's encoder stored as deflated
 * bytes that read back as raw pixels (exr.c, compress_guarded). Every one
 * must read back bit for bit. */
static void test_exr_tiny_round_trips(hush_device dev) {
  static const char *const names[] = {"color", "depth", "normal", "motion", "id"};
  static const int channels[] = {3, 1, 3, 2, 1};
  int bad = 0;
  for (int t = 0; t < 400; t++) {
    const uint32_t w = 1 + (uint32_t)t % 4, h = 1 + (uint32_t)(t / 4) % 3;
    hush_frame f = make_frame(dev, w, h, names, channels, 5);
    /* a share of the values repeated, so that deflate gains a little */
    const float keep = rnd();
    for (int l = 0; l < 5; l++) {
      float *p = layer_pixels(f, names[l], NULL);
      for (size_t i = 1; i < (size_t)w * h * (size_t)channels[l]; i++)
        if (rnd() > keep) p[i] = p[i - 1];
    }
    CHECK_STATUS(dev, hush_frame_write_exr(f, TMP "/tiny.exr", HUSH_EXR_FLOAT), HUSH_OK, "");
    hush_frame g = NULL;
    CHECK_STATUS(dev, hush_frame_read_exr(dev, TMP "/tiny.exr", &g), HUSH_OK, "");
    if (!g || !frames_identical(f, g)) bad++;
    hush_frame_release(g);
    hush_frame_release(f);
  }
  CHECK_MSG(bad == 0, "%d of 400 tiny frames did not read back", bad);
}

/* The EXR channel names hush writes, read back with OpenEXR directly. */
static void test_exr_channel_names(hush_device dev) {
  exr_context_t ctx = NULL;
  exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
  REQUIRE(exr_start_read(&ctx, TMP "/float.exr", &init) == EXR_ERR_SUCCESS);
  const exr_attr_chlist_t *ch = NULL;
  REQUIRE(exr_get_channels(ctx, 0, &ch) == EXR_ERR_SUCCESS);
  static const char *const expected[] = {
      "B",    "G",        "N.X",      "N.Y",      "N.Z",   "P.X",   "P.Y",   "P.Z",     "R",
      "Z",    "albedo.B", "albedo.G", "albedo.R", "foo.A", "foo.B", "foo.G", "foo.R",   "id",
      "mask", "motion.X", "motion.Y", "ref.B",    "ref.G", "ref.R", "spp",   "variance"};
  const int n = (int)(sizeof expected / sizeof expected[0]);
  CHECK(ch->num_channels == n);
  for (int i = 0; i < n && i < ch->num_channels; i++)
    CHECK_MSG(strcmp(ch->entries[i].name.str, expected[i]) == 0,
              "channel %d is '%s', expected '%s'", i, ch->entries[i].name.str, expected[i]);
  exr_compression_t comp;
  CHECK(exr_get_compression(ctx, 0, &comp) == EXR_ERR_SUCCESS && comp == EXR_COMPRESSION_ZIP);
  exr_finish(&ctx);
  (void)dev;
}

static void test_exr_half_round_trip(hush_device dev) {
  hush_frame f = make_frame(dev, 40, 35, all_layers, all_channels, ALL_LAYERS);
  float *color = layer_pixels(f, "color", NULL);
  const float special[] = {65504.0f,  1e-5f,    6.1035156e-05f, 5.9604645e-08f, 1e-8f,
                           -65504.0f, 70000.0f, 0.1f,           1.0f / 3.0f,    2049.0f,
                           -1e30f,    65519.0f, 65520.0f,       INFINITY,       -INFINITY};
  memcpy(color, special, sizeof special);
  float *id = layer_pixels(f, "id", NULL);
  id[0] = 123457.0f; /* not a half: ids must stay exact */
  CHECK_STATUS(dev, hush_frame_write_exr(f, TMP "/half.exr", HUSH_EXR_HALF), HUSH_OK, "");
  CHECK(file_size(TMP "/half.exr") < file_size(TMP "/float.exr"));
  hush_frame g = NULL;
  CHECK_STATUS(dev, hush_frame_read_exr(dev, TMP "/half.exr", &g), HUSH_OK, "");
  REQUIRE(g);
  CHECK(hush_frame_layer_count(g) == ALL_LAYERS);
  const size_t pixels = 40 * 35;
  int bad = 0;
  for (int l = 0; l < ALL_LAYERS; l++) {
    int c = 0;
    const float *a = layer_pixels(f, all_layers[l], &c);
    const float *b = layer_pixels(g, all_layers[l], NULL);
    REQUIRE(a && b);
    const int exact = !strcmp(all_layers[l], "id") || !strcmp(all_layers[l], "depth") ||
                      !strcmp(all_layers[l], "position");
    for (size_t i = 0; i < pixels * (size_t)c; i++) {
      /* finite values past the half range saturate at 65504 */
      const float sat = isfinite(a[i]) ? fmaxf(-65504.0f, fminf(65504.0f, a[i])) : a[i];
      const float want = exact ? a[i] : hush__half_to_float(hush__float_to_half(sat));
      if (memcmp(&want, &b[i], sizeof want) != 0) bad++;
    }
  }
  CHECK_MSG(bad == 0, "%d values differ from their half rounding", bad);
  const float *c2 = layer_pixels(g, "color", NULL);
  CHECK(c2[0] == 65504.0f);
  CHECK_NEAR(c2[1], 1e-5f, 3e-8); /* half subnormal: spacing 6e-8 */
  CHECK(c2[3] == 5.9604645e-08f); /* the smallest half */
  CHECK(c2[4] == 0.0f);
  CHECK(c2[6] == 65504.0f); /* 70000: the largest half, not Inf */
  CHECK(c2[10] == -65504.0f && c2[11] == 65504.0f && c2[12] == 65504.0f);
  CHECK(isinf(c2[13]) && c2[13] > 0 && isinf(c2[14]) && c2[14] < 0); /* Inf stays Inf */
  CHECK_NEAR(c2[7], 0.1f, 0.1f / 2048);
  CHECK(layer_pixels(g, "id", NULL)[0] == 123457.0f);
  hush_frame_release(g);
  hush_frame_release(f);
}

static void test_exr_write_errors(hush_device dev) {
  const char *names[] = {"color", "R"};
  const int channels[] = {3, 1};
  hush_frame f = make_frame(dev, 4, 4, names, channels, 2);
  CHECK_STATUS(dev, hush_frame_write_exr(f, TMP "/dup.exr", HUSH_EXR_FLOAT),
               HUSH_ERROR_INVALID_ARGUMENT, "'R'");
  CHECK(file_size(TMP "/dup.exr") == -1);
  hush_frame_release(f);

  const char *names2[] = {"N"}; /* "N.R" would read back as "normal" */
  const int channels2[] = {3};
  f = make_frame(dev, 4, 4, names2, channels2, 1);
  CHECK_STATUS(dev, hush_frame_write_exr(f, TMP "/n.exr", HUSH_EXR_FLOAT), HUSH_ERROR_UNSUPPORTED,
               "'N'");
  CHECK_STATUS(dev, hush_frame_write_exr(f, TMP "/n.exr", (hush_exr_type)7),
               HUSH_ERROR_INVALID_ARGUMENT, "type");
  hush_frame_release(f);
  f = make_frame(dev, 4, 4, all_layers, all_channels, 1);
  CHECK_STATUS(dev, hush_frame_write_exr(f, TMP "/no_such_dir/x.exr", HUSH_EXR_FLOAT),
               HUSH_ERROR_IO, "no_such_dir");
  CHECK(hush_frame_write_exr(NULL, TMP "/x.exr", HUSH_EXR_FLOAT) == HUSH_ERROR_INVALID_ARGUMENT);
  const char *msg = NULL;
  CHECK(hush_device_get_error(NULL, &msg) == HUSH_ERROR_INVALID_ARGUMENT && strstr(msg, "NULL"));
  hush_frame_release(f);

  f = hush_frame_new(dev, 3, 3);
  CHECK_STATUS(dev, hush_frame_write_exr(f, TMP "/empty_frame.exr", HUSH_EXR_FLOAT),
               HUSH_ERROR_INVALID_ARGUMENT, "no layers");
  /* long layer names need EXR long-name support, and work */
  const char *long_name = "a_rather_long_layer_name_for_an_arbitrary_output_variable";
  REQUIRE(hush_frame_add_layer(f, long_name, 3, NULL) == HUSH_OK);
  CHECK_STATUS(dev, hush_frame_write_exr(f, TMP "/long.exr", HUSH_EXR_HALF), HUSH_OK, "");
  hush_frame g = NULL;
  CHECK_STATUS(dev, hush_frame_read_exr(dev, TMP "/long.exr", &g), HUSH_OK, "");
  CHECK(g && hush_frame_get_layer(g, long_name, NULL) == HUSH_OK);
  hush_frame_release(g);
  hush_frame_release(f);
  CHECK(count_temp_files(TMP) == 0);
}

/* ------------------------------------------------------------------------ */
/* EXR written by OpenEXR: tiled, compressions, uint, grouping rules        */
/* ------------------------------------------------------------------------ */

typedef struct core_channel {
  const char *name;
  exr_pixel_type_t type;
} core_channel;

static float core_value(exr_pixel_type_t type, int c, int x, int y) {
  const int v = (c * 7 + x * 3 + y * 5) % 256;
  return type == EXR_PIXEL_UINT ? (float)(v * 1000 + c) : (float)v * 0.5f;
}

static void silent(exr_const_context_t ctxt, exr_result_t code, const char *msg) {
  (void)ctxt;
  (void)code;
  (void)msg;
}

/* Encodes one chunk from per-channel planes (each in its own type). */
static int core_encode(exr_context_t ctx, exr_encode_pipeline_t *enc, const exr_chunk_info_t *ci,
                       int first, const core_channel *chans, int n, uint8_t *const *planes, int w,
                       int x0, int y0) {
  if ((first ? exr_encoding_initialize(ctx, 0, ci, enc) : exr_encoding_update(ctx, 0, ci, enc)) !=
      EXR_ERR_SUCCESS)
    return 0;
  for (int c = 0; c < enc->channel_count; c++) {
    int k = 0;
    while (k < n && strcmp(chans[k].name, enc->channels[c].channel_name) != 0) k++;
    if (k == n) return 0;
    const int bpe = chans[k].type == EXR_PIXEL_HALF ? 2 : 4;
    enc->channels[c].encode_from_ptr =
        planes[k] + ((size_t)y0 * (size_t)w + (size_t)x0) * (size_t)bpe;
    enc->channels[c].user_pixel_stride = bpe;
    enc->channels[c].user_line_stride = w * bpe;
    enc->channels[c].user_bytes_per_element = (int16_t)bpe;
    enc->channels[c].user_data_type = (uint16_t)chans[k].type;
  }
  if (first && exr_encoding_choose_default_routines(ctx, 0, enc) != EXR_ERR_SUCCESS) return 0;
  return exr_encoding_run(ctx, 0, enc) == EXR_ERR_SUCCESS;
}

/* Writes a w x h single-part file with OpenEXR. display_extra grows the
 * display window past the data window. */
static int write_core_exr(const char *path, exr_storage_t storage, exr_compression_t comp, int w,
                          int h, const core_channel *chans, int n, int display_extra) {
  exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
  init.error_handler_fn = silent;
  exr_context_t ctx = NULL;
  int part = 0, ok = 1;
  if (exr_start_write(&ctx, path, EXR_WRITE_FILE_DIRECTLY, &init) != EXR_ERR_SUCCESS) return 0;
  ok = exr_add_part(ctx, "test", storage, &part) == EXR_ERR_SUCCESS &&
       exr_initialize_required_attr_simple(ctx, part, w, h, comp) == EXR_ERR_SUCCESS;
  if (ok && display_extra) {
    exr_attr_box2i_t disp = {{{{0, 0}}}, {{{w - 1 + display_extra, h - 1}}}};
    ok = exr_set_display_window(ctx, part, &disp) == EXR_ERR_SUCCESS;
  }
  if (ok && storage == EXR_STORAGE_TILED)
    ok = exr_set_tile_descriptor(ctx, part, 16, 16, EXR_TILE_ONE_LEVEL, EXR_TILE_ROUND_DOWN) ==
         EXR_ERR_SUCCESS;
  for (int c = 0; ok && c < n; c++)
    ok = exr_add_channel(ctx, part, chans[c].name, chans[c].type, EXR_PERCEPTUALLY_LOGARITHMIC, 1,
                         1) == EXR_ERR_SUCCESS;
  ok = ok && exr_write_header(ctx) == EXR_ERR_SUCCESS;

  uint8_t *planes[16] = {0};
  for (int c = 0; ok && c < n; c++) {
    planes[c] = malloc((size_t)w * (size_t)h * 4);
    for (int y = 0; y < h; y++)
      for (int x = 0; x < w; x++) {
        const float v = core_value(chans[c].type, c, x, y);
        const size_t i = (size_t)y * (size_t)w + (size_t)x;
        if (chans[c].type == EXR_PIXEL_HALF) {
          const uint16_t hv = hush__float_to_half(v);
          memcpy(planes[c] + 2 * i, &hv, 2);
        } else if (chans[c].type == EXR_PIXEL_UINT) {
          const uint32_t u = (uint32_t)v;
          memcpy(planes[c] + 4 * i, &u, 4);
        } else {
          memcpy(planes[c] + 4 * i, &v, 4);
        }
      }
  }
  exr_encode_pipeline_t enc = EXR_ENCODE_PIPELINE_INITIALIZER;
  exr_chunk_info_t ci;
  int first = 1;
  if (ok && storage == EXR_STORAGE_TILED) {
    for (int ty = 0; ok && ty * 16 < h; ty++)
      for (int tx = 0; ok && tx * 16 < w; tx++, first = 0)
        ok = exr_write_tile_chunk_info(ctx, part, tx, ty, 0, 0, &ci) == EXR_ERR_SUCCESS &&
             core_encode(ctx, &enc, &ci, first, chans, n, planes, w, tx * 16, ty * 16);
  } else if (ok) {
    int32_t lines = 1;
    ok = exr_get_scanlines_per_chunk(ctx, part, &lines) == EXR_ERR_SUCCESS;
    for (int y = 0; ok && y < h; y += lines, first = 0)
      ok = exr_write_scanline_chunk_info(ctx, part, y, &ci) == EXR_ERR_SUCCESS &&
           core_encode(ctx, &enc, &ci, first, chans, n, planes, w, 0, y);
  }
  if (!first) exr_encoding_destroy(ctx, &enc);
  for (int c = 0; c < n; c++) free(planes[c]);
  return exr_finish(&ctx) == EXR_ERR_SUCCESS && ok;
}

/* Checks that channel c of a core file landed in layer/comp. */
static int core_channel_ok(hush_frame f, const char *layer, int comp, exr_pixel_type_t type,
                           int c) {
  int nc = 0;
  const float *p = layer_pixels(f, layer, &nc);
  if (!p || comp >= nc) {
    fprintf(stderr, "  no layer '%s' with component %d\n", layer, comp);
    return 0;
  }
  const int w = (int)hush_frame_width(f), h = (int)hush_frame_height(f);
  for (int y = 0; y < h; y++)
    for (int x = 0; x < w; x++)
      if (p[((size_t)y * (size_t)w + (size_t)x) * (size_t)nc + (size_t)comp] !=
          core_value(type, c, x, y)) {
        fprintf(stderr, "  %s[%d] at (%d, %d): %g, expected %g\n", layer, comp, x, y,
                (double)p[((size_t)y * (size_t)w + (size_t)x) * (size_t)nc + (size_t)comp],
                (double)core_value(type, c, x, y));
        return 0;
      }
  return 1;
}

static void test_exr_core_files(hush_device dev) {
  /* Half RGBA, tiled, PIZ: the 4-channel half case OpenEXR 3.1 unpacks in
   * the wrong order; our own unpacking must get it right. */
  const core_channel rgba[] = {
      {"A", EXR_PIXEL_HALF}, {"B", EXR_PIXEL_HALF}, {"G", EXR_PIXEL_HALF}, {"R", EXR_PIXEL_HALF}};
  const exr_compression_t comps[] = {EXR_COMPRESSION_NONE, EXR_COMPRESSION_RLE,
                                     EXR_COMPRESSION_ZIPS, EXR_COMPRESSION_ZIP,
                                     EXR_COMPRESSION_PIZ,  EXR_COMPRESSION_PXR24};
  for (int t = 0; t < 2; t++) {
    for (size_t k = 0; k < sizeof comps / sizeof comps[0]; k++) {
      const exr_storage_t storage = t ? EXR_STORAGE_TILED : EXR_STORAGE_SCANLINE;
      REQUIRE(write_core_exr(TMP "/core_rgba.exr", storage, comps[k], 37, 41, rgba, 4, 0));
      hush_frame f = NULL;
      CHECK_STATUS(dev, hush_frame_read_exr(dev, TMP "/core_rgba.exr", &f), HUSH_OK, "");
      REQUIRE(f);
      CHECK(hush_frame_layer_count(f) == 1);
      CHECK_MSG(core_channel_ok(f, "color", 0, EXR_PIXEL_HALF, 3) &&
                    core_channel_ok(f, "color", 1, EXR_PIXEL_HALF, 2) &&
                    core_channel_ok(f, "color", 2, EXR_PIXEL_HALF, 1) &&
                    core_channel_ok(f, "color", 3, EXR_PIXEL_HALF, 0),
                "storage %d compression %d", (int)storage, (int)comps[k]);
      hush_frame_release(f);
    }
  }

  /* Mixed types and the grouping rules. */
  const core_channel mixed[] = {
      {"B", EXR_PIXEL_FLOAT},           {"G", EXR_PIXEL_FLOAT},     {"R", EXR_PIXEL_FLOAT},
      {"Z", EXR_PIXEL_FLOAT},           {"id", EXR_PIXEL_UINT},     {"N.X", EXR_PIXEL_HALF},
      {"N.Y", EXR_PIXEL_HALF},          {"N.Z", EXR_PIXEL_HALF},    {"motion.U", EXR_PIXEL_HALF},
      {"motion.V", EXR_PIXEL_HALF},     {"odd.G", EXR_PIXEL_HALF},  {"mix.R", EXR_PIXEL_FLOAT},
      {"mix.X", EXR_PIXEL_FLOAT},       {"taken", EXR_PIXEL_FLOAT}, {"taken.R", EXR_PIXEL_FLOAT},
      {"custom.stuff", EXR_PIXEL_FLOAT}};
  const int nmixed = (int)(sizeof mixed / sizeof mixed[0]);
  REQUIRE(write_core_exr(TMP "/core_mixed.exr", EXR_STORAGE_SCANLINE, EXR_COMPRESSION_ZIP, 19, 33,
                         mixed, nmixed, 0));
  hush_frame f = NULL;
  CHECK_STATUS(dev, hush_frame_read_exr(dev, TMP "/core_mixed.exr", &f), HUSH_OK, "");
  REQUIRE(f);
  CHECK(core_channel_ok(f, "color", 0, EXR_PIXEL_FLOAT, 2));
  CHECK(core_channel_ok(f, "color", 2, EXR_PIXEL_FLOAT, 0));
  CHECK(core_channel_ok(f, "depth", 0, EXR_PIXEL_FLOAT, 3));
  CHECK(core_channel_ok(f, "id", 0, EXR_PIXEL_UINT, 4));
  CHECK(core_channel_ok(f, "normal", 0, EXR_PIXEL_HALF, 5));
  CHECK(core_channel_ok(f, "normal", 2, EXR_PIXEL_HALF, 7));
  CHECK(core_channel_ok(f, "motion", 1, EXR_PIXEL_HALF, 9));
  CHECK(core_channel_ok(f, "odd.G", 0, EXR_PIXEL_HALF, 10));  /* G without R */
  CHECK(core_channel_ok(f, "mix.R", 0, EXR_PIXEL_FLOAT, 11)); /* mixed families */
  CHECK(core_channel_ok(f, "mix.X", 0, EXR_PIXEL_FLOAT, 12));
  CHECK(core_channel_ok(f, "taken", 0, EXR_PIXEL_FLOAT, 13)); /* name already used */
  CHECK(core_channel_ok(f, "taken.R", 0, EXR_PIXEL_FLOAT, 14));
  CHECK(core_channel_ok(f, "custom.stuff", 0, EXR_PIXEL_FLOAT, 15));
  int nc = 0;
  CHECK(layer_pixels(f, "color", &nc) && nc == 3);
  CHECK(layer_pixels(f, "motion", &nc) && nc == 2);
  CHECK(hush_frame_layer_count(f) == 11);
  hush_frame_release(f);

  /* Windows that do not match. */
  const core_channel y_only[] = {{"Y", EXR_PIXEL_HALF}};
  REQUIRE(write_core_exr(TMP "/core_window.exr", EXR_STORAGE_SCANLINE, EXR_COMPRESSION_ZIP, 8, 8,
                         y_only, 1, 3));
  f = NULL;
  CHECK_STATUS(dev, hush_frame_read_exr(dev, TMP "/core_window.exr", &f), HUSH_ERROR_UNSUPPORTED,
               "display window");
  CHECK(f == NULL);
  REQUIRE(write_core_exr(TMP "/core_y.exr", EXR_STORAGE_TILED, EXR_COMPRESSION_RLE, 8, 8, y_only, 1,
                         0));
  CHECK_STATUS(dev, hush_frame_read_exr(dev, TMP "/core_y.exr", &f), HUSH_OK, "");
  CHECK(f && core_channel_ok(f, "Y", 0, EXR_PIXEL_HALF, 0));
  hush_frame_release(f);
}

/* ------------------------------------------------------------------------ */
/* PNG and PFM                                                              */
/* ------------------------------------------------------------------------ */

/* Reads back a written PNG and compares it, in sRGB space, with the
 * expected display transform of src (n channels shown of sc in src). */
static void check_png(hush_device dev, const char *path, const float *src, int sc, int n,
                      uint32_t w, uint32_t h, float exposure, hush_tonemap op) {
  hush_frame f = NULL;
  CHECK_STATUS(dev, hush_frame_read_png(dev, path, "pic", &f), HUSH_OK, "");
  REQUIRE(f);
  int nc = 0;
  const float *p = layer_pixels(f, "pic", &nc);
  CHECK(nc == n);
  double worst = 0;
  for (size_t i = 0; i < (size_t)w * h; i++)
    for (int c = 0; c < n; c++) {
      const float want =
          hush__srgb_encode(hush__tonemap(src[i * (size_t)sc + (size_t)c] * exp2f(exposure), op));
      const double d = fabs((double)hush__srgb_encode(p[i * (size_t)n + (size_t)c]) - want);
      if (d > worst) worst = d;
    }
  CHECK_MSG(worst <= 1.0 / 255 + 1e-6, "%s: worst sRGB error %g", path, worst);
  hush_frame_release(f);
}

static void test_png(hush_device dev) {
  const uint32_t w = 29, h = 17;
  float *rgba = malloc((size_t)w * h * 4 * sizeof *rgba);
  for (size_t i = 0; i < (size_t)w * h * 4; i++) rgba[i] = rnd() * 4.0f - 0.5f;
  hush_image_view v = {rgba, HUSH_FORMAT_FLOAT4, w, h, 0, 0, 0};
  const hush_tonemap ops[] = {HUSH_TONEMAP_CLAMP, HUSH_TONEMAP_REINHARD, HUSH_TONEMAP_ACES};
  for (int k = 0; k < 3; k++) {
    CHECK_STATUS(dev, hush_image_write_png(dev, &v, TMP "/rgb.png", 0.5f, ops[k]), HUSH_OK, "");
    check_png(dev, TMP "/rgb.png", rgba, 4, 3, w, h, 0.5f, ops[k]);
  }
  /* gray: one channel of a strided view */
  hush_image_view gray = {rgba, HUSH_FORMAT_FLOAT, w, h, 4, 16, 0};
  CHECK_STATUS(dev, hush_image_write_png(dev, &gray, TMP "/gray.png", -1.0f, HUSH_TONEMAP_ACES),
               HUSH_OK, "");
  check_png(dev, TMP "/gray.png", rgba + 1, 4, 1, w, h, -1.0f, HUSH_TONEMAP_ACES);

  hush_image_view two = {rgba, HUSH_FORMAT_FLOAT2, w, h, 0, 0, 0};
  CHECK_STATUS(dev, hush_image_write_png(dev, &two, TMP "/two.png", 0, HUSH_TONEMAP_CLAMP),
               HUSH_ERROR_INVALID_ARGUMENT, "1, 3 or 4");
  CHECK_STATUS(dev, hush_image_write_png(dev, &v, TMP "/x.png", 0, (hush_tonemap)9),
               HUSH_ERROR_INVALID_ARGUMENT, "tone");
  CHECK_STATUS(dev, hush_image_write_png(dev, &v, TMP "/x.png", NAN, HUSH_TONEMAP_CLAMP),
               HUSH_ERROR_INVALID_ARGUMENT, "exposure");
  hush_frame f = NULL;
  CHECK_STATUS(dev, hush_frame_read_png(dev, TMP "/rgb.png", "", &f), HUSH_ERROR_INVALID_ARGUMENT,
               "layer name");
  CHECK(f == NULL);
  free(rgba);
}

/* 16-bit gray + alpha and 4-bit palette PNGs, written with libpng. */
static void write_png_raw(const char *path, int color_type, int depth, const uint8_t *rows,
                          size_t row_bytes, uint32_t w, uint32_t h) {
  FILE *fp = fopen(path, "wb");
  REQUIRE(fp);
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, NULL, NULL, NULL);
  png_infop info = png_create_info_struct(png);
  REQUIRE(png && info && !setjmp(png_jmpbuf(png)));
  png_init_io(png, fp);
  png_set_IHDR(png, info, w, h, depth, color_type, PNG_INTERLACE_ADAM7,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  if (color_type == PNG_COLOR_TYPE_PALETTE) {
    png_color palette[16];
    for (int i = 0; i < 16; i++) {
      palette[i].red = (png_byte)(i * 17);
      palette[i].green = (png_byte)(255 - i * 17);
      palette[i].blue = (png_byte)(i * 5);
    }
    png_set_PLTE(png, info, palette, 16);
    png_byte alpha[2] = {0, 128};
    png_set_tRNS(png, info, alpha, 2, NULL);
  }
  png_write_info(png, info);
  const int passes = png_set_interlace_handling(png);
  for (int pass = 0; pass < passes; pass++)
    for (uint32_t y = 0; y < h; y++) png_write_row(png, rows + y * row_bytes);
  png_write_end(png, NULL);
  png_destroy_write_struct(&png, &info);
  fclose(fp);
}

static void test_png_formats(hush_device dev) {
  const uint32_t w = 7, h = 5;
  uint8_t ga16[7 * 5 * 4];
  for (uint32_t i = 0; i < w * h; i++) {
    const unsigned v = i * 1871u;
    ga16[4 * i] = (uint8_t)(v >> 8);
    ga16[4 * i + 1] = (uint8_t)v;
    ga16[4 * i + 2] = 0x12; /* alpha, dropped */
    ga16[4 * i + 3] = 0x34;
  }
  write_png_raw(TMP "/ga16.png", PNG_COLOR_TYPE_GRAY_ALPHA, 16, ga16, w * 4, w, h);
  hush_frame f = NULL;
  CHECK_STATUS(dev, hush_frame_read_png(dev, TMP "/ga16.png", "g", &f), HUSH_OK, "");
  REQUIRE(f);
  int nc = 0;
  const float *p = layer_pixels(f, "g", &nc);
  CHECK(nc == 1);
  CHECK_NEAR(p[9], hush__srgb_decode((float)((9 * 1871u) & 0xffff) / 65535.0f), 1e-6);
  hush_frame_release(f);

  uint8_t pal[5][4]; /* 4-bit indices, 7 pixels a row */
  for (uint32_t y = 0; y < h; y++)
    for (uint32_t x = 0; x < 4; x++)
      pal[y][x] = (uint8_t)(((2 * x + y) % 16) << 4 | ((2 * x + 1 + y) % 16));
  write_png_raw(TMP "/pal.png", PNG_COLOR_TYPE_PALETTE, 4, &pal[0][0], 4, w, h);
  CHECK_STATUS(dev, hush_frame_read_png(dev, TMP "/pal.png", "c", &f), HUSH_OK, "");
  REQUIRE(f);
  p = layer_pixels(f, "c", &nc);
  CHECK(nc == 3);
  const int index = (3 + 2) % 16; /* pixel (3, 2) */
  CHECK_NEAR(p[(2 * w + 3) * 3 + 0], hush__srgb_decode((float)(index * 17) / 255.0f), 1e-6);
  CHECK_NEAR(p[(2 * w + 3) * 3 + 1], hush__srgb_decode((float)(255 - index * 17) / 255.0f), 1e-6);
  CHECK_NEAR(p[(2 * w + 3) * 3 + 2], hush__srgb_decode((float)(index * 5) / 255.0f), 1e-6);
  hush_frame_release(f);

  /* a header of 20000 x 20000 (each side allowed, 4e8 pixels too many)
   * and a token IDAT: refused before any pixel is allocated */
  FILE *fp = fopen(TMP "/huge.png", "wb");
  REQUIRE(fp);
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, NULL, NULL, NULL);
  png_infop info = png_create_info_struct(png);
  REQUIRE(png && info && !setjmp(png_jmpbuf(png)));
  png_init_io(png, fp);
  png_set_IHDR(png, info, 20000, 20000, 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  png_byte token[8] = {0};
  png_write_chunk(png, (png_const_bytep) "IDAT", token, sizeof token);
  png_destroy_write_struct(&png, &info);
  fclose(fp);
  f = NULL;
  CHECK_STATUS(dev, hush_frame_read_png(dev, TMP "/huge.png", "c", &f), HUSH_ERROR_UNSUPPORTED,
               "20000x20000");
  CHECK(f == NULL);
}

static void test_pfm(hush_device dev) {
  const uint32_t w = 13, h = 6;
  float data[13 * 6 * 3];
  for (size_t i = 0; i < sizeof data / sizeof data[0]; i++) data[i] = (rnd() - 0.5f) * 1e4f;
  data[0] = NAN; /* PFM keeps anything */
  for (int ch = 1; ch <= 3; ch += 2) {
    hush_image_view v = {data, ch == 1 ? HUSH_FORMAT_FLOAT : HUSH_FORMAT_FLOAT3, w, h, 0, 0, 0};
    CHECK_STATUS(dev, hush_image_write_pfm(dev, &v, TMP "/x.pfm"), HUSH_OK, "");
    CHECK(file_size(TMP "/x.pfm") == (long)(w * h * (uint32_t)ch * 4) + 13);
    hush_frame f = NULL;
    CHECK_STATUS(dev, hush_frame_read_pfm(dev, TMP "/x.pfm", "img", &f), HUSH_OK, "");
    REQUIRE(f);
    int nc = 0;
    const float *p = layer_pixels(f, "img", &nc);
    CHECK(nc == ch && memcmp(p, data, w * h * (size_t)ch * 4) == 0);
    hush_frame_release(f);
  }
  /* The first row in the file is the bottom of the image. */
  size_t n = 0;
  uint8_t *bytes = read_bytes(TMP "/x.pfm", &n);
  REQUIRE(bytes);
  CHECK(memcmp(bytes, "PF\n13 6\n-1.0\n", 13) == 0);
  float first;
  memcpy(&first, bytes + 13, 4);
  CHECK(first == data[(size_t)(h - 1) * w * 3]);
  free(bytes);

  /* Big-endian, written by hand: 2x1 gray, scale +1. */
  uint8_t be[] = {'P',  'f',  '\n', '2',  ' ',  '1',  '\n', '1',  '.', '0',
                  '\n', 0x3f, 0x80, 0x00, 0x00, 0xc0, 0x00, 0x00, 0x00};
  write_bytes(TMP "/be.pfm", be, sizeof be);
  hush_frame f = NULL;
  CHECK_STATUS(dev, hush_frame_read_pfm(dev, TMP "/be.pfm", "img", &f), HUSH_OK, "");
  REQUIRE(f);
  const float *p = layer_pixels(f, "img", NULL);
  CHECK(p[0] == 1.0f && p[1] == -2.0f);
  hush_frame_release(f);
}

/* Views with strides, offsets and half pixels, through PFM (exact) and EXR. */
static void test_views_with_strides(hush_device dev) {
  const uint32_t w = 11, h = 7;
  const size_t ps = 5 * sizeof(float), rs = ps * w + 12, offset = 8;
  uint8_t *buf = calloc(1, offset + rs * h);
  for (uint32_t y = 0; y < h; y++)
    for (uint32_t x = 0; x < w; x++)
      for (int c = 0; c < 3; c++) {
        const float v = (float)(y * 100 + x * 10 + (uint32_t)c);
        memcpy(buf + offset + y * rs + x * ps + (size_t)c * 4, &v, 4);
      }
  hush_image_view v = {buf, HUSH_FORMAT_FLOAT3, w, h, offset, ps, rs};
  CHECK_STATUS(dev, hush_image_write_pfm(dev, &v, TMP "/strided.pfm"), HUSH_OK, "");
  hush_frame f = NULL;
  CHECK_STATUS(dev, hush_frame_read_pfm(dev, TMP "/strided.pfm", "color", &f), HUSH_OK, "");
  REQUIRE(f);
  const float *p = layer_pixels(f, "color", NULL);
  int bad = 0;
  for (uint32_t y = 0; y < h; y++)
    for (uint32_t x = 0; x < w; x++)
      for (int c = 0; c < 3; c++)
        if (p[(y * w + x) * 3 + (uint32_t)c] != (float)(y * 100 + x * 10 + (uint32_t)c)) bad++;
  CHECK(bad == 0);
  /* and through an EXR: frame -> file -> frame */
  CHECK_STATUS(dev, hush_frame_write_exr(f, TMP "/strided.exr", HUSH_EXR_HALF), HUSH_OK, "");
  hush_frame g = NULL;
  CHECK_STATUS(dev, hush_frame_read_exr(dev, TMP "/strided.exr", &g), HUSH_OK, "");
  CHECK(g && frames_identical(f, g)); /* small integers are exact in half */
  hush_frame_release(g);
  hush_frame_release(f);

  /* a half view with padding */
  uint16_t halves[3 * 2 * 4];
  for (int i = 0; i < 24; i++) halves[i] = hush__float_to_half((float)i * 0.25f);
  hush_image_view hv = {halves, HUSH_FORMAT_HALF3, 3, 2, 0, 8, 24};
  CHECK_STATUS(dev, hush_image_write_pfm(dev, &hv, TMP "/half.pfm"), HUSH_OK, "");
  CHECK_STATUS(dev, hush_frame_read_pfm(dev, TMP "/half.pfm", "h", &f), HUSH_OK, "");
  REQUIRE(f);
  p = layer_pixels(f, "h", NULL);
  CHECK(p[0] == 0.0f && p[3] == 1.0f && p[5] == 1.5f && p[9] == 3.0f && p[17] == 5.5f);
  hush_frame_release(f);
  free(buf);
}

/* ------------------------------------------------------------------------ */
/* Bad input                                                                */
/* ------------------------------------------------------------------------ */

static void test_bad_files(hush_device dev) {
  hush_frame f = NULL;
  CHECK_STATUS(dev, hush_frame_read_exr(dev, TMP "/missing.exr", &f), HUSH_ERROR_IO,
               "cannot open '" TMP "/missing.exr': No such file or directory");
  CHECK(f == NULL);
  CHECK_STATUS(dev, hush_frame_read_png(dev, TMP "/missing.png", "c", &f), HUSH_ERROR_IO,
               "missing.png': No such file");
  CHECK_STATUS(dev, hush_frame_read_pfm(dev, TMP "/missing.pfm", "c", &f), HUSH_ERROR_IO,
               "missing.pfm': No such file");
  CHECK_STATUS(dev, hush_frame_read_exr(dev, TMP, &f), HUSH_ERROR_IO, "directory");

  write_bytes(TMP "/empty", "", 0);
  CHECK_STATUS(dev, hush_frame_read_exr(dev, TMP "/empty", &f), HUSH_ERROR_CORRUPT, "/empty");
  CHECK_STATUS(dev, hush_frame_read_png(dev, TMP "/empty", "c", &f), HUSH_ERROR_CORRUPT, "/empty");
  CHECK_STATUS(dev, hush_frame_read_pfm(dev, TMP "/empty", "c", &f), HUSH_ERROR_CORRUPT, "/empty");

  uint8_t garbage[4096];
  for (size_t i = 0; i < sizeof garbage; i++) garbage[i] = (uint8_t)(rnd() * 256);
  write_bytes(TMP "/garbage", garbage, sizeof garbage);
  CHECK_STATUS(dev, hush_frame_read_exr(dev, TMP "/garbage", &f), HUSH_ERROR_CORRUPT, "/garbage");
  CHECK_STATUS(dev, hush_frame_read_png(dev, TMP "/garbage", "c", &f), HUSH_ERROR_CORRUPT,
               "/garbage");
  CHECK_STATUS(dev, hush_frame_read_pfm(dev, TMP "/garbage", "c", &f), HUSH_ERROR_CORRUPT,
               "/garbage");
  /* garbage after a valid EXR magic number */
  garbage[0] = 0x76, garbage[1] = 0x2f, garbage[2] = 0x31, garbage[3] = 0x01;
  garbage[4] = 2, garbage[5] = garbage[6] = garbage[7] = 0;
  write_bytes(TMP "/garbage.exr", garbage, sizeof garbage);
  CHECK_STATUS(dev, hush_frame_read_exr(dev, TMP "/garbage.exr", &f), HUSH_ERROR_CORRUPT,
               "garbage.exr");

  /* Truncated EXR files: a real multi-layer frame cut to half, and to 100
   * bytes (inside the header). */
  hush_frame big = make_frame(dev, 64, 64, all_layers, all_channels, ALL_LAYERS);
  CHECK_STATUS(dev, hush_frame_write_exr(big, TMP "/trunc.exr", HUSH_EXR_FLOAT), HUSH_OK, "");
  hush_frame_release(big);
  const long full = file_size(TMP "/trunc.exr");
  REQUIRE(full > 1000);
  REQUIRE(truncate(TMP "/trunc.exr", full / 2) == 0);
  CHECK_STATUS(dev, hush_frame_read_exr(dev, TMP "/trunc.exr", &f), HUSH_ERROR_CORRUPT,
               "trunc.exr': cannot read scanlines");
  CHECK(f == NULL);
  REQUIRE(truncate(TMP "/trunc.exr", 100) == 0);
  CHECK_STATUS(dev, hush_frame_read_exr(dev, TMP "/trunc.exr", &f), HUSH_ERROR_CORRUPT,
               "trunc.exr': not a readable OpenEXR file");

  /* A damaged chunk: flip bytes in the middle of the compressed pixels
   * (smooth, so that ZIP does compress them and checks its stream). */
  big = make_frame(dev, 64, 64, all_layers, all_channels, 1);
  float *smooth = layer_pixels(big, "color", NULL);
  for (int i = 0; i < 64 * 64 * 3; i++) smooth[i] = (float)((i * 7) % 97) * 0.25f;
  CHECK_STATUS(dev, hush_frame_write_exr(big, TMP "/damaged.exr", HUSH_EXR_FLOAT), HUSH_OK, "");
  hush_frame_release(big);
  size_t n = 0;
  uint8_t *bytes = read_bytes(TMP "/damaged.exr", &n);
  REQUIRE(bytes && n > 2000);
  for (size_t i = n / 2; i < n / 2 + 64; i++) bytes[i] ^= 0x5a;
  write_bytes(TMP "/damaged.exr", bytes, n);
  free(bytes);
  CHECK_STATUS(dev, hush_frame_read_exr(dev, TMP "/damaged.exr", &f), HUSH_ERROR_CORRUPT,
               "damaged.exr': cannot read scanlines");

  /* A PNG that is text, and one cut short. */
  write_text(TMP "/text.png", "this is not a picture, just some words\n");
  CHECK_STATUS(dev, hush_frame_read_png(dev, TMP "/text.png", "c", &f), HUSH_ERROR_CORRUPT,
               "text.png' is not a PNG");
  bytes = read_bytes(TMP "/rgb.png", &n);
  REQUIRE(bytes);
  write_bytes(TMP "/cut.png", bytes, n / 2);
  free(bytes);
  CHECK_STATUS(dev, hush_frame_read_png(dev, TMP "/cut.png", "c", &f), HUSH_ERROR_CORRUPT,
               "cut.png': corrupt PNG");

  /* PFM headers. */
  static const char *const bad_headers[] = {
      "PX\n2 2\n-1.0\n", "PF\n-3 4\n-1.0\n",       "PF\n3 4\n0\n",     "PF\n70000 2\n-1.0\n",
      "PF\n3 4\n-1.0",   " PF\n3 4\n-1.0\n",       "PF\n3 x4\n-1.0\n", "PF\n3 4\nnan\n",
      "PF\n0 4\n-1.0\n", "PF\n16384 16385\n-1.0\n"};
  for (size_t i = 0; i < sizeof bad_headers / sizeof bad_headers[0]; i++) {
    write_text(TMP "/bad.pfm", bad_headers[i]);
    CHECK_STATUS(dev, hush_frame_read_pfm(dev, TMP "/bad.pfm", "c", &f), HUSH_ERROR_CORRUPT,
                 "bad.pfm");
  }
  write_text(TMP "/short.pfm", "Pf\n4 4\n-1.0\n0123456789");
  CHECK_STATUS(dev, hush_frame_read_pfm(dev, TMP "/short.pfm", "c", &f), HUSH_ERROR_CORRUPT,
               "short.pfm': truncated");
  CHECK(f == NULL);
}

/* A failed write leaves the old file as it was and no temporary file. */
static void test_failed_writes(hush_device dev) {
  float px[4 * 4 * 3];
  for (int i = 0; i < 48; i++) px[i] = (float)i / 48.0f;
  hush_image_view v = {px, HUSH_FORMAT_FLOAT3, 4, 4, 0, 0, 0};
  CHECK_STATUS(dev, hush_image_write_png(dev, &v, TMP "/keep.png", 0, HUSH_TONEMAP_CLAMP), HUSH_OK,
               "");
  CHECK_STATUS(dev, hush_image_write_pfm(dev, &v, TMP "/keep.pfm"), HUSH_OK, "");
  size_t n_png = 0, n_pfm = 0, n;
  uint8_t *old_png = read_bytes(TMP "/keep.png", &n_png);
  uint8_t *old_pfm = read_bytes(TMP "/keep.pfm", &n_pfm);
  REQUIRE(old_png && old_pfm);

  px[3 * 6 + 1] = NAN; /* pixel (2, 1) channel 1 */
  CHECK_STATUS(dev, hush_image_write_png(dev, &v, TMP "/keep.png", 0, HUSH_TONEMAP_CLAMP),
               HUSH_ERROR_NONFINITE, "keep.png': pixel (2, 1) channel 1 is NaN");
  px[3 * 6 + 1] = -INFINITY;
  CHECK_STATUS(dev, hush_image_write_png(dev, &v, TMP "/keep.png", 0, HUSH_TONEMAP_ACES),
               HUSH_ERROR_NONFINITE, "infinite");
  uint8_t *now = read_bytes(TMP "/keep.png", &n);
  CHECK(now && n == n_png && memcmp(now, old_png, n) == 0);
  free(now);

  /* an invalid view fails before anything is written */
  hush_image_view broken = v;
  broken.data = NULL;
  CHECK_STATUS(dev, hush_image_write_pfm(dev, &broken, TMP "/keep.pfm"),
               HUSH_ERROR_INVALID_ARGUMENT, "NULL");
  now = read_bytes(TMP "/keep.pfm", &n);
  CHECK(now && n == n_pfm && memcmp(now, old_pfm, n) == 0);
  free(now);
  CHECK_STATUS(dev, hush_image_write_png(dev, &v, TMP "/no_dir/keep.png", 0, HUSH_TONEMAP_CLAMP),
               HUSH_ERROR_NONFINITE, "keep.png");
  px[3 * 6 + 1] = 0.5f;
  CHECK_STATUS(dev, hush_image_write_pfm(dev, &v, TMP "/no_dir/keep.pfm"), HUSH_ERROR_IO, "no_dir");
  CHECK_STATUS(dev, hush_image_write_png(dev, &v, TMP "/no_dir/keep.png", 0, HUSH_TONEMAP_CLAMP),
               HUSH_ERROR_IO, "no_dir/keep.png");
  CHECK(count_temp_files(TMP) == 0);
  free(old_png);
  free(old_pfm);
}

/* ------------------------------------------------------------------------ */
/* Sequences                                                                */
/* ------------------------------------------------------------------------ */

static void write_sequence_frames(hush_device dev, const hush_sequence *seq, uint32_t w,
                                  uint32_t h) {
  const char *names[] = {"color", "depth"};
  const int channels[] = {3, 1};
  for (uint32_t i = 0; i < seq->frame_count; i++) {
    char path[HUSH_PATH_MAX];
    REQUIRE(hush__sequence_frame_path(dev, seq, i, path, sizeof path) == HUSH_OK);
    hush_frame f = make_frame(dev, w, h, names, channels, 2);
    REQUIRE(hush_frame_write_exr(f, path, HUSH_EXR_HALF) == HUSH_OK);
    hush_frame_release(f);
  }
}

static void test_sequence(hush_device dev) {
  const char *dir = TMP "/seq";
  REQUIRE(mkdir(dir, 0755) == 0);
  hush_sequence seq;
  CHECK_STATUS(dev, hush__sequence_init(dev, &seq, dir, 8, 6, 3), HUSH_OK, "");
  CHECK(strcmp(seq.files[2], "frame_0002.exr") == 0);
  const float odd[] = {0.1f, 1.0f / 3.0f, -1e-7f, 123456.78f, 1e30f, -0.0f, 1e-38f, 7.0f};
  for (uint32_t i = 0; i < 3; i++) {
    for (int k = 0; k < 16; k++) {
      seq.cameras[i].world_to_view[k] = odd[(k + (int)i) % 8] * (float)(i + 1);
      seq.cameras[i].view_to_clip[k] = rnd() * 2.0f - 1.0f;
    }
    seq.cameras[i].jitter[0] = rnd() - 0.5f;
    seq.cameras[i].jitter[1] = -0.25f;
  }
  seq.motion = HUSH_MOTION_VECTORS;
  write_sequence_frames(dev, &seq, 8, 6);
  CHECK_STATUS(dev, hush__sequence_write_cameras(dev, &seq), HUSH_OK, "");
  CHECK(count_temp_files(dir) == 0);

  hush_sequence back;
  CHECK_STATUS(dev, hush__sequence_read(dev, dir, &back), HUSH_OK, "");
  CHECK(back.width == 8 && back.height == 6 && back.frame_count == 3);
  CHECK(back.motion == HUSH_MOTION_VECTORS);
  CHECK(strcmp(back.dir, dir) == 0);
  for (uint32_t i = 0; i < 3 && back.cameras; i++) {
    CHECK(strcmp(back.files[i], seq.files[i]) == 0);
    CHECK(memcmp(&back.cameras[i], &seq.cameras[i], sizeof(hush_camera)) == 0);
  }
  hush_frame_info info;
  hush__sequence_frame_info(&back, 0, &info);
  CHECK(info.history == HUSH_HISTORY_RESET && info.frame_index == 0);
  CHECK(memcmp(info.prev_world_to_view, info.world_to_view, sizeof info.world_to_view) == 0);
  CHECK(info.motion == HUSH_MOTION_VECTORS);
  hush__sequence_frame_info(&back, 2, &info);
  CHECK(info.history == HUSH_HISTORY_CONTINUE && info.frame_index == 2);
  REQUIRE(back.cameras);
  CHECK(memcmp(info.world_to_view, back.cameras[2].world_to_view, 64) == 0);
  CHECK(memcmp(info.prev_view_to_clip, back.cameras[1].view_to_clip, 64) == 0);
  CHECK(info.jitter[0] == back.cameras[2].jitter[0] && info.prev_jitter[1] == -0.25f);

  hush_frame f = NULL;
  CHECK_STATUS(dev, hush__sequence_read_frame(dev, &back, 1, &f), HUSH_OK, "");
  CHECK(f && hush_frame_width(f) == 8 && hush_frame_get_layer(f, "depth", NULL) == HUSH_OK);
  hush_frame_release(f);
  char path[32];
  CHECK_STATUS(dev, hush__sequence_frame_path(dev, &back, 1, path, sizeof path),
               HUSH_ERROR_INVALID_ARGUMENT, "too long");
  CHECK_STATUS(dev, hush__sequence_frame_path(dev, &back, 3, path, sizeof path),
               HUSH_ERROR_INVALID_ARGUMENT, "no frame 3");

  /* a frame of the wrong size */
  const char *names[] = {"color"};
  const int channels[] = {3};
  f = make_frame(dev, 4, 4, names, channels, 1);
  REQUIRE(hush_frame_write_exr(f, TMP "/seq/frame_0001.exr", HUSH_EXR_HALF) == HUSH_OK);
  hush_frame_release(f);
  f = NULL;
  CHECK_STATUS(dev, hush__sequence_read_frame(dev, &back, 1, &f), HUSH_ERROR_CORRUPT,
               "frame_0001.exr is 4x4, the sequence is 8x6");
  CHECK(f == NULL);

  seq.cameras[1].jitter[0] = NAN;
  CHECK_STATUS(dev, hush__sequence_write_cameras(dev, &seq), HUSH_ERROR_INVALID_ARGUMENT,
               "frames[1].jitter[0]");
  hush__sequence_free(&seq);
  hush__sequence_free(&back);
  hush__sequence_free(&back); /* freeing twice is harmless */
}

typedef struct bad_cameras {
  const char *json;
  hush_status status;
  const char *needle;
} bad_cameras;

static void test_sequence_errors(hush_device dev) {
  const char *dir = TMP "/seqbad";
  REQUIRE(mkdir(dir, 0755) == 0);
  hush_sequence seq;
  CHECK_STATUS(dev, hush__sequence_read(dev, dir, &seq), HUSH_ERROR_IO,
               "seqbad/cameras.json': No such file");
  write_text(TMP "/seqbad/a.exr", "x");
  write_text(TMP "/seqbad/b.exr", "x");

#define HEAD "{\"format\":\"hush-cameras/1\",\"width\":4,\"height\":4,\"motion\":\"camera\","
#define M16 "[1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1]"
#define FRAME(file)                                                                                \
  "{\"file\":\"" file "\",\"world_to_view\":" M16 ",\"view_to_clip\":" M16 ",\"jitter\":[0,0]}"
  static const bad_cameras cases[] = {
      {"this is { not json", HUSH_ERROR_CORRUPT, "cameras.json: not valid JSON"},
      {"[1, 2]", HUSH_ERROR_CORRUPT, "cameras.json: expected a JSON object"},
      {HEAD "\"frame_count\":1,\"frames\":[" FRAME("a.exr") "]} trailing", HUSH_ERROR_CORRUPT,
       "not valid JSON"},
      {"{\"width\":4,\"height\":4,\"frame_count\":1,\"motion\":\"camera\",\"frames\":[" FRAME(
           "a.exr") "]}",
       HUSH_ERROR_CORRUPT, "cameras.json: format: missing"},
      {"{\"format\":\"hush-cameras/2\",\"width\":4}", HUSH_ERROR_UNSUPPORTED,
       "format: 'hush-cameras/2'"},
      {"{\"format\":\"hush-cameras/1\",\"height\":4,\"frame_count\":1}", HUSH_ERROR_CORRUPT,
       "cameras.json: width: missing"},
      {"{\"format\":\"hush-cameras/1\",\"width\":4.5,\"height\":4}", HUSH_ERROR_CORRUPT,
       "width: expected an integer"},
      {"{\"format\":\"hush-cameras/1\",\"width\":\"4\",\"height\":4}", HUSH_ERROR_CORRUPT,
       "width: expected an integer, got a string"},
      {"{\"format\":\"hush-cameras/1\",\"width\":4,\"height\":0}", HUSH_ERROR_CORRUPT,
       "height: expected an integer in 1..65536"},
      {HEAD "\"frame_count\":2,\"frames\":[" FRAME("a.exr") "]}", HUSH_ERROR_CORRUPT,
       "frame_count: is 2 but frames has 1 entries"},
      {HEAD "\"frame_count\":1,\"frames\":{}}", HUSH_ERROR_CORRUPT, "frames: expected an array"},
      {"{\"format\":\"hush-cameras/"
       "1\",\"width\":4,\"height\":4,\"frame_count\":1,\"motion\":\"fast\",\"frames\":[]}",
       HUSH_ERROR_CORRUPT, "motion: 'fast'"},
      {HEAD "\"frame_count\":1,\"frames\":[" FRAME("missing.exr") "]}", HUSH_ERROR_IO,
       "frames[0].file: cannot open '" TMP "/seqbad/missing.exr'"},
      {HEAD "\"frame_count\":1,\"frames\":[" FRAME("../seqbad/a.exr") "]}", HUSH_ERROR_CORRUPT,
       "frames[0].file: '../seqbad/a.exr' is not a plain file name"},
      {HEAD "\"frame_count\":1,\"frames\":[" FRAME("sub/a.exr") "]}", HUSH_ERROR_CORRUPT,
       "not a plain file name"},
      {HEAD "\"frame_count\":1,\"frames\":[{\"world_to_view\":" M16 "}]}", HUSH_ERROR_CORRUPT,
       "frames[0].file: missing"},
      {HEAD "\"frame_count\":2,\"frames\":[" FRAME(
           "a.exr") ",{\"file\":\"b.exr\",\"world_to_view\":[1,0,0,0,0,1,0,0,0,0,1,0,0,0,0],"
                    "\"view_to_clip\":" M16 ",\"jitter\":[0,0]}]}",
       HUSH_ERROR_CORRUPT, "cameras.json: frames[1].world_to_view: expected 16 numbers, got 15"},
      {HEAD "\"frame_count\":1,\"frames\":[{\"file\":\"a.exr\",\"world_to_view\":" M16
            ",\"view_to_clip\":[1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,\"NaN\"],\"jitter\":[0,0]}]}",
       HUSH_ERROR_CORRUPT, "frames[0].view_to_clip: element 15 is a string"},
      {HEAD "\"frame_count\":1,\"frames\":[{\"file\":\"a.exr\",\"world_to_view\":" M16
            ",\"view_to_clip\":" M16 ",\"jitter\":[0,NaN]}]}",
       HUSH_ERROR_CORRUPT, "not valid JSON"},
      {HEAD "\"frame_count\":1,\"frames\":[{\"file\":\"a.exr\",\"world_to_view\":" M16
            ",\"view_to_clip\":" M16 ",\"jitter\":[0,1e39]}]}",
       HUSH_ERROR_CORRUPT, "frames[0].jitter: element 1 (1e+39) is not a finite float"},
      {HEAD "\"frame_count\":1,\"frames\":[{\"file\":\"a.exr\",\"world_to_view\":" M16
            ",\"view_to_clip\":" M16 "}]}",
       HUSH_ERROR_CORRUPT, "frames[0].jitter: missing"},
      {HEAD "\"frame_count\":1,\"frames\":[{\"file\":\"a.exr\",\"world_to_view\":" M16
            ",\"view_to_clip\":" M16 ",\"jitter\":\"0 0\"}]}",
       HUSH_ERROR_CORRUPT, "frames[0].jitter: expected an array of 2 numbers, got a string"},
      {HEAD "\"frame_count\":1,\"frames\":[7]}", HUSH_ERROR_CORRUPT,
       "frames[0]: expected an object"},
  };
  for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
    write_text(TMP "/seqbad/cameras.json", cases[i].json);
    memset(&seq, 0x7f, sizeof seq);
    const hush_status s = hush__sequence_read(dev, dir, &seq);
    CHECK_MSG(expect(dev, s, cases[i].status, cases[i].needle), "case %zu", i);
    CHECK(seq.files == NULL && seq.cameras == NULL && seq.dir == NULL);
  }
  write_text(TMP "/seqbad/cameras.json",
             HEAD "\"frame_count\":2,\"frames\":[" FRAME("a.exr") "," FRAME("b.exr") "]}");
  CHECK_STATUS(dev, hush__sequence_read(dev, dir, &seq), HUSH_OK, "");
  hush_frame f = NULL;
  CHECK_STATUS(dev, hush__sequence_read_frame(dev, &seq, 0, &f), HUSH_ERROR_CORRUPT, "a.exr");
  hush__sequence_free(&seq);
#undef HEAD
#undef M16
#undef FRAME
}

int main(void) {
  remove_tree(TMP);
  REQUIRE(mkdir(TMP, 0755) == 0);
  hush_device dev = hush_device_new(NULL);
  REQUIRE(dev);

  test_frame_api(dev);
  test_exr_float_round_trip(dev);
  test_exr_tiny_round_trips(dev);
  test_exr_channel_names(dev);
  test_exr_half_round_trip(dev);
  test_exr_write_errors(dev);
  test_exr_core_files(dev);
  test_png(dev);
  test_png_formats(dev);
  test_pfm(dev);
  test_views_with_strides(dev);
  test_bad_files(dev);
  test_failed_writes(dev);
  test_sequence(dev);
  test_sequence_errors(dev);

  CHECK(count_temp_files(TMP) == 0);
  CHECK(hush_device_get_error(dev, NULL) == HUSH_OK);
  hush_device_release(dev);
  return check_summary();
}
