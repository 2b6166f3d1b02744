/*
 * regression.c — BMFR's per-block fit: stochastic regularisation,
 * Householder QR of the augmented matrix computing only R, back
 * substitution, weighted sum (see regression.h; bmfr-koskela-2019.md
 * §3.3-3.4, Heath 1997 pp. 92-93 for solving from R alone).
 */
#include "filters/bmfr/regression.h"

#include "core/rng.h"
#include "filters/bmfr/simd.h"

#include <math.h>
#include <string.h>

/* Inlined, so that a constant argument (y == NULL) selects its loop. */
#if defined(__GNUC__)
#  define HUSH_INLINE inline __attribute__((always_inline))
#else
#  define HUSH_INLINE inline
#endif

void hush__bmfr_noise_table(float *table, int count, int n, size_t ld, uint64_t frame, float eps) {
  const uint32_t seed = hush_hash32((uint32_t)frame ^ hush_hash32((uint32_t)(frame >> 32) + 0x9e3779b9u));
  memset(table, 0, ld * sizeof *table); /* the constant feature */
  for (int m = 1; m < count; m++) {
    float *col = table + (size_t)m * ld;
    const uint32_t sm = hush_hash32(seed + (uint32_t)m * 0x85ebca6bu);
    double sum = 0.0;
    for (int i = 0; i < n; i++) {
      /* 24 random bits -> [-1, 1) */
      const float u = (float)(hush_hash32(sm ^ (uint32_t)i * 0xc2b2ae35u) >> 8) * (2.0f / 16777216.0f);
      col[i] = eps * (u - 1.0f);
      sum += col[i];
    }
    const float mean = (float)(sum / n);
    for (int i = 0; i < n; i++) col[i] -= mean;
    for (size_t i = (size_t)n; i < ld; i++) col[i] = 0.0f;
  }
}

/* The loops below run over whole vectors of VF_LANES rows: ld is a
 * multiple of 16, and rows n..ld-1 are zero in every column (and in the
 * mask), so they add nothing to a sum and stay zero under an update. */

/* sum_{i = k}^{ld-1} a[i] b[i]: the vector holding row k with the rows
 * above k weighted 0, then whole vectors, two running sums. */
static float dot_from(const float *restrict a, const float *restrict b, int k, size_t ld) {
  size_t i = (size_t)k & ~(size_t)(VF_LANES - 1);
  vf s0 = vf_from((int)i, k) * vf_load(a + i) * vf_load(b + i), s1 = {0};
  for (i += VF_LANES; i + 2 * VF_LANES <= ld; i += 2 * VF_LANES) {
    s0 = vf_fma(vf_load(a + i), vf_load(b + i), s0);
    s1 = vf_fma(vf_load(a + i + VF_LANES), vf_load(b + i + VF_LANES), s1);
  }
  if (i < ld) s0 = vf_fma(vf_load(a + i), vf_load(b + i), s0);
  return vf_sum(s0 + s1);
}

/*
 * One Householder step on a group of g <= 4 columns a[0..g-1], rows k..ld-1
 * (rows above k untouched): a_j -= c_j x, fused with the next step's dot
 * products dots[j] = sum_{i >= k} y[i] a_j[i] after the update. y == NULL:
 * a[0] is the next pivot column itself (y = a[0], updated first in each
 * vector). Each vector of x and y is loaded once for the whole group and
 * each column streamed once, with its running sums in registers. The
 * vector holding row k is done with a 0/1 weight per row (rows above k:
 * a - (0 c) x = a exactly, and no term in the sum), so no row is left to
 * a scalar loop. Two running sums per column, for the even and the odd
 * vectors of rows: with one, each vector waited on the previous one's FMA
 * (4 cycles), where Zen 5 issues the group's four FMAs in two (the
 * stand-alone fit 9.2k -> 8.1k TSC ticks per 32x32 block without
 * refinement; docs/bmfr.md, tenth round).
 */
