/*
 * png.c — 8-bit sRGB PNG pictures. hush_image_write_png applies the display
 * transform (exposure, tone curve, sRGB; tonemap.h) and writes through a
 * temporary file; hush_frame_read_png decodes any PNG (gray, palette, RGB,
 * with or without alpha, 1 to 16 bits) back to linear float, dropping alpha.
 *
 * libpng reports errors by calling our error function, which records the
 * message and longjmps back to the setjmp in png_encode() / png_decode().
 * Those two functions keep all their state in a caller's struct, so nothing
 * they change lives in a local variable that longjmp could leave stale.
 */
#include "core/device.h"
#include "core/image.h"
#include "io/atomic_file.h"
#include "io/frame.h"
#include "io/png.h"
#include "io/tonemap.h"
#include "io/view_rows.h"

#include <errno.h>
#include <math.h>
#include <png.h>
#include <setjmp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define PNG_MAX_SIZE 65536u
/* Largest width * height read, as for EXR (HUSH_EXR_MAX_PIXELS): a small
 * file can claim 65536 x 65536 and deflate to 48 GB of float pixels. */
#define PNG_MAX_PIXELS ((uint64_t)1 << 28)

typedef struct png_message {
  char text[256];
} png_message;

static void on_png_error(png_structp png, png_const_charp msg) {
  png_message *m = png_get_error_ptr(png);
  if (m) snprintf(m->text, sizeof m->text, "%s", msg);
  png_longjmp(png, 1);
}

static void on_png_warning(png_structp png, png_const_charp msg) {
  (void)png;
  (void)msg; /* warnings (odd ancillary chunks) do not change the pixels */
}

/* ------------------------------------------------------------------------ */
/* Writing                                                                  */
/* ------------------------------------------------------------------------ */

/* Applies the display transform to the whole view. Fails on the first
 * NaN/Inf, before any file is touched. */
static hush_status display_pixels(hush_device device, const hush_image_view *view, const char *path,
                                  float exposure, hush_tonemap op, int out_ch, uint8_t *out) {
  const float scale = exp2f(exposure);
  const uint32_t w = view->width;
  float *row = malloc((size_t)w * (size_t)out_ch * sizeof *row);
  if (!row) return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory writing '%s'", path);
  for (uint32_t y = 0; y < view->height; y++) {
    hush__view_load_row(view, y, out_ch, row);
    for (uint32_t i = 0; i < w * (uint32_t)out_ch; i++) {
      if (!isfinite(row[i])) {
        const char *what = isnan(row[i]) ? "NaN" : "infinite";
        free(row);
        return hush__fail(device, HUSH_ERROR_NONFINITE,
                          "cannot write '%s': pixel (%u, %u) channel %u is %s", path,
                          i / (uint32_t)out_ch, y, i % (uint32_t)out_ch, what);
      }
      *out++ = hush__display8(row[i], scale, op);
    }
  }
  free(row);
  return HUSH_OK;
}

typedef struct png_job {
  FILE *f;
  const uint8_t *pixels;
  uint32_t width, height;
  int channels;
} png_job;

static int png_encode(png_structp png, png_infop info, const png_job *job) {
  if (setjmp(png_jmpbuf(png))) return 0;
  png_init_io(png, job->f);
  png_set_IHDR(png, info, job->width, job->height, 8,
               job->channels == 1 ? PNG_COLOR_TYPE_GRAY : PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_set_sRGB_gAMA_and_cHRM(png, info, PNG_sRGB_INTENT_PERCEPTUAL);
  png_write_info(png, info);
  const size_t row_bytes = (size_t)job->width * (size_t)job->channels;
  for (uint32_t y = 0; y < job->height; y++) png_write_row(png, job->pixels + y * row_bytes);
  png_write_end(png, NULL);
  return 1;
}

static hush_status write_png_file(hush_device device, const char *path, const png_job *pixels) {
  char tmp[HUSH_PATH_MAX];
  FILE *f = hush__atomic_open(device, path, tmp);
  if (!f) return HUSH_ERROR_IO;
  png_message message = {{0}};
  png_structp png =
      png_create_write_struct(PNG_LIBPNG_VER_STRING, &message, on_png_error, on_png_warning);
  png_infop info = png ? png_create_info_struct(png) : NULL;
  if (!info) {
    png_destroy_write_struct(&png, NULL);
    hush__atomic_abort(f, tmp);
    return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory writing '%s'", path);
  }
  png_job job = *pixels;
  job.f = f;
  const int ok = png_encode(png, info, &job);
  png_destroy_write_struct(&png, &info);
  if (!ok) {
    hush__atomic_abort(f, tmp);
    return hush__fail(device, HUSH_ERROR_IO, "cannot write '%s': %s", path, message.text);
  }
  return hush__atomic_commit(device, f, tmp, path);
}

hush_status hush__png_write8(hush_device device, const char *path, const uint8_t *pixels,
                             uint32_t width, uint32_t height, int channels) {
  if (width == 0 || height == 0 || width > PNG_MAX_SIZE || height > PNG_MAX_SIZE ||
      (channels != 1 && channels != 3))
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                      "cannot write '%s': a %ux%u picture of %d channels", path, width, height,
                      channels);
  const png_job job = {NULL, pixels, width, height, channels};
  return write_png_file(device, path, &job);
}

