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
 * One exp per tap, in base 2: the depth and luminance exponents are summed,
 * log2 e is folded into their per-pixel reciprocal denominators (computed
 * by Newton steps, not divisions), the kernel weight h into the polynomial
 * of 2^f; w_n is a power of two by repeated squaring (sigma_n = 128: 7
 * multiplies) or, for any other sigma_n, joins the exponent as
 * sigma_n log2(dot). That 2^t is a polynomial with svgf's
 * weight_exp=accurate; by default (fast) it is svgf_exp2_neg_fast's linear
 * interpolation between powers of two, within 3 % (below).
 *
 * Every weight w = w_n w_z w_l at or below e^-20 is made exactly 0 (one
 * compare and a zero-masked operation): such a tap weighs under 2e-9 of
 * the centre, yet with a 1-spp firefly of 1e5 (or a demodulated one) next
 * to it that is still visible, and its tiny weights (squared for the
 * variance) would produce subnormal floats, which cost x86 a microcode
 * assist each (measured: 3x slower a-trous on frames with background). The
 * exponent is clamped at SVGF_S_MAX and the dot at 2^(-SVGF_S_MAX /
 * sigma_n) so no intermediate goes subnormal either; a clamped weight is
 * below the floor, hence 0. Branch-free so loops over them vectorise
 * without -ffast-math; fmaf is exact per IEEE, so results do not
 * depend on the vector width.
 */
#ifndef HUSH_FILTERS_SVGF_WEIGHTS_H
#define HUSH_FILTERS_SVGF_WEIGHTS_H

#include "core/vecmath.h"

#include <math.h>
#include <stdint.h>
#include <string.h>

/* Keep the depth and luminance weights' denominators away from 0: a flat
 * facing plane (zero gradient) or zero variance must not divide by 0. */
#define SVGF_EPS_Z 1e-3f
#define SVGF_EPS_L 1e-4f

/* sqrt(x) for x >= 0 in a loop that must vectorise (with the default
 * -fmath-errno gcc keeps a branch to the library sqrtf for errno, which
 * stops the vectoriser): 1/sqrt by the bit-level first guess and three
 * Newton steps, then one Newton step of sqrt itself with fmaf; within an
 * ulp or two of sqrtf (0 for 0). */
static HUSH_ALWAYS_INLINE float svgf_sqrt_pos(float x) {
  const float y = hush__rsqrt_vec(x);
  const float s = x * y;
  return fmaf(0.5f * y, fmaf(-s, s, x), s);
}

/* 1/x for x in [1e-30, 1e30] (the callers clamp): the bit-level first
 * guess (relative error <= 12 %) and two Newton steps with fmaf (relative
 * error within 2e-4): for the a-trous depth denominators, where a 1e-4
 * error in an exponent changes nothing visible and each step costs two
 * operations per tap pair. vdivps costs 10-16 cycles per vector; this is
 * 5 arithmetic instructions that pipeline. */
static HUSH_ALWAYS_INLINE float svgf_rcp2_pos(float x) {
  uint32_t bits;
  memcpy(&bits, &x, sizeof bits);
  bits = 0x7EF311C3u - bits;
  float y;
  memcpy(&y, &bits, sizeof y);
  y = fmaf(y, fmaf(-x, y, 1.0f), y);
  return fmaf(y, fmaf(-x, y, 1.0f), y);
}

/* svgf_rcp2_pos and a third Newton step: within 6e-8 relative of 1/x. */
static HUSH_ALWAYS_INLINE float svgf_rcp_pos(float x) {
  const float y = svgf_rcp2_pos(x);
  return fmaf(y, fmaf(-x, y, 1.0f), y);
}

/* 2^-s for s in [-126, 126] by the degree-4 minimax polynomial of 2^f on
 * [-1/2, 1/2] (relative error 2.6e-6): the a-trous tap weight, where the
 * caller zeroes every weight whose s is past its floor, so s outside that
 * range (even NaN or Inf) may give anything here. */
static HUSH_ALWAYS_INLINE float svgf_exp2_neg4(float s) {
  const float magic = 12582912.0f; /* 1.5 * 2^23 */
  const float big = magic - s;     /* rounds -s to an integer n */
  const float g = s + (big - magic); /* -f */
  float y = fmaf(g, 0.009570101908f, -0.05591786032f);
  y = fmaf(g, y, 0.2402474483f);
  y = fmaf(g, y, -0.6931218147f);
  y = fmaf(g, y, 0.9999992614f);
  uint32_t nb, yb;
  memcpy(&nb, &big, sizeof nb);
  memcpy(&yb, &y, sizeof yb);
  yb += nb << 23;
  memcpy(&y, &yb, sizeof y);
  return y;
}

