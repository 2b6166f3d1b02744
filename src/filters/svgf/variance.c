/*
 * variance.c — 7x7 bilateral spatial variance estimate (see variance.h;
 * Dundr 2018 §4.4).
 */
#include "filters/svgf/variance.h"

#include "core/stream.h" /* hush__prefetch */

#define BLOCK 128
#define R SVGF_SPATIAL_VARIANCE_RADIUS

static inline int clampi(int v, int lo, int hi) { return v < lo ? lo : v > hi ? hi : v; }

/* Columns of a block's moments window: the block and R on each side. */
#define WIN (BLOCK + 2 * R)

typedef struct block_acc {
  float sw[BLOCK], s1[BLOCK], s2[BLOCK];
  /* a border block's moments window, columns and rows clamped */
  float win[2][2 * R + 1][WIN];
} block_acc;

/* Where a block reads its moments: m1, m2 at its pixel (x0, y), a row
 * stride, and whether they are a window (rows clamped in it: the row
 * offsets are dy) or the planes (rows clamped by the offsets). */
typedef struct block_moments {
  const float *m1, *m2;
  ptrdiff_t stride;
  int scratch;
} block_moments;

/* The moments around the n pixels from (x0, y) of a W x H frame, R
 * pixels on every side, columns and rows clamped to the frame (the values
 * a padded copy of the planes would hold there): 2R + 1 rows of n + 2R
 * columns, row stride ws; pixel (x0, y) at win[p] + R * ws + R. */
static void fill_window(const float *const mom[2], int W, int H, int y, int x0, int n,
                        float *win0, float *win1, ptrdiff_t ws) {
  float *const win[2] = {win0, win1};
  for (int p = 0; p < 2; p++)
    for (int j = 0; j <= 2 * R; j++) {
      const float *row = mom[p] + (size_t)clampi(y + j - R, 0, H - 1) * W;
      float *w = win[p] + j * ws;
      for (int i = 0; i < n + 2 * R; i++) w[i] = row[clampi(x0 + i - R, 0, W - 1)];
    }
}

/* Adds the taps (x + dx, y + dy) and (x - dx, y - dy) for pixels
 * [x0, x0 + n) of row y. */
static HUSH_ALWAYS_INLINE void block_pair(const svgf_guide *g, const block_moments *m, int dx,
                                          int dy, int y, int x0, int n, const svgf_exp2_poly *poly,
                                          const int squarings, block_acc *acc) {
  const int H = g->height;
  const ptrdiff_t gs = (ptrdiff_t)g->zn->stride, ms = m->stride;
  const int ya = clampi(y + dy, 0, H - 1), yb = clampi(y - dy, 0, H - 1);
  /* signed: a tap left of column 0 is in the pad, before the plane's start */
  const ptrdiff_t gp = (ptrdiff_t)y * gs + x0, ga = (ptrdiff_t)ya * gs + x0 + dx,
                  gb = (ptrdiff_t)yb * gs + x0 - dx;
  /* the moments' rows relative to row y (clamped like the guide's) */
  const ptrdiff_t ma = (m->scratch ? dy : ya - y) * ms + dx,
                  mb = (m->scratch ? -dy : yb - y) * ms - dx;
  const float *restrict zp = g->zn->plane[0] + gp, *restrict za = g->zn->plane[0] + ga,
                        *restrict zb = g->zn->plane[0] + gb;
  const float *restrict n0p = g->zn->plane[1] + gp, *restrict n0a = g->zn->plane[1] + ga,
                        *restrict n0b = g->zn->plane[1] + gb;
  const float *restrict n1p = g->zn->plane[2] + gp, *restrict n1a = g->zn->plane[2] + ga,
                        *restrict n1b = g->zn->plane[2] + gb;
  const float *restrict n2p = g->zn->plane[3] + gp, *restrict n2a = g->zn->plane[3] + ga,
                        *restrict n2b = g->zn->plane[3] + gb;
  const float *restrict m1a = m->m1 + ma, *restrict m1b = m->m1 + mb;
  const float *restrict m2a = m->m2 + ma, *restrict m2b = m->m2 + mb;
  const size_t pi = (size_t)y * g->width + x0;
  const float *restrict gx = g->gx + pi, *restrict gy = g->gy + pi, *restrict zon = g->zon + pi;
  float *restrict sw = acc->sw, *restrict s1 = acc->s1, *restrict s2 = acc->s2;
  const float fdx = (float)dx, fdy = (float)dy, sigma_z = g->sigma_z;
  /* locals: the stores to acc must not make the loop reload them */
  const svgf_exp2_poly p = *poly;
  const float sigma_n_log2e = g->np.sigma_n_log2e, dot_floor = g->np.dot_floor;
#pragma omp simd
  for (int x = 0; x < n; x++) {
    /* the mirrored taps see the same |grad z . (q - p)| */
    const float dd = fmaf(sigma_z, fabsf(fmaf(gx[x], fdx, gy[x] * fdy)), SVGF_EPS_Z);
    const float rdd = zon[x] * SVGF_LOG2E * svgf_rcp_pos(dd < 1e30f ? dd : 1e30f);
    const float da = fmaf(n0p[x], n0a[x], fmaf(n1p[x], n1a[x], n2p[x] * n2a[x]));
    const float db = fmaf(n0p[x], n0b[x], fmaf(n1p[x], n1b[x], n2p[x] * n2b[x]));
    const float wa =
        svgf_tap_weight(fabsf(zp[x] - za[x]) * rdd, da, squarings, sigma_n_log2e, dot_floor, &p);
    const float wb =
        svgf_tap_weight(fabsf(zp[x] - zb[x]) * rdd, db, squarings, sigma_n_log2e, dot_floor, &p);
    sw[x] += wa + wb;
    s1[x] = fmaf(wa, m1a[x], fmaf(wb, m1b[x], s1[x]));
    s2[x] = fmaf(wa, m2a[x], fmaf(wb, m2b[x], s2[x]));
  }
}

