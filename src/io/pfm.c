/*
 * pfm.c — Portable Float Map files, the plain float exchange format of many
 * denoisers and image tools: "PF" (RGB) or "Pf" (gray), then width, height
 * and a scale whose sign gives the byte order (negative: little-endian), then
 * raw float32 rows from the BOTTOM of the image to the top.
 *
 * We write little-endian with scale -1. The reader is strict about the
 * header (no comments, decimal sizes, one whitespace byte before the
 * pixels), accepts either byte order, ignores the scale's magnitude (as
 * other tools do) and checks the file holds every pixel before allocating.
 */
#include "core/device.h"
#include "core/image.h"
#include "io/atomic_file.h"
#include "io/frame.h"
#include "io/view_rows.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#define PFM_MAX_SIZE 65536u
#define PFM_MAX_PIXELS ((uint64_t)1 << 28) /* 16384 x 16384 */
#define PFM_TOKEN_MAX 32

static int host_is_little_endian(void) {
  const uint32_t one = 1;
  uint8_t first;
  memcpy(&first, &one, 1);
  return first == 1;
}

static void swap_bytes32(float *values, size_t n) {
  uint8_t *b = (uint8_t *)values;
  for (size_t i = 0; i < n; i++, b += 4) {
    uint8_t t = b[0];
    b[0] = b[3];
    b[3] = t;
    t = b[1];
    b[1] = b[2];
    b[2] = t;
  }
}

static int is_space(int c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r'; }

/* ------------------------------------------------------------------------ */
/* Writing                                                                  */
/* ------------------------------------------------------------------------ */

hush_status hush_image_write_pfm(hush_device device, const hush_image_view *view,
                                 const char *path) {
  if (!device)
    return hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT, "hush_image_write_pfm: device is NULL");
  if (!path || !*path)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                      "hush_image_write_pfm: path is NULL or empty");
  hush_status status = hush__view_validate(device, view, path, 1, 0);
  if (status != HUSH_OK) return status;
  const int channels = hush_format_channels(view->format);
  if (channels == 2)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                      "'%s': a PFM file needs a view of 1, 3 or 4 channels, not 2", path);
  const int out_ch = channels == 1 ? 1 : 3;
  const size_t row_len = (size_t)view->width * (size_t)out_ch;
  float *row = malloc(row_len * sizeof *row);
  if (!row) return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory writing '%s'", path);

  char tmp[HUSH_PATH_MAX];
  FILE *f = hush__atomic_open(device, path, tmp);
  if (!f) {
    free(row);
    return HUSH_ERROR_IO;
  }
  int ok =
      fprintf(f, "%s\n%u %u\n-1.0\n", out_ch == 1 ? "Pf" : "PF", view->width, view->height) > 0;
  const int swap = !host_is_little_endian();
  for (uint32_t i = 0; ok && i < view->height; i++) {
    hush__view_load_row(view, view->height - 1 - i, out_ch, row);
    if (swap) swap_bytes32(row, row_len);
    ok = fwrite(row, sizeof *row, row_len, f) == row_len;
  }
  free(row);
  if (!ok) {
    const int err = errno;
    hush__atomic_abort(f, tmp);
    return hush__fail(device, HUSH_ERROR_IO, "cannot write '%s': %s", path, strerror(err));
  }
  return hush__atomic_commit(device, f, tmp, path);
}

/* ------------------------------------------------------------------------ */
/* Reading                                                                  */
/* ------------------------------------------------------------------------ */

typedef struct pfm_header {
  int channels;
  uint32_t width, height;
  int little_endian;
} pfm_header;

/* Reads one token and the single whitespace byte that ends it, after any
 * whitespace when skip_space is set. Returns 0 if the token is empty, too
 * long or ends the file. */
static int read_token(FILE *f, int skip_space, char token[PFM_TOKEN_MAX]) {
  int n = 0, c = getc(f);
  while (skip_space && is_space(c)) c = getc(f);
  for (; c != EOF && !is_space(c); c = getc(f)) {
    if (n == PFM_TOKEN_MAX - 1) return 0;
    token[n++] = (char)c;
  }
  token[n] = '\0';
  return n > 0 && c != EOF;
}

/* Strict decimal: digits only, 1..PFM_MAX_SIZE. */
static int parse_size(const char *s, uint32_t *out) {
  uint64_t v = 0;
  if (!*s) return 0;
  for (; *s; s++) {
    if (*s < '0' || *s > '9') return 0;
    v = v * 10 + (uint64_t)(*s - '0');
    if (v > PFM_MAX_SIZE) return 0;
  }
  *out = (uint32_t)v;
  return v > 0;
}