static HUSH_INLINE void reflect_group(float *const a[4], const float c[4], const int g,
                                      const float *restrict x, const float *restrict y, int k,
                                      size_t ld, float dots[4]) {
  size_t i = (size_t)k & ~(size_t)(VF_LANES - 1);
  const vf keep = vf_from((int)i, k);
  vf cv[4], s[4];
  {
    const vf xv = vf_load(x + i);
    vf yv = y ? vf_load(y + i) : (vf){0};
    for (int j = 0; j < g; j++) {
      cv[j] = vf_set1(c[j]);
      const vf t = vf_fnma(cv[j] * keep, xv, vf_load(a[j] + i));
      vf_store(a[j] + i, t);
      if (!y && j == 0) yv = t;
      s[j] = keep * yv * t;
    }
  }
  vf odd[4] = {{0}, {0}, {0}, {0}};
  for (i += VF_LANES; i + VF_LANES < ld; i += 2 * VF_LANES) {
    const vf xv = vf_load(x + i), xw = vf_load(x + i + VF_LANES);
    vf yv = y ? vf_load(y + i) : (vf){0}, yw = y ? vf_load(y + i + VF_LANES) : (vf){0};
    for (int j = 0; j < g; j++) {
      const vf t = vf_fnma(cv[j], xv, vf_load(a[j] + i));
      const vf u = vf_fnma(cv[j], xw, vf_load(a[j] + i + VF_LANES));
      vf_store(a[j] + i, t);
      vf_store(a[j] + i + VF_LANES, u);
      if (!y && j == 0) {
        yv = t;
        yw = u;
      }
      s[j] = vf_fma(yv, t, s[j]);
      odd[j] = vf_fma(yw, u, odd[j]);
    }
  }
  for (; i < ld; i += VF_LANES) {
    const vf xv = vf_load(x + i);
    vf yv = y ? vf_load(y + i) : (vf){0};
    for (int j = 0; j < g; j++) {
      const vf t = vf_fnma(cv[j], xv, vf_load(a[j] + i));
      vf_store(a[j] + i, t);
      if (!y && j == 0) yv = t;
      s[j] = vf_fma(yv, t, s[j]);
    }
  }
  for (int j = 0; j < g; j++) dots[j] = vf_sum(s[j] + odd[j]);
}

/* Columns per group of householder_r's update passes (reflect_group takes
 * up to 4). Two: on an AMD Zen 4 (32 KiB L1, the block's 52 KiB matrix
 * streamed from L2) the fit stage is 5-9 % faster than with groups of four
 * (1280x720, p5 of three alternated pairs: 1 thread 19.5 -> 17.6-18.3 ms,
 * 2 threads 9.7-10.7 -> 9.4-9.5), and one column is no better. Same bits:
 * each column's update and dot product are the same operations in the same
 * order. */
#define REFLECT_GROUP 2
/* householder_r dispatches g of 1 or 2 only (a group of four with a correct
 * dispatch was no faster on Zen 3 either: fit 8.45-9.0 against 8.5-8.9 ms,
 * 640x360, 1 thread) */
_Static_assert(REFLECT_GROUP == 1 || REFLECT_GROUP == 2, "householder_r calls g = 1 or 2");

/* d[j][c] = sum_i t_j[i] r_c[i] over the ld rows for the three residuals
 * and g <= 3 features t_j, one pass. Each of the 3 g sums is a chain of one
 * FMA per vector, so a pass over one feature (three chains) waits on the
 * FMA's latency; three features keep the FMA pipes busy. Each sum is the
 * same operations in the same order whatever g (same bits). */
static HUSH_INLINE void dot3_group(const float *const t[3], const int g,
                                   const float *restrict r0, const float *restrict r1,
                                   const float *restrict r2, size_t ld,
                                   float d[3][BMFR_CHANNELS]) {
  vf s[3][BMFR_CHANNELS] = {{{0}}};
  for (size_t i = 0; i < ld; i += VF_LANES) {
    const vf a = vf_load(r0 + i), b = vf_load(r1 + i), c = vf_load(r2 + i);
    for (int j = 0; j < g; j++) {
      const vf tv = vf_load(t[j] + i);
      s[j][0] = vf_fma(tv, a, s[j][0]);
      s[j][1] = vf_fma(tv, b, s[j][1]);
      s[j][2] = vf_fma(tv, c, s[j][2]);
    }
  }
  for (int j = 0; j < g; j++)
    for (int c = 0; c < BMFR_CHANNELS; c++) d[j][c] = vf_sum(s[j][c]);
}

