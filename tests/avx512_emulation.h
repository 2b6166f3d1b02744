/*
 * avx512_emulation.h — builds hush's AVX-512 loops on a CPU without AVX-512,
 * for `make test-avx512-emu` only (force-included with -include; never in a
 * build that ships). SIMDe (Debian's libsimde-dev) implements the intrinsics
 * with the instructions the build targets, so the tests run the AVX-512 code
 * paths (svgf's a-trous and spatial variance, BMFR's fit, the reprojection's
 * masks, the path-space hash) wherever CI lands: its VM's host CPU changes
 * between Zen 3 (AVX2) and Zen 4 (AVX-512), and a loop written on one was
 * otherwise never run on the other. What this checks is the loops' logic
 * (lanes, masks, offsets, tails); the speed and the hardware's approximations
 * (vrcp14ps's 2^-14) are not emulated: they are replaced by exact results,
 * which every test's tolerance already admits.
 *
 * SIMDe 0.7.4 (Debian 12) lacks or misdeclares a few of the intrinsics hush
 * uses; those are defined below, each for the forms hush calls.
 */
#ifndef HUSH_TESTS_AVX512_EMULATION_H
#define HUSH_TESTS_AVX512_EMULATION_H

#include <immintrin.h>
#define SIMDE_ENABLE_NATIVE_ALIASES
#include <simde/x86/avx512.h>

#include <limits.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

#define __AVX512F__ 1
#define __AVX512VL__ 1
#define __AVX512BW__ 1
#define __AVX512DQ__ 1
#define __AVX512CD__ 1

/* Non-temporal stores: plain stores. */
#undef _mm512_stream_ps
#define _mm512_stream_ps(p, a) simde_mm512_storeu_ps((p), (a))
#undef _mm512_stream_si512
#define _mm512_stream_si512(p, a) simde_mm512_storeu_si512((p), (a))

#undef _mm512_shuffle_f32x4
#define _mm512_shuffle_f32x4(a, b, i) simde_mm512_shuffle_f32x4((a), (b), (i))

/* SIMDe's alias takes four arguments. */
#undef _mm512_mask_cmpge_epi32_mask
#define _mm512_mask_cmpge_epi32_mask(k, a, b) \
  ((simde__mmask16)((k) & simde_mm512_cmpge_epi32_mask((a), (b))))

static inline void hush_emu_get_f(float *out, simde__m512 a) { memcpy(out, &a, 64); }
static inline void hush_emu_get_i(int32_t *out, simde__m512i a) { memcpy(out, &a, 64); }

/* vreduceps with M = 0 and rounding towards -Inf (weights.h): t - floor(t);
 * 0 for an infinity (no weight depends on it: the floor's mask drops t =
 * -Inf, and t is never +Inf). */
static inline simde__m512 hush_emu_reduce_floor(simde__m512 a) {
  float x[16];
  hush_emu_get_f(x, a);
  for (int i = 0; i < 16; i++) x[i] = isinf(x[i]) ? 0.0f : x[i] - floorf(x[i]);
  simde__m512 r;
  memcpy(&r, x, 64);
  return r;
}
#undef _mm512_reduce_ps
#define _mm512_reduce_ps(a, imm) hush_emu_reduce_floor(a)

/* Integer lane tests into masks: a < b, a != b, (a & b) == 0 (the last
 * two have no SIMDe 0.7.4 alias; the reprojection's and TAA's chunk tests
 * use them). */
enum { HUSH_EMU_LT, HUSH_EMU_NE, HUSH_EMU_TESTN };
static inline simde__mmask16 hush_emu_lanes_epi32(simde__m512i a, simde__m512i b, int op) {
  int32_t x[16], y[16];
  hush_emu_get_i(x, a);
  hush_emu_get_i(y, b);
  simde__mmask16 m = 0;
  for (int i = 0; i < 16; i++) {
    const int t = op == HUSH_EMU_LT ? x[i] < y[i] : op == HUSH_EMU_NE ? x[i] != y[i]
                                                                      : (x[i] & y[i]) == 0;
    m |= (simde__mmask16)(t << i);
  }
  return m;
}
#undef _mm512_cmplt_epi32_mask
#define _mm512_cmplt_epi32_mask(a, b) hush_emu_lanes_epi32((a), (b), HUSH_EMU_LT)
#undef _mm512_mask_cmplt_epi32_mask
#define _mm512_mask_cmplt_epi32_mask(k, a, b) \
  ((simde__mmask16)((k) & hush_emu_lanes_epi32((a), (b), HUSH_EMU_LT)))
