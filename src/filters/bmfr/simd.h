/*
 * simd.h — one vector register of floats for BMFR's per-block loops
 * (regression.c): the GCC/Clang vector extension, as
 * src/filters/nca/model.c, 16 lanes with AVX-512, 8 with AVX, else 4,
 * with a fused multiply-add where the target has one.
 *
 * Why not plain loops: the block fit keeps several running sums per column
 * (the Householder dot products, the three colour channels) in registers
 * across a whole column, and GCC leaves such lane arrays in memory; with
 * vf they are named registers. The build is ISO C (no FMA contraction),
 * so a*b + c is two roundings unless written as vf_fma.
 */
#ifndef HUSH_FILTERS_BMFR_SIMD_H
#define HUSH_FILTERS_BMFR_SIMD_H

#if defined(__AVX512F__) || defined(__FMA__) || defined(__AVX__)
#  include <immintrin.h>
#endif

/* One register wide (passing a vector wider than the target's registers by
 * value would change the ABI; 4 lanes are SSE2, always there on x86-64). */
#if defined(__AVX512F__)
#  define VF_LANES 16
#elif defined(__AVX__)
#  define VF_LANES 8
#else
#  define VF_LANES 4
#endif

typedef float vf __attribute__((vector_size(VF_LANES * 4)));

/* Unaligned load and store (the block buffers are 64-byte aligned, the
 * image rows are not). */
static inline vf vf_load(const float *p) {
  vf v;
  __builtin_memcpy(&v, p, sizeof v);
  return v;
}
static inline void vf_store(float *p, vf v) { __builtin_memcpy(p, &v, sizeof v); }

static inline vf vf_set1(float x) { return x - (vf){0}; } /* x - 0 is x, also for -0 */

/* a * b + c, one rounding where the target has FMA. */
static inline vf vf_fma(vf a, vf b, vf c) {
#if defined(__AVX512F__)
  return _mm512_fmadd_ps(a, b, c);
#elif defined(__FMA__) && VF_LANES == 8
  return _mm256_fmadd_ps(a, b, c);
#else
  return a * b + c;
#endif
}

/* c - a * b, one rounding where the target has FMA. */
static inline vf vf_fnma(vf a, vf b, vf c) {
#if defined(__AVX512F__)
  return _mm512_fnmadd_ps(a, b, c);
#elif defined(__FMA__) && VF_LANES == 8
  return _mm256_fnmadd_ps(a, b, c);
#else
  return c - a * b;
#endif
}

typedef int vi __attribute__((vector_size(VF_LANES * 4)));

/* One register of doubles, for the fit's small solves (regression.c). */
#define VD_LANES (VF_LANES / 2)
typedef double vd __attribute__((vector_size(VD_LANES * 8)));

static inline vd vd_load(const double *p) {
  vd v;
  __builtin_memcpy(&v, p, sizeof v);
  return v;
}
static inline void vd_store(double *p, vd v) { __builtin_memcpy(p, &v, sizeof v); }

/* m ? a : b per lane, m from a comparison (all bits set or clear) */
static inline vf vf_select(vi m, vf a, vf b) { return (vf)(((vi)a & m) | ((vi)b & ~m)); }

/* b < a ? b : a and b > a ? b : a per lane (as the scalar code's minf and
 * maxf, so the same value for the same inputs): exactly the min and max
 * instructions with b first (x < y ? x : y, NaN and equal giving y), one
 * operation where gcc made the compare and select two, through a mask
 * register */
static inline vf vf_min(vf a, vf b) {
#if defined(__AVX512F__)
  return _mm512_min_ps(b, a);
#elif defined(__AVX__) && VF_LANES == 8
  return _mm256_min_ps(b, a);
#else
  return vf_select(b < a, b, a);
#endif
}
static inline vf vf_max(vf a, vf b) {
#if defined(__AVX512F__)
  return _mm512_max_ps(b, a);
#elif defined(__AVX__) && VF_LANES == 8
  return _mm256_max_ps(b, a);
#else
  return vf_select(b > a, b, a);
#endif
}

/* 1 in the lanes whose index i0 + l is at least k, else 0. */
static inline vf vf_from(int i0, int k) {
  vf keep = {0}; /* every lane is set below; -O1 (ThreadSanitizer build) cannot tell */
  for (int l = 0; l < VF_LANES; l++) keep[l] = i0 + l >= k ? 1.0f : 0.0f;
  return keep;
}

/* The sum of the lanes, in a fixed order (halving tree: lane l += lane l +
 * w for w = VF_LANES / 2, .., 1). With AVX, the halves added in registers:
 * through memory, gcc stored the vector and reloaded its pieces (a fit
 * takes ~180 such sums a block); the same additions, the same bits. */
static inline float vf_sum(vf v) {
#if defined(__AVX512F__)
  const __m256 a = _mm256_add_ps(_mm512_castps512_ps256(v),
                                 _mm256_castpd_ps(_mm512_extractf64x4_pd(_mm512_castps_pd(v), 1)));
#elif defined(__AVX__) && VF_LANES == 8
  const __m256 a = v;
#endif
#if defined(__AVX512F__) || (defined(__AVX__) && VF_LANES == 8)
  const __m128 b = _mm_add_ps(_mm256_castps256_ps128(a), _mm256_extractf128_ps(a, 1));
  const __m128 c = _mm_add_ps(b, _mm_movehl_ps(b, b));
  return _mm_cvtss_f32(_mm_add_ss(c, _mm_shuffle_ps(c, c, 1)));
#else
  float s[VF_LANES];
  __builtin_memcpy(s, &v, sizeof v);
  for (int w = VF_LANES / 2; w > 0; w /= 2)
    for (int l = 0; l < w; l++) s[l] += s[l + w];
  return s[0];
#endif
}

#endif
