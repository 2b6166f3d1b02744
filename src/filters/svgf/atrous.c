/*
 * atrous.c — one edge-avoiding a-trous level of SVGF (see atrous.h;
 * Dundr 2018 §4.1.4, Schied et al. 2017).
 */
#include "filters/svgf/atrous.h"

#include "core/hmath.h"

const svgf_kernel svgf_kernel_5x5 = {2, {1.0f / 16, 1.0f / 4, 3.0f / 8, 1.0f / 4, 1.0f / 16}};
const svgf_kernel svgf_kernel_3x3 = {1, {1.0f / 4, 1.0f / 2, 1.0f / 4, 0.0f, 0.0f}};

/* Pixels per block: the block's accumulators and p-side rows stay in L1
 * while every tap pair streams over them. */
#define BLOCK 128
/* (2 * 2 + 1)^2 - 1 taps in mirrored pairs */
#define MAX_PAIRS 12

typedef struct tap_pair {
  int dx, dy;   /* tap a = (x + dx, y + dy), tap b = (x - dx, y - dy) */
  float fdx, fdy;
  float h;      /* kernel weight, the same for both */
  svgf_exp2_poly poly; /* 2^f times h (weights.h) */
} tap_pair;

/* The taps other than the centre, one of each mirrored pair: dy > 0, or
 * dy == 0 and dx > 0. Returns the count. */
static int tap_pairs(const svgf_kernel *k, int step, tap_pair *pairs) {
  int n = 0;
  const int r = k->radius;
  for (int j = 0; j <= r; j++)
    for (int i = -r; i <= r; i++) {
      if (j == 0 && i <= 0) continue;
      tap_pair *t = &pairs[n++];
      t->dx = i * step;
      t->dy = j * step;
      t->fdx = (float)t->dx;
      t->fdy = (float)t->dy;
      t->h = k->h[r + i] * k->h[r + j];
      t->poly = svgf_exp2_poly_scaled(t->h);
    }
  return n;
}

static inline int clampi(int v, int lo, int hi) { return v < lo ? lo : v > hi ? hi : v; }

/* Row pointers of one pixel row (or tap row) of the signal and the guide. */
typedef struct rows {
  const float *z, *n0, *n1, *n2, *l, *c0, *c1, *c2, *v, *ok;
} rows;

static inline rows rows_at(const svgf_guide *g, const svgf_padded *in, int y, int x) {
  const size_t gi = (size_t)y * g->zn->stride + (size_t)x, si = (size_t)y * in->stride + (size_t)x;
  rows r;
  r.z = g->zn->plane[0] + gi;
  r.n0 = g->zn->plane[1] + gi;
  r.n1 = g->zn->plane[2] + gi;
  r.n2 = g->zn->plane[3] + gi;
  r.l = in->plane[SVGF_LUM] + si;
  r.c0 = in->plane[SVGF_R] + si;
  r.c1 = in->plane[SVGF_G] + si;
  r.c2 = in->plane[SVGF_B] + si;
  r.v = in->plane[SVGF_VAR] + si;
  r.ok = in->plane[SVGF_VALID] + si;
  return r;
}

/* Everything a block reads at p, and its accumulators: block-local arrays
 * (on the stack of the worker), so the tap loop addresses them from one
 * base register and keeps the general registers for the 9 tap planes. */
typedef struct block_acc {
  float sw[BLOCK], s0[BLOCK], s1[BLOCK], s2[BLOCK], sv[BLOCK];
  float inv_l[BLOCK]; /* log2 e / (sigma_l sqrt(g3x3(var_p)) + eps_l) */
  float z[BLOCK], l[BLOCK], n0[BLOCK], n1[BLOCK], n2[BLOCK];
  float sgx[BLOCK], sgy[BLOCK], zl[BLOCK]; /* sigma_z grad z (clamped), zon log2 e */
  float rdd[MAX_PAIRS][BLOCK]; /* log2 e / (sigma_z |grad z . (q - p)| + eps_z), 0: depth weight off */
} block_acc;

/* inv_l for pixels [x0, x0 + n) of row y: the 3x3 Gaussian (1 2 1)/4 x
 * (1 2 1)/4 of the variance, rows clamped, columns by the padding (fmaf
 * spelled out: ISO C does not contract a * b + c). */
