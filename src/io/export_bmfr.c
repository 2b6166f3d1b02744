/*
 * export_bmfr.c — the published BMFR code's input layout (see
 * export_bmfr.h): four 3-channel float EXRs per frame and camera_matrices.h.
 */
#include "io/export_bmfr.h"

#include "core/device.h"
#include "core/hmath.h"
#include "core/image.h"
#include "io/atomic_file.h"

#include <stdio.h>
#include <string.h>

/* A contiguous 3-channel layer of frame, or NULL after reporting. */
static const float *layer3(hush_device device, hush_frame frame, const char *name) {
  hush_image_view v;
  if (hush_frame_get_layer(frame, name, &v) != HUSH_OK) {
    hush__fail(device, HUSH_ERROR_NOT_FOUND, "bmfr export: the frame has no '%s' layer", name);
    return NULL;
  }
  if (v.format != HUSH_FORMAT_FLOAT3 || v.pixel_stride != 3 * sizeof(float) ||
      v.row_stride != (size_t)v.width * 3 * sizeof(float)) {
    hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
               "bmfr export: layer '%s' is not a packed 3-channel float image", name);
    return NULL;
  }
  return (const float *)((const char *)v.data + v.byte_offset);
}

/* Writes n = width * height RGB floats as dir/<name><index>.exr: a frame of
 * one "color" layer, which the EXR writer names R, G, B. */
static hush_status write_rgb(hush_device device, const char *dir, const char *name,
                             uint32_t index, uint32_t width, uint32_t height, const float *rgb) {
  char path[HUSH_PATH_MAX];
  if ((size_t)snprintf(path, sizeof path, "%s/%s%u.exr", dir, name, index) >= sizeof path)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "bmfr export: path too long in '%s'",
                      dir);
  hush_frame f = hush_frame_new(device, width, height);
  if (!f) return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "bmfr export: out of memory");
  hush_image_view v;
  hush_status st = hush_frame_add_layer(f, "color", 3, &v);
  if (st == HUSH_OK) {
    memcpy((char *)v.data + v.byte_offset, rgb, (size_t)width * height * 3 * sizeof(float));
    st = hush_frame_write_exr(f, path, HUSH_EXR_FLOAT);
  }
  hush_frame_release(f);
  return st;
}

/* color / albedo per channel, and the albedo that undoes it (see the guard
 * in export_bmfr.h). */
static void demodulate(const float *color, const float *albedo, size_t n, float *out_color,
                       float *out_albedo) {
  for (size_t i = 0; i < 3 * n; i++) {
    const float a = albedo[i];
    if (a >= HUSH_BMFR_MIN_ALBEDO) {
      out_color[i] = color[i] / a;
      out_albedo[i] = a;
    } else {
      out_color[i] = color[i];
      out_albedo[i] = 1.0f;
    }
  }
}

/* The albedo to demodulate by: the frame's, except at sky pixels (nothing
 * hit: normal 0), where it is the pixel's own radiance, so that their colour
 * is 1 (see export_bmfr.h: why the sky must not reach the fit). */
static void demodulation_albedo(const float *color, const float *albedo, const float *normal,
                                size_t n, float *out) {
  for (size_t p = 0; p < n; p++) {
    const float *nn = normal + 3 * p;
    const float *src = (nn[0] == 0.0f && nn[1] == 0.0f && nn[2] == 0.0f) ? color : albedo;
    out[3 * p] = src[3 * p];
    out[3 * p + 1] = src[3 * p + 1];
    out[3 * p + 2] = src[3 * p + 2];
  }
}