/* 1 when a pixel without data (age not > 0: a progressive hole nothing
 * reached, Dundr §4.2) lies in the 7x7 windows of pixels [x0, x0 + n) of
 * row y. */
static int window_has_empty(const float *age, int W, int H, int y, int x0, int n) {
  int empty = 0;
  const int xa = clampi(x0 - R, 0, W - 1), xb = clampi(x0 + n - 1 + R, 0, W - 1);
  for (int dy = -R; dy <= R; dy++) {
    const float *row = age + (size_t)clampi(y + dy, 0, H - 1) * W;
    for (int x = xa; x <= xb; x++) empty |= !(row[x] > 0.0f);
  }
  return empty;
}

/*
 * Pixels [x0, x0 + n) of row y where some pixel of a window has no data:
 * per pixel, each tap (the centre too) counted only where it has data
 * (age > 0), with block_pair's weights; no data at all gives variance 0.
 */
static void variance_row_valid(const svgf_guide *g, const float *const mom[2], const float *age,
                               float min_age, float *var, int y, int x0, int n,
                               const svgf_exp2_poly *poly, const int squarings) {
  const int W = g->width, H = g->height;
  const ptrdiff_t gs = (ptrdiff_t)g->zn->stride;
  const float sigma_z = g->sigma_z;
  for (int x = x0; x < x0 + n; x++) {
    const size_t i = (size_t)y * W + x;
    if (!(age[i] < min_age)) continue;
    const ptrdiff_t gp = (ptrdiff_t)y * gs + x;
    float sw = 0.0f, s1 = 0.0f, s2 = 0.0f;
    for (int dy = -R; dy <= R; dy++) {
      const int yy = clampi(y + dy, 0, H - 1);
      for (int dx = -R; dx <= R; dx++) {
        /* the padded guide repeats the edge pixel: so do the age and the
         * moments, by a clamped column */
        const size_t mq = (size_t)yy * W + (size_t)clampi(x + dx, 0, W - 1);
        if (!(age[mq] > 0.0f)) continue;
        /* signed: a tap left of column 0 is in the pad */
        const ptrdiff_t gq = (ptrdiff_t)yy * gs + x + dx;
        float w = 1.0f;
        if (dx || dy) {
          const float dd = fmaf(sigma_z, fabsf(fmaf(g->gx[i], (float)dx, g->gy[i] * (float)dy)),
                                SVGF_EPS_Z);
          const float rdd = g->zon[i] * SVGF_LOG2E * svgf_rcp_pos(dd < 1e30f ? dd : 1e30f);
          const float d = g->zn->plane[1][gp] * g->zn->plane[1][gq] +
                          g->zn->plane[2][gp] * g->zn->plane[2][gq] +
                          g->zn->plane[3][gp] * g->zn->plane[3][gq];
          w = svgf_tap_weight(fabsf(g->zn->plane[0][gp] - g->zn->plane[0][gq]) * rdd, d,
                              squarings, g->np.sigma_n_log2e, g->np.dot_floor, poly);
        }
        sw += w;
        s1 += w * mom[0][mq];
        s2 += w * mom[1][mq];
      }
    }
    const float inv = sw > 0.0f ? 1.0f / sw : 0.0f;
    const float e1 = s1 * inv, e2 = s2 * inv;
    const float est = e2 - e1 * e1;
    var[i] = est > 0.0f ? est : 0.0f;
  }
}

