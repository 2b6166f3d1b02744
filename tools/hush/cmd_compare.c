/*
 * cmd_compare.c — `hush compare A.exr B.exr`: how far a render is from a
 * reference made elsewhere (e.g. living-room/TungstenRender.exr): the mean
 * luminance of both and their ratio, the RMSE of the colour and of the
 * luminance, and optionally both images side by side in one PNG, tone
 * mapped the same way.
 *
 * Sizes may differ by an integer factor: the larger image is box-filtered
 * down to the smaller one first, so a low-resolution render can be checked
 * against a full-resolution reference (the noise of the smaller one then
 * remains in the RMSE).
 */
#include "cli.h"
#include "core/hmath.h"
#include "eval/metrics.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *const help_text =
    "usage: hush compare A.exr B.exr [options]\n"
    "\n"
    "Compares one layer of two EXR images (B is the reference) and prints the\n"
    "mean luminance of each, their ratio A/B, and the RMSE of the colour and of\n"
    "the luminance. If the sizes differ by an integer factor, the larger image\n"
    "is box-filtered down to the size of the smaller one.\n"
    "\n"
    "options:\n"
    "  --layer NAME         the layer of both images (default color)\n"
    "  --downsample N       box-filter both by N first, 1..64 (default 1)\n"
    "  --side-by-side PNG   also write A | B side by side as one PNG\n"
    "  --exposure E         for the PNG: radiance * 2^E, -64..64 (default 0)\n"
    "  --tonemap T          for the PNG: clamp, reinhard or aces (default aces)\n"
    "  -h, --help           show this help\n";

/* One layer as 3 floats per pixel, row-major, owned by us. */
typedef struct rgb_image {
  uint32_t width, height;
  float *px;
} rgb_image;

static int load_rgb(const char *cmd, hush_device device, const char *path, const char *layer,
                    rgb_image *out) {
  hush_frame frame = NULL;
  hush_status st = hush_frame_read_exr(device, path, &frame);
  if (st != HUSH_OK) return cli_device_error(cmd, device, st, path);
  hush_image_view v;
  st = hush_frame_get_layer(frame, layer, &v);
  if (st != HUSH_OK) {
    hush_frame_release(frame);
    return cli_error(cmd, "%s has no layer '%s'", path, layer);
  }
  const int nc = hush_format_channels(v.format);
  if (nc != 1 && nc != 3 && nc != 4) {
    hush_frame_release(frame);
    return cli_error(cmd, "layer '%s' of %s has %d channels; 1, 3 or 4 are compared", layer,
                     path, nc);
  }
  out->width = v.width;
  out->height = v.height;
  out->px = malloc((size_t)v.width * v.height * 3 * sizeof(float));
  if (!out->px) {
    hush_frame_release(frame);
    return cli_error(cmd, "out of memory");
  }
  const size_t row = hush_format_pixel_size(v.format) * v.width;
  const size_t stride = v.row_stride ? v.row_stride : row;
  for (uint32_t y = 0; y < v.height; y++) {
    const float *src = (const float *)((const char *)v.data + v.byte_offset + y * stride);
    for (uint32_t x = 0; x < v.width; x++)
      for (int c = 0; c < 3; c++)
        out->px[3 * ((size_t)y * v.width + x) + c] = src[(size_t)x * nc + (nc == 1 ? 0 : c)];
  }
  hush_frame_release(frame);
  return 0;
}

/* Box filter by an integer factor (the image must divide evenly). */
static int box_down(rgb_image *im, uint32_t f) {
  if (f <= 1) return 0;
  const uint32_t w = im->width / f, h = im->height / f;
  float *px = calloc((size_t)w * h * 3, sizeof(float));
  if (!px) return -1;
  for (uint32_t y = 0; y < h * f; y++)
    for (uint32_t x = 0; x < w * f; x++)
      for (int c = 0; c < 3; c++)
        px[3 * ((size_t)(y / f) * w + x / f) + c] += im->px[3 * ((size_t)y * im->width + x) + c];
  const float norm = 1.0f / (float)(f * f);
  for (size_t i = 0; i < (size_t)w * h * 3; i++) px[i] *= norm;
  free(im->px);
  im->px = px;
  im->width = w;
  im->height = h;
  return 0;
}

static double mean_luminance(const rgb_image *im) {
  double sum = 0.0;
  const size_t n = (size_t)im->width * im->height;
  for (size_t i = 0; i < n; i++)
    sum += hush_luminance(im->px[3 * i], im->px[3 * i + 1], im->px[3 * i + 2]);
  return n ? sum / (double)n : 0.0;
}

static double luminance_rmse(const rgb_image *a, const rgb_image *b) {
  double sum = 0.0;
  const size_t n = (size_t)a->width * a->height;
  for (size_t i = 0; i < n; i++) {
    const double d = hush_luminance(a->px[3 * i], a->px[3 * i + 1], a->px[3 * i + 2]) -
                     hush_luminance(b->px[3 * i], b->px[3 * i + 1], b->px[3 * i + 2]);
    sum += d * d;
  }
  return n ? sqrt(sum / (double)n) : 0.0;
}

