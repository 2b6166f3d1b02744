/*
 * progressive.c — SVGF below one sample per pixel (see progressive.h;
 * Dundr 2018 §4.2.1-4.2.5).
 */
#include "filters/svgf/progressive.h"

#include "core/device.h"
#include "core/hmath.h"
#include "filters/holes.h"
#include "filters/svgf/weights.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define NO_KEY UINT64_MAX
#define FAR_AWAY 1e30f

static inline int is_hole(float spp) { return !(spp > 0.0f); }
static inline int clampi(int v, int lo, int hi) { return v < lo ? lo : v > hi ? hi : v; }

hush_status svgf_progressive_init(hush_device device, svgf_progressive *p, uint32_t W,
                                  uint32_t H) {
  memset(p, 0, sizeof *p);
  p->width = W;
  p->height = H;
  const size_t n = (size_t)W * H;
  hush_status s = hush__planar_init(device, &p->pos[0], 4, W, H);
  if (!s) s = hush__planar_init(device, &p->pos[1], 4, W, H);
  if (!s) s = hush__planar_init(device, &p->depth, 1, W, H);
  if (!s) s = hush__planar_init(device, &p->near_far, 2, W, H);
  if (!s) s = hush__planar_init(device, &p->scratch, 2, W, H);
  if (!s) s = hush__planar_init(device, &p->background, 1, W, H);
  if (!s) {
    p->pyramid_floats = hush__holes_pyramid_floats(W, H, SVGF_PYRAMID_MAX_PLANES);
    p->src = hush__alloc_counted(n, sizeof *p->src);
    p->keys = hush__alloc_counted(n, sizeof *p->keys);
    p->pyramid = p->pyramid_floats ? hush__alloc_floats(p->pyramid_floats) : NULL;
    if (!p->src || !p->keys || (p->pyramid_floats && !p->pyramid))
      s = hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "svgf: out of memory");
  }
  if (s) svgf_progressive_free(p);
  return s;
}

void svgf_progressive_free(svgf_progressive *p) {
  for (int i = 0; i < 2; i++) hush__planar_free(&p->pos[i]);
  hush__planar_free(&p->depth);
  hush__planar_free(&p->near_far);
  hush__planar_free(&p->scratch);
  hush__planar_free(&p->background);
  free(p->src);
  free(p->keys);
  hush__free_floats(p->pyramid);
  memset(p, 0, sizeof *p);
}

int svgf_has_holes(const float *spp, size_t n, int threads) {
  return hush__holes_any(spp, n, threads);
}

/* ---- §4.2.1 hole filling by a pyramid (shared: filters/holes.h) --------- */

void svgf_fill_holes(svgf_progressive *p, const float *spp, float *const *planes, int count,
                     int threads) {
  hush__holes_fill(p->pyramid, p->width, p->height, spp, planes, count, threads);
}

void svgf_split_background(svgf_progressive *p, const float *spp, float *const *geometry,
                           int count, int threads) {
  /* scratch is free until the near/far passes of svgf_forward_scatter */
  float *const surface[1] = {p->scratch.plane[1]};
  hush__holes_split_background(p->pyramid, p->width, p->height, spp, surface, geometry, count,
                               NULL, threads);
  const long long n = (long long)p->width * p->height;
  const float *z = geometry[0];
  float *bg = p->background.plane[0];
#pragma omp parallel for simd schedule(static) num_threads(threads)
  for (long long i = 0; i < n; i++) bg[i] = is_hole(spp[i]) && !(z[i] > 0.0f) ? 1.0f : 0.0f;
}

/* ---- §4.2.5 near and far traced depth over 27x27 -------------------------- */

/* One 3x3 min/max pass with taps `step` apart: in (2 planes) -> out. */
static void min_max_pass(const float *in_near, const float *in_far, float *out_near,
                         float *out_far, int W, int H, int step, int threads) {
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < H; y++)
    for (int x = 0; x < W; x++) {
      float nr = FAR_AWAY, fr = -FAR_AWAY;
      for (int j = -1; j <= 1; j++) {
        const size_t row = (size_t)clampi(y + j * step, 0, H - 1) * W;
        for (int i = -1; i <= 1; i++) {
          const size_t q = row + clampi(x + i * step, 0, W - 1);
          nr = in_near[q] < nr ? in_near[q] : nr;
          fr = in_far[q] > fr ? in_far[q] : fr;
        }
      }
      out_near[(size_t)y * W + x] = nr;
      out_far[(size_t)y * W + x] = fr;
    }
}