/* Row y (see atrous.c on why SQUARINGS is dispatched outside the region). */
static HUSH_ALWAYS_INLINE void variance_row(const svgf_guide *g, const float *const mom[2],
                                            const float *age, float min_age, float *var, int y,
                                            const svgf_exp2_poly *poly, const int squarings,
                                            block_acc *acc) {
  const int W = g->width, H = g->height;
  for (int x0 = 0; x0 < W; x0 += BLOCK) {
    const int n = W - x0 < BLOCK ? W - x0 : BLOCK;
    const float *restrict a = age + (size_t)y * W + x0;
    int need = 0;
    for (int x = 0; x < n; x++) need |= a[x] < min_age;
    if (!need) continue;
    if (window_has_empty(age, W, g->height, y, x0, n)) {
      variance_row_valid(g, mom, age, min_age, var, y, x0, n, poly, squarings);
      continue;
    }
    const size_t o = (size_t)y * W + (size_t)x0;
    const float *restrict m1 = mom[0] + o;
    const float *restrict m2 = mom[1] + o;
    /* a block whose taps reach past the row's ends reads a clamped window */
    block_moments m = {m1, m2, W, 0};
    if (x0 < R || x0 + n + R > W) {
      fill_window(mom, W, H, y, x0, n, &acc->win[0][0][0], &acc->win[1][0][0], WIN);
      m.m1 = &acc->win[0][R][R];
      m.m2 = &acc->win[1][R][R];
      m.stride = WIN;
      m.scratch = 1;
    }
#pragma omp simd
    for (int x = 0; x < n; x++) {
      acc->sw[x] = 1.0f;
      acc->s1[x] = m1[x];
      acc->s2[x] = m2[x];
    }
    for (int dy = 0; dy <= R; dy++)
      for (int dx = -R; dx <= R; dx++)
        if (dy > 0 || dx > 0) block_pair(g, &m, dx, dy, y, x0, n, poly, squarings, acc);
    float *restrict v = var + (size_t)y * W + x0;
#pragma omp simd
    for (int x = 0; x < n; x++) {
      const float inv = 1.0f / acc->sw[x];
      const float e1 = acc->s1[x] * inv, e2 = acc->s2[x] * inv;
      const float est = e2 - e1 * e1;
      const float est0 = hush__select_bits(est > 0.0f, est, 0.0f);
      v[x] = hush__select_bits(a[x] < min_age, est0, v[x]);
    }
  }
}

/* dynamic: only blocks with a short history cost anything */
#define VARIANCE_ROWS(NAME, SQUARINGS)                                                       \
  static void NAME(const svgf_guide *g, const float *const m[2], const float *age,           \
                   float min_age, float *var, int threads) {                                 \
    const svgf_exp2_poly poly = svgf_exp2_poly_scaled(1.0f); /* the weights are 2^t */      \
    _Pragma("omp parallel num_threads(threads)") {                                          \
      block_acc acc __attribute__((aligned(64)));                                            \
      _Pragma("omp for schedule(dynamic, 8)") for (int y = 0; y < g->height; y++)            \
          variance_row(g, m, age, min_age, var, y, &poly, SQUARINGS, &acc);                    \
    }                                                                                        \
  }
VARIANCE_ROWS(variance_rows_pow64, 6)
VARIANCE_ROWS(variance_rows_pow128, 7)
VARIANCE_ROWS(variance_rows_pow256, 8)
VARIANCE_ROWS(variance_rows_any, -1)

#if (defined(__AVX512F__) || (defined(__AVX2__) && defined(__FMA__))) && defined(__x86_64__)
/* What the intrinsic loops below (AVX-512, else AVX2) share: a row's planes
 * and its 24 tap pairs, rows clamped at the frame's border. */
#include <immintrin.h>

#define NPAIRS ((2 * R + 1) * (2 * R + 1) / 2)

/* A border vector's moments window (fill_window): its columns, enough for
 * the AVX-512 loop's 16 pixels and R on each side. */
#define VWIN 32
_Static_assert(16 + 2 * R <= VWIN, "a vector's window fits");

typedef struct avx_vpair {
  /* tap offsets in floats: in the guide, in the moments' planes and in a
   * border vector's window */
  ptrdiff_t ga, gb, ma, mb, sa, sb;
  float fdx, fdy;
} avx_vpair;

/* Row y as the intrinsic loops take it. */
typedef struct vrow {
  avx_vpair pairs[NPAIRS];
  const float *z, *n0, *n1, *n2, *m1, *m2, *a, *gx, *gy, *zon;
  float *v;
} vrow;

