/*
 * psf_hash.h — the key of a path vertex in hashed path-space filtering
 * (hashed-path-space-filtering-binder-2019.md §3.1-3.2, Algorithm 1):
 *
 *   l  = level_of_detail(d)           d: path length to the vertex
 *   x' = x + jitter(n) * cell(l)      a uniform offset in the tangent plane
 *   l' = level_of_detail(d')          d' recomputed at x' (Algorithm 1's l')
 *   x~ = floor(x' / cell(l'))
 *   i  = hash(x~, l')                 which cache line (and first slot)
 *   v  = hash2(x~, l', n~, w~)        verification: quantised normal n~ or,
 *                                     for glossy vertices, direction w~
 *
 * with cell(l) = scale * pixel_angle * 2^l and level_of_detail(d) =
 * floor(log2 d), so a cell is scale times (0.5 to 1) the projected size of
 * a pixel at the vertex's distance; glossy_scale times that for glossy
 * vertices (§4's coarser cells for glossy surfaces: the direction in v
 * splits their cells again, so at the same size they would gather few
 * vertices, and a glossy highlight stays a firefly). The normal goes into v
 * only (§3.1, Figure 4c): vertices of one cell with different normals share
 * a cache line and are told apart by linear probing.
 *
 * Everything is a pure function of the vertex, the frame and the parameters,
 * so keys do not depend on the thread that computes them.
 */
#ifndef HUSH_PSF_HASH_H
#define HUSH_PSF_HASH_H

#include "hush.h"
#include "core/rng.h"
#include "core/vecmath.h" /* hush__select_bits */

#include <math.h>
#include <stdint.h>
#include <string.h>

#if defined(__AVX512F__) && defined(__x86_64__)
#include <immintrin.h>
#endif

/* Bits of a key: the verification hash below, the age (priority, §3.4) above. */
#define HUSH_PSF_AGE_SHIFT 26u
#define HUSH_PSF_VMASK ((1u << HUSH_PSF_AGE_SHIFT) - 1u)
#define HUSH_PSF_AGE_MAX 63u