/* A | B in one frame, written as PNG with the given tone mapping. */
static int write_side_by_side(const char *cmd, hush_device device, const rgb_image *a,
                              const rgb_image *b, const char *path, float exposure,
                              hush_tonemap tonemap) {
  const uint32_t w = a->width, h = a->height;
  hush_frame f = hush_frame_new(device, 2 * w, h);
  if (!f) return cli_error(cmd, "out of memory");
  hush_image_view v;
  hush_status st = hush_frame_add_layer(f, "color", 3, &v);
  if (st == HUSH_OK) {
    float *dst = v.data;
    for (uint32_t y = 0; y < h; y++) {
      memcpy(dst + 3 * ((size_t)y * 2 * w), a->px + 3 * (size_t)y * w, 3 * w * sizeof(float));
      memcpy(dst + 3 * ((size_t)y * 2 * w + w), b->px + 3 * (size_t)y * w, 3 * w * sizeof(float));
    }
    st = hush_image_write_png(device, &v, path, exposure, tonemap);
  }
  hush_frame_release(f);
  return st == HUSH_OK ? 0 : cli_device_error(cmd, device, st, path);
}

/* Brings both to the same size: the larger one is box-filtered down. */
static int match_sizes(const char *cmd, rgb_image *a, rgb_image *b, const char *pa,
                       const char *pb) {
  rgb_image *big = a->width >= b->width ? a : b;
  const rgb_image *small = big == a ? b : a;
  const uint32_t f = small->width ? big->width / small->width : 0;
  if (f == 0 || big->width != f * small->width || big->height != f * small->height)
    return cli_error(cmd, "%s is %ux%u and %s is %ux%u: not an integer factor apart", pa,
                     a->width, a->height, pb, b->width, b->height);
  return box_down(big, f) ? cli_error(cmd, "out of memory") : 0;
}

int cmd_compare(int argc, char **argv) {
  const char *cmd = "compare";
  const char *paths[2] = {NULL, NULL}, *layer = "color", *png = NULL;
  uint32_t down = 1;
  float exposure = 0.0f;
  hush_tonemap tonemap = HUSH_TONEMAP_ACES;
  int npaths = 0;
  cli_args args;
  cli_args_init(&args, cmd, argc, argv);
  const char *arg, *val;
  while (cli_next(&args, &arg)) {
    if (cli_is_help(arg)) {
      fputs(help_text, stdout);
      return 0;
    } else if (cli_option(&args, arg, "--layer", &val)) {
      layer = val;
    } else if (cli_option(&args, arg, "--downsample", &val)) {
      down = cli_parse_uint(cmd, "--downsample", val, 1, 64);
    } else if (cli_option(&args, arg, "--side-by-side", &val)) {
      png = val;
    } else if (cli_option(&args, arg, "--exposure", &val)) {
      exposure = cli_parse_float(cmd, "--exposure", val, -64.0f, 64.0f);
    } else if (cli_option(&args, arg, "--tonemap", &val)) {
      tonemap = cli_parse_tonemap(cmd, "--tonemap", val);
    } else if (cli_is_positional(&args, arg) && npaths < 2) {
      paths[npaths++] = arg;
    } else {
      cli_unknown_option(&args, arg);
    }
  }
  if (npaths != 2) cli_usage_error(cmd, "needs two images, A and the reference B");

  hush_device device = hush_device_new(NULL);
  if (!device) return cli_error(cmd, "cannot create a device");
  rgb_image a = {0, 0, NULL}, b = {0, 0, NULL};
  int rc = load_rgb(cmd, device, paths[0], layer, &a);
  if (!rc) rc = load_rgb(cmd, device, paths[1], layer, &b);
  if (!rc) rc = match_sizes(cmd, &a, &b, paths[0], paths[1]);
  if (!rc && (box_down(&a, down) || box_down(&b, down))) rc = cli_error(cmd, "out of memory");
  if (!rc) {
    const double la = mean_luminance(&a), lb = mean_luminance(&b);
    const hush_error_stats e = hush__error_stats(a.px, b.px, (size_t)a.width * a.height, 3);
    printf("size %ux%u\nmean luminance A %.6g  B %.6g  ratio A/B %.4f\n", a.width, a.height, la,
           lb, lb > 0.0 ? la / lb : 0.0);
    printf("rmse %.6g  luminance rmse %.6g  relmse %.6g\n", e.rmse, luminance_rmse(&a, &b),
           e.rel_mse);
    if (png) rc = write_side_by_side(cmd, device, &a, &b, png, exposure, tonemap);
  }
  free(a.px);
  free(b.px);
  hush_device_release(device);
  return rc;
}