/* Vector i of build_column's column: a = t + mask (u - mean), stored and
 * returned. */
static HUSH_INLINE vf column_vector(float *restrict a, const float *restrict t,
                                   const float *restrict u, vf mv, vf mk, size_t i) {
  const vf v = vf_fma(mk, vf_load(u + i) - mv, t ? vf_load(t + i) : (vf){0});
  vf_store(a + i, v);
  return v;
}

/* One column of the augmented matrix: a = t + mask (u - mean) (t NULL: 0),
 * returning sum_{i >= 1} mask[i] a[i], the first reflection's dot product
 * with column 0 (the mask), taken while the column is written; in two
 * running sums (even and odd vectors), as reflect_group's. */
static float build_column(float *restrict a, const float *restrict t, const float *restrict u,
                          float mean, const float *restrict mask, size_t ld) {
  const vf mv = vf_set1(mean);
  const vf mk0 = vf_load(mask);
  vf s = vf_from(0, 1) * mk0 * column_vector(a, t, u, mv, mk0, 0), odd = {0};
  size_t i = VF_LANES;
  for (; i + VF_LANES < ld; i += 2 * VF_LANES) {
    const vf mk = vf_load(mask + i), mk1 = vf_load(mask + i + VF_LANES);
    s = vf_fma(mk, column_vector(a, t, u, mv, mk, i), s);
    odd = vf_fma(mk1, column_vector(a, t, u, mv, mk1, i + VF_LANES), odd);
  }
  for (; i < ld; i += VF_LANES) {
    const vf mk = vf_load(mask + i);
    s = vf_fma(mk, column_vector(a, t, u, mv, mk, i), s);
  }
  return vf_sum(s + odd);
}

/*
 * The first m Householder reflections of the n x ncols matrix A (columns of
 * ld floats, rows n..ld-1 zero), applied to all its columns; Q is never
 * formed. Afterwards rows 0..m-1 of columns k >= row hold R (and the
 * right-hand sides r in columns m..ncols-1). Below the diagonal, the
 * columns keep the reflection vectors' tails, which nothing reads.
 * Per step k, with x = A[k..n-1][k]: alpha = -sign(x_k) |x|, v = x - alpha
 * e_k, and every later column a gets a -= (2 v.a / v.v) v. The dot
 * products x.a below the pivot come from the previous step's update pass
 * (dots[j]; dots0 gives step 0's); rows k and k + 1 are updated apart,
 * then rows k + 2.. in groups of REFLECT_GROUP columns, the first group led by
 * column k + 1 (the next pivot column, whose updated rows the others'
 * next dot products need).
 */
static void householder_r(float *A, size_t ld, int n, int m, int ncols, const float *dots0) {
  float dots[BMFR_MAX_FEATURES + BMFR_CHANNELS]; /* sum_{i > k} x_i a_ij, this step */
  memcpy(dots, dots0, (size_t)ncols * sizeof *dots);
  for (int k = 0; k < m && k < n; k++) {
    float *restrict x = A + (size_t)k * ld;
    const float xk = x[k], sigma = dots[k];
    const float norm = sqrtf(xk * xk + sigma);
    if (!(norm > 0.0f)) {
      /* a zero column: R_kk = 0, nothing to reflect; the next step's dots
       * are over rows k + 2.. */
      if (k + 1 < m)
        for (int j = k + 1; j < ncols; j++)
          dots[j] = dot_from(A + (size_t)(k + 1) * ld, A + (size_t)j * ld, k + 2, ld);
      continue;
    }
    const float alpha = xk > 0.0f ? -norm : norm;
    const float vk = xk - alpha; /* |vk| >= norm: no cancellation */
    const float scale = 2.0f / (sigma + vk * vk);
    float c[BMFR_MAX_FEATURES + BMFR_CHANNELS];
    for (int j = k + 1; j < ncols; j++) {
      float *a = A + (size_t)j * ld;
      c[j] = (vk * a[k] + dots[j]) * scale;
      a[k] -= c[j] * vk;
      a[k + 1] -= c[j] * x[k + 1];
    }
    x[k] = alpha;
    /* the last reflection: rows below m are never read */
    if (k + 1 >= m || k + 2 > n) continue;
    const float *y = A + (size_t)(k + 1) * ld;
    for (int j = k + 1; j < ncols; j += REFLECT_GROUP) {
      const int g = ncols - j < REFLECT_GROUP ? ncols - j : REFLECT_GROUP;
      float *cols[4] = {NULL, NULL, NULL, NULL};
      for (int q = 0; q < g; q++) cols[q] = A + (size_t)(j + q) * ld;
      const float *yy = j == k + 1 ? NULL : y;
      if (g == 2)
        reflect_group(cols, c + j, 2, x, yy, k + 2, ld, dots + j);
      else
        reflect_group(cols, c + j, 1, x, yy, k + 2, ld, dots + j);
    }
  }
}

