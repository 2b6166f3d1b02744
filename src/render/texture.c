/*
 * texture.c — texture storage, loading and lookups. Colour maps (JPG, PNG)
 * are decoded from sRGB to linear floats, opacity maps keep their alpha (or
 * grey) values as stored, EXR environment maps are read as they are. Every
 * texture is stored with row 0 at the top; lookups take OBJ-style uvs with
 * (0, 0) at the bottom-left.
 *
 * libjpeg reports errors by calling error_exit, which we point at a function
 * that keeps the message and longjmps back to decode_jpeg(); its state lives
 * in a caller's struct so longjmp cannot leave a stale local behind. PNGs go
 * through libpng's simplified API, which keeps its messages in the png_image
 * instead of printing them.
 */
#include "render/scene.h"

#include "core/device.h"
#include "io/frame.h"

#include <errno.h>
#include <stdio.h> /* before jpeglib.h, which uses FILE */
#include <jpeglib.h>
#include <math.h>
#include <png.h>
#include <setjmp.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>

/* Larger textures are refused rather than risking a huge allocation. */
#define TEXTURE_MAX_PIXELS ((uint64_t)1 << 28)

/* ------------------------------------------------------------------------ */
/* Storage and lookups                                                      */
/* ------------------------------------------------------------------------ */

hush_status hush__texture_init(hush_device device, hush_texture *t, const char *name,
                               uint32_t width, uint32_t height, int channels) {
  memset(t, 0, sizeof *t);
  snprintf(t->name, sizeof t->name, "%s", name ? name : "");
  if (width == 0 || height == 0 || channels < 1 || channels > 4 ||
      (uint64_t)width * height > TEXTURE_MAX_PIXELS)
    return hush__fail(device, HUSH_ERROR_UNSUPPORTED,
                      "texture '%s': %ux%u with %d channels is not supported", t->name, width,
                      height, channels);
  t->texels = calloc((size_t)width * height * (size_t)channels, sizeof *t->texels);
  if (!t->texels)
    return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory for texture '%s' (%ux%u)",
                      t->name, width, height);
  t->width = width;
  t->height = height;
  t->channels = channels;
  return HUSH_OK;
}

void hush__texture_free(hush_texture *t) {
  if (!t) return;
  free(t->texels);
  t->texels = NULL;
  t->width = t->height = 0;
  t->channels = 0;
}

/* The fractional part in [0, 1); non-finite coordinates read texel 0. */
static float wrap01(float x) {
  if (!isfinite(x)) return 0.0f;
  const float f = x - floorf(x);
  return f < 1.0f ? f : 0.0f;
}

/* i modulo n into [0, n). The texel coordinates of hush__texture_sample lie
 * in [-1, n - 1], so the 64-bit divisions (~4 per lookup, most of its time)
 * are only the fallback. */
static uint32_t wrap_index(int64_t i, uint32_t n) {
  if (i >= 0 && i < (int64_t)n) return (uint32_t)i;
  if (i == -1) return n - 1;
  return (uint32_t)((i % n + n) % n);
}

void hush__texture_sample(const hush_texture *t, float u, float v, float out[4]) {
  const int nc = t->channels;
  if (!t->texels || t->width == 0 || t->height == 0) {
    for (int c = 0; c < nc && c < 4; c++) out[c] = 0.0f;
    return;
  }
  const uint32_t w = t->width, h = t->height;
  /* Texel (i, row r from the top) has its centre at u = (i + 0.5) / w,
   * v = 1 - (r + 0.5) / h. */
  const float tx = wrap01(u) * (float)w - 0.5f;
  const float ty = (1.0f - wrap01(v)) * (float)h - 0.5f;
  const float fx0 = floorf(tx), fy0 = floorf(ty);
  const float fx = tx - fx0, fy = ty - fy0;
  const uint32_t x0 = wrap_index((int64_t)fx0, w), y0 = wrap_index((int64_t)fy0, h);
  const uint32_t x1 = x0 + 1 == w ? 0 : x0 + 1;
  const uint32_t y1 = y0 + 1 == h ? 0 : y0 + 1;
  const float *r0 = t->texels + (size_t)y0 * w * (size_t)nc;
  const float *r1 = t->texels + (size_t)y1 * w * (size_t)nc;
  for (int c = 0; c < nc && c < 4; c++) {
    const float a = r0[(size_t)x0 * nc + c] * (1.0f - fx) + r0[(size_t)x1 * nc + c] * fx;
    const float b = r1[(size_t)x0 * nc + c] * (1.0f - fx) + r1[(size_t)x1 * nc + c] * fx;
    out[c] = a * (1.0f - fy) + b * fy;
  }
}