hush_status hush__bmfr_write_frame(hush_device device, const char *dir, uint32_t index,
                                   hush_frame frame) {
  const uint32_t W = hush_frame_width(frame), H = hush_frame_height(frame);
  const float *color = layer3(device, frame, "color");
  const float *albedo = color ? layer3(device, frame, "albedo") : NULL;
  const float *normal = albedo ? layer3(device, frame, "normal") : NULL;
  const float *position = normal ? layer3(device, frame, "position") : NULL;
  if (!position) return HUSH_ERROR_NOT_FOUND;
  const size_t n = (size_t)W * H;
  float *demod = hush__alloc_floats(9 * n);
  if (!demod) return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "bmfr export: out of memory");
  float *alb = demod + 3 * n, *by = demod + 6 * n;
  demodulation_albedo(color, albedo, normal, n, by);
  demodulate(color, by, n, demod, alb);
  hush_status st = write_rgb(device, dir, "color", index, W, H, demod);
  if (st == HUSH_OK) st = write_rgb(device, dir, "albedo", index, W, H, alb);
  if (st == HUSH_OK) st = write_rgb(device, dir, "shading_normal", index, W, H, normal);
  if (st == HUSH_OK) st = write_rgb(device, dir, "world_position", index, W, H, position);
  hush__free_floats(demod);
  return st;
}

void hush__bmfr_matrix(const hush_camera *camera, float out[16]) {
  hush_m4_mul(out, camera->view_to_clip, camera->world_to_view);
  /* negate clip y (row 1 of every column): NDC y = -1 becomes the top row */
  for (int c = 0; c < 4; c++) out[c * 4 + 1] = 0.0f - out[c * 4 + 1]; /* no -0 in the header */
}

void hush__bmfr_pixel_offset(const hush_camera *camera, float out[2]) {
  out[0] = 0.5f + camera->jitter[0];
  out[1] = 0.5f - camera->jitter[1]; /* measured up from the pixel's bottom edge */
}

static void write_header(FILE *f, const hush_camera *cameras, uint32_t count, float pos_limit,
                         float normal_limit) {
  fprintf(f,
          "/* camera_matrices.h: written by `hush render --export bmfr` for the published\n"
          " * BMFR code. camera_matrices[i][c][r]: row r of column c of frame i's\n"
          " * view-projection matrix (no jitter; NDC y = -1 is the top row).\n"
          " * pixel_offsets[i]: frame i's sample inside its pixel, x right, y up.\n"
          " * The two limits are the reprojection tests' thresholds (squared world\n"
          " * distance, squared normal distance); they depend on the scene's scale. */\n"
          "const float position_limit_squared = %.9g;\n"
          "const float normal_limit_squared = %.9g;\n\n",
          (double)pos_limit, (double)normal_limit);
  fprintf(f, "const float camera_matrices[%u][4][4] = {\n", count);
  for (uint32_t i = 0; i < count; i++) {
    float m[16];
    hush__bmfr_matrix(&cameras[i], m);
    fprintf(f, "  { /* frame %u */\n", i);
    for (int c = 0; c < 4; c++)
      fprintf(f, "    {%.9g, %.9g, %.9g, %.9g}%s\n", (double)m[c * 4], (double)m[c * 4 + 1],
              (double)m[c * 4 + 2], (double)m[c * 4 + 3], c < 3 ? "," : "");
    fprintf(f, "  }%s\n", i + 1 < count ? "," : "");
  }
  fprintf(f, "};\n\nconst float pixel_offsets[%u][2] = {\n", count);
  for (uint32_t i = 0; i < count; i++) {
    float o[2];
    hush__bmfr_pixel_offset(&cameras[i], o);
    fprintf(f, "  {%.9g, %.9g}%s\n", (double)o[0], (double)o[1], i + 1 < count ? "," : "");
  }
  fprintf(f, "};\n");
}

hush_status hush__bmfr_write_cameras(hush_device device, const char *dir,
                                     const hush_camera *cameras, uint32_t count,
                                     float position_limit_squared, float normal_limit_squared) {
  if (count == 0)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "bmfr export: no frames");
  char path[HUSH_PATH_MAX], tmp[HUSH_PATH_MAX];
  if ((size_t)snprintf(path, sizeof path, "%s/camera_matrices.h", dir) >= sizeof path)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "bmfr export: path too long in '%s'",
                      dir);
  FILE *f = hush__atomic_open(device, path, tmp);
  if (!f) return HUSH_ERROR_IO;
  write_header(f, cameras, count, position_limit_squared, normal_limit_squared);
  return hush__atomic_commit(device, f, tmp, path);
}
