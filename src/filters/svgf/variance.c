/*
 * variance.c — 7x7 bilateral spatial variance estimate (see variance.h;
 * Dundr 2018 §4.4).
 */
#include "filters/svgf/variance.h"

#define BLOCK 128
#define R SVGF_SPATIAL_VARIANCE_RADIUS

static inline int clampi(int v, int lo, int hi) { return v < lo ? lo : v > hi ? hi : v; }

typedef struct block_acc {
  float sw[BLOCK], s1[BLOCK], s2[BLOCK];
} block_acc;

/* Adds the taps (x + dx, y + dy) and (x - dx, y - dy) for pixels
 * [x0, x0 + n) of row y. */
static HUSH_ALWAYS_INLINE void block_pair(const svgf_guide *g, const svgf_padded *m, int dx,
                                          int dy, int y, int x0, int n, const svgf_exp2_poly *poly,
                                          const int squarings, block_acc *acc) {
  const int H = g->height;
  const size_t gs = g->zn->stride, ms = m->stride;
  const int ya = clampi(y + dy, 0, H - 1), yb = clampi(y - dy, 0, H - 1);
  const size_t gp = (size_t)y * gs + x0, ga = (size_t)ya * gs + x0 + dx,
               gb = (size_t)yb * gs + x0 - dx;
  const size_t ma = (size_t)ya * ms + x0 + dx, mb = (size_t)yb * ms + x0 - dx;
  const float *restrict zp = g->zn->plane[0] + gp, *restrict za = g->zn->plane[0] + ga,
                        *restrict zb = g->zn->plane[0] + gb;
  const float *restrict n0p = g->zn->plane[1] + gp, *restrict n0a = g->zn->plane[1] + ga,
                        *restrict n0b = g->zn->plane[1] + gb;
  const float *restrict n1p = g->zn->plane[2] + gp, *restrict n1a = g->zn->plane[2] + ga,
                        *restrict n1b = g->zn->plane[2] + gb;
  const float *restrict n2p = g->zn->plane[3] + gp, *restrict n2a = g->zn->plane[3] + ga,
                        *restrict n2b = g->zn->plane[3] + gb;
  const float *restrict m1a = m->plane[0] + ma, *restrict m1b = m->plane[0] + mb;
  const float *restrict m2a = m->plane[1] + ma, *restrict m2b = m->plane[1] + mb;
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
static void variance_row_valid(const svgf_guide *g, const svgf_padded *m, const float *age,
                               float min_age, float *var, int y, int x0, int n,
                               const svgf_exp2_poly *poly, const int squarings) {
  const int W = g->width, H = g->height;
  const size_t gs = g->zn->stride, ms = m->stride;
  const float sigma_z = g->sigma_z;
  for (int x = x0; x < x0 + n; x++) {
    const size_t i = (size_t)y * W + x;
    if (!(age[i] < min_age)) continue;
    const size_t gp = (size_t)y * gs + x;
    float sw = 0.0f, s1 = 0.0f, s2 = 0.0f;
    for (int dy = -R; dy <= R; dy++) {
      const int yy = clampi(y + dy, 0, H - 1);
      for (int dx = -R; dx <= R; dx++) {
        /* the padded planes repeat the edge pixel: so does the age */
        if (!(age[(size_t)yy * W + clampi(x + dx, 0, W - 1)] > 0.0f)) continue;
        const size_t gq = (size_t)yy * gs + x + dx, mq = (size_t)yy * ms + x + dx;
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
        s1 += w * m->plane[0][mq];
        s2 += w * m->plane[1][mq];
      }
    }
    const float inv = sw > 0.0f ? 1.0f / sw : 0.0f;
    const float e1 = s1 * inv, e2 = s2 * inv;
    const float est = e2 - e1 * e1;
    var[i] = est > 0.0f ? est : 0.0f;
  }
}

/* Row y (see atrous.c on why SQUARINGS is dispatched outside the region). */
static HUSH_ALWAYS_INLINE void variance_row(const svgf_guide *g, const svgf_padded *m,
                                            const float *age, float min_age, float *var, int y,
                                            const svgf_exp2_poly *poly, const int squarings,
                                            block_acc *acc) {
  const int W = g->width;
  for (int x0 = 0; x0 < W; x0 += BLOCK) {
    const int n = W - x0 < BLOCK ? W - x0 : BLOCK;
    const float *restrict a = age + (size_t)y * W + x0;
    int need = 0;
    for (int x = 0; x < n; x++) need |= a[x] < min_age;
    if (!need) continue;
    if (window_has_empty(age, W, g->height, y, x0, n)) {
      variance_row_valid(g, m, age, min_age, var, y, x0, n, poly, squarings);
      continue;
    }
    const float *restrict m1 = svgf_padded_row(m, 0, y) + x0;
    const float *restrict m2 = svgf_padded_row(m, 1, y) + x0;
#pragma omp simd
    for (int x = 0; x < n; x++) {
      acc->sw[x] = 1.0f;
      acc->s1[x] = m1[x];
      acc->s2[x] = m2[x];
    }
    for (int dy = 0; dy <= R; dy++)
      for (int dx = -R; dx <= R; dx++)
        if (dy > 0 || dx > 0) block_pair(g, m, dx, dy, y, x0, n, poly, squarings, acc);
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
  static void NAME(const svgf_guide *g, const svgf_padded *m, const float *age,              \
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

void svgf_spatial_variance(const svgf_guide *g, const svgf_padded *moments, const float *age,
                           float min_age, float *var, int threads) {
  switch (g->np.squarings) {
  case 6: variance_rows_pow64(g, moments, age, min_age, var, threads); break;
  case 7: variance_rows_pow128(g, moments, age, min_age, var, threads); break;
  case 8: variance_rows_pow256(g, moments, age, min_age, var, threads); break;
  default: variance_rows_any(g, moments, age, min_age, var, threads); break;
  }
}