/* ------------------------------------------------------------------------ */
/* Decoding helpers                                                         */
/* ------------------------------------------------------------------------ */

static float srgb_to_linear(float c) {
  return c <= 0.04045f ? c / 12.92f : powf((c + 0.055f) / 1.055f, 2.4f);
}

static void srgb_table(float table[256]) {
  for (int i = 0; i < 256; i++) table[i] = srgb_to_linear((float)i / 255.0f);
}

/* Reads a whole file; *data is malloc'd. */
static hush_status read_file(hush_device device, const char *path, const char *what,
                             unsigned char **data, size_t *size) {
  *data = NULL;
  *size = 0;
  FILE *f = fopen(path, "rb");
  if (!f)
    return hush__fail(device, errno == ENOENT ? HUSH_ERROR_NOT_FOUND : HUSH_ERROR_IO,
                      "%s: cannot open '%s': %s", what, path, strerror(errno));
  struct stat st;
  if (fstat(fileno(f), &st) != 0 || !S_ISREG(st.st_mode) || st.st_size <= 0) {
    fclose(f);
    return hush__fail(device, HUSH_ERROR_IO, "%s: '%s' is not a readable non-empty file", what,
                      path);
  }
  unsigned char *buf = malloc((size_t)st.st_size);
  if (!buf) {
    fclose(f);
    return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "%s: out of memory reading '%s'", what,
                      path);
  }
  const size_t got = fread(buf, 1, (size_t)st.st_size, f);
  fclose(f);
  if (got != (size_t)st.st_size) {
    free(buf);
    return hush__fail(device, HUSH_ERROR_IO, "%s: cannot read '%s'", what, path);
  }
  *data = buf;
  *size = got;
  return HUSH_OK;
}

static const char *base_name(const char *path) {
  const char *s = strrchr(path, '/');
  return s ? s + 1 : path;
}

/* ------------------------------------------------------------------------ */
/* JPEG                                                                     */
/* ------------------------------------------------------------------------ */

typedef struct jpeg_job {
  struct jpeg_error_mgr err; /* first, so the error manager finds the job */
  jmp_buf jump;
  char message[JMSG_LENGTH_MAX];
  struct jpeg_decompress_struct cinfo;
  int created;
  unsigned char *rgb; /* width * height * 3 */
  uint32_t width, height;
} jpeg_job;

static void on_jpeg_error(j_common_ptr cinfo) {
  jpeg_job *job = (jpeg_job *)cinfo->err;
  cinfo->err->format_message(cinfo, job->message);
  longjmp(job->jump, 1);
}

static void on_jpeg_message(j_common_ptr cinfo) {
  (void)cinfo; /* warnings (corrupt-but-decodable data) do not stop decoding */
}

