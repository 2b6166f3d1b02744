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

/* The valid ranges of up to RANGES_MAX columns cols[k] together: one pass,
 * the mask's test made once per vector for all of them (six passes of
 * valid_range tested it six times and read it six times). */
#define RANGES_MAX 6
static void valid_ranges(const float *const *cols, int count, const float *restrict mask, int n,
                         float *lo, float *hi) {
  vf l[RANGES_MAX], h[RANGES_MAX];
  for (int k = 0; k < count; k++) {
    l[k] = vf_set1(FLT_MAX);
    h[k] = vf_set1(-FLT_MAX);
  }
  int i = 0;
  for (; i + VF_LANES <= n; i += VF_LANES) {
#if defined(__AVX512F__)
    const __mmask16 ok = _mm512_cmp_ps_mask(vf_load(mask + i), _mm512_set1_ps(0.5f), _CMP_GT_OQ);
    for (int k = 0; k < count; k++) {
      const vf v = vf_load(cols[k] + i);
      l[k] = _mm512_mask_min_ps(l[k], ok, v, l[k]);
      h[k] = _mm512_mask_max_ps(h[k], ok, v, h[k]);
    }
#else
    const vi ok = vf_load(mask + i) > vf_set1(0.5f);
    for (int k = 0; k < count; k++) {
      const vf v = vf_load(cols[k] + i);
      l[k] = vf_min(l[k], vf_select(ok, v, vf_set1(FLT_MAX)));
      h[k] = vf_max(h[k], vf_select(ok, v, vf_set1(-FLT_MAX)));
    }
#endif
  }
  for (int k = 0; k < count; k++) {
    float lmin = FLT_MAX, hmax = -FLT_MAX;
    for (int j = 0; j < VF_LANES; j++) {
      lmin = l[k][j] < lmin ? l[k][j] : lmin;
      hmax = h[k][j] > hmax ? h[k][j] : hmax;
    }
    for (int q = i; q < n; q++) {
      const int v = mask[q] > 0.5f;
      const float a = v ? cols[k][q] : FLT_MAX, b = v ? cols[k][q] : -FLT_MAX;
      lmin = a < lmin ? a : lmin;
      hmax = b > hmax ? b : hmax;
    }
    lo[k] = lmin;
    hi[k] = hmax;
  }
}

/* out = x scaled from [lo, hi] to [-1, 1], clamped there, 0 on holes. A
 * channel that varies by less than 1e-5 of its magnitude over the block
 * is float rounding, not signal: it becomes 0 (the constant feature
 * already covers it) rather than rounding noise stretched to [-1, 1]. */
static void scale_of(float lo, float hi, float *centre, float *inv) {
  const float mid = 0.5f * (lo + hi), half = 0.5f * (hi - lo);
  const int flat = !(half > 1e-5f * fabsf(mid)) || !(half > 1e-30f);
  *inv = flat ? 0.0f : 1.0f / half;
  *centre = flat ? 0.0f : mid;
}

