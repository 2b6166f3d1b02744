/*
 * weights.c — reads and writes the "nca" weights file (format in weights.h
 * and docs/nca.md). Every field is checked on load, so a truncated,
 * corrupted or foreign file is refused with a message instead of feeding
 * garbage to the filter.
 */
#include "filters/nca/weights.h"

#include "io/atomic_file.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

static const unsigned char magic[8] = {'H', 'U', 'S', 'H', 'N', 'C', 'A', 0};

static uint32_t fnv1a(const unsigned char *p, size_t n) {
  uint32_t h = 2166136261u;
  for (size_t i = 0; i < n; i++) h = (h ^ p[i]) * 16777619u;
  return h;
}

static void put_u32(unsigned char *p, uint32_t v) {
  p[0] = (unsigned char)v;
  p[1] = (unsigned char)(v >> 8);
  p[2] = (unsigned char)(v >> 16);
  p[3] = (unsigned char)(v >> 24);
}

static uint32_t get_u32(const unsigned char *p) {
  return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

static void put_f32(unsigned char *p, float f) {
  uint32_t v;
  memcpy(&v, &f, 4);
  put_u32(p, v);
}

static float get_f32(const unsigned char *p) {
  const uint32_t v = get_u32(p);
  float f;
  memcpy(&f, &v, 4);
  return f;
}

hush_status hush__nca_weights_check(hush_device device, const hush_nca_weights *w,
                                    const char *what) {
  if (w->iterations < 1 || w->iterations > HUSH_NCA_MAX_ITERATIONS)
    return hush__fail(device, HUSH_ERROR_CORRUPT, "%s: iteration count %u is not in 1..%d", what,
                      w->iterations, HUSH_NCA_MAX_ITERATIONS);
  if (w->color_transform > HUSH_NCA_LOG1P)
    return hush__fail(device, HUSH_ERROR_CORRUPT, "%s: unknown colour transform %u", what,
                      w->color_transform);
  for (int i = 0; i < HUSH_NCA_WEIGHT_COUNT; i++)
    if (!isfinite(w->w[i]))
      return hush__fail(device, HUSH_ERROR_CORRUPT, "%s: weight %d is not finite", what, i);
  for (int i = 0; i < HUSH_NCA_CHANNELS; i++)
    if (!isfinite(w->bias[i]))
      return hush__fail(device, HUSH_ERROR_CORRUPT, "%s: bias %d is not finite", what, i);
  return HUSH_OK;
}

void hush__nca_weights_encode(const hush_nca_weights *w, unsigned char *buf) {
  memcpy(buf, magic, 8);
  put_u32(buf + 8, HUSH_NCA_FILE_VERSION);
  put_u32(buf + 12, HUSH_NCA_CHANNELS);
  put_u32(buf + 16, HUSH_NCA_PERCEPTION);
  put_u32(buf + 20, w->iterations);
  put_u32(buf + 24, w->color_transform);
  put_u32(buf + 28, HUSH_NCA_PARAM_COUNT);
  unsigned char *p = buf + HUSH_NCA_FILE_HEADER;
  for (int i = 0; i < HUSH_NCA_WEIGHT_COUNT; i++, p += 4) put_f32(p, w->w[i]);
  for (int i = 0; i < HUSH_NCA_CHANNELS; i++, p += 4) put_f32(p, w->bias[i]);
  put_u32(p, fnv1a(buf, (size_t)(p - buf)));
}

hush_status hush__nca_weights_decode(hush_device device, const unsigned char *buf, size_t size,
                                     const char *what, hush_nca_weights *out) {
  if (size < 12 || memcmp(buf, magic, 8) != 0)
    return hush__fail(device, HUSH_ERROR_CORRUPT, "%s: not an nca weights file (bad magic)",
                      what);
  const uint32_t version = get_u32(buf + 8);
  if (version != HUSH_NCA_FILE_VERSION)
    return hush__fail(device, HUSH_ERROR_UNSUPPORTED,
                      "%s: weights file version %u, this build reads version %u", what, version,
                      HUSH_NCA_FILE_VERSION);
  if (size != HUSH_NCA_FILE_SIZE)
    return hush__fail(device, HUSH_ERROR_CORRUPT, "%s: %zu bytes, a version %u file has %u%s",
                      what, size, HUSH_NCA_FILE_VERSION, HUSH_NCA_FILE_SIZE,
                      size < HUSH_NCA_FILE_SIZE ? " (truncated)" : "");
  const uint32_t channels = get_u32(buf + 12), perception = get_u32(buf + 16);
  const uint32_t count = get_u32(buf + 28);
  if (channels != HUSH_NCA_CHANNELS || perception != HUSH_NCA_PERCEPTION ||
      count != HUSH_NCA_PARAM_COUNT)
    return hush__fail(device, HUSH_ERROR_CORRUPT,
                      "%s: dimensions %u channels, %u perception, %u parameters; expected %d, "
                      "%d, %d",
                      what, channels, perception, count, HUSH_NCA_CHANNELS, HUSH_NCA_PERCEPTION,
                      HUSH_NCA_PARAM_COUNT);
  const size_t body = HUSH_NCA_FILE_SIZE - 4;
  const uint32_t stored = get_u32(buf + body), computed = fnv1a(buf, body);
  if (stored != computed)
    return hush__fail(device, HUSH_ERROR_CORRUPT,
                      "%s: checksum mismatch (stored %08x, computed %08x): the file is corrupt",
                      what, stored, computed);
  hush_nca_weights w;
  w.iterations = get_u32(buf + 20);
  w.color_transform = get_u32(buf + 24);
  const unsigned char *p = buf + HUSH_NCA_FILE_HEADER;
  for (int i = 0; i < HUSH_NCA_WEIGHT_COUNT; i++, p += 4) w.w[i] = get_f32(p);
  for (int i = 0; i < HUSH_NCA_CHANNELS; i++, p += 4) w.bias[i] = get_f32(p);
  hush_status s = hush__nca_weights_check(device, &w, what);
  if (s) return s;
  *out = w;
  return HUSH_OK;
}

hush_status hush__nca_weights_load(hush_device device, const char *path, hush_nca_weights *w) {
  FILE *f = fopen(path, "rb");
  if (!f)
    return hush__fail(device, HUSH_ERROR_IO, "%s: cannot open: %s", path, strerror(errno));
  /* one byte more than a valid file, to detect trailing data */
  unsigned char buf[HUSH_NCA_FILE_SIZE + 1];
  const size_t n = fread(buf, 1, sizeof buf, f);
  const int err = ferror(f);
  fclose(f);
  if (err) return hush__fail(device, HUSH_ERROR_IO, "%s: read error", path);
  return hush__nca_weights_decode(device, buf, n, path, w);
}

hush_status hush__nca_weights_save(hush_device device, const char *path,
                                   const hush_nca_weights *w) {
  hush_status s = hush__nca_weights_check(device, w, path);
  if (s) return s;
  unsigned char buf[HUSH_NCA_FILE_SIZE];
  hush__nca_weights_encode(w, buf);
  char tmp[HUSH_PATH_MAX];
  FILE *f = hush__atomic_open(device, path, tmp);
  if (!f) return HUSH_ERROR_IO;
  if (fwrite(buf, 1, sizeof buf, f) != sizeof buf) {
    hush__atomic_abort(f, tmp);
    return hush__fail(device, HUSH_ERROR_IO, "%s: write error", path);
  }
  return hush__atomic_commit(device, f, tmp, path);
}