static void block_inv_l(const svgf_padded *in, int y, int x0, int n, float sigma_l,
                        const float *eps_l, block_acc *acc) {
  const int H = in->height;
  const float *restrict up = svgf_padded_row(in, SVGF_VAR, y > 0 ? y - 1 : y) + x0;
  const float *restrict mid = svgf_padded_row(in, SVGF_VAR, y) + x0;
  const float *restrict dn = svgf_padded_row(in, SVGF_VAR, y < H - 1 ? y + 1 : y) + x0;
  float *restrict inv_l = acc->inv_l;
  if (eps_l) {
    const float *restrict eps = eps_l + (size_t)y * in->width + x0;
#pragma omp simd
    for (int x = 0; x < n; x++) {
      const float hu = fmaf(0.5f, up[x], 0.25f * (up[x - 1] + up[x + 1]));
      const float hm = fmaf(0.5f, mid[x], 0.25f * (mid[x - 1] + mid[x + 1]));
      const float hd = fmaf(0.5f, dn[x], 0.25f * (dn[x - 1] + dn[x + 1]));
      const float v = fmaf(0.5f, hm, 0.25f * (hu + hd));
      const float d = fmaf(sigma_l, svgf_sqrt_pos(v), eps[x]);
      inv_l[x] = SVGF_LOG2E * svgf_rcp_pos(d < 1e30f ? d : 1e30f);
    }
  } else {
#pragma omp simd
    for (int x = 0; x < n; x++) {
      const float hu = fmaf(0.5f, up[x], 0.25f * (up[x - 1] + up[x + 1]));
      const float hm = fmaf(0.5f, mid[x], 0.25f * (mid[x - 1] + mid[x + 1]));
      const float hd = fmaf(0.5f, dn[x], 0.25f * (dn[x - 1] + dn[x + 1]));
      const float v = fmaf(0.5f, hm, 0.25f * (hu + hd));
      const float d = fmaf(sigma_l, svgf_sqrt_pos(v), SVGF_EPS_L);
      inv_l[x] = SVGF_LOG2E * svgf_rcp_pos(d < 1e30f ? d : 1e30f);
    }
  }
}

/* The p side of pixels [x0, x0 + n) of row y into the block: guide, luminance
 * and, per tap pair (both taps of a pair see the same |grad z . (q - p)|),
 * the reciprocal depth denominator. */
static HUSH_ALWAYS_INLINE void block_p_side(const svgf_guide *g, const svgf_padded *in,
                                            const tap_pair *pairs, int npairs, int y, int x0,
                                            int n, block_acc *acc) {
  const rows p = rows_at(g, in, y, x0);
#pragma omp simd
  for (int x = 0; x < n; x++) {
    acc->z[x] = p.z[x];
    acc->l[x] = p.l[x];
    acc->n0[x] = p.n0[x];
    acc->n1[x] = p.n1[x];
    acc->n2[x] = p.n2[x];
  }
  const size_t pi = (size_t)y * g->width + x0;
  const float *restrict gx = g->gx + pi, *restrict gy = g->gy + pi, *restrict zon = g->zon + pi;
  const float sigma_z = g->sigma_z;
  /* once per pixel what every pair needs: the gradient within +-1e20 (NaN
   * taken as 1e20), so that a denominator, at most 1e20 times the largest
   * offset, is in the range of svgf_rcp_pos without a clamp per pair */
  float *restrict sgx = acc->sgx, *restrict sgy = acc->sgy, *restrict zl = acc->zl;
#pragma omp simd
  for (int x = 0; x < n; x++) {
    const float ax = sigma_z * gx[x], ay = sigma_z * gy[x];
    const float cx = ax < 1e20f ? ax : 1e20f, cy = ay < 1e20f ? ay : 1e20f;
    sgx[x] = cx > -1e20f ? cx : -1e20f;
    sgy[x] = cy > -1e20f ? cy : -1e20f;
    zl[x] = zon[x] * SVGF_LOG2E;
  }
  for (int k = 0; k < npairs; k++) {
    const float fdx = pairs[k].fdx, fdy = pairs[k].fdy;
    float *restrict rdd = acc->rdd[k];
    /* fmaf spelled out: ISO C mode does not contract a * b + c */
#pragma omp simd
    for (int x = 0; x < n; x++)
      rdd[x] = zl[x] * svgf_rcp_pos(fabsf(fmaf(sgx[x], fdx, sgy[x] * fdy)) + SVGF_EPS_Z);
  }
}