/* Parses "PF" / "Pf" (at the very start), width, height and scale. The
 * scale is followed by exactly one whitespace byte, then the pixels. Fills a
 * short reason on failure. */
static int parse_header(FILE *f, pfm_header *h, const char **reason) {
  char token[PFM_TOKEN_MAX];
  if (!read_token(f, 0, token) || token[0] != 'P' || (token[1] != 'F' && token[1] != 'f') ||
      token[2] != '\0') {
    *reason = "not a PFM file (expected \"PF\" or \"Pf\")";
    return 0;
  }
  h->channels = token[1] == 'F' ? 3 : 1;
  if (!read_token(f, 1, token) || !parse_size(token, &h->width)) {
    *reason = "bad width (expected an integer in 1..65536)";
    return 0;
  }
  if (!read_token(f, 1, token) || !parse_size(token, &h->height)) {
    *reason = "bad height (expected an integer in 1..65536)";
    return 0;
  }
  if ((uint64_t)h->width * h->height > PFM_MAX_PIXELS) {
    *reason = "too many pixels (more than 2^28)";
    return 0;
  }
  char *end = NULL;
  if (!read_token(f, 1, token)) {
    *reason = "missing scale";
    return 0;
  }
  const double scale = strtod(token, &end);
  if (*end != '\0' || !isfinite(scale) || scale == 0.0) {
    *reason = "bad scale (expected a non-zero number)";
    return 0;
  }
  h->little_endian = scale < 0.0;
  return 1;
}

/* Bytes left in f after its current position, or -1 if unknown. */
static long long bytes_left(FILE *f) {
  struct stat st;
  const long pos = ftell(f);
  if (pos < 0 || fstat(fileno(f), &st) != 0 || !S_ISREG(st.st_mode)) return -1;
  return (long long)st.st_size - pos;
}

static hush_status read_pixels(hush_device device, FILE *f, const char *path, const pfm_header *h,
                               const char *layer_name, hush_frame *out) {
  const size_t row_len = (size_t)h->width * (size_t)h->channels;
  const long long need = (long long)(row_len * sizeof(float) * h->height);
  const long long have = bytes_left(f);
  if (have >= 0 && have < need)
    return hush__fail(device, HUSH_ERROR_CORRUPT,
                      "'%s': truncated: %ux%u needs %lld bytes of pixels, the file has %lld", path,
                      h->width, h->height, need, have);
  hush_frame frame = hush_frame_new(device, h->width, h->height);
  if (!frame) return HUSH_ERROR_OUT_OF_MEMORY;
  hush_image_view view;
  hush_status status = hush_frame_add_layer(frame, layer_name, h->channels, &view);
  if (status != HUSH_OK) {
    hush_frame_release(frame);
    return status;
  }
  const int swap = h->little_endian != host_is_little_endian();
  for (uint32_t i = 0; i < h->height; i++) {
    float *row = (float *)view.data + (size_t)(h->height - 1 - i) * row_len;
    if (fread(row, sizeof *row, row_len, f) != row_len) {
      hush_frame_release(frame);
      if (ferror(f))
        return hush__fail(device, HUSH_ERROR_IO, "cannot read '%s': %s", path, strerror(errno));
      return hush__fail(device, HUSH_ERROR_CORRUPT, "'%s': truncated in row %u of %u", path, i,
                        h->height);
    }
    if (swap) swap_bytes32(row, row_len);
  }
  *out = frame;
  return HUSH_OK;
}

hush_status hush_frame_read_pfm(hush_device device, const char *path, const char *layer_name,
                                hush_frame *frame) {
  if (!device)
    return hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT, "hush_frame_read_pfm: device is NULL");
  if (!frame)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "hush_frame_read_pfm: frame is NULL");
  *frame = NULL;
  if (!path || !*path)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                      "hush_frame_read_pfm: path is NULL or empty");
  if (!layer_name || !*layer_name || strlen(layer_name) >= HUSH_LAYER_NAME_MAX)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                      "hush_frame_read_pfm: layer name must have 1 to %d characters",
                      HUSH_LAYER_NAME_MAX - 1);
  FILE *f = fopen(path, "rb");
  if (!f) return hush__fail(device, HUSH_ERROR_IO, "cannot open '%s': %s", path, strerror(errno));
  pfm_header h;
  const char *reason = NULL;
  hush_status status;
  if (!parse_header(f, &h, &reason)) {
    status = ferror(f)
                 ? hush__fail(device, HUSH_ERROR_IO, "cannot read '%s': %s", path, strerror(errno))
                 : hush__fail(device, HUSH_ERROR_CORRUPT, "'%s': %s", path, reason);
  } else {
    status = read_pixels(device, f, path, &h, layer_name, frame);
  }
  fclose(f);
  return status;
}