/* Decodes to 8-bit RGB in job->rgb. Returns 0 on failure (job->message). */
static int decode_jpeg(jpeg_job *job, const unsigned char *data, size_t size) {
  job->cinfo.err = jpeg_std_error(&job->err);
  job->err.error_exit = on_jpeg_error;
  job->err.output_message = on_jpeg_message;
  if (setjmp(job->jump)) return 0;
  jpeg_create_decompress(&job->cinfo);
  job->created = 1;
  jpeg_mem_src(&job->cinfo, data, (unsigned long)size);
  jpeg_read_header(&job->cinfo, TRUE);
  job->cinfo.out_color_space = JCS_RGB;
  jpeg_start_decompress(&job->cinfo);
  job->width = job->cinfo.output_width;
  job->height = job->cinfo.output_height;
  if (job->cinfo.output_components != 3 || job->width == 0 || job->height == 0 ||
      (uint64_t)job->width * job->height > TEXTURE_MAX_PIXELS) {
    snprintf(job->message, sizeof job->message, "unsupported size or colour layout");
    return 0;
  }
  job->rgb = malloc((size_t)job->width * job->height * 3);
  if (!job->rgb) {
    snprintf(job->message, sizeof job->message, "out of memory");
    return 0;
  }
  while (job->cinfo.output_scanline < job->height) {
    JSAMPROW row = job->rgb + (size_t)job->cinfo.output_scanline * job->width * 3;
    jpeg_read_scanlines(&job->cinfo, &row, 1);
  }
  jpeg_finish_decompress(&job->cinfo);
  return 1;
}

static hush_status load_jpeg(hush_device device, const char *path, const char *what,
                             hush_texture_kind kind, hush_texture *t) {
  unsigned char *data;
  size_t size;
  hush_status st = read_file(device, path, what, &data, &size);
  if (st != HUSH_OK) return st;
  jpeg_job *job = calloc(1, sizeof *job);
  if (!job) {
    free(data);
    return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "%s: out of memory", what);
  }
  const int ok = decode_jpeg(job, data, size);
  if (job->created) jpeg_destroy_decompress(&job->cinfo);
  free(data);
  if (!ok) {
    st = hush__fail(device, HUSH_ERROR_CORRUPT, "%s: cannot decode JPEG '%s': %s", what, path,
                    job->message);
  } else {
    const int nc = kind == HUSH_TEXTURE_ALPHA ? 1 : 3;
    st = hush__texture_init(device, t, base_name(path), job->width, job->height, nc);
    if (st == HUSH_OK) {
      float lut[256];
      srgb_table(lut);
      const size_t n = (size_t)job->width * job->height;
      for (size_t i = 0; i < n; i++) {
        const unsigned char *p = job->rgb + i * 3;
        if (nc == 1) {
          /* a JPEG opacity map: its grey level, as stored */
          t->texels[i] = (p[0] + p[1] + p[2]) / (3.0f * 255.0f);
        } else {
          for (int c = 0; c < 3; c++)
            t->texels[i * 3 + c] = kind == HUSH_TEXTURE_SRGB ? lut[p[c]] : p[c] / 255.0f;
        }
      }
    }
  }
  free(job->rgb);
  free(job);
  return st;
}

/* ------------------------------------------------------------------------ */
/* PNG                                                                      */
/* ------------------------------------------------------------------------ */