/* Adds the tap (x + dx, y + dy) with kernel weight h (in poly) to the accumulators of
 * pixels [x0, x0 + n) of row y; rdd is its pair's depth denominator. */
static HUSH_ALWAYS_INLINE void block_tap(const svgf_guide *g, const svgf_padded *in, int dx,
                                         int dy, const svgf_exp2_poly *poly,
                                         const float *rdd_pair, int y,
                                         int x0, int n, const int squarings, const int validity,
                                         block_acc *acc) {
  const rows q = rows_at(g, in, clampi(y + dy, 0, g->height - 1), x0 + dx);
  /* locals: the stores to acc must not make the loop reload them */
  const svgf_exp2_poly p = *poly;
  const float sigma_n_log2e = g->np.sigma_n_log2e, dot_floor = g->np.dot_floor;
  const float *restrict rdd = rdd_pair;
#pragma omp simd
  for (int x = 0; x < n; x++) {
    const float sz = fmaf(fabsf(acc->z[x] - q.z[x]), rdd[x], fabsf(acc->l[x] - q.l[x]) * acc->inv_l[x]);
    const float dot = fmaf(acc->n0[x], q.n0[x], fmaf(acc->n1[x], q.n1[x], acc->n2[x] * q.n2[x]));
    float w = svgf_tap_weight(sz, dot, squarings, sigma_n_log2e, dot_floor, &p);
    if (validity) w *= q.ok[x]; /* a constant: resolved at compile time */
    acc->sw[x] += w;
    acc->s0[x] = fmaf(w, q.c0[x], acc->s0[x]);
    acc->s1[x] = fmaf(w, q.c1[x], acc->s1[x]);
    acc->s2[x] = fmaf(w, q.c2[x], acc->s2[x]);
    acc->sv[x] = fmaf(w * w, q.v[x], acc->sv[x]);
  }
}

/* Row y of one level. SQUARINGS is a literal at every call: the OpenMP
 * region is outlined before inlining, so the dispatch on it has to sit
 * outside the parallel region for the constant to reach the vector loop. */