/* Coefficients are capped here: with pivots above the cut-off they never
 * come near, and it keeps any sum of them times features in [-1, 1] finite. */
#define COEF_MAX 1e18

static inline double clamp_coef(double v) {
  v = v > COEF_MAX ? COEF_MAX : v < -COEF_MAX ? -COEF_MAX : v;
  return v == v ? v : 0.0;
}

/* R of the factorised A (upper triangle, rows 0..count-1) as a dense
 * row-major double matrix, read many times by the substitutions. */
typedef struct r_factor {
  double r[BMFR_MAX_FEATURES][BMFR_MAX_FEATURES];
  int count;
  double tol; /* a pivot at or below it gives weight 0 */
} r_factor;

static void r_factor_of(r_factor *R, const float *A, size_t ld, int count, double tol) {
  R->count = count;
  R->tol = tol;
  for (int k = 0; k < count; k++)
    for (int j = k; j < count; j++) R->r[k][j] = (double)A[(size_t)j * ld + k];
}

/* x[c] = R^-1 b[c] by back substitution for the three channels together
 * (independent chains: the divisions of one overlap the others'). */
static void back_substitute(const r_factor *R, const double b[BMFR_CHANNELS][BMFR_MAX_FEATURES],
                            double x[BMFR_CHANNELS][BMFR_MAX_FEATURES]) {
  for (int k = R->count - 1; k >= 0; k--) {
    const double rkk = R->r[k][k];
    const int use = fabs(rkk) > R->tol;
    for (int c = 0; c < BMFR_CHANNELS; c++) {
      double s = b[c][k];
      for (int j = k + 1; j < R->count; j++) s -= R->r[k][j] * x[c][j];
      x[c][k] = clamp_coef(use ? s / rkk : 0.0);
    }
  }
}

/* x[c] = R^-T b[c] by forward substitution, the three channels together. */
static void forward_substitute(const r_factor *R, const double b[BMFR_CHANNELS][BMFR_MAX_FEATURES],
                               double x[BMFR_CHANNELS][BMFR_MAX_FEATURES]) {
  for (int k = 0; k < R->count; k++) {
    const double rkk = R->r[k][k];
    const int use = fabs(rkk) > R->tol;
    for (int c = 0; c < BMFR_CHANNELS; c++) {
      double s = b[c][k];
      for (int j = 0; j < k; j++) s -= R->r[j][k] * x[c][j];
      x[c][k] = clamp_coef(use ? s / rkk : 0.0);
    }
  }
}

/*
 * s[c][v] -= (NEG) or += sum_m k[c][m] T[m][i + v VF_LANES .. +VF_LANES) for
 * the three channels and V (1 or 2) vectors of rows, the features in order.
 * Each sum is a chain of one FMA per feature: three chains (one vector) left
 * the FMA pipes waiting on its latency, six keep them busy (refinement
 * residuals and weighted sum: fit 19.05 -> 18.8 ms on one thread,
 * docs/bmfr.md, eighth round). Per lane the same operations in the same
 * order whatever V: the same bits.
 */