static void near_far(svgf_progressive *p, int threads) {
  const int W = (int)p->width, H = (int)p->height;
  const long long n = (long long)W * H;
  float *nr = p->near_far.plane[0], *fr = p->near_far.plane[1];
  float *tn = p->scratch.plane[0], *tf = p->scratch.plane[1];
  const float *z = p->depth.plane[0];
#pragma omp parallel for schedule(static) num_threads(threads)
  for (long long i = 0; i < n; i++) {
    const int traced = z[i] > 0.0f; /* holes and background carry no depth */
    tn[i] = traced ? z[i] : FAR_AWAY;
    tf[i] = traced ? z[i] : -FAR_AWAY;
  }
  min_max_pass(tn, tf, nr, fr, W, H, 1, threads);
  min_max_pass(nr, fr, tn, tf, W, H, 3, threads);
  min_max_pass(tn, tf, nr, fr, W, H, 9, threads);
}

/* ---- §4.2.4 forward reprojection by scatter ------------------------------ */

static inline uint32_t float_bits(float f) {
  uint32_t b;
  memcpy(&b, &f, sizeof b);
  return b;
}

static inline void atomic_min_u64(uint64_t *p, uint64_t v) {
  uint64_t cur = __atomic_load_n(p, __ATOMIC_RELAXED);
  while (v < cur &&
         !__atomic_compare_exchange_n(p, &cur, v, 1, __ATOMIC_RELAXED, __ATOMIC_RELAXED)) {
  }
}

void svgf_forward_scatter(svgf_progressive *p, const float *spp, const float *prev_age,
                          const hush_frame_info *info, int threads) {
  const int W = (int)p->width, H = (int)p->height;
  const long long n = (long long)W * H;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (long long i = 0; i < n; i++) {
    p->keys[i] = NO_KEY;
    p->src[i] = -1;
  }
  if (!p->has_pos || !prev_age) return;
  near_far(p, threads);
  float vp[16];
  hush_m4_mul(vp, info->view_to_clip, info->world_to_view);
  const float *w2v = info->world_to_view;
  const hush_planar *pos = &p->pos[p->latest];
  /* positive floats order like their bits: the key's minimum is the
   * nearest surface, ties broken by the source index (deterministic) */
#pragma omp parallel for schedule(static) num_threads(threads)
  for (long long i = 0; i < n; i++) {
    if (!(prev_age[i] > 0.0f) || !(pos->plane[3][i] > 0.0f)) continue;
    const float X = pos->plane[0][i], Y = pos->plane[1][i], Z = pos->plane[2][i];
    const hush_vec4 c = hush_m4_mul_v4(vp, X, Y, Z, 1.0f);
    const float d = -(w2v[2] * X + w2v[6] * Y + w2v[10] * Z + w2v[14]);
    if (!(c.w > 0.0f) || !(d > 0.0f)) continue;
    const float px = (c.x / c.w + 1.0f) * 0.5f * (float)W;
    const float py = (1.0f - c.y / c.w) * 0.5f * (float)H;
    if (!(px >= 0.0f && px < (float)W && py >= 0.0f && py < (float)H)) continue;
    const size_t t = (size_t)(int)py * W + (size_t)(int)px;
    atomic_min_u64(&p->keys[t], ((uint64_t)float_bits(d) << 32) | (uint64_t)i);
  }
  const float *nr = p->near_far.plane[0], *fr = p->near_far.plane[1];
#pragma omp parallel for schedule(static) num_threads(threads)
  for (long long t = 0; t < n; t++) {
    if (p->keys[t] == NO_KEY) continue;
    const int32_t s = (int32_t)(p->keys[t] & 0xffffffffu);
    const uint32_t db = (uint32_t)(p->keys[t] >> 32);
    float d;
    memcpy(&d, &db, sizeof d);
    /* a moved sample closer to the far than the near traced surface around
     * it was seen through a hole (§4.2.5) */
    const int moved = s != (int32_t)t;
    const int known = nr[t] < FAR_AWAY && fr[t] > -FAR_AWAY;
    if (is_hole(spp[t]) && moved && known && d - nr[t] > fr[t] - d) continue;
    p->src[t] = s;
  }
}