static void vrow_of(const svgf_guide *g, const float *const mom[2], const float *age, float *var,
                    int y, vrow *r) {
  const int W = g->width, H = g->height;
  const size_t gs = g->zn->stride, ms = (size_t)W;
  int k = 0;
  for (int dy = 0; dy <= R; dy++)
    for (int dx = -R; dx <= R; dx++) {
      if (dy == 0 && dx <= 0) continue;
      const int ya = clampi(y + dy, 0, H - 1) - y, yb = clampi(y - dy, 0, H - 1) - y;
      r->pairs[k].ga = (ptrdiff_t)ya * (ptrdiff_t)gs + dx;
      r->pairs[k].gb = (ptrdiff_t)yb * (ptrdiff_t)gs - dx;
      r->pairs[k].ma = (ptrdiff_t)ya * (ptrdiff_t)ms + dx;
      r->pairs[k].mb = (ptrdiff_t)yb * (ptrdiff_t)ms - dx;
      r->pairs[k].sa = (ptrdiff_t)dy * VWIN + dx;
      r->pairs[k].sb = -(ptrdiff_t)dy * VWIN - dx;
      r->pairs[k].fdx = (float)dx;
      r->pairs[k].fdy = (float)dy;
      k++;
    }
  r->z = g->zn->plane[0] + (size_t)y * gs;
  r->n0 = g->zn->plane[1] + (size_t)y * gs;
  r->n1 = g->zn->plane[2] + (size_t)y * gs;
  r->n2 = g->zn->plane[3] + (size_t)y * gs;
  r->m1 = mom[0] + (size_t)y * ms;
  r->m2 = mom[1] + (size_t)y * ms;
  const size_t pi = (size_t)y * W;
  r->a = age + pi;
  r->gx = g->gx + pi;
  r->gy = g->gy + pi;
  r->zon = g->zon + pi;
  r->v = var + pi;
}

/* The bottom tap row's lines SVGF_PREFETCH_AHEAD pixels past the
 * rightmost tap of the vector at x, as the a-trous does (atrous.c), for the
 * young pixels' neighbours to come: variance stage 7.7-7.9 -> 7.05-7.45 ms on the
 * classroom's rendered frames (2 threads, 1280x720, Zen 3, alternated
 * runs; 5.4-5.7 -> 4.8-5.1 on Zen 4 with the AVX-512 loop's folded
 * weight), unchanged on the bench's frames, where fewer pixels are young. */
static HUSH_ALWAYS_INLINE void vrow_prefetch(const vrow *r, int x) {
  const avx_vpair *last = &r->pairs[NPAIRS - 1];
  const ptrdiff_t ga = (last->ga + SVGF_PREFETCH_AHEAD) * (ptrdiff_t)sizeof(float);
  const ptrdiff_t ma = (last->ma + SVGF_PREFETCH_AHEAD) * (ptrdiff_t)sizeof(float);
  const float *const guide[4] = {r->z + x, r->n0 + x, r->n1 + x, r->n2 + x};
  const float *const moments[2] = {r->m1 + x, r->m2 + x};
  hush__prefetch_planes(guide, 4, ga);
  hush__prefetch_planes(moments, 2, ma);
}
#endif

#if defined(__AVX512F__) && defined(__x86_64__)
#define VL 16 /* pixels per vector */
/*
 * The exp-normal-weight estimate in AVX-512 intrinsics, as the a-trous
 * (atrous.c): per vector of 16 pixels with a short-history pixel, the 48
 * taps with the sums in registers; a vector whose windows hold a pixel
 * without data goes through variance_row_valid. The weight floor is the
 * zero mask of the exp; the depth denominators use vrcp14ps.
 */

static HUSH_ALWAYS_INLINE void avx_vtap(const float *z, const float *n0, const float *n1,
                                        const float *n2, const float *m1, const float *m2,
                                        ptrdiff_t go, ptrdiff_t mo, __m512 rdd, __m512 zp,
                                        __m512 n0p, __m512 n1p, __m512 n2p, __m512 nbias,
                                        __m512 *sw, __m512 *s1, __m512 *s2, const int FAST) {
  const __m512 dz = _mm512_abs_ps(_mm512_sub_ps(zp, _mm512_loadu_ps(z + go)));
  __m512 t = _mm512_fnmadd_ps(dz, rdd, nbias);
  t = _mm512_fmadd_ps(n0p, _mm512_loadu_ps(n0 + go), t);
  t = _mm512_fmadd_ps(n1p, _mm512_loadu_ps(n1 + go), t);
  t = _mm512_fmadd_ps(n2p, _mm512_loadu_ps(n2 + go), t);
  /* FAST: t is the fast weight's biased bits (avx_variance_row), its floor
   * those of the floor's exponent */
  const float nfloor = -20.0f * SVGF_LOG2E;
  const __m512 tfloor = _mm512_set1_ps(FAST ? (float)svgf_fast_exp_bits(nfloor) : nfloor);
  const __mmask16 keep = _mm512_cmp_ps_mask(t, tfloor, _CMP_GT_OQ);
  const __m512 w = FAST ? svgf_avx_exp2_fast_biased(keep, t)
                       : _mm512_maskz_scalef_ps(keep, svgf_avx_exp2_frac(t), t);
  *sw = _mm512_add_ps(*sw, w);
  *s1 = _mm512_fmadd_ps(w, _mm512_loadu_ps(m1 + mo), *s1);
  *s2 = _mm512_fmadd_ps(w, _mm512_loadu_ps(m2 + mo), *s2);
}

