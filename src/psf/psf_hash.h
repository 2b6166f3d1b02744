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

/* The key loop (hush__psf_keys_planar) must vectorise, as it is most of
 * the cost of adding a vertex: GCC does not if-convert its float selects
 * and floorf, so these helpers select with integer masks on the bits. */
static inline float hush__psf_bits_f(uint32_t u) {
  float f;
  memcpy(&f, &u, sizeof f);
  return f;
}
static inline uint32_t hush__psf_f_bits(float f) {
  uint32_t u;
  memcpy(&u, &f, sizeof u);
  return u;
}
/* x where keep is 1, +0 where it is 0. */
static inline float hush__psf_keep(float x, int keep) {
  return hush__psf_bits_f(hush__psf_f_bits(x) & (0u - (uint32_t)keep));
}

/* floor(log2(d)) for d > 0 from the float's exponent bits, clamped to
 * [-100, 100] (0 and tiny distances share the lowest level, NaN and Inf the
 * highest). */
static inline int hush__psf_level(float d) {
  const int e = (int)((hush__psf_f_bits(d) >> 23) & 0xffu) - 127;
  return e < -100 ? -100 : e > 100 ? 100 : e;
}

/* 2^level as a float (|level| < 127). */
static inline float hush__psf_exp2i(int level) {
  return hush__psf_bits_f((uint32_t)(level + 127) << 23);
}

static inline float hush__psf_cell(const hush_psf_key_params *k, int level) {
  return k->scale * k->pixel_angle * hush__psf_exp2i(level);
}

/* 1 / sqrt(x) by the bit trick and two Newton steps (relative error below
 * 1e-6; x = 0 gives a large finite value, so x * rsqrt(x) = 0). */
static inline float hush__psf_rsqrt(float x) {
  float y = hush__psf_bits_f(0x5f375a86u - (hush__psf_f_bits(x) >> 1));
  y = y * (1.5f - 0.5f * x * y * y);
  return y * (1.5f - 0.5f * x * y * y);
}

/* sqrt(x) for x >= 0. */
static inline float hush__psf_sqrt(float x) { return x * hush__psf_rsqrt(x); }

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

/* A component in [-1, 1] quantised to 4 levels (NaN gives 0). */
static inline uint32_t hush__psf_quant4(float c) {
  const float t = (c + 1.0f) * 2.0f;
  const int q = (int32_t)hush__psf_keep(t, fabsf(t) < 16.0f);
  return (uint32_t)(q < 0 ? 0 : q > 3 ? 3 : q);
}

/* floor(x) as an int32 for |x| < 2e9; *ok &= that (NaN fails it). */
static inline uint32_t hush__psf_floor_i32(float x, int *ok) {
  const int in = fabsf(x) < 2.0e9f;
  const float xc = hush__psf_keep(x, in);
  const int32_t t = (int32_t)xc;
  *ok &= in;
  return (uint32_t)(t - (int32_t)((float)t > xc));
}

static inline float hush__psf_dist3(const float a[3], const float b[3]) {
  const float dx = a[0] - b[0], dy = a[1] - b[1], dz = a[2] - b[2];
  return sqrtf(dx * dx + dy * dy + dz * dz);
}

/* Keys of n vertices: keys[j] and valid[j] (0 when the vertex cannot be
 * keyed: not finite, or too far out for 32-bit cell coordinates; its key is
 * then 0). Written without branches on the vertex so the loop vectorises:
 * this is most of the cost of adding a vertex. */
#define HUSH_PSF_KEY_BLOCK 64u