hush_status hush_image_write_png(hush_device device, const hush_image_view *view, const char *path,
                                 float exposure, hush_tonemap tonemap) {
  if (!device)
    return hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT, "hush_image_write_png: device is NULL");
  if (!path || !*path)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                      "hush_image_write_png: path is NULL or empty");
  hush_status status = hush__view_validate(device, view, path, 1, 0);
  if (status != HUSH_OK) return status;
  const int channels = hush_format_channels(view->format);
  if (channels == 2)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                      "'%s': a PNG picture needs a view of 1, 3 or 4 channels, not 2", path);
  if (!isfinite(exposure))
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "'%s': exposure is not finite", path);
  if (!hush__tonemap_valid(tonemap))
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "'%s': unknown tone mapping %d", path,
                      (int)tonemap);

  const int out_ch = channels == 1 ? 1 : 3;
  uint8_t *pixels = malloc((size_t)view->width * view->height * (size_t)out_ch);
  if (!pixels)
    return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory writing '%s'", path);
  status = display_pixels(device, view, path, exposure, tonemap, out_ch, pixels);
  if (status == HUSH_OK) {
    const png_job job = {NULL, pixels, view->width, view->height, out_ch};
    status = write_png_file(device, path, &job);
  }
  free(pixels);
  return status;
}

/* ------------------------------------------------------------------------ */
/* Reading                                                                  */
/* ------------------------------------------------------------------------ */

typedef enum decode_result {
  DECODE_OK,
  DECODE_ERROR,
  DECODE_TOO_LARGE,
  DECODE_NO_MEMORY
} decode_result;

typedef struct png_reader {
  FILE *f;
  png_structp png;
  png_infop info;
  uint32_t width, height;
  int channels; /* as decoded: 1..4, alpha may still be there */
  int bytes;    /* per sample: 1 or 2 */
  size_t row_bytes;
  uint8_t *data;
  png_bytep *rows;
} png_reader;

