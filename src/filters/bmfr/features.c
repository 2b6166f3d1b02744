/*
 * features.c — BMFR's multi-order feature set and its per-block columns
 * (see features.h; bmfr-koskela-2019.md §3.3, §3.4 and §5).
 */
#include "filters/bmfr/features.h"

#include "filters/bmfr/simd.h"

#include <float.h>
#include <math.h>
#include <string.h>

void hush__bmfr_features_build(bmfr_feature_set *set, const float exponents[BMFR_SRC_COUNT][2],
                               int gradients) {
  static const int first[BMFR_SRC_COUNT] = {BMFR_BASE_NORMAL, BMFR_BASE_POSITION,
                                            BMFR_BASE_DEPTH, BMFR_BASE_ALBEDO};
  static const int channels[BMFR_SRC_COUNT] = {3, 3, 1, 3};
  memset(set, 0, sizeof *set);
  set->f[0].base = -1;
  set->f[0].exponent = 0.0f;
  set->count = 1;
  for (int s = 0; s < BMFR_SRC_COUNT; s++)
    for (int e = 0; e < 2; e++) {
      const float g = exponents[s][e];
      if (!(g > 0.0f)) continue;
      set->needs |= 1u << s;
      for (int c = 0; c < channels[s]; c++) {
        set->f[set->count].base = first[s] + c;
        set->f[set->count].exponent = g;
        set->count++;
      }
    }
  set->gradients = gradients != 0;
  if (gradients)
    for (int c = 0; c < 2; c++) {
      set->f[set->count].base = BMFR_BASE_GRADIENT + c;
      set->f[set->count].exponent = 1.0f;
      set->count++;
    }
}

/* Running minima and maxima of whole vectors over the valid rows (mask >
 * 0.5): with AVX-512 a compare into a mask register and a masked min and
 * max (gcc's reduction made each a compare and a select, in one chain). */
typedef struct vrange {
  vf l[4], h[4];
} vrange;

static inline void vrange_init(vrange *r) {
  for (int k = 0; k < 4; k++) {
    r->l[k] = vf_set1(FLT_MAX);
    r->h[k] = vf_set1(-FLT_MAX);
  }
}

static inline void vrange_add(vrange *r, int k, vf v, vf m) {
#if defined(__AVX512F__)
  const __mmask16 ok = _mm512_cmp_ps_mask(m, _mm512_set1_ps(0.5f), _CMP_GT_OQ);
  r->l[k] = _mm512_mask_min_ps(r->l[k], ok, v, r->l[k]);
  r->h[k] = _mm512_mask_max_ps(r->h[k], ok, v, r->h[k]);
#else
  const vi ok = m > vf_set1(0.5f);
  r->l[k] = vf_min(r->l[k], vf_select(ok, v, vf_set1(FLT_MAX)));
  r->h[k] = vf_max(r->h[k], vf_select(ok, v, vf_set1(-FLT_MAX)));
#endif
}

/* The scalar rows left over, then the lanes: a minimum is exact in any
 * order. */
static void vrange_result(const vrange *r, const float *restrict x, const float *restrict mask,
                          int i, int n, float *lo, float *hi) {
  float lmin = FLT_MAX, hmax = -FLT_MAX;
  for (int k = 0; k < 4; k++)
    for (int j = 0; j < VF_LANES; j++) {
      lmin = r->l[k][j] < lmin ? r->l[k][j] : lmin;
      hmax = r->h[k][j] > hmax ? r->h[k][j] : hmax;
    }
  for (; i < n; i++) {
    const int v = mask[i] > 0.5f;
    const float a = v ? x[i] : FLT_MAX, b = v ? x[i] : -FLT_MAX;
    lmin = a < lmin ? a : lmin;
    hmax = b > hmax ? b : hmax;
  }
  *lo = lmin;
  *hi = hmax;
}

/* Min and max of x over the valid rows; lo > hi when there is none. Four
 * running minima and maxima, so that no vector waits on the last one. */
static void valid_range(const float *restrict x, const float *restrict mask, int n, float *lo,
                        float *hi) {
  vrange r;
  vrange_init(&r);
  int i = 0;
  for (; i + 4 * VF_LANES <= n; i += 4 * VF_LANES)
    for (int k = 0; k < 4; k++)
      vrange_add(&r, k, vf_load(x + i + k * VF_LANES), vf_load(mask + i + k * VF_LANES));
  vrange_result(&r, x, mask, i, n, lo, hi);
}