typedef struct hush_psf_key_params {
  float scale;             /* cell size in projected pixels */
  float glossy_scale;      /* cell size of glossy vertices relative to scale */
  float pixel_angle;       /* pixel width at unit distance */
  float jitter;            /* tangent-plane jitter, in cells (0: none) */
  int normals;             /* quantised normal in the verification hash */
  int glossy_normals;      /* the same for glossy vertices */
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

/* The key loop (hush__psf_keys_planar) is written without branches on the
 * vertex so that it vectorises: it is most of the cost of adding a vertex.
 * Vertex records (hush_psf_vertex) are copied to planes this many at a time
 * first; a caller that keeps planes (the renderer) saves the copy. */
#define HUSH_PSF_KEY_BLOCK 64u

/* Vertices as one array per component (a structure of arrays), so that
 * the key loop reads them with vector loads. The arrays are the caller's. */
typedef struct hush_psf_planes {
  const float *position[3], *normal[3], *origin[3], *distance, *radiance[3];
  const uint32_t *seed, *flags;
} hush_psf_planes;

/* Keys of the vertices first .. first + n - 1 of v: keys[j] and valid[j]
 * (0 when the vertex cannot be keyed: not finite, or too far out for 32-bit
 * cell coordinates; its key is then 0). */
static inline void hush__psf_keys_planar(const hush_psf_key_params *k, const hush_psf_planes *v,
                                         size_t first, uint32_t n, hush_psf_key *restrict keys,
                                         int *restrict valid) {
  const float *restrict P0 = v->position[0] + first, *restrict P1 = v->position[1] + first;
  const float *restrict P2 = v->position[2] + first, *restrict N0 = v->normal[0] + first;
  const float *restrict N1 = v->normal[1] + first, *restrict N2 = v->normal[2] + first;
  const float *restrict O0 = v->origin[0] + first, *restrict O1 = v->origin[1] + first;
  const float *restrict O2 = v->origin[2] + first, *restrict D = v->distance + first;
  const float *restrict R0 = v->radiance[0] + first, *restrict R1 = v->radiance[1] + first;
  const float *restrict R2 = v->radiance[2] + first;
  const uint32_t *restrict S = v->seed + first, *restrict G = v->flags + first;
  const float base = k->scale * k->pixel_angle, jit = k->jitter;
  const float glossy_base = base * k->glossy_scale;
  const uint32_t frame = k->frame, normals = k->normals ? 1u : 0u;
  const uint32_t glossy_normals = k->glossy_normals ? 1u : 0u;
  for (size_t j = 0; j < n; j++) { /* size_t: affine indices, so the loop vectorises */
    const float x0 = P0[j], x1 = P1[j], x2 = P2[j];
    const float n0 = N0[j], n1 = N1[j], n2 = N2[j];
    const float o0 = O0[j], o1 = O1[j], o2 = O2[j];
    float w0 = o0 - x0, w1 = o1 - x1, w2 = o2 - x2;
    const float len = hush__psf_sqrt(w0 * w0 + w1 * w1 + w2 * w2);
    const int level0 = hush__psf_level(D[j] + len);
    const uint32_t glossy = (G[j] & HUSH_PSF_GLOSSY) != 0u, gm = 0u - glossy;
    const float unit = hush__select_bits((int)glossy, glossy_base, base);
    const float cell0 = unit * hush__psf_exp2i(level0);
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
    const float inv = 1.0f / (unit * hush__psf_exp2i(level));
    /* NaN fails every comparison: this also rejects non-finite input */
    int ok = (fabsf(R0[j]) < 3.0e38f) & (fabsf(R1[j]) < 3.0e38f) & (fabsf(R2[j]) < 3.0e38f) &
             (fabsf(D[j]) < 3.0e38f) & (fabsf(len) < 3.0e38f);
    const uint32_t q0 = hush__psf_floor_i32(y0 * inv, &ok);
    const uint32_t q1 = hush__psf_floor_i32(y1 * inv, &ok);
    const uint32_t q2 = hush__psf_floor_i32(y2 * inv, &ok);
    const uint32_t lv = (uint32_t)(level + 256);
    const uint32_t i = hush_pcg_hash(q0 ^ hush_pcg_hash(q1 ^ hush_pcg_hash(q2 ^ hush_pcg_hash(lv))));
    const uint32_t nq = (hush__psf_quant4(n0) | hush__psf_quant4(n1) << 2 |
                         hush__psf_quant4(n2) << 4 | 1u << 6) *
                        ((normals & ~gm) | (glossy_normals & gm));
    const float il = hush__psf_rsqrt(len * len);
    w0 *= il;
    w1 *= il;
    w2 *= il;
    const uint32_t wq = (hush__psf_quant4(w0) | hush__psf_quant4(w1) << 2 |
                         hush__psf_quant4(w2) << 4 | 1u << 6) *
                        glossy;
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

/* Planar copies of at most HUSH_PSF_KEY_BLOCK vertices (the caller's
 * hush_psf_vertex array), and planes pointing into them. */
typedef struct hush_psf_block {
  float f[13][HUSH_PSF_KEY_BLOCK];
  uint32_t seed[HUSH_PSF_KEY_BLOCK], flags[HUSH_PSF_KEY_BLOCK];
} hush_psf_block;

_Static_assert(sizeof(hush_psf_vertex) == 15 * sizeof(float),
               "a vertex record is 15 words: position, normal, origin, distance, radiance, "
               "seed, flags");

#if defined(__AVX512F__) && defined(__x86_64__)
/* The 128-bit lanes of four vectors transposed: out[L] lane g = a[g] lane L. */
static inline void hush__psf_lanes4(const __m512 a[4], __m512 out[4]) {
  const __m512 v0 = _mm512_shuffle_f32x4(a[0], a[1], _MM_SHUFFLE(1, 0, 1, 0));
  const __m512 v1 = _mm512_shuffle_f32x4(a[0], a[1], _MM_SHUFFLE(3, 2, 3, 2));
  const __m512 v2 = _mm512_shuffle_f32x4(a[2], a[3], _MM_SHUFFLE(1, 0, 1, 0));
  const __m512 v3 = _mm512_shuffle_f32x4(a[2], a[3], _MM_SHUFFLE(3, 2, 3, 2));
  out[0] = _mm512_shuffle_f32x4(v0, v2, _MM_SHUFFLE(2, 0, 2, 0));
  out[1] = _mm512_shuffle_f32x4(v0, v2, _MM_SHUFFLE(3, 1, 3, 1));
  out[2] = _mm512_shuffle_f32x4(v1, v3, _MM_SHUFFLE(2, 0, 2, 0));
  out[3] = _mm512_shuffle_f32x4(v1, v3, _MM_SHUFFLE(3, 1, 3, 1));
}

/* Records j .. j + 15 to the planes at j: a 16x16 transpose (the 15 words
 * of each record, and a zero) in 64 shuffles, where copying word by word
 * costs 15 loads and 15 stores per record (the copy was a quarter of
 * hush_psf_add_vertices). */
static inline void hush__psf_block_fill16(hush_psf_block *b, const hush_psf_vertex *vs,
                                          uint32_t j) {
  const float *src = (const float *)(const void *)(vs + j);
  __m512 r[16], t[16];
  for (int i = 0; i < 16; i++) r[i] = _mm512_maskz_loadu_ps(0x7fff, src + 15 * i);
  /* t[2i], t[2i+1], lane L: words 4L, 4L+1 and 4L+2, 4L+3 of records 2i, 2i+1 interleaved */
  for (int i = 0; i < 16; i += 2) {
    t[i] = _mm512_unpacklo_ps(r[i], r[i + 1]);
    t[i + 1] = _mm512_unpackhi_ps(r[i], r[i + 1]);
  }
  /* r[4g + c], lane L: word 4L + c of records 4g .. 4g + 3 */
  for (int g = 0; g < 16; g += 4) {
    const __m512d t0 = _mm512_castps_pd(t[g]), t1 = _mm512_castps_pd(t[g + 1]);
    const __m512d t2 = _mm512_castps_pd(t[g + 2]), t3 = _mm512_castps_pd(t[g + 3]);
    r[g] = _mm512_castpd_ps(_mm512_unpacklo_pd(t0, t2));
    r[g + 1] = _mm512_castpd_ps(_mm512_unpackhi_pd(t0, t2));
    r[g + 2] = _mm512_castpd_ps(_mm512_unpacklo_pd(t1, t3));
    r[g + 3] = _mm512_castpd_ps(_mm512_unpackhi_pd(t1, t3));
  }
  for (int c = 0; c < 4; c++) {
    const __m512 a[4] = {r[c], r[4 + c], r[8 + c], r[12 + c]};
    __m512 w[4]; /* w[L]: word 4L + c of the 16 records */
    hush__psf_lanes4(a, w);
    for (int L = 0; L < 4; L++) {
      const int word = 4 * L + c;
      if (word < 13) _mm512_storeu_ps(&b->f[word][j], w[L]);
      else if (word == 13) _mm512_storeu_si512(&b->seed[j], _mm512_castps_si512(w[L]));
      else if (word == 14) _mm512_storeu_si512(&b->flags[j], _mm512_castps_si512(w[L]));
    }
  }
}
#endif

static inline void hush__psf_block_fill(hush_psf_block *b, const hush_psf_vertex *vs, uint32_t n,
                                        hush_psf_planes *planes) {
  uint32_t j = 0;
#if defined(__AVX512F__) && defined(__x86_64__)
  for (; j + 16 <= n; j += 16) hush__psf_block_fill16(b, vs, j);
#endif
  for (; j < n; j++) {
    const hush_psf_vertex *v = &vs[j];
    for (int c = 0; c < 3; c++) {
      b->f[c][j] = v->position[c];
      b->f[3 + c][j] = v->normal[c];
      b->f[6 + c][j] = v->origin[c];
      b->f[10 + c][j] = v->radiance[c];
    }
    b->f[9][j] = v->distance;
    b->seed[j] = v->seed;
    b->flags[j] = v->flags;
  }
  for (int c = 0; c < 3; c++) {
    planes->position[c] = b->f[c];
    planes->normal[c] = b->f[3 + c];
    planes->origin[c] = b->f[6 + c];
    planes->radiance[c] = b->f[10 + c];
  }
  planes->distance = b->f[9];
  planes->seed = b->seed;
  planes->flags = b->flags;
}

/* Keys of n vertices given as hush_psf_vertex records: keys[j] and valid[j]
 * (0 when the vertex cannot be keyed: not finite, or too far out for 32-bit
 * cell coordinates; its key is then 0). */
static inline void hush__psf_keys(const hush_psf_key_params *k, const hush_psf_vertex *vs,
                                  uint32_t n, hush_psf_key *keys, int *valid) {
  hush_psf_block block;
  hush_psf_planes planes;
  for (uint32_t at = 0; at < n; at += HUSH_PSF_KEY_BLOCK) {
    const uint32_t m = n - at < HUSH_PSF_KEY_BLOCK ? n - at : HUSH_PSF_KEY_BLOCK;
    hush__psf_block_fill(&block, vs + at, m, &planes);
    hush__psf_keys_planar(k, &planes, 0, m, keys + at, valid + at);
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