/* The fast tap weight (svgf's weight_exp=fast, the default): 2^t as the
 * float whose bits are (u + 127) 2^23 truncated to an integer, u = t +
 * SVGF_FAST_EXP_SHIFT (Schraudolph 1999): 2^floor(u) (1 + frac(u)), 2^u
 * interpolated linearly between powers of two, whose error (1 + f) / 2^f
 * peaks at 1.0615 (f = 1 / ln 2 - 1); the shift, log2(2 / 2.0615), centres
 * it, so every weight is within 2.98 % of 2^t, and it never increases as t
 * falls. One fused multiply-add and one conversion, where the polynomial
 * and its exponent take eight operations of the tap's 25 (the a-trous 11-13
 * % faster on Zen 3, with the AVX2 floor below; docs/svgf-speed.md,
 * twenty-third round). */
#define SVGF_FAST_EXP_SHIFT (-0.043678f)
#define SVGF_FAST_EXP_BIAS ((127.0f + SVGF_FAST_EXP_SHIFT) * 8388608.0f)
/* 2^23: t's unit in the fast weight's bits */
#define SVGF_FAST_EXP_UNIT 8388608.0f

/* Pixels past a row's rightmost bottom tap whose lines the vector loops of
 * the a-trous and the 7x7 variance prefetch (atrous.c, variance.c). */
#define SVGF_PREFETCH_AHEAD 32

/* The bits of the fast weight 2^t for t in [-64, 64] (the vector loops'
 * floor, svgf_avx2_exp2_fast). */
static inline int32_t svgf_fast_exp_bits(float t) {
  return (int32_t)fmaf(t, 8388608.0f, SVGF_FAST_EXP_BIAS);
}

/* 2^-s by the fast weight, for s in [-64, 64] (clamped there, NaN taken as
 * 64, so the conversion stays in range; the caller zeroes weights past the
 * floor, s < 29, as with svgf_exp2_neg4). */
static HUSH_ALWAYS_INLINE float svgf_exp2_neg_fast(float s) {
  s = hush__select_bits(s < 64.0f, s, 64.0f);  /* a min (NaN: 64) */
  s = hush__select_bits(s > -64.0f, s, -64.0f); /* a max */
  const int32_t b = (int32_t)fmaf(-s, 8388608.0f, SVGF_FAST_EXP_BIAS);
  float y;
  memcpy(&y, &b, sizeof y);
  return y;
}

/* Exponents are in base 2 (see the top): log2 e joins the reciprocals. */
#define SVGF_LOG2E 1.44269504f
/* Weights at or below e^-20 are 0 (see the top). */
#define SVGF_WEIGHT_FLOOR 2.0611536e-9f /* e^-20 */
/* The clamp of the exponent magnitude s of 2^-s: 2^-29 is below the floor. */
#define SVGF_S_MAX 29.0f

/* Coefficients c0..c5 of the degree-5 minimax polynomial of 2^f on
 * [-1/2, 1/2] (relative error 7.5e-8, 2.3e-7 in float arithmetic), as a
 * polynomial of g = -f (odd coefficients negated), pre-multiplied by the
 * kernel weight h of a tap, so that the tap's weight h 2^-s costs no
 * negation and no multiply by h; and the weight floor times h. */
typedef struct svgf_exp2_poly {
  float c[6];
  float floor; /* h SVGF_WEIGHT_FLOOR */
} svgf_exp2_poly;

static inline svgf_exp2_poly svgf_exp2_poly_scaled(float h) {
  static const float c[6] = {1.0000001192092896f, -0.6931469440460205f, 0.24022120237350464f,
                             -0.05550713092088699f, 0.009675540961325169f,
                             -0.0013276472454890609f};
  svgf_exp2_poly p;
  for (int k = 0; k < 6; k++) p.c[k] = h * c[k];
  p.floor = h * SVGF_WEIGHT_FLOOR;
  return p;
}

/* h 2^-s for s in [0, s_max] (s above is taken as s_max, s_max <= 60):
 * -s = n + f with n = round(-s) by the 1.5 * 2^23 trick, the polynomial
 * of 2^f times h in g = -f = s + n, and n added straight into its exponent
 * bits (h 2^f is in [2^-9, 2], so the result stays normal). NaN is taken
 * as s_max. */
static HUSH_ALWAYS_INLINE float svgf_exp2_neg_h(float s, float s_max, const svgf_exp2_poly *p) {
  s = hush__select_bits(s < s_max, s, s_max); /* a min (NaN: s_max) */
  const float magic = 12582912.0f; /* 1.5 * 2^23 */
  const float big = magic - s;     /* rounds -s to an integer n */
  const float g = s + (big - magic);
  float y = fmaf(g, p->c[5], p->c[4]);
  y = fmaf(g, y, p->c[3]);
  y = fmaf(g, y, p->c[2]);
  y = fmaf(g, y, p->c[1]);
  y = fmaf(g, y, p->c[0]);
  uint32_t nb, yb;
  memcpy(&nb, &big, sizeof nb);
  memcpy(&yb, &y, sizeof yb);
  yb += nb << 23; /* the low bits of big are n; 0x4B400000 << 23 wraps to 0 */
  memcpy(&y, &yb, sizeof y);
  return y;
}