static HUSH_ALWAYS_INLINE void level_row(const svgf_guide *g, const svgf_level_params *lp,
                                         const svgf_padded *in, const svgf_level_out *out,
                                         const tap_pair *pairs, int npairs,
                                         int y, const int squarings,
                                         const int validity, block_acc *acc) {
  const int W = g->width;
  const float hc = lp->kernel->h[lp->kernel->radius];
  const float h0 = hc * hc;
  for (int x0 = 0; x0 < W; x0 += BLOCK) {
    const int n = W - x0 < BLOCK ? W - x0 : BLOCK;
    block_inv_l(in, y, x0, n, lp->sigma_l, lp->eps_l, acc);
    if (validity) {
      /* a pixel without data has no luminance to compare: weight 1 */
      const float *restrict ok = svgf_padded_row(in, SVGF_VALID, y) + x0;
#pragma omp simd
      for (int x = 0; x < n; x++) acc->inv_l[x] *= ok[x];
    }
    {
      const rows p = rows_at(g, in, y, x0);
      /* the centre tap: every edge-stopping weight is 1 */
#pragma omp simd
      for (int x = 0; x < n; x++) {
        const float hp = validity ? h0 * p.ok[x] : h0;
        acc->sw[x] = hp;
        acc->s0[x] = hp * p.c0[x];
        acc->s1[x] = hp * p.c1[x];
        acc->s2[x] = hp * p.c2[x];
        acc->sv[x] = hp * hp * p.v[x];
      }
    }
    block_p_side(g, in, pairs, npairs, y, x0, n, acc);
    for (int k = 0; k < npairs; k++) {
      const tap_pair *t = &pairs[k];
      block_tap(g, in, t->dx, t->dy, &t->poly, acc->rdd[k], y, x0, n, squarings, validity,
                acc);
      block_tap(g, in, -t->dx, -t->dy, &t->poly, acc->rdd[k], y, x0, n, squarings, validity,
                acc);
    }
    const size_t o = (size_t)y * out->stride + (size_t)x0;
    float *restrict r = out->plane[SVGF_R] + o, *restrict gr = out->plane[SVGF_G] + o,
                    *restrict bl = out->plane[SVGF_B] + o;
    if (validity) {
      /* nothing valid in reach: stays a hole (0, not valid) */
      float *restrict ok = out->plane[SVGF_VALID] ? out->plane[SVGF_VALID] + o : acc->inv_l;
#pragma omp simd
      for (int x = 0; x < n; x++) {
        const int some = acc->sw[x] > 0.0f;
        ok[x] = hush__select_bits(some, 1.0f, 0.0f);
        acc->sw[x] = hush__select_bits(some, acc->sw[x], 1.0f);
        acc->sv[x] = hush__select_bits(some, acc->sv[x], 0.0f);
      }
    }
#pragma omp simd
    for (int x = 0; x < n; x++) {
      const float inv = 1.0f / acc->sw[x];
      r[x] = acc->s0[x] * inv;
      gr[x] = acc->s1[x] * inv;
      bl[x] = acc->s2[x] * inv;
    }
    if (out->plane[SVGF_VAR]) {
      float *restrict v = out->plane[SVGF_VAR] + o;
#pragma omp simd
      for (int x = 0; x < n; x++) {
        const float inv = 1.0f / acc->sw[x];
        v[x] = acc->sv[x] * inv * inv;
      }
    }
    if (out->plane[SVGF_LUM]) {
      float *restrict l = out->plane[SVGF_LUM] + o;
#pragma omp simd
      for (int x = 0; x < n; x++) l[x] = hush_luminance(r[x], gr[x], bl[x]);
    }
  }
  if (out->pad > 0)
    for (int c = 0; c < SVGF_SIGNAL_CHANNELS; c++)
      if (out->plane[c]) svgf_pad_row(out->plane[c] + (size_t)y * out->stride, W, out->pad);
}

#define LEVEL_ROWS(NAME, SQUARINGS, VALIDITY)                                                           \
  static void NAME(const svgf_guide *g, const svgf_level_params *lp, const svgf_padded *in,  \
                   const svgf_level_out *out, int threads) {                                 \
    tap_pair pairs[MAX_PAIRS];                                                                \
    const int npairs = tap_pairs(lp->kernel, lp->step, pairs);                                \
    _Pragma("omp parallel num_threads(threads)") {                                           \
      block_acc acc __attribute__((aligned(64)));                                             \
      _Pragma("omp for schedule(static)") for (int y = 0; y < g->height; y++)                 \
          level_row(g, lp, in, out, pairs, npairs, y, SQUARINGS, VALIDITY, &acc);             \
    }                                                                                         \
  }
LEVEL_ROWS(level_rows_pow64, 6, 0)
LEVEL_ROWS(level_rows_pow128, 7, 0)
LEVEL_ROWS(level_rows_pow256, 8, 0)
LEVEL_ROWS(level_rows_any, -1, 0)
LEVEL_ROWS(level_rows_pow128_valid, 7, 1)
LEVEL_ROWS(level_rows_any_valid, -1, 1)

void svgf_atrous_level(const svgf_guide *g, const svgf_level_params *lp, const svgf_padded *in,
                       const svgf_level_out *out, int threads) {
  if (lp->validity) {
    if (g->np.squarings == 7)
      level_rows_pow128_valid(g, lp, in, out, threads);
    else
      level_rows_any_valid(g, lp, in, out, threads);
    return;
  }
  /* the normal weight's power as straight-line code for the usual sigma_n */
  switch (g->np.squarings) {
  case 6: level_rows_pow64(g, lp, in, out, threads); break;
  case 7: level_rows_pow128(g, lp, in, out, threads); break;
  case 8: level_rows_pow256(g, lp, in, out, threads); break;
  default: level_rows_any(g, lp, in, out, threads); break;
  }
}