static hush_status load_png(hush_device device, const char *path, const char *what,
                            hush_texture_kind kind, hush_texture *t) {
  unsigned char *data;
  size_t size;
  hush_status st = read_file(device, path, what, &data, &size);
  if (st != HUSH_OK) return st;
  png_image image;
  memset(&image, 0, sizeof image);
  image.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_memory(&image, data, size)) {
    st = hush__fail(device, HUSH_ERROR_CORRUPT, "%s: cannot decode PNG '%s': %s", what, path,
                    image.message);
    free(data);
    return st;
  }
  const int has_alpha = (image.format & PNG_FORMAT_FLAG_ALPHA) != 0;
  /* 8-bit formats of the simplified API are sRGB-encoded and not
   * premultiplied, which is what a colour map and its alpha are. */
  image.format = PNG_FORMAT_RGBA;
  unsigned char *rgba = NULL;
  if ((uint64_t)image.width * image.height <= TEXTURE_MAX_PIXELS)
    rgba = malloc(PNG_IMAGE_SIZE(image));
  if (!rgba) {
    png_image_free(&image);
    free(data);
    return hush__fail(device, HUSH_ERROR_UNSUPPORTED, "%s: PNG '%s' (%ux%u) is too large", what,
                      path, image.width, image.height);
  }
  if (!png_image_finish_read(&image, NULL, rgba, 0, NULL)) {
    st = hush__fail(device, HUSH_ERROR_CORRUPT, "%s: cannot decode PNG '%s': %s", what, path,
                    image.message);
    png_image_free(&image);
    free(rgba);
    free(data);
    return st;
  }
  free(data);
  const int nc = kind == HUSH_TEXTURE_ALPHA ? 1 : 3;
  st = hush__texture_init(device, t, base_name(path), image.width, image.height, nc);
  if (st == HUSH_OK) {
    float lut[256];
    srgb_table(lut);
    const size_t n = (size_t)image.width * image.height;
    for (size_t i = 0; i < n; i++) {
      const unsigned char *p = rgba + i * 4;
      if (nc == 1) {
        /* opacity: the alpha channel, or the grey level of an opaque image */
        t->texels[i] = has_alpha ? p[3] / 255.0f : (p[0] + p[1] + p[2]) / (3.0f * 255.0f);
      } else {
        for (int c = 0; c < 3; c++)
          t->texels[i * 3 + c] = kind == HUSH_TEXTURE_SRGB ? lut[p[c]] : p[c] / 255.0f;
      }
    }
  }
  free(rgba);
  return st;
}

/* ------------------------------------------------------------------------ */
/* EXR                                                                      */
/* ------------------------------------------------------------------------ */

static hush_status load_exr(hush_device device, const char *path, const char *what,
                            hush_texture_kind kind, hush_texture *t) {
  hush_frame frame = NULL;
  hush_status st = hush_frame_read_exr(device, path, &frame);
  if (st != HUSH_OK) return st;
  const hush_layer *layer = hush__frame_find(frame, "color");
  if (!layer && frame->layer_count > 0) layer = &frame->layers[0];
  if (!layer) {
    hush_frame_release(frame);
    return hush__fail(device, HUSH_ERROR_CORRUPT, "%s: EXR '%s' has no channels", what, path);
  }
  const int nc = kind == HUSH_TEXTURE_ALPHA ? 1 : 3;
  st = hush__texture_init(device, t, base_name(path), frame->width, frame->height, nc);
  if (st == HUSH_OK) {
    const size_t n = (size_t)frame->width * frame->height;
    const int lc = layer->channels;
    for (size_t i = 0; i < n; i++) {
      const float *p = layer->pixels + i * (size_t)lc;
      for (int c = 0; c < nc; c++) {
        float x = p[c < lc ? c : lc - 1];
        /* NaN/Inf texels would poison every path that sees them */
        if (!isfinite(x) || x < 0.0f) x = 0.0f;
        t->texels[i * (size_t)nc + c] = x; /* EXR data is linear already */
      }
    }
  }
  hush_frame_release(frame);
  return st;
}

/* ------------------------------------------------------------------------ */
/* Loading by file type                                                     */
/* ------------------------------------------------------------------------ */

static int has_extension(const char *path, const char *ext) {
  const size_t n = strlen(path), e = strlen(ext);
  return n > e && strcasecmp(path + n - e, ext) == 0;
}

hush_status hush__texture_load(hush_device device, const char *path, const char *what,
                               hush_texture_kind kind, hush_texture *t) {
  memset(t, 0, sizeof *t);
  struct stat st;
  if (stat(path, &st) != 0)
    return hush__fail(device, HUSH_ERROR_NOT_FOUND, "%s: texture '%s' not found", what, path);
  if (has_extension(path, ".jpg") || has_extension(path, ".jpeg"))
    return load_jpeg(device, path, what, kind, t);
  if (has_extension(path, ".png")) return load_png(device, path, what, kind, t);
  if (has_extension(path, ".exr")) return load_exr(device, path, what, kind, t);
  return hush__fail(device, HUSH_ERROR_UNSUPPORTED,
                    "%s: texture '%s': unsupported file type (JPG, PNG and EXR are)", what, path);
}