static HUSH_ALWAYS_INLINE void avx_variance_row(const svgf_guide *g, const float *const mom[2],
                                                const float *age, float min_age, float *var,
                                                int y, int has_empty,
                                                const svgf_exp2_poly *poly, const int FAST) {
  const int W = g->width, H = g->height;
  vrow r;
  vrow_of(g, mom, age, var, y, &r);
  float win[2][2 * R + 1][VWIN] __attribute__((aligned(64)));
  const avx_vpair *pairs = r.pairs;
  const float *z = r.z, *n0 = r.n0, *n1 = r.n1, *n2 = r.n2, *m1 = r.m1, *m2 = r.m2;
  const float *a = r.a, *gx = r.gx, *gy = r.gy, *zon = r.zon;
  float *v = r.v;
  /* FAST: the exponent's terms in the fast weight's units and its bias in
   * nbias, as the a-trous's (atrous.c): the tap's exponent is the weight's
   * biased bits, u = t 2^23 + bias */
  const float unit = FAST ? SVGF_FAST_EXP_UNIT : 1.0f;
  const __m512 sn = _mm512_set1_ps(g->np.sigma_n_log2e * unit);
  const __m512 nbias =
      _mm512_set1_ps(FAST ? fmaf(-g->np.sigma_n_log2e, SVGF_FAST_EXP_UNIT, SVGF_FAST_EXP_BIAS)
                          : -g->np.sigma_n_log2e);
  const __m512 sz = _mm512_set1_ps(g->sigma_z), eps_z = _mm512_set1_ps(SVGF_EPS_Z);
  const int sky_skip = g->np.sigma_n_log2e >= 20.0f * SVGF_LOG2E;
  for (int x = 0; x < W; x += 16) {
    const int n = W - x < 16 ? W - x : 16;
    const __mmask16 lanes = (__mmask16)((1u << n) - 1u);
    const __mmask16 young =
        _mm512_mask_cmp_ps_mask(lanes, _mm512_maskz_loadu_ps(lanes, a + x), _mm512_set1_ps(min_age),
                                _CMP_LT_OQ);
    if (!young) continue;
    vrow_prefetch(&r, x);
    if (has_empty && window_has_empty(age, W, H, y, x, n)) {
      variance_row_valid(g, mom, age, min_age, var, y, x, n, poly,
                         FAST ? SVGF_NORMAL_EXP_FAST : SVGF_NORMAL_EXP);
      continue;
    }
    /* taps past the row's ends (and the tail's lanes past it) read the
     * moments from a window with clamped columns and rows */
    const int border = x < R || x + VL + R > W;
    if (border) fill_window(mom, W, H, y, x, VL, &win[0][0][0], &win[1][0][0], VWIN);
    const float *m1x = border ? &win[0][R][R] : m1 + x, *m2x = border ? &win[1][R][R] : m2 + x;
    /* the tail's lanes past the row read the pads and the next row: their
     * sums are never stored */
    const __m512 sgx = _mm512_max_ps(
        _mm512_min_ps(_mm512_mul_ps(sz, _mm512_maskz_loadu_ps(lanes, gx + x)), _mm512_set1_ps(1e20f)),
        _mm512_set1_ps(-1e20f));
    const __m512 sgy = _mm512_max_ps(
        _mm512_min_ps(_mm512_mul_ps(sz, _mm512_maskz_loadu_ps(lanes, gy + x)), _mm512_set1_ps(1e20f)),
        _mm512_set1_ps(-1e20f));
    const __m512 zl = _mm512_mul_ps(_mm512_maskz_loadu_ps(lanes, zon + x), _mm512_set1_ps(SVGF_LOG2E * unit));
    const __m512 zp = _mm512_maskz_loadu_ps(lanes, z + x);
    const __m512 n0p = _mm512_mul_ps(sn, _mm512_maskz_loadu_ps(lanes, n0 + x));
    const __m512 n1p = _mm512_mul_ps(sn, _mm512_maskz_loadu_ps(lanes, n1 + x));
    const __m512 n2p = _mm512_mul_ps(sn, _mm512_maskz_loadu_ps(lanes, n2 + x));
    __m512 sw = _mm512_set1_ps(1.0f);
    __m512 s1 = _mm512_maskz_loadu_ps(lanes, m1 + x), s2 = _mm512_maskz_loadu_ps(lanes, m2 + x);
    /* No surface under any young lane (the sky: normal 0): every tap's
     * exponent is at most -sigma_n log2 e, below the weight floor when
     * sigma_n >= 20, so each weight would be exactly 0; the taps are
     * skipped, the same bits. */
    const __mmask16 surface = _mm512_cmp_ps_mask(n0p, _mm512_setzero_ps(), _CMP_NEQ_UQ) |
                              _mm512_cmp_ps_mask(n1p, _mm512_setzero_ps(), _CMP_NEQ_UQ) |
                              _mm512_cmp_ps_mask(n2p, _mm512_setzero_ps(), _CMP_NEQ_UQ);
    const int npairs = (surface & young) || !sky_skip ? NPAIRS : 0;
    for (int p = 0; p < npairs; p++) {
      const avx_vpair *t = &pairs[p];
      const __m512 d = _mm512_fmadd_ps(sgx, _mm512_set1_ps(t->fdx), _mm512_mul_ps(sgy, _mm512_set1_ps(t->fdy)));
      const __m512 rdd = _mm512_mul_ps(zl, _mm512_rcp14_ps(_mm512_add_ps(_mm512_abs_ps(d), eps_z)));
      const ptrdiff_t ma = border ? t->sa : t->ma, mb = border ? t->sb : t->mb;
      avx_vtap(z + x, n0 + x, n1 + x, n2 + x, m1x, m2x, t->ga, ma, rdd, zp, n0p, n1p, n2p, nbias,
               &sw, &s1, &s2, FAST);
      avx_vtap(z + x, n0 + x, n1 + x, n2 + x, m1x, m2x, t->gb, mb, rdd, zp, n0p, n1p, n2p, nbias,
               &sw, &s1, &s2, FAST);
    }
    const __m512 inv = svgf_avx_rcp(sw);
    const __m512 e1 = _mm512_mul_ps(s1, inv), e2 = _mm512_mul_ps(s2, inv);
    const __m512 est = _mm512_max_ps(_mm512_fnmadd_ps(e1, e1, e2), _mm512_setzero_ps());
    _mm512_mask_storeu_ps(v + x, young, est);
  }
}