static HUSH_INLINE void feature_sums(const float *T, int count, size_t ld, size_t i,
                                     const float *const k[BMFR_CHANNELS], const int V,
                                     const int NEG, vf s[BMFR_CHANNELS][2]) {
  for (int m = 0; m < count; m++) {
    vf t[2];
    for (int v = 0; v < V; v++) t[v] = vf_load(T + (size_t)m * ld + i + (size_t)v * VF_LANES);
    for (int c = 0; c < BMFR_CHANNELS; c++) {
      const vf kc = vf_set1(k[c][m]);
      for (int v = 0; v < V; v++)
        s[c][v] = NEG ? vf_fnma(kc, t[v], s[c][v]) : vf_fma(kc, t[v], s[c][v]);
    }
  }
}

void hush__bmfr_fit(const float *T, int count, const float *const z[BMFR_CHANNELS],
                    const float *noise, const float *mask, int n, int nvalid, size_t ld, float *A,
                    int refine, float *scratch, float coef[BMFR_CHANNELS][BMFR_MAX_FEATURES]) {
  /* A = [T + N, z] (eq. 7), holes zero in every column; while each column
   * is written, its dot product with column 0 below row 0 (the first
   * reflection's) is taken, which saves the QR a pass per column */
  float dots0[BMFR_MAX_FEATURES + BMFR_CHANNELS];
  dots0[0] = build_column(A, NULL, mask, 0.0f, mask, ld);
  for (int m = 1; m < count; m++) {
    const float *restrict nz = noise + (size_t)m * ld;
    float mean = 0.0f;
    if (nvalid < n && nvalid > 0) {
      /* keep the noise zero-mean over the rows that take part */
      double s = 0.0;
#pragma omp simd reduction(+ : s)
      for (int i = 0; i < n; i++) s += (double)(mask[i] * nz[i]);
      mean = (float)(s / nvalid);
    }
    dots0[m] = build_column(A + (size_t)m * ld, T + (size_t)m * ld, nz, mean, mask, ld);
  }
  for (int c = 0; c < BMFR_CHANNELS; c++)
    dots0[count + c] = build_column(A + (size_t)(count + c) * ld, NULL, z[c], 0.0f, mask, ld);

  householder_r(A, ld, n, count, count + BMFR_CHANNELS, dots0);

  /* R alpha = r per channel (eq. 5). A pivot below the cut-off is a
   * direction the block does not determine: its weight is 0 (the feature
   * columns are at most 1 in magnitude, so a column norm is at most
   * sqrt(nvalid); the regularisation noise alone gives about
   * eps sqrt(nvalid / 3), far above the cut-off for the default eps). */
  const double tol = 1e-4 * sqrt((double)(nvalid > 0 ? nvalid : 1));
  r_factor R;
  r_factor_of(&R, A, ld, count, tol);
  double w[BMFR_CHANNELS][BMFR_MAX_FEATURES], r[BMFR_CHANNELS][BMFR_MAX_FEATURES];
  for (int c = 0; c < BMFR_CHANNELS; c++)
    for (int k = 0; k < count; k++) r[c][k] = A[(size_t)(count + c) * ld + k];
  back_substitute(&R, (const double(*)[BMFR_MAX_FEATURES])r, w);

  /* Refinement towards eq. 2's solution on the noise-free features: the
   * noise that keeps the factorisation stable also perturbs the weights
   * (errors in the variables, about eps / sqrt(n) of each). One step of
   * a += (R^T R)^-1 T^T (z - T a) with the noisy R as the preconditioner
   * removes that to first order; in the directions the noise regularises
   * (near-collinear features), R^T R is dominated by the noise and the
   * step stays small, so the regularisation keeps its effect there. */
  for (int it = 0; it < refine; it++) {
    /* residuals of the three channels (one pass, the features summed
     * per row), then their dots with each feature (one pass per feature) */
    float *restrict r0 = scratch, *restrict r1 = scratch + ld, *restrict r2 = scratch + 2 * ld;
    float a0[BMFR_MAX_FEATURES], a1[BMFR_MAX_FEATURES], a2[BMFR_MAX_FEATURES];
    for (int m = 0; m < count; m++) {
      a0[m] = (float)w[0][m];
      a1[m] = (float)w[1][m];
      a2[m] = (float)w[2][m];
    }
    const float *const a[BMFR_CHANNELS] = {a0, a1, a2};
    float *const res[BMFR_CHANNELS] = {r0, r1, r2};
    size_t i = 0;
    for (; i + 2 * VF_LANES <= ld; i += 2 * VF_LANES) {
      vf sums[BMFR_CHANNELS][2];
      for (int v = 0; v < 2; v++) {
        const vf mk = vf_load(mask + i + (size_t)v * VF_LANES);
        for (int c = 0; c < BMFR_CHANNELS; c++)
          sums[c][v] = vf_load(z[c] + i + (size_t)v * VF_LANES) * mk;
      }
      feature_sums(T, count, ld, i, a, 2, 1, sums);
      for (int v = 0; v < 2; v++)
        for (int c = 0; c < BMFR_CHANNELS; c++)
          vf_store(res[c] + i + (size_t)v * VF_LANES, sums[c][v]);
    }
    for (; i < ld; i += VF_LANES) {
      vf sums[BMFR_CHANNELS][2] = {{{0}}};
      const vf mk = vf_load(mask + i);
      for (int c = 0; c < BMFR_CHANNELS; c++) sums[c][0] = vf_load(z[c] + i) * mk;
      feature_sums(T, count, ld, i, a, 1, 1, sums);
      for (int c = 0; c < BMFR_CHANNELS; c++) vf_store(res[c] + i, sums[c][0]);
    }
    double g[BMFR_CHANNELS][BMFR_MAX_FEATURES];
    for (int m = 0; m < count; m += 3) {
      const int k = count - m < 3 ? count - m : 3;
      const float *t[3] = {T + (size_t)m * ld, T + (size_t)(m + 1) * ld, T + (size_t)(m + 2) * ld};
      float d3[3][BMFR_CHANNELS];
      if (k == 3)
        dot3_group(t, 3, r0, r1, r2, ld, d3);
      else if (k == 2)
        dot3_group(t, 2, r0, r1, r2, ld, d3);
      else
        dot3_group(t, 1, r0, r1, r2, ld, d3);
      for (int j = 0; j < k; j++)
        for (int c = 0; c < BMFR_CHANNELS; c++) g[c][m + j] = d3[j][c];
    }
    double u[BMFR_CHANNELS][BMFR_MAX_FEATURES], d[BMFR_CHANNELS][BMFR_MAX_FEATURES];
    forward_substitute(&R, (const double(*)[BMFR_MAX_FEATURES])g, u);
    back_substitute(&R, (const double(*)[BMFR_MAX_FEATURES])u, d);
    for (int c = 0; c < BMFR_CHANNELS; c++)
      for (int m = 0; m < count; m++) w[c][m] = clamp_coef(w[c][m] + d[c][m]);
  }
  for (int c = 0; c < BMFR_CHANNELS; c++)
    for (int k = 0; k < count; k++) coef[c][k] = (float)w[c][k];
}

