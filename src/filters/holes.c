/*
 * holes.c — hole detection and the pyramid fill of Dundr 2018 §4.2.1; see
 * holes.h.
 */
#include "filters/holes.h"

#include "core/device.h"
#include "core/image.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

static inline int clampi(int v, int lo, int hi) { return v < lo ? lo : v > hi ? hi : v; }

int hush__holes_any(const float *valid, size_t n, int threads) {
  int holes = 0;
  const long long count = (long long)n;
#pragma omp parallel for reduction(| : holes) schedule(static) num_threads(threads)
  for (long long i = 0; i < count; i++) holes |= hush__holes_is_hole(valid[i]);
  return holes;
}

size_t hush__holes_pyramid_floats(uint32_t W, uint32_t H, int planes) {
  size_t total = 0;
  uint32_t w = W, h = H;
  while (w > 1 || h > 1) {
    w = (w + 2) / 3;
    h = (h + 2) / 3;
    total += (size_t)w * h * (size_t)(planes + 1); /* + validity */
  }
  return total;
}

hush_status hush__holes_reserve(hush_device device, hush_holes *h, uint32_t width,
                                uint32_t height, int planes) {
  const size_t need = hush__holes_pyramid_floats(width, height, planes);
  if (h->pyramid && h->floats >= need) return HUSH_OK;
  hush__free_floats(h->pyramid);
  h->floats = 0;
  h->pyramid = need ? hush__alloc_floats(need) : NULL;
  if (need && !h->pyramid) return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "holes: out of memory");
  h->floats = need;
  return HUSH_OK;
}

void hush__holes_free(hush_holes *h) {
  hush__free_floats(h->pyramid);
  memset(h, 0, sizeof *h);
}

typedef struct level {
  int w, h;
  float *v[HUSH_HOLES_MAX_PLANES]; /* values */
  float *ok;                        /* 1 where valid (level 0: NULL, from `valid`) */
} level;

void hush__holes_fill(float *pyramid, uint32_t width, uint32_t height, const float *valid,
                      float *const *planes, int count, int threads) {
  if (count > HUSH_HOLES_MAX_PLANES) count = HUSH_HOLES_MAX_PLANES;
  level lv[32];
  int L = 1;
  lv[0].w = (int)width;
  lv[0].h = (int)height;
  for (int k = 0; k < count; k++) lv[0].v[k] = planes[k];
  lv[0].ok = NULL;
  float *mem = pyramid;
  /* down: 3x3 averages of the valid pixels, until a level has no hole */
  int holes = 1;
  while (holes && (lv[L - 1].w > 1 || lv[L - 1].h > 1) && L < 32) {
    const level *f = &lv[L - 1];
    level *c = &lv[L];
    c->w = (f->w + 2) / 3;
    c->h = (f->h + 2) / 3;
    const size_t n = (size_t)c->w * c->h;
    for (int k = 0; k < count; k++, mem += n) c->v[k] = mem;
    c->ok = mem;
    mem += n;
    holes = 0;
#pragma omp parallel for reduction(| : holes) schedule(static) num_threads(threads)
    for (int y = 0; y < c->h; y++)
      for (int x = 0; x < c->w; x++) {
        float sum[HUSH_HOLES_MAX_PLANES] = {0};
        float m = 0.0f;
        for (int j = 3 * y; j < 3 * y + 3 && j < f->h; j++)
          for (int i = 3 * x; i < 3 * x + 3 && i < f->w; i++) {
            const size_t q = (size_t)j * f->w + i;
            const float ok = f->ok ? f->ok[q] : (float)!hush__holes_is_hole(valid[q]);
            for (int k = 0; k < count; k++) sum[k] += ok * f->v[k][q];
            m += ok;
          }
        const size_t o = (size_t)y * c->w + x;
        for (int k = 0; k < count; k++) c->v[k][o] = m > 0.0f ? sum[k] / m : 0.0f;
        c->ok[o] = m > 0.0f ? 1.0f : 0.0f;
        holes |= !(m > 0.0f);
      }
    L++;
  }
  /* up: every hole of a level from the bilinear lookup of the one above
   * (filled already; the top is whole, or all zero without any sample) */
  for (int l = L - 2; l >= 0; l--) {
    const level *c = &lv[l + 1];
    level *f = &lv[l];
#pragma omp parallel for schedule(static) num_threads(threads)
    for (int y = 0; y < f->h; y++)
      for (int x = 0; x < f->w; x++) {
        const size_t o = (size_t)y * f->w + x;
        const int ok = f->ok ? f->ok[o] > 0.0f : !hush__holes_is_hole(valid[o]);
        if (ok) continue;
        const float sx = ((float)x + 0.5f) / 3.0f - 0.5f, sy = ((float)y + 0.5f) / 3.0f - 0.5f;
        const int x0 = clampi((int)floorf(sx), 0, c->w - 1), y0 = clampi((int)floorf(sy), 0, c->h - 1);
        const int x1 = clampi(x0 + 1, 0, c->w - 1), y1 = clampi(y0 + 1, 0, c->h - 1);
        float fx = sx - (float)x0, fy = sy - (float)y0;
        fx = fx < 0.0f ? 0.0f : fx > 1.0f ? 1.0f : fx;
        fy = fy < 0.0f ? 0.0f : fy > 1.0f ? 1.0f : fy;
        for (int k = 0; k < count; k++) {
          const float *v = c->v[k];
          const float top = v[(size_t)y0 * c->w + x0] * (1 - fx) + v[(size_t)y0 * c->w + x1] * fx;
          const float bot = v[(size_t)y1 * c->w + x0] * (1 - fx) + v[(size_t)y1 * c->w + x1] * fx;
          f->v[k][o] = top * (1 - fy) + bot * fy;
        }
        if (f->ok) f->ok[o] = 1.0f;
      }
  }
}