static decode_result png_decode(png_reader *r) {
  if (setjmp(png_jmpbuf(r->png))) return DECODE_ERROR;
  png_init_io(r->png, r->f);
  png_set_sig_bytes(r->png, 8);
  png_read_info(r->png, r->info);
  r->width = png_get_image_width(r->png, r->info);
  r->height = png_get_image_height(r->png, r->info);
  if (r->width > PNG_MAX_SIZE || r->height > PNG_MAX_SIZE ||
      (uint64_t)r->width * r->height > PNG_MAX_PIXELS)
    return DECODE_TOO_LARGE;

  const int color = png_get_color_type(r->png, r->info);
  if (color == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(r->png);
  if (color == PNG_COLOR_TYPE_GRAY && png_get_bit_depth(r->png, r->info) < 8)
    png_set_expand_gray_1_2_4_to_8(r->png);
  if (color & PNG_COLOR_MASK_ALPHA) png_set_strip_alpha(r->png);
  png_set_interlace_handling(r->png);
  png_read_update_info(r->png, r->info);

  r->channels = png_get_channels(r->png, r->info);
  r->bytes = png_get_bit_depth(r->png, r->info) == 16 ? 2 : 1;
  r->row_bytes = png_get_rowbytes(r->png, r->info);
  if (r->channels < 1 || r->channels > 4 ||
      r->row_bytes != (size_t)r->width * (size_t)r->channels * (size_t)r->bytes)
    png_error(r->png, "unexpected pixel layout after decoding");

  r->data = malloc(r->row_bytes * r->height);
  r->rows = malloc(r->height * sizeof *r->rows);
  if (!r->data || !r->rows) return DECODE_NO_MEMORY;
  for (uint32_t y = 0; y < r->height; y++) r->rows[y] = r->data + y * r->row_bytes;
  png_read_image(r->png, r->rows);
  png_read_end(r->png, NULL);
  return DECODE_OK;
}

/* Converts the decoded sRGB samples to linear floats in a new frame. Gray
 * (with or without alpha) gives 1 channel, colour 3. */
static hush_status png_to_frame(hush_device device, const png_reader *r, const char *layer_name,
                                hush_frame *out) {
  const int out_ch = r->channels <= 2 ? 1 : 3;
  hush_frame frame = hush_frame_new(device, r->width, r->height);
  if (!frame) return HUSH_ERROR_OUT_OF_MEMORY; /* the size is valid: only memory can lack */
  hush_image_view view;
  hush_status status = hush_frame_add_layer(frame, layer_name, out_ch, &view);
  if (status != HUSH_OK) {
    hush_frame_release(frame);
    return status;
  }
  float lut8[256];
  for (int i = 0; i < 256; i++) lut8[i] = hush__srgb_decode((float)i / 255.0f);
  float *dst = view.data;
  for (uint32_t y = 0; y < r->height; y++) {
    const uint8_t *src = r->rows[y];
    for (uint32_t x = 0; x < r->width; x++, src += r->channels * r->bytes) {
      for (int c = 0; c < out_ch; c++) {
        if (r->bytes == 1) {
          *dst++ = lut8[src[c]];
        } else { /* PNG samples are big-endian */
          const unsigned v = (unsigned)src[2 * c] << 8 | src[2 * c + 1];
          *dst++ = hush__srgb_decode((float)v / 65535.0f);
        }
      }
    }
  }
  *out = frame;
  return HUSH_OK;
}

static hush_status read_png_file(hush_device device, FILE *f, const char *path,
                                 const char *layer_name, hush_frame *out) {
  png_message message = {{0}};
  png_reader r;
  memset(&r, 0, sizeof r);
  r.f = f;
  r.png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &message, on_png_error, on_png_warning);
  r.info = r.png ? png_create_info_struct(r.png) : NULL;
  if (!r.info) {
    png_destroy_read_struct(&r.png, NULL, NULL);
    return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory reading '%s'", path);
  }
  hush_status status = HUSH_OK;
  switch (png_decode(&r)) {
  case DECODE_OK: status = png_to_frame(device, &r, layer_name, out); break;
  case DECODE_ERROR:
    status = hush__fail(device, HUSH_ERROR_CORRUPT, "'%s': corrupt PNG: %s", path, message.text);
    break;
  case DECODE_TOO_LARGE:
    status =
        hush__fail(device, HUSH_ERROR_UNSUPPORTED,
                   "'%s': %ux%u is larger than %u pixels a side or %llu pixels in all", path,
                   r.width, r.height, PNG_MAX_SIZE, (unsigned long long)PNG_MAX_PIXELS);
    break;
  case DECODE_NO_MEMORY:
    status = hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory reading '%s' (%ux%u)",
                        path, r.width, r.height);
    break;
  }
  png_destroy_read_struct(&r.png, &r.info, NULL);
  free(r.rows);
  free(r.data);
  return status;
}

hush_status hush_frame_read_png(hush_device device, const char *path, const char *layer_name,
                                hush_frame *frame) {
  if (!device)
    return hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT, "hush_frame_read_png: device is NULL");
  if (!frame)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "hush_frame_read_png: frame is NULL");
  *frame = NULL;
  if (!path || !*path)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                      "hush_frame_read_png: path is NULL or empty");
  if (!layer_name || !*layer_name || strlen(layer_name) >= HUSH_LAYER_NAME_MAX)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                      "hush_frame_read_png: layer name must have 1 to %d characters",
                      HUSH_LAYER_NAME_MAX - 1);
  FILE *f = fopen(path, "rb");
  if (!f) return hush__fail(device, HUSH_ERROR_IO, "cannot open '%s': %s", path, strerror(errno));
  png_byte signature[8];
  const size_t got = fread(signature, 1, sizeof signature, f);
  if (ferror(f)) {
    const int err = errno;
    fclose(f);
    return hush__fail(device, HUSH_ERROR_IO, "cannot read '%s': %s", path, strerror(err));
  }
  if (got != sizeof signature || png_sig_cmp(signature, 0, sizeof signature) != 0) {
    fclose(f);
    return hush__fail(device, HUSH_ERROR_CORRUPT, "'%s' is not a PNG file (bad signature)", path);
  }
  const hush_status status = read_png_file(device, f, path, layer_name, frame);
  fclose(f);
  return status;
}