void hush__bmfr_synthesize(const float *T, int count, int n, size_t ld,
                           const float coef[BMFR_CHANNELS][BMFR_MAX_FEATURES],
                           float *const y[BMFR_CHANNELS]) {
  const float *const k[BMFR_CHANNELS] = {coef[0], coef[1], coef[2]};
  /* the features summed in registers per vector of rows: one store per
   * channel (rows n..ld-1 of T are zero: they give 0); > 0 also maps a NaN
   * (impossible with finite inputs) to 0 */
  const vf zero = {0};
  size_t i = 0;
  for (; i + 2 * VF_LANES <= ld; i += 2 * VF_LANES) {
    vf sums[BMFR_CHANNELS][2] = {{zero, zero}, {zero, zero}, {zero, zero}};
    feature_sums(T, count, ld, i, k, 2, 0, sums);
    for (int v = 0; v < 2; v++)
      for (int c = 0; c < BMFR_CHANNELS; c++)
        vf_store(y[c] + i + (size_t)v * VF_LANES, vf_select(sums[c][v] > zero, sums[c][v], zero));
  }
  for (; i < ld; i += VF_LANES) {
    vf sums[BMFR_CHANNELS][2] = {{zero, zero}, {zero, zero}, {zero, zero}};
    feature_sums(T, count, ld, i, k, 1, 0, sums);
    for (int c = 0; c < BMFR_CHANNELS; c++)
      vf_store(y[c] + i, vf_select(sums[c][0] > zero, sums[c][0], zero));
  }
}
