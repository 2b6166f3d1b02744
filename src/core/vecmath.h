/*
 * vecmath.h — scalar helpers for loops the compiler must vectorise: a
 * bitwise select, floorf, 1/sqrt and a natural logarithm that GCC turns
 * into vector code without -ffast-math.
 *
 * The build is -O3 without -ffast-math (results must not depend on the
 * vector width). Under the default -ftrapping-math gcc vectorises floorf
 * only with -fno-trapping-math, and through a select with a constant arm
 * (c ? x : 0.0f) it may move a later comparison, conversion or load (which
 * may trap) under a branch, which stops the vectorisation of the loop.
 * These do the same work without either. */
#ifndef HUSH_CORE_VECMATH_H
#define HUSH_CORE_VECMATH_H

#include <math.h>
#include <stdint.h>
#include <string.h>

#if defined(__GNUC__)
#  define HUSH_ALWAYS_INLINE inline __attribute__((always_inline))
#else
#  define HUSH_ALWAYS_INLINE inline
#endif

/* cond ? x : y for cond 0 or 1, by masking the bits. */
static inline float hush__select_bits(int cond, float x, float y) {
  uint32_t bx, by;
  memcpy(&bx, &x, sizeof bx);
  memcpy(&by, &y, sizeof by);
  const uint32_t m = (uint32_t)-cond;
  bx = (bx & m) | (by & ~m);
  memcpy(&x, &bx, sizeof x);
  return x;
}

/* 1/sqrt(x) for x in [1e-30, 1e30], without the libm call that gcc keeps
 * for errno (-fmath-errno), which stops the vectoriser: the bit-level first
 * guess and three Newton steps (relative error within 3e-7). */
static inline float hush__rsqrt_vec(float x) {
  int32_t bits;
  memcpy(&bits, &x, sizeof bits);
  bits = 0x5f375a86 - (bits >> 1);
  float y;
  memcpy(&y, &bits, sizeof y);
  const float hx = 0.5f * x;
  y = y * fmaf(-hx * y, y, 1.5f);
  y = y * fmaf(-hx * y, y, 1.5f);
  y = y * fmaf(-hx * y, y, 1.5f);
  return y;
}

/* d^(2^n) by n squarings, n 0..10 (no more are done). Spelled out, not a
 * loop: gcc vectorises no loop around an inner loop; with n a constant or
 * invariant in the caller's loop the tests fold or hoist. */
static HUSH_ALWAYS_INLINE float hush__pow2_squarings(float d, int n) {
  if (n > 0) d *= d;
  if (n > 1) d *= d;
  if (n > 2) d *= d;
  if (n > 3) d *= d;
  if (n > 4) d *= d;
  if (n > 5) d *= d;
  if (n > 6) d *= d;
  if (n > 7) d *= d;
  if (n > 8) d *= d;
  if (n > 9) d *= d;
  return d;
}

/* floorf(s), bit for bit (also -0, infinities and NaN). With SSE4.1 one
 * rounding instruction (roundps/vrndscaleps, exact), which gcc vectorises
 * given -fno-trapping-math; else a truncating conversion of s where |s| <
 * 2^23 (else s is an integer, inf or NaN), one less when that rounded up,
 * and the sign of s kept on a zero. */
static inline float hush__floorf_vec(float s) {
#if defined(__SSE4_1__)
  return __builtin_floorf(s);
#else
  const int small = fabsf(s) < 8388608.0f; /* 2^23 */
  const float c = hush__select_bits(small, s, 0.0f);
  const float t = (float)(int32_t)c;
  /* selects, not ?: (gcc does not if-convert these in every loop) */
  float f = hush__select_bits(t > c, t - 1.0f, t);
  f = hush__select_bits(f == 0.0f, s * 0.0f, f); /* floorf(-0) = -0 */
  return hush__select_bits(small, f, s);
#endif
}

/* ln(d) for d > 0 (d <= 1e-30 is taken as 1e-30): d = m 2^e with m in
 * [sqrt(1/2), sqrt(2)), ln m = 2 atanh(s), s = (m-1)/(m+1), |s| < 0.172, by
 * its series to s^9 (absolute error below 1e-9). */
static HUSH_ALWAYS_INLINE float hush__ln_pos(float d) {
  d = hush__select_bits(d > 1e-30f, d, 1e-30f);
  int32_t bits;
  memcpy(&bits, &d, sizeof bits);
  float e = (float)((bits >> 23) - 127);
  const int32_t mbits = (bits & 0x007fffff) | 0x3f800000;
  float m;
  memcpy(&m, &mbits, sizeof m);
  const int big = m > 1.41421356f;
  m = hush__select_bits(big, 0.5f * m, m);
  e = hush__select_bits(big, e + 1.0f, e);
  const float sv = (m - 1.0f) / (m + 1.0f), s2 = sv * sv;
  const float series = 1.0f + s2 * (1.0f / 3 + s2 * (1.0f / 5 + s2 * (1.0f / 7 + s2 * (1.0f / 9))));
  return e * 0.693147181f + 2.0f * sv * series;
}

#endif
