/*
 * psf_hash.h — the key of a path vertex in hashed path-space filtering
 * (hashed-path-space-filtering-binder-2019.md §3.1-3.2, Algorithm 1):
 *
 *   l  = level_of_detail(d)           d: path length to the vertex
 *   x' = x + jitter(n) * cell(l)      a uniform offset in the tangent plane
 *   l' = level_of_detail(d')          d' recomputed at x' (Algorithm 1's l')
 *   x~ = floor(x' / cell(l'))
 *   i  = hash(x~, l')                 which cache line (and first slot)
 *   v  = hash2(x~, l', n~, w~)        verification: quantised normal n~ and,
 *                                     for glossy vertices, direction w~
 *
 * with cell(l) = scale * pixel_angle * 2^l and level_of_detail(d) =
 * floor(log2 d), so a cell is scale times (0.5 to 1) the projected size of
 * a pixel at the vertex's distance. The normal goes into v only (§3.1,
 * Figure 4c): vertices of one cell with different normals share a cache line
 * and are told apart by linear probing.
 *
 * Everything is a pure function of the vertex, the frame and the parameters,
 * so keys do not depend on the thread that computes them.
 */
#ifndef HUSH_PSF_HASH_H
#define HUSH_PSF_HASH_H

#include "hush.h"
#include "core/rng.h"

#include <math.h>
#include <stdint.h>
#include <string.h>

/* Bits of a key: the verification hash below, the age (priority, §3.4) above. */
#define HUSH_PSF_AGE_SHIFT 26u
#define HUSH_PSF_VMASK ((1u << HUSH_PSF_AGE_SHIFT) - 1u)
#define HUSH_PSF_AGE_MAX 63u

typedef struct hush_psf_key_params {
  float scale;             /* cell size in projected pixels */
  float pixel_angle;       /* pixel width at unit distance */
  float jitter;            /* tangent-plane jitter, in cells (0: none) */
  int normals;             /* quantised normal in the verification hash */
  uint32_t frame;          /* mixed into the jitter's random numbers */
} hush_psf_key_params;

typedef struct hush_psf_key {
  uint32_t i;              /* primary hash */
  uint32_t v;              /* verification hash, 1 .. HUSH_PSF_VMASK */
} hush_psf_key;

/* floor(log2(d)) for d > 0, from the float's exponent bits (d is clamped
 * to the normal range, so tiny and non-positive distances share the lowest
 * level); frexpf would be a library call per vertex. */
static inline int hush__psf_level(float d) {
  d = d > 1e-30f ? (d < 1e30f ? d : 1e30f) : 1e-30f;
  uint32_t bits;
  memcpy(&bits, &d, sizeof bits);
  return (int)((bits >> 23) & 0xffu) - 127;
}

/* 2^level as a float (|level| < 127). */
static inline float hush__psf_exp2i(int level) {
  const uint32_t bits = (uint32_t)(level + 127) << 23;
  float f;
  memcpy(&f, &bits, sizeof f);
  return f;
}

static inline float hush__psf_cell(const hush_psf_key_params *k, int level) {
  return k->scale * k->pixel_angle * hush__psf_exp2i(level);
}

/* Murmur3's finaliser: the verification hash must not be a function of the
 * primary one, so it uses another mixer than rng.h's PCG. */
static inline uint32_t hush__psf_fmix(uint32_t h) {
  h ^= h >> 16;
  h *= 0x85ebca6bu;
  h ^= h >> 13;
  h *= 0xc2b2ae35u;
  h ^= h >> 16;
  return h;
}

/* A component in [-1, 1] quantised to 4 levels. */
static inline uint32_t hush__psf_quant4(float c) {
  const int q = (int)floorf((c + 1.0f) * 2.0f);
  return (uint32_t)(q < 0 ? 0 : q > 3 ? 3 : q);
}

static inline float hush__psf_dist3(const float a[3], const float b[3]) {
  const float dx = a[0] - b[0], dy = a[1] - b[1], dz = a[2] - b[2];
  return sqrtf(dx * dx + dy * dy + dz * dz);
}

/* Computes the key of v; returns 0 when the vertex cannot be keyed (not
 * finite, or too far out for 32-bit cell coordinates). */
static inline int hush__psf_key_of(const hush_psf_key_params *k, const hush_psf_vertex *v,
                                   hush_psf_key *out) {
  const float *x = v->position, *n = v->normal;
  const float d = v->distance + hush__psf_dist3(x, v->origin);
  const float cell = hush__psf_cell(k, hush__psf_level(d));
  /* tangent frame of n (Duff et al. 2017, branchless) */
  const float sign = copysignf(1.0f, n[2]);
  const float a = -1.0f / (sign + n[2]), b = n[0] * n[1] * a;
  const float t[3] = {1.0f + sign * n[0] * n[0] * a, sign * b, -sign * n[0]};
  const float bt[3] = {b, sign + n[1] * n[1] * a, -n[1]};
  /* one 32-bit hash gives both 16-bit jitter coordinates */
  const uint32_t r = hush_pcg_hash(hush_pcg_hash(v->seed) ^ k->frame);
  const float u1 = (float)(r & 0xffffu) * (1.0f / 65536.0f) - 0.5f;
  const float u2 = (float)(r >> 16) * (1.0f / 65536.0f) - 0.5f;
  const float j = k->jitter * cell;
  float xj[3];
  for (int c = 0; c < 3; c++) xj[c] = x[c] + (t[c] * u1 + bt[c] * u2) * j;
  const int level = hush__psf_level(v->distance + hush__psf_dist3(xj, v->origin));
  const float inv = 1.0f / hush__psf_cell(k, level);
  int32_t q[3];
  for (int c = 0; c < 3; c++) {
    const float f = floorf(xj[c] * inv);
    if (!(fabsf(f) < 2.0e9f)) return 0; /* NaN, Inf or beyond int32 */
    q[c] = (int32_t)f;
  }
  const uint32_t lv = (uint32_t)(level + 256);
  out->i = hush_pcg_hash((uint32_t)q[0] ^
                         hush_pcg_hash((uint32_t)q[1] ^ hush_pcg_hash((uint32_t)q[2] ^
                                                                      hush_pcg_hash(lv))));
  uint32_t extra = 0;
  if (k->normals)
    extra = hush__psf_quant4(n[0]) | hush__psf_quant4(n[1]) << 2 | hush__psf_quant4(n[2]) << 4 |
            1u << 6;
  if (v->flags & HUSH_PSF_GLOSSY) {
    float w[3];
    for (int c = 0; c < 3; c++) w[c] = v->origin[c] - x[c];
    const float len = sqrtf(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
    const float il = len > 0.0f ? 1.0f / len : 0.0f;
    extra |= (hush__psf_quant4(w[0] * il) | hush__psf_quant4(w[1] * il) << 2 |
              hush__psf_quant4(w[2] * il) << 4 | 1u << 6)
             << 8;
  }
  uint32_t h = hush__psf_fmix((uint32_t)q[0] * 0x9e3779b1u + lv);
  h = hush__psf_fmix(h ^ ((uint32_t)q[1] * 0x85ebca77u));
  h = hush__psf_fmix(h ^ ((uint32_t)q[2] * 0xc2b2ae3du));
  h = hush__psf_fmix(h ^ extra);
  h &= HUSH_PSF_VMASK;
  out->v = h ? h : 1u; /* 0 marks an empty slot */
  return 1;
}

#endif