/* The sources that landed in the 3x3 neighbourhood of t (t itself first). */
static int landed_around(const svgf_progressive *p, int x, int y, int32_t out[9]) {
  const int W = (int)p->width, H = (int)p->height;
  int m = 0;
  const int32_t own = p->src[(size_t)y * W + x];
  if (own >= 0) {
    out[0] = own;
    return 1;
  }
  for (int j = -1; j <= 1; j++)
    for (int i = -1; i <= 1; i++) {
      const int xx = x + i, yy = y + j;
      if (xx < 0 || yy < 0 || xx >= W || yy >= H) continue;
      const int32_t s = p->src[(size_t)yy * W + xx];
      if (s >= 0) out[m++] = s;
    }
  return m;
}

void svgf_forward_state(const svgf_progressive *p, const float *spp,
                        const float *const prev[6], float *const cur[6], float alpha_min,
                        float alpha_moments_min, int threads) {
  const int W = (int)p->width, H = (int)p->height;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < H; y++)
    for (int x = 0; x < W; x++) {
      const size_t t = (size_t)y * W + x;
      if (!is_hole(spp[t])) continue;
      int32_t s[9];
      const int m = prev && !(p->background.plane[0][t] > 0.0f) ? landed_around(p, x, y, s) : 0;
      if (m > 0) {
        for (int k = 0; k < 6; k++) {
          float sum = 0.0f;
          for (int i = 0; i < m; i++) sum += prev[k][s[i]];
          cur[k][t] = sum / (float)m;
        }
        continue;
      }
      /* nothing landed: the backward reprojection's history, which the
       * blend mixed with a 0 sample: c = (1 - a) h, age = gathered + 1 */
      const float age = cur[5][t];
      if (age > 1.0f) {
        const float a = 1.0f / age > alpha_min ? 1.0f / age : alpha_min;
        const float am = 1.0f / age > alpha_moments_min ? 1.0f / age : alpha_moments_min;
        if (a < 1.0f && am < 1.0f) {
          for (int k = 0; k < 3; k++) cur[k][t] /= 1.0f - a;
          for (int k = 3; k < 5; k++) cur[k][t] /= 1.0f - am;
          cur[5][t] = age - 1.0f;
          continue;
        }
      }
      for (int k = 0; k < 6; k++) cur[k][t] = 0.0f;
    }
}

void svgf_carry_positions(svgf_progressive *p, const float *spp, const float *const position[3],
                          const float *depth, int threads) {
  const int W = (int)p->width, H = (int)p->height;
  const hush_planar *prev = &p->pos[p->latest];
  hush_planar *next = &p->pos[1 - p->latest];
  const int have = p->has_pos;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < H; y++)
    for (int x = 0; x < W; x++) {
      const size_t t = (size_t)y * W + x;
      int32_t s[9];
      const int m = is_hole(spp[t]) && have && !(p->background.plane[0][t] > 0.0f)
                        ? landed_around(p, x, y, s)
                        : 0;
      if (m > 0) {
        float acc[4] = {0, 0, 0, 0};
        for (int i = 0; i < m; i++)
          for (int k = 0; k < 4; k++) acc[k] += prev->plane[k][s[i]];
        for (int k = 0; k < 4; k++) next->plane[k][t] = acc[k] / (float)m;
        continue;
      }
      /* traced (or filled) surface */
      for (int k = 0; k < 3; k++) next->plane[k][t] = position[k][t];
      next->plane[3][t] = depth[t] > 0.0f ? 1.0f : 0.0f;
    }
  p->latest = 1 - p->latest;
  p->has_pos = 1;
}

void svgf_progressive_epsilon(const float *samples, float epsilon, float *eps, size_t n,
                              int threads) {
  const long long count = (long long)n;
#pragma omp parallel for simd schedule(static) num_threads(threads)
  for (long long i = 0; i < count; i++) {
    const float s = samples[i] > 1.0f ? samples[i] : 1.0f;
    eps[i] = SVGF_EPS_L + (samples[i] < 4.0f ? epsilon / s : 0.0f);
  }
}