#undef _mm512_cmpneq_epi32_mask
#define _mm512_cmpneq_epi32_mask(a, b) hush_emu_lanes_epi32((a), (b), HUSH_EMU_NE)
#undef _mm512_testn_epi32_mask
#define _mm512_testn_epi32_mask(a, b) hush_emu_lanes_epi32((a), (b), HUSH_EMU_TESTN)

/* The minimum or maximum of the lanes in k (INT_MAX or INT_MIN for none). */
static inline int hush_emu_mask_reduce(simde__mmask16 k, simde__m512i a, int want_max) {
  int32_t x[16];
  hush_emu_get_i(x, a);
  int r = want_max ? INT_MIN : INT_MAX;
  for (int i = 0; i < 16; i++)
    if (k >> i & 1) r = want_max ? (x[i] > r ? x[i] : r) : (x[i] < r ? x[i] : r);
  return r;
}
#undef _mm512_mask_reduce_max_epi32
#define _mm512_mask_reduce_max_epi32(k, a) hush_emu_mask_reduce((k), (a), 1)
#undef _mm512_mask_reduce_min_epi32
#define _mm512_mask_reduce_min_epi32(k, a) hush_emu_mask_reduce((k), (a), 0)

/* vcvttps2dq zero-masked: INT_MIN for NaN and out of range, as the hardware. */
static inline simde__m512i hush_emu_maskz_cvtt(simde__mmask16 k, simde__m512 a) {
  float x[16];
  int32_t r[16];
  hush_emu_get_f(x, a);
  for (int i = 0; i < 16; i++) {
    const int in_range = x[i] > -2147483904.0f && x[i] < 2147483648.0f; /* NaN: 0 */
    r[i] = !(k >> i & 1) ? 0 : in_range ? (int32_t)x[i] : INT_MIN;
  }
  simde__m512i out;
  memcpy(&out, r, 64);
  return out;
}
#undef _mm512_maskz_cvttps_epi32
#define _mm512_maskz_cvttps_epi32(k, a) hush_emu_maskz_cvtt((k), (a))

/* Masked loads and stores touch only the lanes in k, as the hardware's
 * (which never faults on the others): AddressSanitizer then checks exactly
 * what a real AVX-512 CPU would read and write. */
static inline simde__m512 hush_emu_maskz_loadu(simde__mmask16 k, const void *p) {
  float r[16];
  for (int i = 0; i < 16; i++) r[i] = (k >> i & 1) ? ((const float *)p)[i] : 0.0f;
  simde__m512 out;
  memcpy(&out, r, 64);
  return out;
}
#undef _mm512_maskz_loadu_ps
#define _mm512_maskz_loadu_ps(k, p) hush_emu_maskz_loadu((k), (p))

static inline void hush_emu_mask_storeu(void *p, simde__mmask16 k, simde__m512 a) {
  float x[16];
  hush_emu_get_f(x, a);
  for (int i = 0; i < 16; i++)
    if (k >> i & 1) ((float *)p)[i] = x[i];
}
#undef _mm512_mask_storeu_ps
#define _mm512_mask_storeu_ps(p, k, a) hush_emu_mask_storeu((p), (k), (a))

#undef _mm512_mask_cmp_ps_mask
#define _mm512_mask_cmp_ps_mask(k, a, b, imm) \
  ((simde__mmask16)((k) & simde_mm512_cmp_ps_mask((a), (b), (imm))))

static inline uint16_t hush_emu_test_epi8(simde__m128i a, simde__m128i b) {
  const simde__m128i z =
      simde_mm_cmpeq_epi8(simde_mm_and_si128(a, b), simde_mm_setzero_si128());
  return (uint16_t)(~simde_mm_movemask_epi8(z) & 0xffff);
}
#undef _mm_test_epi8_mask
#define _mm_test_epi8_mask(a, b) hush_emu_test_epi8((a), (b))

/* No SIMDe 0.7.4 alias either (the kind bytes of the blends' and TAA's
 * contiguity tests). */
static inline uint16_t hush_emu_cmpeq_epi8(simde__m128i a, simde__m128i b) {
  return (uint16_t)(simde_mm_movemask_epi8(simde_mm_cmpeq_epi8(a, b)) & 0xffff);
}
#undef _mm_cmpeq_epi8_mask
#define _mm_cmpeq_epi8_mask(a, b) hush_emu_cmpeq_epi8((a), (b))

/* vrcp14ps and vrsqrt14ps: exact, within the hardware's 2^-14. */
#undef _mm512_rcp14_ps
#define _mm512_rcp14_ps(a) simde_mm512_div_ps(simde_mm512_set1_ps(1.0f), (a))
#undef _mm512_rsqrt14_ps
#define _mm512_rsqrt14_ps(a) \
  simde_mm512_div_ps(simde_mm512_set1_ps(1.0f), simde_mm512_sqrt_ps(a))

#endif
