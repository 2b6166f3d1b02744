/*
 * weights.h — the edge-stopping weights of SVGF between a pixel p and a tap
 * q, written for the inner vector loops of the a-trous (atrous.c) and the
 * spatial variance estimate (variance.c):
 *
 *   w_z = exp(-|z_p - z_q| / (sigma_z |grad z_p . (p - q)| + eps_z))
 *   w_n = max(0, n_p . n_q)^sigma_n
 *   w_l = exp(-|l_p - l_q| / (sigma_l sqrt(g3x3(var_p)) + eps_l))
 *
 * (Dundr 2018 §4.1.4.2-4.1.4.5; Schied et al. 2017 in papers/NOTES.md.)
 * One exp per tap: the depth and luminance exponents are summed; w_n is a
 * power of two by repeated squaring (sigma_n = 128: 7 multiplies) or, for
 * any other sigma_n, joins the exp as sigma_n ln(dot).
 *
 * Every product w = w_n w_z w_l below e^-20 is made exactly 0: such a tap
 * weighs under 2e-9 of the centre, and its tiny weights (squared for the
 * variance) would otherwise produce subnormal floats, which cost x86 a
 * microcode assist each (measured: 3x slower a-trous on frames with
 * background). Branch-free so loops over them vectorise without
 * -ffast-math; fmaf is exact per IEEE, so results do not depend on the
 * vector width.
 */
#ifndef HUSH_FILTERS_SVGF_WEIGHTS_H
#define HUSH_FILTERS_SVGF_WEIGHTS_H

#include "temporal/reproject.h" /* HUSH_ALWAYS_INLINE, hush__select_bits */

#include <math.h>
#include <stdint.h>
#include <string.h>

/* Keep the depth and luminance weights' denominators away from 0: a flat
 * facing plane (zero gradient) or zero variance must not divide by 0. */
#define SVGF_EPS_Z 1e-3f
#define SVGF_EPS_L 1e-4f
/* Weights at or below e^-20 are 0 (see above). */
#define SVGF_WEIGHT_FLOOR 2.0611536e-9f /* e^-20 */

/* sqrt(x) for x >= 0 in a loop that must vectorise (with the default
 * -fmath-errno gcc keeps a branch to the library sqrtf for errno, which
 * stops the vectoriser): 1/sqrt by the bit-level first guess and three
 * Newton steps, then one Newton step of sqrt itself with fmaf; within an
 * ulp or two of sqrtf (0 for 0). */
static HUSH_ALWAYS_INLINE float svgf_sqrt_pos(float x) {
  int32_t bits;
  memcpy(&bits, &x, sizeof bits);
  bits = 0x5f375a86 - (bits >> 1);
  float y;
  memcpy(&y, &bits, sizeof y);
  const float hx = 0.5f * x;
  y = y * fmaf(-hx * y, y, 1.5f);
  y = y * fmaf(-hx * y, y, 1.5f);
  y = y * fmaf(-hx * y, y, 1.5f);
  const float s = x * y;
  return fmaf(0.5f * y, fmaf(-s, s, x), s);
}

/* e^x for x <= 0 (x above 0 is not needed); x below -21 is taken as -21
 * (the callers zero every weight below e^-20 anyway): 2^n * 2^f with
 * n = round(x log2 e) by the 1.5 * 2^23 trick (its low mantissa bits are n
 * as an integer), |f| <= 1/2, and a degree-6 Taylor polynomial of e^(f ln 2)
 * (relative error about 1e-7). */
static HUSH_ALWAYS_INLINE float svgf_exp_neg(float x) {
  x = x > -21.0f ? x : -21.0f; /* a max: 1 instruction */
  const float t = x * 1.44269504f;
  const float magic = 12582912.0f; /* 1.5 * 2^23 */
  const float big = t + magic;     /* rounds t to an integer */
  const float n = big - magic;
  const float f = (t - n) * 0.693147181f; /* 2^(t-n) = e^f */
  float p = fmaf(f, 1.0f / 720, 1.0f / 120);
  p = fmaf(f, p, 1.0f / 24);
  p = fmaf(f, p, 1.0f / 6);
  p = fmaf(f, p, 0.5f);
  p = fmaf(f, p, 1.0f);
  p = fmaf(f, p, 1.0f);
  int32_t bits;
  memcpy(&bits, &big, sizeof bits);
  bits = (bits - 0x4B400000 + 127) << 23; /* 2^n */
  float scale;
  memcpy(&scale, &bits, sizeof scale);
  return p * scale;
}

/* ln(d) for d > 0 (d <= 0 is taken as 1e-30): d = m 2^e with m in
 * [sqrt(1/2), sqrt(2)), ln m = 2 atanh(s), s = (m-1)/(m+1), |s| < 0.172, by
 * its series to s^9 (absolute error below 1e-9). */
static HUSH_ALWAYS_INLINE float svgf_log_pos(float d) {
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

/* How sigma_n is applied: squarings >= 0 when sigma_n = 2^squarings (then
 * dots are raised to at least dot_floor = e^(-21 / sigma_n) first, so no
 * square goes subnormal; such a dot's power is below the weight floor, and
 * the weight becomes 0 as it should), else -1: through the exp. */
typedef struct svgf_normal_power {
  int squarings;
  float sigma_n, dot_floor;
} svgf_normal_power;

static inline svgf_normal_power svgf_normal_power_of(float sigma_n) {
  svgf_normal_power np = {-1, sigma_n, 0.0f};
  for (int k = 0; k <= 10; k++) /* as many squarings as svgf_weight spells out */
    if (sigma_n == (float)(1 << k)) {
      np.squarings = k;
      np.dot_floor = expf(-21.0f / sigma_n);
    }
  return np;
}

/* The weight of one tap: exponent e_zl = -(|dz| / dd + |dl| / dl_max)
 * (passed pre-summed, <= 0) times the normal weight of `dot`. SQUARINGS is
 * a compile-time constant at every call (the caller dispatches once per
 * level), so this is straight-line code. */
static HUSH_ALWAYS_INLINE float svgf_weight(float e_zl, float dot, const int squarings,
                                            float sigma_n, float dot_floor) {
  float w;
  if (squarings >= 0) {
    float d = dot > dot_floor ? dot : dot_floor; /* a max */
    /* spelled out: gcc does not vectorise a loop around an inner loop */
    if (squarings > 0) d *= d;
    if (squarings > 1) d *= d;
    if (squarings > 2) d *= d;
    if (squarings > 3) d *= d;
    if (squarings > 4) d *= d;
    if (squarings > 5) d *= d;
    if (squarings > 6) d *= d;
    if (squarings > 7) d *= d;
    if (squarings > 8) d *= d;
    if (squarings > 9) d *= d;
    w = d * svgf_exp_neg(e_zl);
  } else {
    w = svgf_exp_neg(fmaf(sigma_n, svgf_log_pos(dot), e_zl));
  }
  return hush__select_bits(w > SVGF_WEIGHT_FLOOR, w, 0.0f);
}

#endif