/* svgf_tap_weight's SQUARINGS for the normal weight 2^(-sigma_n log2 e (1 -
 * dot)) (svgf's normal_weight=exp): the first-order form of max(0, dot)^
 * sigma_n, within 0.0021 of it at sigma_n 128, in the exponent (no power). */
#define SVGF_NORMAL_EXP (-2)
/* SVGF_NORMAL_EXP with the fast weight (weight_exp=fast,
 * svgf_exp2_neg_fast), for callers whose h is 1 (the polynomial p is not
 * used; the floor is decided on the exponent, as the vector loops do). */
#define SVGF_NORMAL_EXP_FAST (-3)

/* The weight h w_n w_z w_l of one tap from s_zl = (|dz| / dd + |dl| /
 * dl_max) log2 e (>= 0) and the normals' `dot`. SQUARINGS is a
 * compile-time constant at every call (the caller dispatches once per
 * level), so this is straight-line code; sigma_n_log2e and dot_floor are
 * those of svgf_normal_power, read once per loop by the caller. */
static HUSH_ALWAYS_INLINE float svgf_tap_weight(float s_zl, float dot, const int squarings,
                                                float sigma_n_log2e, float dot_floor,
                                                const svgf_exp2_poly *p) {
  float w;
  if (squarings == SVGF_NORMAL_EXP_FAST) {
    const float s = fmaf(sigma_n_log2e, 1.0f - dot, s_zl);
    return hush__select_bits(s < 20.0f * SVGF_LOG2E, svgf_exp2_neg_fast(s), 0.0f);
  }
  if (squarings == SVGF_NORMAL_EXP) {
    w = svgf_exp2_neg_h(fmaf(sigma_n_log2e, 1.0f - dot, s_zl), SVGF_S_MAX, p);
    return hush__select_bits(w > p->floor, w, 0.0f);
  }
  if (squarings < 0) {
    w = svgf_exp2_neg_h(fmaf(-sigma_n_log2e, hush__ln_pos(dot), s_zl), SVGF_S_MAX, p);
    return hush__select_bits(w > p->floor, w, 0.0f);
  }
  float d = hush__select_bits(dot > dot_floor, dot, dot_floor); /* a max */
  d = hush__pow2_squarings(d, squarings);
  w = d * svgf_exp2_neg_h(s_zl, SVGF_S_MAX, p);
  return hush__select_bits(w > p->floor, w, 0.0f);
}

/* How sigma_n is applied: squarings >= 0 when sigma_n = 2^squarings (then
 * dots are raised to at least dot_floor = 2^(-SVGF_S_MAX / sigma_n) first,
 * so no square goes subnormal), else -1: through the exponent, as
 * sigma_n_log2e log(dot). */
typedef struct svgf_normal_power {
  int squarings;
  float sigma_n, sigma_n_log2e, dot_floor;
} svgf_normal_power;

static inline svgf_normal_power svgf_normal_power_of(float sigma_n) {
  svgf_normal_power np = {-1, sigma_n, sigma_n * SVGF_LOG2E, 0.0f};
  for (int k = 0; k <= 10; k++) /* as many squarings as svgf_tap_weight spells out */
    if (sigma_n == (float)(1 << k)) {
      np.squarings = k;
      np.dot_floor = exp2f(-SVGF_S_MAX / sigma_n);
    }
  return np;
}

#if defined(__AVX512F__) && defined(__x86_64__)
/* The AVX-512 loops' (atrous.c, variance.c) pieces. */
#include <immintrin.h>

/* 2^frac(t), frac(t) = t - floor(t) in [0, 1) by vreduceps, as the
 * degree-3 minimax polynomial of relative error 7.5e-5 (an edge-stopping
 * weight needs no more; each degree is one operation of every tap);
 * vscalefps(y, t) then multiplies by 2^floor(t), so 2^t costs 5
 * operations. */
static HUSH_ALWAYS_INLINE __m512 svgf_avx_exp2_frac(__m512 t) {
  const __m512 f = _mm512_reduce_ps(t, _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC);
  __m512 y = _mm512_fmadd_ps(f, _mm512_set1_ps(0.07802491592f), _mm512_set1_ps(0.2260639489f));
  y = _mm512_fmadd_ps(f, y, _mm512_set1_ps(0.6958361991f));
  return _mm512_fmadd_ps(f, y, _mm512_set1_ps(0.9999247990f));
}

