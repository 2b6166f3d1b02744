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

/* Rows of the small double matrices (R's inverse, the Gram matrix): the
 * largest feature set rounded up to whole vectors of eight doubles. */
#define RW 24
_Static_assert(BMFR_MAX_FEATURES <= RW, "a row holds every feature");
_Static_assert(RW % (3 * VD_LANES) == 0, "rows of a third of RW are whole vectors");

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

/* Vector i of build_column's column: a = t + mask (u - mean), stored and
 * returned. */
static HUSH_INLINE vf column_vector(float *restrict a, const float *restrict t,
                                   const float *restrict u, vf mv, vf mk, size_t i) {
  const vf v = vf_fma(mk, vf_load(u + i) - mv, t ? vf_load(t + i) : (vf){0});
  vf_store(a + i, v);
  return v;
}

/* One column of the augmented matrix after the first reflection, rows 1..
 * (hush__bmfr_fit): a = t + mask (u - mean) (t NULL: 0), returning
 * sum_{i >= 2} y[i] a[i], the second reflection's dot product with its
 * pivot column y (NULL: this column is y), taken while the column is
 * written; in two running sums (even and odd vectors), as
 * reflect_group's. Row 0 is the caller's. */
static float build_column(float *restrict a, const float *restrict t, const float *restrict u,
                          float mean, const float *restrict mask, const float *restrict y,
                          size_t ld) {
  const vf mv = vf_set1(mean);
  const vf mk0 = vf_load(mask);
  const vf v0 = column_vector(a, t, u, mv, mk0, 0);
  vf s = vf_from(0, 2) * (y ? vf_load(y) : v0) * v0, odd = {0};
  size_t i = VF_LANES;
  for (; i + VF_LANES < ld; i += 2 * VF_LANES) {
    const vf mk = vf_load(mask + i), mk1 = vf_load(mask + i + VF_LANES);
    const vf v = column_vector(a, t, u, mv, mk, i);
    const vf w = column_vector(a, t, u, mv, mk1, i + VF_LANES);
    s = vf_fma(y ? vf_load(y + i) : v, v, s);
    odd = vf_fma(y ? vf_load(y + i + VF_LANES) : w, w, odd);
  }
  for (; i < ld; i += VF_LANES) {
    const vf mk = vf_load(mask + i);
    const vf v = column_vector(a, t, u, mv, mk, i);
    s = vf_fma(y ? vf_load(y + i) : v, v, s);
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
static void householder_r(float *A, size_t ld, int n, int k0, int m, int ncols,
                          const float *dots0) {
  float dots[BMFR_MAX_FEATURES + BMFR_CHANNELS]; /* sum_{i > k} x_i a_ij, this step */
  memcpy(dots, dots0, (size_t)ncols * sizeof *dots);
  for (int k = k0; k < m && k < n; k++) {
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
 * row-major double matrix. */
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

/*
 * B = R^-1, by back substitution on the identity's columns all at once,
 * rows padded with zeros to NV vectors of doubles (NV a constant at each
 * call). A pivot at or below the cut-off gives a zero row: b -> B b is
 * then back substitution with that feature's weight set to 0, and b -> B^T
 * b forward substitution with the same rule. Substituting each right-hand
 * side in turn waited, row by row, on a chain of dependent multiply-adds
 * and a division; here a row is one vector operation on the rows below
 * (the fit's solves and refinement: 11.5k -> 10.8k TSC ticks a 32x32
 * block on its own, docs/bmfr.md, thirteenth round).
 */
static HUSH_INLINE void r_inverse(const r_factor *R, double B[][RW], const int NV) {
  const int n = R->count;
  for (int k = n - 1; k >= 0; k--) {
    const double rkk = R->r[k][k];
    const double inv = fabs(rkk) > R->tol ? 1.0 / rkk : 0.0;
    double row[RW];
    for (int i = 0; i < NV * VD_LANES; i++) row[i] = i == k ? 1.0 : 0.0;
    /* the row just finished (k + 1) last: the others' terms need not wait
     * for it */
    for (int j = n - 1; j > k; j--) {
      const double r = R->r[k][j];
      for (int i = 0; i < NV * VD_LANES; i++) row[i] -= r * B[j][i];
    }
    for (int i = 0; i < NV * VD_LANES; i++) B[k][i] = row[i] * inv;
  }
}

/* out = sum_j x[j] M[j] over count rows of NV vectors: two running sums
 * per vector (even and odd rows), as the loops over a block's rows. */
static HUSH_INLINE void vd_combine(const double *x, const double (*M)[RW], int count, const int NV,
                                   vd out[RW / VD_LANES]) {
  vd even[RW / VD_LANES], odd[RW / VD_LANES];
  for (int v = 0; v < NV; v++) even[v] = odd[v] = (vd){0};
  int j = 0;
  for (; j + 1 < count; j += 2)
    for (int v = 0; v < NV; v++) {
      even[v] += x[j] * vd_load(M[j] + v * VD_LANES);
      odd[v] += x[j + 1] * vd_load(M[j + 1] + v * VD_LANES);
    }
  if (j < count)
    for (int v = 0; v < NV; v++) even[v] += x[j] * vd_load(M[j] + v * VD_LANES);
  for (int v = 0; v < NV; v++) out[v] = even[v] + odd[v];
}

/*
 * s[c][v] += sum_m k[c][m] T[m][i + v VF_LANES .. +VF_LANES) for the three
 * channels and V (1 or 2) vectors of rows, the features in order. Each sum
 * is a chain of one FMA per feature: three chains (one vector) left the FMA
 * pipes waiting on its latency, six keep them busy (the weighted sum: fit
 * 19.05 -> 18.8 ms on one thread, docs/bmfr.md, eighth round). Per lane the
 * same operations in the same order whatever V: the same bits.
 */
static HUSH_INLINE void feature_sums(const float *T, int count, size_t ld, size_t i,
                                     const float *const k[BMFR_CHANNELS], const int V,
                                     vf s[BMFR_CHANNELS][2]) {
  for (int m = 0; m < count; m++) {
    vf t[2];
    for (int v = 0; v < V; v++) t[v] = vf_load(T + (size_t)m * ld + i + (size_t)v * VF_LANES);
    for (int c = 0; c < BMFR_CHANNELS; c++) {
      const vf kc = vf_set1(k[c][m]);
      for (int v = 0; v < V; v++) s[c][v] = vf_fma(kc, t[v], s[c][v]);
    }
  }
}

/* out[a][b] = sum over the ld rows of X[a][i] Y[b][i], for na x nb <= 24
 * pairs of columns (na, nb <= 6, constants at each call, so the 24 sums
 * stay in registers: each row vector's loads serve them all). */
static HUSH_INLINE void gram_block(const float *const *X, const int na, const float *const *Y,
                                   const int nb, size_t ld, float out[6][6]) {
  vf acc[6][6];
  for (int a = 0; a < na; a++)
    for (int b = 0; b < nb; b++) acc[a][b] = (vf){0};
  for (size_t i = 0; i < ld; i += VF_LANES) {
    vf x[6], y[6];
    for (int a = 0; a < na; a++) x[a] = vf_load(X[a] + i);
    for (int b = 0; b < nb; b++) y[b] = vf_load(Y[b] + i);
    for (int a = 0; a < na; a++)
      for (int b = 0; b < nb; b++) acc[a][b] = vf_fma(x[a], y[b], acc[a][b]);
  }
  for (int a = 0; a < na; a++)
    for (int b = 0; b < nb; b++) out[a][b] = vf_sum(acc[a][b]);
}

#if VF_LANES == 16
/* out[p] = sum over the ld rows of c[pa[p]][i] c[pb[p]][i] for the np <=
 * 21 pairs of the nc <= 9 columns c (constants at each call: the loops
 * unroll, each column's vector loaded once a row vector for all its
 * pairs, the sums in registers). The same FMA chain per pair as
 * gram_block's: the same bits. */
static HUSH_INLINE void gram_pairs(const float *const *c, const int nc, const int *pa,
                                   const int *pb, const int np, size_t ld, float *out) {
  vf acc[21];
#pragma GCC unroll 21
  for (int p = 0; p < np; p++) acc[p] = (vf){0};
  for (size_t i = 0; i < ld; i += VF_LANES) {
    vf x[9];
#pragma GCC unroll 9
    for (int k = 0; k < nc; k++) x[k] = vf_load(c[k] + i);
#pragma GCC unroll 21
    for (int p = 0; p < np; p++) acc[p] = vf_fma(x[pa[p]], x[pb[p]], acc[p]);
  }
#pragma GCC unroll 21
  for (int p = 0; p < np; p++) out[p] = vf_sum(acc[p]);
}

/* The sums of pairs (ga[p], gb[p]) of [T | z]'s columns (ga < 10 <= gb:
 * into h) into G (both halves) and h, for the default ten features. */
static void gram_store(const int *ga, const int *gb, int np, const float *o,
                       double G[BMFR_MAX_FEATURES][RW],
                       double h[BMFR_CHANNELS][RW]) {
  for (int p = 0; p < np; p++) {
    if (gb[p] >= 10)
      h[gb[p] - 10][ga[p]] = o[p];
    else
      G[ga[p]][gb[p]] = G[gb[p]][ga[p]] = o[p];
  }
}
/* The default set's Gram passes (gram): per pass its columns of [T | z]
 * and its pairs, as indices into those columns (pa, pb) and into [T | z]
 * (ga, gb). */
typedef struct gram_pass_def {
  int nc, np;
  int cols[9];
  int pa[21], pb[21], ga[21], gb[21];
} gram_pass_def;

static const gram_pass_def gram_passes[5] = {
    {6, 18, {0, 1, 2, 3, 8, 9},
     {0, 0, 0, 0, 1, 1, 1, 2, 2, 3, 0, 0, 1, 1, 2, 2, 3, 3},
     {0, 1, 2, 3, 1, 2, 3, 2, 3, 3, 4, 5, 4, 5, 4, 5, 4, 5},
     {0, 0, 0, 0, 1, 1, 1, 2, 2, 3, 0, 0, 1, 1, 2, 2, 3, 3},
     {0, 1, 2, 3, 1, 2, 3, 2, 3, 3, 8, 9, 8, 9, 8, 9, 8, 9}},
    {6, 18, {4, 5, 6, 7, 8, 9},
     {0, 0, 0, 0, 1, 1, 1, 2, 2, 3, 0, 0, 1, 1, 2, 2, 3, 3},
     {0, 1, 2, 3, 1, 2, 3, 2, 3, 3, 4, 5, 4, 5, 4, 5, 4, 5},
     {4, 4, 4, 4, 5, 5, 5, 6, 6, 7, 4, 4, 5, 5, 6, 6, 7, 7},
     {4, 5, 6, 7, 5, 6, 7, 6, 7, 7, 8, 9, 8, 9, 8, 9, 8, 9}},
    {8, 16, {0, 1, 2, 3, 4, 5, 6, 7},
     {0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2, 3, 3, 3, 3},
     {4, 5, 6, 7, 4, 5, 6, 7, 4, 5, 6, 7, 4, 5, 6, 7},
     {0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2, 3, 3, 3, 3},
     {4, 5, 6, 7, 4, 5, 6, 7, 4, 5, 6, 7, 4, 5, 6, 7}},
    {9, 21, {0, 1, 2, 3, 8, 9, 10, 11, 12},
     {4, 4, 5, 0, 0, 0, 1, 1, 1, 2, 2, 2, 3, 3, 3, 4, 4, 4, 5, 5, 5},
     {4, 5, 5, 6, 7, 8, 6, 7, 8, 6, 7, 8, 6, 7, 8, 6, 7, 8, 6, 7, 8},
     {8, 8, 9, 0, 0, 0, 1, 1, 1, 2, 2, 2, 3, 3, 3, 8, 8, 8, 9, 9, 9},
     {8, 9, 9, 10, 11, 12, 10, 11, 12, 10, 11, 12, 10, 11, 12, 10, 11, 12, 10, 11, 12}},
    {7, 12, {4, 5, 6, 7, 10, 11, 12},
     {0, 0, 0, 1, 1, 1, 2, 2, 2, 3, 3, 3},
     {4, 5, 6, 4, 5, 6, 4, 5, 6, 4, 5, 6},
     {4, 4, 4, 5, 5, 5, 6, 6, 6, 7, 7, 7},
     {10, 11, 12, 10, 11, 12, 10, 11, 12, 10, 11, 12}},
};

/* Pass k of gram_passes (k a constant: the pass's sizes are then too, and
 * gram_pairs unrolls). */
static HUSH_INLINE void gram_pass(const float *const *t, const int k, size_t ld,
                                  double G[BMFR_MAX_FEATURES][RW],
                                  double h[BMFR_CHANNELS][RW]) {
  const gram_pass_def *d = &gram_passes[k];
  const float *c[9];
  for (int q = 0; q < d->nc; q++) c[q] = t[d->cols[q]];
  float sums[21];
  gram_pairs(c, d->nc, d->pa, d->pb, d->np, ld, sums);
  gram_store(d->ga, d->gb, d->np, sums, G, h);
}
#endif

/* A tile of the generic Gram pass: GRAM_RA x GRAM_RB sums, as many as the
 * register file holds with the loads (32 vectors with AVX-512, 16 else). */
#if VF_LANES == 16
#  define GRAM_RA 4
#  define GRAM_RB 6
#else
#  define GRAM_RA 2
#  define GRAM_RB 4
#endif

/* A column of zeros standing in for the columns past the last in a tile
 * (their sums are computed and dropped); blocks up to 64x64 padded. */
#define GRAM_ZERO_LD (64 * 64 + 64)
static const float gram_zero[GRAM_ZERO_LD];

/*
 * The refinement's Gram matrix G = T^T T (count x count) and h[c] = T^T
 * z_c over the ld rows (T is 0 on holes and past n, so z needs no mask).
 * AVX-512 builds take the default ten features in five register-blocked
 * passes, one FMA a row vector for each of the 85 sums (gram_pairs; six
 * passes of rectangular tiles took 98); other sets and builds tile the
 * upper triangle of [T | z]'s columns GRAM_RA x GRAM_RB at a time,
 * padding with zero columns.
 */
static void gram(const float *T, int count, const float *const z[BMFR_CHANNELS], size_t ld,
                 double G[BMFR_MAX_FEATURES][RW],
                 double h[BMFR_CHANNELS][RW]) {
  const float *t[BMFR_MAX_FEATURES + BMFR_CHANNELS];
  for (int m = 0; m < count; m++) t[m] = T + (size_t)m * ld;
  for (int c = 0; c < BMFR_CHANNELS; c++) t[count + c] = z[c];
  float o[6][6];
#if VF_LANES == 16
  if (count == 10) {
    /* the 85 sums of the default set in five register-blocked passes (85
     * FMAs a row vector, each pass's columns loaded once): P = features
     * 0-3, Q = 4-7, R = 8-9, z the radiance: P x (P, R), Q x (Q, R), P x Q,
     * (P, R) x z with R x R, Q x z, the diagonal blocks' upper triangles
     * alone (gram_passes) */
    gram_pass(t, 0, ld, G, h);
    gram_pass(t, 1, ld, G, h);
    gram_pass(t, 2, ld, G, h);
    gram_pass(t, 3, ld, G, h);
    gram_pass(t, 4, ld, G, h);
    return;
  }
#endif
  const int cols = count + BMFR_CHANNELS;
  if (ld > GRAM_ZERO_LD) { /* (no padding column this long: pair by pair) */
    for (int i = 0; i < count; i++)
      for (int j = i; j < cols; j++) {
        gram_block(&t[i], 1, &t[j], 1, ld, o);
        if (j >= count)
          h[j - count][i] = o[0][0];
        else
          G[i][j] = G[j][i] = o[0][0];
      }
    return;
  }
  for (int a0 = 0; a0 < count; a0 += GRAM_RA)
    for (int b0 = a0; b0 < cols; b0 += GRAM_RB) {
      const float *X[GRAM_RA], *Y[GRAM_RB];
      for (int a = 0; a < GRAM_RA; a++) X[a] = a0 + a < count ? t[a0 + a] : gram_zero;
      for (int b = 0; b < GRAM_RB; b++) Y[b] = b0 + b < cols ? t[b0 + b] : gram_zero;
      gram_block(X, GRAM_RA, Y, GRAM_RB, ld, o);
      for (int a = 0; a < GRAM_RA && a0 + a < count; a++)
        for (int b = 0; b < GRAM_RB && b0 + b < cols; b++) {
          const int i = a0 + a, j = b0 + b;
          if (j >= count)
            h[j - count][i] = o[a][b];
          else if (j >= i)
            G[i][j] = G[j][i] = o[a][b];
        }
    }
}

/*
 * The weights w[c] (rows of NV vectors, a constant at each call) from the
 * factorised A: w = R^-1 r (eq. 5), then `refine` steps towards eq. 2's
 * solution on the noise-free features. The noise that keeps the
 * factorisation stable also perturbs the weights (errors in the
 * variables, about eps / sqrt(n) of each). A step of
 * w += (R^T R)^-1 T^T (z - T w) with the noisy R as the preconditioner
 * removes that to first order; in the directions the noise regularises
 * (near-collinear features), R^T R is dominated by the noise and the step
 * stays small, so the regularisation keeps its effect there.
 * T^T (z - T w) is taken as h - G w from the Gram matrix G = T^T T and
 * h = T^T z, summed once in float (gram). The difference of two float sums
 * loses the residual's own precision: an exact combination of the features
 * comes out to about 2e-6 instead of 1e-6 (test_bmfr), far inside the
 * 1e-3 asked.
 * A step is kept only if it lowers the residual |z - T w|^2, which changes
 * by d^T G d - 2 d^T (h - G w): with fewer valid pixels than about twice
 * the features, the noise's cross terms in R^T R can make the iteration
 * diverge (weights of 1e4 to 1e12 and fitted values hundreds of times the
 * block's radiance with 9 valid pixels, test_bmfr); there the first
 * rejected step ends the channel's refinement.
 */
static HUSH_INLINE void solve(const r_factor *R, const float *A, size_t ld, int refine,
                              double G[BMFR_MAX_FEATURES][RW], double h[BMFR_CHANNELS][RW],
                              const int NV, double w[BMFR_CHANNELS][RW]) {
  const int count = R->count;
  double B[BMFR_MAX_FEATURES][RW], BT[BMFR_MAX_FEATURES][RW];
  r_inverse(R, B, NV);
  for (int j = 0; j < count; j++)
    for (int i = 0; i < NV * VD_LANES; i++) BT[j][i] = i < count ? B[i][j] : 0.0;
  for (int c = 0; c < BMFR_CHANNELS; c++) {
    double r[BMFR_MAX_FEATURES];
    for (int k = 0; k < count; k++) r[k] = A[(size_t)(count + c) * ld + k];
    vd x[RW / VD_LANES];
    vd_combine(r, (const double(*)[RW])BT, count, NV, x);
    for (int v = 0; v < NV; v++) vd_store(w[c] + v * VD_LANES, x[v]);
    for (int k = 0; k < count; k++) w[c][k] = clamp_coef(w[c][k]);
  }
  if (refine <= 0) return;
  for (int j = 0; j < count; j++)
    for (int i = count; i < NV * VD_LANES; i++) G[j][i] = 0.0;
  for (int c = 0; c < BMFR_CHANNELS; c++)
    for (int i = count; i < NV * VD_LANES; i++) h[c][i] = 0.0;
  for (int c = 0; c < BMFR_CHANNELS; c++)
    for (int it = 0; it < refine; it++) {
      vd gw[RW / VD_LANES], g[RW / VD_LANES], u[RW / VD_LANES], d[RW / VD_LANES];
      vd gd[RW / VD_LANES];
      double gs[RW], us[RW], ds[RW];
      vd_combine(w[c], (const double(*)[RW])G, count, NV, gw);
      for (int v = 0; v < NV; v++) {
        g[v] = vd_load(h[c] + v * VD_LANES) - gw[v];
        vd_store(gs + v * VD_LANES, g[v]);
      }
      vd_combine(gs, (const double(*)[RW])B, count, NV, u); /* R^-T g */
      for (int v = 0; v < NV; v++) vd_store(us + v * VD_LANES, u[v]);
      vd_combine(us, (const double(*)[RW])BT, count, NV, d); /* R^-1 R^-T g */
      for (int v = 0; v < NV; v++) vd_store(ds + v * VD_LANES, d[v]);
      vd_combine(ds, (const double(*)[RW])G, count, NV, gd);
      vd e = {0};
      for (int v = 0; v < NV; v++) e += d[v] * (gd[v] - 2.0 * g[v]);
      double change = 0.0;
      for (int l = 0; l < VD_LANES; l++) change += e[l];
      if (!(change < 0.0)) break;
      for (int k = 0; k < count; k++) w[c][k] = clamp_coef(w[c][k] + ds[k]);
    }
}

/* sums[j] = sum over the ld rows of column j of [T | mask z] (T is 0 on
 * holes), for the first reflection when there is no Gram matrix. */
static void column_sums(const float *T, int count, const float *const z[BMFR_CHANNELS],
                        const float *mask, size_t ld, double *sums) {
  for (int j = 0; j < count + BMFR_CHANNELS; j++) {
    const float *t = j < count ? T + (size_t)j * ld : z[j - count];
    vf s = {0}, odd = {0};
    size_t i = 0;
    for (; i + VF_LANES < ld; i += 2 * VF_LANES) {
      s = vf_fma(vf_load(mask + i), vf_load(t + i), s);
      odd = vf_fma(vf_load(mask + i + VF_LANES), vf_load(t + i + VF_LANES), odd);
    }
    for (; i < ld; i += VF_LANES) s = vf_fma(vf_load(mask + i), vf_load(t + i), s);
    sums[j] = vf_sum(s + odd);
  }
}

void hush__bmfr_fit(const float *T, int count, const float *const z[BMFR_CHANNELS],
                    const float *noise, const float *mask, int n, int nvalid, size_t ld, float *A,
                    int refine, float coef[BMFR_CHANNELS][BMFR_MAX_FEATURES]) {
  const int ncols = count + BMFR_CHANNELS;
  /* the refinement's Gram matrix first: its row 0 holds the column sums
   * the first reflection needs (T's column 0 is the mask) */
  double G[BMFR_MAX_FEATURES][RW], h[BMFR_CHANNELS][RW], sums[BMFR_MAX_FEATURES + BMFR_CHANNELS];
  if (refine > 0) {
    gram(T, count, z, ld, G, h);
    for (int j = 0; j < count; j++) sums[j] = G[0][j];
    for (int c = 0; c < BMFR_CHANNELS; c++) sums[count + c] = h[c][0];
  } else {
    column_sums(T, count, z, mask, ld, sums);
  }
  /* The augmented matrix A = [T + N, z] (eq. 7), holes zero in every
   * column, is never formed: each column is written as the first
   * Householder reflection leaves it. Column 0 is the mask (the constant
   * feature, no noise), x = mask: with alpha = -sign(x_0) sqrt(nvalid) and
   * v = x - alpha e_0, a column a becomes a - c v, c = 2 v.a / v.v, and
   * v.a = vk a_0 + sum_{i >= 1} mask_i a_i comes from the column's sum
   * over the valid rows. The noise is zero-mean there (re-centred below
   * when there are holes), so a feature column's sum is T's (up to the
   * rounding of the noise's mean, about 1e-9 of it); rows 1.. of a - c v
   * are then t + mask (u - (mean + c)), a build with another mean. Where
   * the build and the QR's first pass wrote each column and then updated
   * it, one pass writes it, and column 0 is not written at all: a 32x32
   * block's fit stand-alone 11.07k -> 9.99k TSC ticks, the fit stage 4.09
   * -> 3.90 ms (docs/bmfr.md, thirteenth round). The results move by
   * rounding only (about 1e-7 of the output). */
  const float m0 = mask[0];
  const double norm = sqrt((double)nvalid);
  const double alpha = nvalid > 0 ? (m0 > 0.0f ? -norm : norm) : 0.0;
  const double vk = m0 - alpha;
  const double scale = nvalid > 0 ? 2.0 / ((double)(nvalid - (m0 > 0.0f)) + vk * vk) : 0.0;
  float dots[BMFR_MAX_FEATURES + BMFR_CHANNELS];
  A[0] = (float)alpha;
  for (int j = 1; j < ncols; j++) {
    const int feature = j < count;
    const float *t = feature ? T + (size_t)j * ld : NULL;
    const float *u = feature ? noise + (size_t)j * ld : z[j - count];
    float mean = 0.0f;
    if (feature && nvalid < n && nvalid > 0) {
      /* keep the noise zero-mean over the rows that take part */
      double s = 0.0;
#pragma omp simd reduction(+ : s)
      for (int i = 0; i < n; i++) s += (double)(mask[i] * u[i]);
      mean = (float)(s / nvalid);
    }
    /* the column's row 0 as built, then v.a and c */
    const float a0 = fmaf(m0, u[0] - mean, t ? t[0] : 0.0f);
    const double va = vk * a0 + (sums[j] - (double)m0 * a0);
    const double c = va * scale;
    float *a = A + (size_t)j * ld;
    dots[j] = build_column(a, t, u, (float)(mean + c), mask, j == 1 ? NULL : A + ld, ld);
    a[0] = (float)(a0 - c * vk);
  }
  householder_r(A, ld, n, 1, count, ncols, dots);

  /* R alpha = r per channel (eq. 5). A pivot below the cut-off is a
   * direction the block does not determine: its weight is 0 (the feature
   * columns are at most 1 in magnitude, so a column norm is at most
   * sqrt(nvalid); the regularisation noise alone gives about
   * eps sqrt(nvalid / 3), far above the cut-off for the default eps). */
  const double tol = 1e-4 * sqrt((double)(nvalid > 0 ? nvalid : 1));
  r_factor R;
  r_factor_of(&R, A, ld, count, tol);
  double w[BMFR_CHANNELS][RW];
  /* rows of 8, 16 or 24 doubles: NV a constant in each */
  if (count <= RW / 3)
    solve(&R, A, ld, refine, G, h, RW / 3 / VD_LANES, w);
  else if (count <= 2 * RW / 3)
    solve(&R, A, ld, refine, G, h, 2 * RW / 3 / VD_LANES, w);
  else
    solve(&R, A, ld, refine, G, h, RW / VD_LANES, w);
  for (int c = 0; c < BMFR_CHANNELS; c++)
    for (int k = 0; k < count; k++) coef[c][k] = (float)w[c][k];
}

/* The weighted sum clamped below at 0, as the published code does
 * (radiance is not negative); > 0 also maps a NaN (impossible with finite
 * inputs) to 0. */
static inline vf positive(vf s) { return vf_select(s > (vf){0}, s, (vf){0}); }

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
    feature_sums(T, count, ld, i, k, 2, sums);
    for (int v = 0; v < 2; v++)
      for (int c = 0; c < BMFR_CHANNELS; c++)
        vf_store(y[c] + i + (size_t)v * VF_LANES, positive(sums[c][v]));
  }
  for (; i < ld; i += VF_LANES) {
    vf sums[BMFR_CHANNELS][2] = {{zero, zero}, {zero, zero}, {zero, zero}};
    feature_sums(T, count, ld, i, k, 1, sums);
    for (int c = 0; c < BMFR_CHANNELS; c++)
      vf_store(y[c] + i, positive(sums[c][0]));
  }
}

void hush__bmfr_synthesize_rows(const float *T, int count, size_t ld, int B,
                                const float coef[BMFR_CHANNELS][BMFR_MAX_FEATURES],
                                const float *mask, const float *const z[BMFR_CHANNELS], int r0,
                                int r1, float *const out[BMFR_CHANNELS], size_t stride) {
  const float *const k[BMFR_CHANNELS] = {coef[0], coef[1], coef[2]};
  const vf zero = {0};
  for (int r = r0; r < r1; r++)
    for (int x = 0; x < B; x += 2 * VF_LANES) {
      const size_t i = (size_t)r * (size_t)B + (size_t)x, o = (size_t)(r - r0) * stride + (size_t)x;
      vf sums[BMFR_CHANNELS][2] = {{zero, zero}, {zero, zero}, {zero, zero}};
      feature_sums(T, count, ld, i, k, 2, sums);
      for (int v = 0; v < 2; v++) {
        const size_t iv = i + (size_t)v * VF_LANES;
        const vi valid = vf_load(mask + iv) > zero;
        for (int c = 0; c < BMFR_CHANNELS; c++) {
          vf_store(out[c] + o + (size_t)v * VF_LANES,
                   vf_select(valid, positive(sums[c][v]), vf_load(z[c] + iv)));
        }
      }
    }
}