void hush__holes_split_background(float *pyramid, uint32_t width, uint32_t height,
                                  const float *valid, float *const *scratch, float *const *planes,
                                  int count, float *const *motion, int threads) {
  const long long n = (long long)width * height;
  const float *depth = planes[0];
  float *surface = scratch[0];
#pragma omp parallel for simd schedule(static) num_threads(threads)
  for (long long i = 0; i < n; i++) surface[i] = depth[i] > 0.0f ? 1.0f : 0.0f;
  if (motion)
#pragma omp parallel for simd schedule(static) num_threads(threads)
    for (long long i = 0; i < n; i++) {
      scratch[1][i] = motion[0][i] * surface[i];
      scratch[2][i] = motion[1][i] * surface[i];
    }
  hush__holes_fill(pyramid, width, height, valid, scratch, motion ? 3 : 1, threads);
#pragma omp parallel for schedule(static) num_threads(threads)
  for (long long i = 0; i < n; i++) {
    if (!hush__holes_is_hole(valid[i])) continue;
    const float sf = surface[i];
    const int on_surface = sf > 0.5f;
    const float k = on_surface ? 1.0f / sf : 0.0f;
    for (int c = 0; c < count; c++) planes[c][i] *= k;
    for (int c = 0; motion && c < 2; c++) {
      /* fill(m) = fill(m s) + fill(m (1 - s)), the same weights */
      const float ms = scratch[1 + c][i];
      motion[c][i] = on_surface ? ms / sf : (motion[c][i] - ms) / (1.0f - sf);
    }
  }
}

void hush__holes_normalize_normals(const float *valid, const float *depth, float *const n[3],
                                   size_t count, int threads) {
  const long long c = (long long)count;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (long long i = 0; i < c; i++) {
    if (!(depth[i] > 0.0f)) {
      n[0][i] = n[1][i] = 0.0f;
      n[2][i] = 1.0f;
      continue;
    }
    if (!hush__holes_is_hole(valid[i])) continue;
    const float l2 = n[0][i] * n[0][i] + n[1][i] * n[1][i] + n[2][i] * n[2][i];
    if (!(l2 > 1e-12f)) continue;
    const float s = 1.0f / sqrtf(l2);
    for (int k = 0; k < 3; k++) n[k][i] *= s;
  }
}