#define HAVE_AVX_VARIANCE 1
#elif defined(__AVX2__) && defined(__FMA__) && defined(__x86_64__)
#define VL 8 /* pixels per vector */
/*
 * The same in AVX2 + FMA intrinsics (x86-64-v3 builds), on vectors of 8
 * pixels: the weight floor as a compare and an AND, vrcpps with a Newton
 * step for the depth denominators (weights.h), masked loads and stores
 * where a row ends. The formulas within the tests' tolerance, not the
 * portable loop's bits.
 */

/* The exponent of the tap at guide offset go. */
static HUSH_ALWAYS_INLINE __m256 avx_vtap_exponent(const float *z, const float *n0,
                                                   const float *n1, const float *n2,
                                                   ptrdiff_t go, __m256 rdd, __m256 zp,
                                                   __m256 n0p, __m256 n1p, __m256 n2p,
                                                   __m256 nbias) {
  const __m256 dz = svgf_avx2_abs(_mm256_sub_ps(zp, _mm256_loadu_ps(z + go)));
  __m256 t = _mm256_fnmadd_ps(dz, rdd, nbias);
  t = _mm256_fmadd_ps(n0p, _mm256_loadu_ps(n0 + go), t);
  t = _mm256_fmadd_ps(n1p, _mm256_loadu_ps(n1 + go), t);
  return _mm256_fmadd_ps(n2p, _mm256_loadu_ps(n2 + go), t);
}

/* Its weight from the exponent t, added to the sums with the moments at
 * offset mo. */
static HUSH_ALWAYS_INLINE void avx_vtap_add(const float *m1, const float *m2, ptrdiff_t mo,
                                            __m256 t, __m256 *sw, __m256 *s1, __m256 *s2,
                                            const int FAST) {
  const float nfloor = -20.0f * SVGF_LOG2E;
  const __m256 w = FAST ? svgf_avx2_exp2_fast_biased(t, _mm256_set1_epi32(svgf_fast_exp_bits(nfloor)))
                        : svgf_avx2_exp2_floored(t, _mm256_set1_ps(nfloor));
  *sw = _mm256_add_ps(*sw, w);
  *s1 = _mm256_fmadd_ps(w, _mm256_loadu_ps(m1 + mo), *s1);
  *s2 = _mm256_fmadd_ps(w, _mm256_loadu_ps(m2 + mo), *s2);
}