/* Keys of at most HUSH_PSF_KEY_BLOCK vertices given as planar arrays. */
static inline void hush__psf_keys_planar(const hush_psf_key_params *k, uint32_t n,
                                         const float *restrict P, const float *restrict N,
                                         const float *restrict O, const float *restrict D,
                                         const float *restrict R, const uint32_t *restrict S,
                                         const uint32_t *restrict G, hush_psf_key *restrict keys,
                                         int *restrict valid) {
  const size_t B = HUSH_PSF_KEY_BLOCK; /* size_t indices: affine, so the loop vectorises */
  const float base = k->scale * k->pixel_angle, jit = k->jitter;
  const uint32_t frame = k->frame, normals = k->normals ? 1u : 0u;
  for (size_t j = 0; j < n; j++) {
    const float x0 = P[j], x1 = P[B + j], x2 = P[2 * B + j];
    const float n0 = N[j], n1 = N[B + j], n2 = N[2 * B + j];
    const float o0 = O[j], o1 = O[B + j], o2 = O[2 * B + j];
    float w0 = o0 - x0, w1 = o1 - x1, w2 = o2 - x2;
    const float len = hush__psf_sqrt(w0 * w0 + w1 * w1 + w2 * w2);
    const int level0 = hush__psf_level(D[j] + len);
    const float cell0 = base * hush__psf_exp2i(level0);
    /* tangent frame of n (Duff et al. 2017, branchless) */
    const float sign = copysignf(1.0f, n2);
    const float a = -1.0f / (sign + n2), b = n0 * n1 * a;
    const float t0 = 1.0f + sign * n0 * n0 * a, t1 = sign * b, t2 = -sign * n0;
    const float b0 = b, b1 = sign + n1 * n1 * a, b2 = -n1;
    /* one 32-bit hash gives both 16-bit jitter coordinates */
    const uint32_t r = hush_pcg_hash(hush_pcg_hash(S[j]) ^ frame);
    const float u1 = (float)(r & 0xffffu) * (1.0f / 65536.0f) - 0.5f;
    const float u2 = (float)(r >> 16) * (1.0f / 65536.0f) - 0.5f;
    const float jc = jit * cell0;
    const float y0 = x0 + (t0 * u1 + b0 * u2) * jc;
    const float y1 = x1 + (t1 * u1 + b1 * u2) * jc;
    const float y2 = x2 + (t2 * u1 + b2 * u2) * jc;
    const float e0 = o0 - y0, e1 = o1 - y1, e2 = o2 - y2;
    const int level = hush__psf_level(D[j] + hush__psf_sqrt(e0 * e0 + e1 * e1 + e2 * e2));
    const float inv = 1.0f / (base * hush__psf_exp2i(level));
    /* NaN fails every comparison: this also rejects non-finite input */
    int ok = (fabsf(R[j]) < 3.0e38f) & (fabsf(R[B + j]) < 3.0e38f) &
             (fabsf(R[2 * B + j]) < 3.0e38f) & (fabsf(D[j]) < 3.0e38f) & (fabsf(len) < 3.0e38f);
    const uint32_t q0 = hush__psf_floor_i32(y0 * inv, &ok);
    const uint32_t q1 = hush__psf_floor_i32(y1 * inv, &ok);
    const uint32_t q2 = hush__psf_floor_i32(y2 * inv, &ok);
    const uint32_t lv = (uint32_t)(level + 256);
    const uint32_t i = hush_pcg_hash(q0 ^ hush_pcg_hash(q1 ^ hush_pcg_hash(q2 ^ hush_pcg_hash(lv))));
    const uint32_t nq = (hush__psf_quant4(n0) | hush__psf_quant4(n1) << 2 |
                         hush__psf_quant4(n2) << 4 | 1u << 6) *
                        normals;
    const float il = hush__psf_rsqrt(len * len);
    w0 *= il;
    w1 *= il;
    w2 *= il;
    const uint32_t wq = (hush__psf_quant4(w0) | hush__psf_quant4(w1) << 2 |
                         hush__psf_quant4(w2) << 4 | 1u << 6) *
                        (G[j] & HUSH_PSF_GLOSSY);
    const uint32_t extra = nq | wq << 8;
    uint32_t h = hush__psf_fmix(q0 * 0x9e3779b1u + lv);
    h = hush__psf_fmix(h ^ (q1 * 0x85ebca77u));
    h = hush__psf_fmix(h ^ (q2 * 0xc2b2ae3du));
    h = hush__psf_fmix(h ^ extra) & HUSH_PSF_VMASK;
    const uint32_t mask = 0u - (uint32_t)ok; /* a mask, not a branch (vectorisation) */
    keys[j].i = i & mask;
    keys[j].v = (h | (uint32_t)(h == 0u)) & mask; /* 0 marks an empty slot */
    valid[j] = ok;
  }
}

/* How many vertices ahead hush__psf_keys prefetches (about 2 KB). */
#define HUSH_PSF_VERTEX_AHEAD 32u

/* Keys of n vertices: keys[j] and valid[j] (0 when the vertex cannot be
 * keyed: not finite, or too far out for 32-bit cell coordinates; its key is
 * then 0). The vertices are first copied to planar arrays so that the
 * arithmetic, most of the cost of adding a vertex, vectorises. */
static inline void hush__psf_keys(const hush_psf_key_params *k, const hush_psf_vertex *vs,
                                  uint32_t n, hush_psf_key *keys, int *valid) {
  enum { B = HUSH_PSF_KEY_BLOCK };
  float P[3 * B], N[3 * B], O[3 * B], D[B], R[3 * B];
  uint32_t S[B], G[B];
  for (uint32_t at = 0; at < n; at += B) {
    const uint32_t m = n - at < B ? n - at : B;
    for (uint32_t j = 0; j < m; j++) {
      /* the vertices stream from memory: ask for them well ahead */
      if (at + j + HUSH_PSF_VERTEX_AHEAD < n) __builtin_prefetch(&vs[at + j + HUSH_PSF_VERTEX_AHEAD]);
      const hush_psf_vertex *v = &vs[at + j];
      for (int c = 0; c < 3; c++) {
        P[c * B + j] = v->position[c];
        N[c * B + j] = v->normal[c];
        O[c * B + j] = v->origin[c];
        R[c * B + j] = v->radiance[c];
      }
      D[j] = v->distance;
      S[j] = v->seed;
      G[j] = v->flags;
    }
    hush__psf_keys_planar(k, m, P, N, O, D, R, S, G, keys + at, valid + at);
  }
}

/* The key of one vertex; returns 0 when it cannot be keyed. */
static inline int hush__psf_key_of(const hush_psf_key_params *k, const hush_psf_vertex *v,
                                   hush_psf_key *out) {
  int ok;
  hush__psf_keys(k, v, 1, out, &ok);
  return ok;
}

#endif