/* out = x scaled from [lo, hi] to [-1, 1], clamped there, 0 on holes. A
 * channel that varies by less than 1e-5 of its magnitude over the block
 * is float rounding, not signal: it becomes 0 (the constant feature
 * already covers it) rather than rounding noise stretched to [-1, 1]. */
static void scale_range(const float *x, const float *restrict mask, int n, float lo, float hi,
                        float *out) { /* out may be x: element by element */
  const float mid = 0.5f * (lo + hi), half = 0.5f * (hi - lo);
  const int flat = !(half > 1e-5f * fabsf(mid)) || !(half > 1e-30f);
  const float inv = flat ? 0.0f : 1.0f / half;
  const float centre = flat ? 0.0f : mid;
  /* whole vectors with the clamps as min and max instructions (gcc made
   * each a compare and a masked select), then the rest */
  const vf cv = vf_set1(centre), iv = vf_set1(inv), lo1 = vf_set1(-1.0f), hi1 = vf_set1(1.0f);
  int i = 0;
  for (; i + VF_LANES <= n; i += VF_LANES) {
    const vf v = (vf_load(x + i) - cv) * iv;
    vf_store(out + i, vf_min(vf_max(v, lo1), hi1) * vf_load(mask + i));
  }
  for (; i < n; i++) {
    float s = (x[i] - centre) * inv;
    s = s < -1.0f ? -1.0f : s;
    s = s > 1.0f ? 1.0f : s;
    out[i] = s * mask[i];
  }
}

/* out = x scaled from its valid range to [-1, 1] (scale_range). */
static void scale_unit(const float *restrict x, const float *restrict mask, int n,
                       float *restrict out) {
  float lo, hi;
  valid_range(x, mask, n, &lo, &hi);
  scale_range(x, mask, n, lo, hi, out);
}

/* t = s^g for s in [-1, 1], with the min and max of t over the valid rows
 * (lo > hi when there is none), the range taken in the last pass: repeated products for small integer
 * exponents (vectorised), sign-preserving powf otherwise. */
static void power_range(float *t, const float *restrict s, const float *restrict mask,
                        int n, float g, float *lo, float *hi) {
  const float r = roundf(g);
  float l = FLT_MAX, h = -FLT_MAX;
  if (r == g && g >= 1.0f && g <= 16.0f) {
    /* t = s, then k - 1 products, the last one fused with the range */
    const int k = (int)g;
    if (k > 2) memcpy(t, s, (size_t)n * sizeof *t);
    for (int e = 1; e < k - 1; e++) {
#pragma omp simd
      for (int i = 0; i < n; i++) t[i] *= s[i];
    }
    const float *u = k > 2 ? t : s; /* s^(k-1) */
#pragma omp simd reduction(min : l) reduction(max : h)
    for (int i = 0; i < n; i++) {
      const float v = k > 1 ? u[i] * s[i] : s[i];
      t[i] = v;
      const int ok = mask[i] > 0.5f;
      const float a = ok ? v : FLT_MAX, b = ok ? v : -FLT_MAX;
      l = a < l ? a : l;
      h = b > h ? b : h;
    }
  } else {
    for (int i = 0; i < n; i++) {
      const float v = copysignf(powf(fabsf(s[i]), g), s[i]);
      t[i] = v;
      if (mask[i] > 0.5f) {
        l = v < l ? v : l;
        h = v > h ? v : h;
      }
    }
  }
  *lo = l;
  *hi = h;
}

void hush__bmfr_features_block(const bmfr_feature_set *set, const float *base, const float *mask,
                               int n, size_t ld, float *T, float *scratch) {
  for (int m = 0; m < set->count; m++) {
    float *col = T + (size_t)m * ld;
    const bmfr_feature *f = &set->f[m];
    if (f->base < 0) {
      memcpy(col, mask, (size_t)n * sizeof *col);
    } else if (f->exponent == 1.0f) {
      scale_unit(base + (size_t)f->base * ld, mask, n, col);
    } else {
      /* the scaled channel: an earlier feature's column when the set has
       * the channel with exponent 1 (eq. 8's w and w^2), else computed */
      const float *s = NULL;
      for (int q = 1; q < m && !s; q++)
        if (set->f[q].base == f->base && set->f[q].exponent == 1.0f) s = T + (size_t)q * ld;
      if (!s) {
        scale_unit(base + (size_t)f->base * ld, mask, n, scratch);
        s = scratch;
      }
      float lo, hi;
      power_range(col, s, mask, n, f->exponent, &lo, &hi);
      scale_range(col, mask, n, lo, hi, col);
    }
    for (size_t i = (size_t)n; i < ld; i++) col[i] = 0.0f;
  }
}