static void scale_range(const float *x, const float *restrict mask, int n, float lo, float hi,
                        float *out) { /* out may be x: element by element */
  float centre, inv;
  scale_of(lo, hi, &centre, &inv);
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

/* scale_range into out, and sq = out^2 (power_range's t for g = 2: the
 * same product) with its range over the valid rows, in the same pass
 * (eq. 8's w and w^2: the squares were a pass of their own). */
static void scale_square(const float *restrict x, const float *restrict mask, int n, float lo,
                         float hi, float *restrict out, float *restrict sq, float *sq_lo,
                         float *sq_hi) {
  float centre, inv;
  scale_of(lo, hi, &centre, &inv);
  const vf cv = vf_set1(centre), iv = vf_set1(inv), lo1 = vf_set1(-1.0f), hi1 = vf_set1(1.0f);
  vrange r;
  vrange_init(&r);
  int i = 0;
  for (; i + VF_LANES <= n; i += VF_LANES) {
    const vf m = vf_load(mask + i);
    const vf v = vf_min(vf_max((vf_load(x + i) - cv) * iv, lo1), hi1) * m;
    const vf q = v * v;
    vf_store(out + i, v);
    vf_store(sq + i, q);
    vrange_add(&r, 0, q, m);
  }
  const int tail = i;
  for (; i < n; i++) {
    float s = (x[i] - centre) * inv;
    s = s < -1.0f ? -1.0f : s;
    s = s > 1.0f ? 1.0f : s;
    out[i] = s * mask[i];
    sq[i] = out[i] * out[i];
  }
  vrange_result(&r, sq, mask, tail, n, sq_lo, sq_hi);
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
  /* the valid range of each base channel a feature scales, RANGES_MAX
   * channels a pass */
  float lo[BMFR_BASE_COUNT], hi[BMFR_BASE_COUNT];
  int chans[BMFR_BASE_COUNT], nch = 0;
  for (int m = 0; m < set->count; m++) {
    const int b = set->f[m].base;
    int seen = b < 0;
    for (int k = 0; k < nch && !seen; k++) seen = chans[k] == b;
    if (!seen) chans[nch++] = b;
  }
  for (int k0 = 0; k0 < nch; k0 += RANGES_MAX) {
    const int cnt = nch - k0 < RANGES_MAX ? nch - k0 : RANGES_MAX;
    const float *cols[RANGES_MAX];
    float l[RANGES_MAX], h[RANGES_MAX];
    for (int k = 0; k < cnt; k++) cols[k] = base + (size_t)chans[k0 + k] * ld;
    valid_ranges(cols, cnt, mask, n, l, h);
    for (int k = 0; k < cnt; k++) {
      lo[chans[k0 + k]] = l[k];
      hi[chans[k0 + k]] = h[k];
    }
  }
  /* the squares computed with their channel (scale_square): their ranges */
  float sq_lo[BMFR_MAX_FEATURES], sq_hi[BMFR_MAX_FEATURES];
  int squared[BMFR_MAX_FEATURES] = {0};
  for (int m = 0; m < set->count; m++) {
    float *col = T + (size_t)m * ld;
    const bmfr_feature *f = &set->f[m];
    if (f->base < 0) {
      memcpy(col, mask, (size_t)n * sizeof *col);
    } else if (f->exponent == 1.0f) {
      /* a later square of the channel whose source is this column (the
       * channel's first feature of exponent 1, as below) */
      int q2 = -1;
      int first = 1;
      for (int q = 1; q < m && first; q++)
        first = !(set->f[q].base == f->base && set->f[q].exponent == 1.0f);
      for (int q = m + 1; q < set->count && first && q2 < 0; q++)
        if (set->f[q].base == f->base && set->f[q].exponent == 2.0f) q2 = q;
      const float *x = base + (size_t)f->base * ld;
      if (q2 >= 0) {
        scale_square(x, mask, n, lo[f->base], hi[f->base], col, T + (size_t)q2 * ld, &sq_lo[q2],
                     &sq_hi[q2]);
        squared[q2] = 1;
      } else {
        scale_range(x, mask, n, lo[f->base], hi[f->base], col);
      }
    } else if (squared[m]) {
      scale_range(col, mask, n, sq_lo[m], sq_hi[m], col);
    } else {
      /* the scaled channel: an earlier feature's column when the set has
       * the channel with exponent 1 (eq. 8's w and w^2), else computed */
      const float *s = NULL;
      for (int q = 1; q < m && !s; q++)
        if (set->f[q].base == f->base && set->f[q].exponent == 1.0f) s = T + (size_t)q * ld;
      if (!s) {
        scale_range(base + (size_t)f->base * ld, mask, n, lo[f->base], hi[f->base], scratch);
        s = scratch;
      }
      float plo, phi;
      power_range(col, s, mask, n, f->exponent, &plo, &phi);
      scale_range(col, mask, n, plo, phi, col);
    }
    for (size_t i = (size_t)n; i < ld; i++) col[i] = 0.0f;
  }
}