/* 2^t where keep, else 0, by the fast weight (svgf_exp2_neg_fast), from
 * u = t 2^23 + SVGF_FAST_EXP_BIAS: the loops fold the scale and the bias
 * into the terms of t (SVGF_FAST_EXP_UNIT), one operation fewer per tap
 * than computing u here. The conversion is zero-masked: lanes not kept may
 * hold any u (an out-of-range conversion is masked out). */
static HUSH_ALWAYS_INLINE __m512 svgf_avx_exp2_fast_biased(__mmask16 keep, __m512 u) {
  return _mm512_castsi512_ps(_mm512_maskz_cvttps_epi32(keep, u));
}

/* 1/x from vrcp14ps and one Newton step (relative error about 2^-28). */
static HUSH_ALWAYS_INLINE __m512 svgf_avx_rcp(__m512 x) {
  const __m512 y = _mm512_rcp14_ps(x);
  return _mm512_fmadd_ps(y, _mm512_fnmadd_ps(x, y, _mm512_set1_ps(1.0f)), y);
}

#elif defined(__AVX2__) && defined(__FMA__) && defined(__x86_64__)
/* The AVX2 loops' (x86-64-v3 builds: atrous.c, variance.c) pieces: the
 * AVX-512 ones above with what AVX2 lacks spelled out. */
#include <immintrin.h>

static HUSH_ALWAYS_INLINE __m256 svgf_avx2_abs(__m256 x) {
  return _mm256_and_ps(x, _mm256_castsi256_ps(_mm256_set1_epi32(0x7fffffff)));
}

/* 1/x by vrcpps and one Newton step (relative error about 2^-22). */
static HUSH_ALWAYS_INLINE __m256 svgf_avx2_rcp(__m256 x) {
  const __m256 y = _mm256_rcp_ps(x);
  return _mm256_fmadd_ps(y, _mm256_fnmadd_ps(x, y, _mm256_set1_ps(1.0f)), y);
}

/* 2^t where t > nfloor, else 0 (NaN: 0): svgf_avx_exp2_frac's polynomial
 * and the floor of the AVX-512 tap. */
static HUSH_ALWAYS_INLINE __m256 svgf_avx2_exp2_floored(__m256 t, __m256 nfloor) {
  const __m256 keep = _mm256_cmp_ps(t, nfloor, _CMP_GT_OQ);
  const __m256 fl = _mm256_round_ps(t, _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC);
  const __m256 f = _mm256_sub_ps(t, fl);
  __m256 y = _mm256_fmadd_ps(f, _mm256_set1_ps(0.07802491592f), _mm256_set1_ps(0.2260639489f));
  y = _mm256_fmadd_ps(f, y, _mm256_set1_ps(0.6958361991f));
  y = _mm256_fmadd_ps(f, y, _mm256_set1_ps(0.9999247990f));
  /* kept lanes have t > nfloor > -126: the result is normal */
  const __m256i e = _mm256_slli_epi32(_mm256_cvtps_epi32(fl), 23);
  const __m256 w = _mm256_castsi256_ps(_mm256_add_epi32(_mm256_castps_si256(y), e));
  return _mm256_and_ps(w, keep);
}

/* svgf_avx2_exp2_fast from u = t 2^23 + SVGF_FAST_EXP_BIAS, for loops
 * that fold the scale and the bias into the terms of t (SVGF_FAST_EXP_UNIT):
 * one operation fewer per tap. */
static HUSH_ALWAYS_INLINE __m256 svgf_avx2_exp2_fast_biased(__m256 u, __m256i bfloor) {
  const __m256i b = _mm256_cvttps_epi32(u);
  return _mm256_castsi256_ps(_mm256_and_si256(b, _mm256_cmpgt_epi32(b, bfloor)));
}

/* 2^t by the fast weight (svgf_exp2_neg_fast) where its bits are above
 * bfloor, those of the floor's exponent (svgf_fast_exp_bits), else 0. The
 * bits never decrease as t grows, so this keeps what t > floor keeps but
 * for exponents within a rounding step (8e-6) of the floor; NaN converts
 * to INT_MIN: 0. An integer compare of the bits instead of a float compare
 * of t: the a-trous 3-4 % faster on Zen 3 (docs/svgf-speed.md,
 * twenty-third round). Kept lanes have t > -60, in range of the
 * truncating conversion. */
static HUSH_ALWAYS_INLINE __m256 svgf_avx2_exp2_fast(__m256 t, __m256i bfloor) {
  const __m256 u =
      _mm256_fmadd_ps(t, _mm256_set1_ps(8388608.0f), _mm256_set1_ps(SVGF_FAST_EXP_BIAS));
  return svgf_avx2_exp2_fast_biased(u, bfloor);
}

#endif

#endif