static HUSH_ALWAYS_INLINE void avx_variance_row(const svgf_guide *g, const float *const mom[2],
                                                const float *age, float min_age, float *var,
                                                int y, int has_empty,
                                                const svgf_exp2_poly *poly, const int FAST) {
  const int W = g->width, H = g->height;
  vrow r;
  vrow_of(g, mom, age, var, y, &r);
  float win[2][2 * R + 1][VWIN] __attribute__((aligned(64)));
  const avx_vpair *pairs = r.pairs;
  const float *z = r.z, *n0 = r.n0, *n1 = r.n1, *n2 = r.n2, *m1 = r.m1, *m2 = r.m2;
  const float *a = r.a, *gx = r.gx, *gy = r.gy, *zon = r.zon;
  float *v = r.v;
  /* FAST: the exponent's terms in the fast weight's units and its bias in
   * nbias, as the a-trous's (atrous.c): the tap's exponent is the weight's
   * biased bits, u = t 2^23 + bias */
  const float unit = FAST ? SVGF_FAST_EXP_UNIT : 1.0f;
  const __m256 sn = _mm256_set1_ps(g->np.sigma_n_log2e * unit);
  const __m256 nbias =
      _mm256_set1_ps(FAST ? fmaf(-g->np.sigma_n_log2e, SVGF_FAST_EXP_UNIT, SVGF_FAST_EXP_BIAS)
                          : -g->np.sigma_n_log2e);
  const __m256 sz = _mm256_set1_ps(g->sigma_z), eps_z = _mm256_set1_ps(SVGF_EPS_Z);
  const __m256 zero = _mm256_setzero_ps();
  const int sky_skip = g->np.sigma_n_log2e >= 20.0f * SVGF_LOG2E;
  for (int x = 0; x < W; x += 8) {
    const int n = W - x < 8 ? W - x : 8;
    const __m256i lanes = _mm256_cmpgt_epi32(_mm256_set1_epi32(n), _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
#define LDL(P) _mm256_maskload_ps((P) + x, lanes)
    const __m256 young = _mm256_and_ps(_mm256_cmp_ps(LDL(a), _mm256_set1_ps(min_age), _CMP_LT_OQ),
                                       _mm256_castsi256_ps(lanes));
    const int young_bits = _mm256_movemask_ps(young);
    if (!young_bits) continue;
    vrow_prefetch(&r, x);
    if (has_empty && window_has_empty(age, W, H, y, x, n)) {
      variance_row_valid(g, mom, age, min_age, var, y, x, n, poly,
                         FAST ? SVGF_NORMAL_EXP_FAST : SVGF_NORMAL_EXP);
      continue;
    }
    /* taps past the row's ends (and the tail's lanes past it) read the
     * moments from a window with clamped columns and rows */
    const int border = x < R || x + VL + R > W;
    if (border) fill_window(mom, W, H, y, x, VL, &win[0][0][0], &win[1][0][0], VWIN);
    const float *m1x = border ? &win[0][R][R] : m1 + x, *m2x = border ? &win[1][R][R] : m2 + x;
    /* the tail's lanes past the row read the pads and the next row: their
     * sums are never stored */
    const __m256 sgx = _mm256_max_ps(_mm256_min_ps(_mm256_mul_ps(sz, LDL(gx)), _mm256_set1_ps(1e20f)),
                                     _mm256_set1_ps(-1e20f));
    const __m256 sgy = _mm256_max_ps(_mm256_min_ps(_mm256_mul_ps(sz, LDL(gy)), _mm256_set1_ps(1e20f)),
                                     _mm256_set1_ps(-1e20f));
    const __m256 zl = _mm256_mul_ps(LDL(zon), _mm256_set1_ps(SVGF_LOG2E * unit));
    const __m256 zp = LDL(z);
    const __m256 n0p = _mm256_mul_ps(sn, LDL(n0));
    const __m256 n1p = _mm256_mul_ps(sn, LDL(n1));
    const __m256 n2p = _mm256_mul_ps(sn, LDL(n2));
    __m256 sw = _mm256_set1_ps(1.0f);
    __m256 s1 = LDL(m1), s2 = LDL(m2);
#undef LDL
    /* the sky's vectors skip their taps, as the AVX-512 loop's */
    const __m256 surf = _mm256_or_ps(_mm256_or_ps(_mm256_cmp_ps(n0p, zero, _CMP_NEQ_UQ),
                                                  _mm256_cmp_ps(n1p, zero, _CMP_NEQ_UQ)),
                                     _mm256_cmp_ps(n2p, zero, _CMP_NEQ_UQ));
    const int surface = _mm256_movemask_ps(_mm256_and_ps(surf, young)) != 0;
    if (surface || !sky_skip) {
      /* software-pipelined as the a-trous's AVX2 pair loop (atrous.c):
       * pair p + 1's exponents before pair p's weights; the depth factors
       * first */
      __m256 rdd[NPAIRS];
      for (int p = 0; p < NPAIRS; p++) {
        const avx_vpair *t = &pairs[p];
        const __m256 d = _mm256_fmadd_ps(sgx, _mm256_set1_ps(t->fdx), _mm256_mul_ps(sgy, _mm256_set1_ps(t->fdy)));
        rdd[p] = _mm256_mul_ps(zl, svgf_avx2_rcp(_mm256_add_ps(svgf_avx2_abs(d), eps_z)));
      }
      const float *zx = z + x, *n0x = n0 + x, *n1x = n1 + x, *n2x = n2 + x;
      __m256 ta = avx_vtap_exponent(zx, n0x, n1x, n2x, pairs[0].ga, rdd[0], zp, n0p, n1p, n2p, nbias);
      __m256 tb = avx_vtap_exponent(zx, n0x, n1x, n2x, pairs[0].gb, rdd[0], zp, n0p, n1p, n2p, nbias);
      for (int p = 0; p < NPAIRS; p++) {
        const avx_vpair *t = &pairs[p];
        __m256 na = ta, nb = tb;
        if (p + 1 < NPAIRS) {
          const avx_vpair *u = &pairs[p + 1];
          na = avx_vtap_exponent(zx, n0x, n1x, n2x, u->ga, rdd[p + 1], zp, n0p, n1p, n2p, nbias);
          nb = avx_vtap_exponent(zx, n0x, n1x, n2x, u->gb, rdd[p + 1], zp, n0p, n1p, n2p, nbias);
        }
        avx_vtap_add(m1x, m2x, border ? t->sa : t->ma, ta, &sw, &s1, &s2, FAST);
        avx_vtap_add(m1x, m2x, border ? t->sb : t->mb, tb, &sw, &s1, &s2, FAST);
        ta = na;
        tb = nb;
      }
    }
    const __m256 inv = svgf_avx2_rcp(sw);
    const __m256 e1 = _mm256_mul_ps(s1, inv), e2 = _mm256_mul_ps(s2, inv);
    const __m256 est = _mm256_max_ps(_mm256_fnmadd_ps(e1, e1, e2), zero);
    _mm256_maskstore_ps(v + x, _mm256_castps_si256(young), est);
  }
}

#define HAVE_AVX_VARIANCE 1
#else
VARIANCE_ROWS(variance_rows_exp, SVGF_NORMAL_EXP)
VARIANCE_ROWS(variance_rows_exp_fast, SVGF_NORMAL_EXP_FAST)
#define HAVE_AVX_VARIANCE 0
#endif

#if HAVE_AVX_VARIANCE
static void avx_variance_row_accurate(const svgf_guide *g, const float *const m[2],
                                      const float *age, float min_age, float *var, int y,
                                      int has_empty, const svgf_exp2_poly *poly) {
  avx_variance_row(g, m, age, min_age, var, y, has_empty, poly, 0);
}

static void avx_variance_row_fast(const svgf_guide *g, const float *const m[2], const float *age,
                                  float min_age, float *var, int y, int has_empty,
                                  const svgf_exp2_poly *poly) {
  avx_variance_row(g, m, age, min_age, var, y, has_empty, poly, 1);
}

static void variance_rows_exp_avx(const svgf_guide *g, const float *const m[2], const float *age,
                                  float min_age, float *var, int fast, int holes, int threads) {
  const svgf_exp2_poly poly = svgf_exp2_poly_scaled(1.0f);
  const long long npix = (long long)g->width * g->height;
  int has_empty = 0;
  if (holes) {
#pragma omp parallel for simd reduction(| : has_empty) num_threads(threads)
    for (long long i = 0; i < npix; i++) has_empty |= !(age[i] > 0.0f);
  }
  void (*const row)(const svgf_guide *, const float *const[2], const float *, float, float *, int,
                    int, const svgf_exp2_poly *) =
      fast ? avx_variance_row_fast : avx_variance_row_accurate;
#pragma omp parallel for schedule(dynamic, 8) num_threads(threads)
  for (int y = 0; y < g->height; y++) row(g, m, age, min_age, var, y, has_empty, &poly);
}
#endif

void svgf_spatial_variance(const svgf_guide *g, const float *const moments[2], const float *age,
                           float min_age, float *var, int normal_exp, int fast_exp, int holes,
                           int threads) {
  if (normal_exp) {
#if HAVE_AVX_VARIANCE
    variance_rows_exp_avx(g, moments, age, min_age, var, fast_exp, holes, threads);
#else
    if (fast_exp)
      variance_rows_exp_fast(g, moments, age, min_age, var, threads);
    else
      variance_rows_exp(g, moments, age, min_age, var, threads);
#endif
    return;
  }
  switch (g->np.squarings) {
  case 6: variance_rows_pow64(g, moments, age, min_age, var, threads); break;
  case 7: variance_rows_pow128(g, moments, age, min_age, var, threads); break;
  case 8: variance_rows_pow256(g, moments, age, min_age, var, threads); break;
  default: variance_rows_any(g, moments, age, min_age, var, threads); break;
  }
}
