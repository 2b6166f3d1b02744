/*
 * regression.c — BMFR's per-block fit: stochastic regularisation,
 * Householder QR of the augmented matrix computing only R, back
 * substitution, weighted sum (see regression.h; bmfr-koskela-2019.md
 * §3.3-3.4, Heath 1997 pp. 92-93 for solving from R alone).
 */
#include "filters/bmfr/regression.h"

#include "core/rng.h"

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

/* Independent partial sums of a dot product: one vector accumulator would
 * wait on the FMA latency every iteration; DOT_LANES lanes give the core
 * several chains to overlap (a fixed order, so still deterministic). */
#define DOT_LANES 32

/* sum_{i = k}^{n-1} a[i] b[i] */
static inline float dot_from(const float *restrict a, const float *restrict b, int k, int n) {
  float acc[DOT_LANES] = {0};
  int i = k;
  for (; i + DOT_LANES <= n; i += DOT_LANES)
    for (int l = 0; l < DOT_LANES; l++) acc[l] += a[i + l] * b[i + l];
  float s = 0.0f;
  for (; i < n; i++) s += a[i] * b[i];
  for (int w = DOT_LANES / 2; w > 0; w /= 2)
    for (int l = 0; l < w; l++) acc[l] += acc[l + w];
  return s + acc[0];
}

/* a[i] -= c x[i] for i = k..n-1 */
static inline void axpy_from(float *restrict a, const float *restrict x, float c, int k, int n) {
#pragma omp simd
  for (int i = k; i < n; i++) a[i] -= c * x[i];
}

/* a[i] -= c x[i] and returns sum y[i] a[i] (after the update), over
 * i = k..n-1: one step's update fused with the next step's dot product, so
 * each column is streamed once per step instead of twice. y == NULL means
 * y = a (the sum of squares). */
static HUSH_INLINE float axpy_dot_from(float *restrict a, const float *restrict x,
                                       const float *restrict y, float c, int k, int n) {
  float acc[DOT_LANES] = {0};
  int i = k;
  for (; i + DOT_LANES <= n; i += DOT_LANES)
    for (int l = 0; l < DOT_LANES; l++) {
      const float t = a[i + l] - c * x[i + l];
      a[i + l] = t;
      acc[l] += (y ? y[i + l] : t) * t;
    }
  float s = 0.0f;
  for (; i < n; i++) {
    a[i] -= c * x[i];
    s += (y ? y[i] : a[i]) * a[i];
  }
  for (int w = DOT_LANES / 2; w > 0; w /= 2)
    for (int l = 0; l < w; l++) acc[l] += acc[l + w];
  return s + acc[0];
}

/*
 * The first m Householder reflections of the n x ncols matrix A (columns of
 * ld floats), applied to all its columns; Q is never formed. Afterwards
 * rows 0..m-1 of columns k >= row hold R (and the right-hand sides r in
 * columns m..ncols-1). Below the diagonal, the columns keep the
 * reflection vectors' tails, which nothing reads.
 * Per step k, with x = A[k..n-1][k]: alpha = -sign(x_k) |x|, v = x - alpha
 * e_k, and every later column a gets a -= (2 v.a / v.v) v. The dot
 * products x.a below the pivot come from the previous step's update pass
 * (dots[j]; dots0, when not NULL, gives step 0's); column k + 1 is updated
 * first so the others can use it.
 */
static void householder_r(float *A, size_t ld, int n, int m, int ncols, const float *dots0) {
  float dots[BMFR_MAX_FEATURES + BMFR_CHANNELS]; /* sum_{i > k} x_i a_ij, this step */
  int have_dots = dots0 != NULL;
  if (have_dots) memcpy(dots, dots0, (size_t)ncols * sizeof *dots);
  for (int k = 0; k < m && k < n; k++) {
    float *restrict x = A + (size_t)k * ld;
    if (!have_dots)
      for (int j = k; j < ncols; j++) dots[j] = dot_from(x, A + (size_t)j * ld, k + 1, n);
    have_dots = 0;
    const float xk = x[k], sigma = dots[k];
    const float norm = sqrtf(xk * xk + sigma);
    if (!(norm > 0.0f)) continue; /* a zero column: R_kk = 0, nothing to reflect */
    const float alpha = xk > 0.0f ? -norm : norm;
    const float vk = xk - alpha; /* |vk| >= norm: no cancellation */
    const float scale = 2.0f / (sigma + vk * vk);
    if (k + 1 < ncols && k + 2 <= n) {
      /* column k + 1, then the others with the dots of step k + 1 */
      float *y = A + (size_t)(k + 1) * ld;
      for (int j = k + 1; j < ncols; j++) {
        float *a = A + (size_t)j * ld;
        const float c = (vk * a[k] + dots[j]) * scale;
        a[k] -= c * vk;
        a[k + 1] -= c * x[k + 1];
        dots[j] = j == k + 1 ? axpy_dot_from(a, x, NULL, c, k + 2, n)
                             : axpy_dot_from(a, x, y, c, k + 2, n);
      }
      have_dots = 1;
    } else {
      for (int j = k + 1; j < ncols; j++) {
        float *restrict a = A + (size_t)j * ld;
        const float c = (vk * a[k] + dots[j]) * scale;
        a[k] -= c * vk;
        axpy_from(a, x, c, k + 1, n);
      }
    }
    x[k] = alpha;
  }
}

/* Coefficients are capped here: with pivots above the cut-off they never
 * come near, and it keeps any sum of them times features in [-1, 1] finite. */
#define COEF_MAX 1e18

static inline double clamp_coef(double v) {
  v = v > COEF_MAX ? COEF_MAX : v < -COEF_MAX ? -COEF_MAX : v;
  return v == v ? v : 0.0;
}

/* R_kj of the factorised A (upper triangle, rows 0..count-1). */
#define R_AT(A, ld, k, j) ((double)(A)[(size_t)(j) * (ld) + (k)])

/* x = R^-1 b by back substitution; a pivot at or below tol gives 0. */
static void back_substitute(const float *A, size_t ld, int count, double tol, const double *b,
                            double *x) {
  for (int k = count - 1; k >= 0; k--) {
    double s = b[k];
    for (int j = k + 1; j < count; j++) s -= R_AT(A, ld, k, j) * x[j];
    const double rkk = R_AT(A, ld, k, k);
    x[k] = clamp_coef(fabs(rkk) > tol ? s / rkk : 0.0);
  }
}

/* x = R^-T b by forward substitution; a pivot at or below tol gives 0. */
static void forward_substitute(const float *A, size_t ld, int count, double tol,
                               const double *b, double *x) {
  for (int k = 0; k < count; k++) {
    double s = b[k];
    for (int j = 0; j < k; j++) s -= R_AT(A, ld, j, k) * x[j];
    const double rkk = R_AT(A, ld, k, k);
    x[k] = clamp_coef(fabs(rkk) > tol ? s / rkk : 0.0);
  }
}

void hush__bmfr_fit(const float *T, int count, const float *const z[BMFR_CHANNELS],
                    const float *noise, const float *mask, int n, int nvalid, size_t ld, float *A,
                    int refine, float *scratch, float coef[BMFR_CHANNELS][BMFR_MAX_FEATURES]) {
  /* A = [T + N, z] (eq. 7), holes zero in every column; while each column
   * is written, its dot product with column 0 below row 0 (the first
   * reflection's) is taken, which saves the QR a pass per column */
  float dots0[BMFR_MAX_FEATURES + BMFR_CHANNELS];
  const float *restrict x0 = T; /* column 0: the mask */
  memcpy(A, T, ld * sizeof *A);
  dots0[0] = dot_from(x0, x0, 1, n);
  for (int m = 1; m < count; m++) {
    const float *restrict t = T + (size_t)m * ld, *restrict nz = noise + (size_t)m * ld;
    float *restrict a = A + (size_t)m * ld;
    float mean = 0.0f;
    if (nvalid < n && nvalid > 0) {
      /* keep the noise zero-mean over the rows that take part */
      double s = 0.0;
      for (int i = 0; i < n; i++) s += (double)(mask[i] * nz[i]);
      mean = (float)(s / nvalid);
    }
#pragma omp simd
    for (size_t i = 0; i < ld; i++) a[i] = t[i] + mask[i] * (nz[i] - mean);
    dots0[m] = dot_from(x0, a, 1, n);
  }
  for (int c = 0; c < BMFR_CHANNELS; c++) {
    const float *restrict zc = z[c];
    float *restrict a = A + (size_t)(count + c) * ld;
#pragma omp simd
    for (int i = 0; i < n; i++) a[i] = zc[i] * mask[i];
    for (size_t i = (size_t)n; i < ld; i++) a[i] = 0.0f;
    dots0[count + c] = dot_from(x0, a, 1, n);
  }

  householder_r(A, ld, n, count, count + BMFR_CHANNELS, dots0);

  /* R alpha = r per channel (eq. 5). A pivot below the cut-off is a
   * direction the block does not determine: its weight is 0 (the feature
   * columns are at most 1 in magnitude, so a column norm is at most
   * sqrt(nvalid); the regularisation noise alone gives about
   * eps sqrt(nvalid / 3), far above the cut-off for the default eps). */
  const double tol = 1e-4 * sqrt((double)(nvalid > 0 ? nvalid : 1));
  double w[BMFR_CHANNELS][BMFR_MAX_FEATURES];
  for (int c = 0; c < BMFR_CHANNELS; c++) {
    double r[BMFR_MAX_FEATURES];
    for (int k = 0; k < count; k++) r[k] = A[(size_t)(count + c) * ld + k];
    back_substitute(A, ld, count, tol, r, w[c]);
  }

  /* Refinement towards eq. 2's solution on the noise-free features: the
   * noise that keeps the factorisation stable also perturbs the weights
   * (errors in the variables, about eps / sqrt(n) of each). One step of
   * a += (R^T R)^-1 T^T (z - T a) with the noisy R as the preconditioner
   * removes that to first order; in the directions the noise regularises
   * (near-collinear features), R^T R is dominated by the noise and the
   * step stays small, so the regularisation keeps its effect there. */
  for (int it = 0; it < refine; it++) {
    /* residuals of the three channels, then their dots with each feature */
    float *restrict r0 = scratch, *restrict r1 = scratch + ld, *restrict r2 = scratch + 2 * ld;
    const float *restrict z0 = z[0], *restrict z1 = z[1], *restrict z2 = z[2];
#pragma omp simd
    for (int i = 0; i < n; i++) {
      r0[i] = z0[i] * mask[i];
      r1[i] = z1[i] * mask[i];
      r2[i] = z2[i] * mask[i];
    }
    for (int m = 0; m < count; m++) {
      const float *restrict t = T + (size_t)m * ld;
      const float a0 = (float)w[0][m], a1 = (float)w[1][m], a2 = (float)w[2][m];
#pragma omp simd
      for (int i = 0; i < n; i++) {
        r0[i] -= a0 * t[i];
        r1[i] -= a1 * t[i];
        r2[i] -= a2 * t[i];
      }
    }
    double g[BMFR_CHANNELS][BMFR_MAX_FEATURES];
    for (int m = 0; m < count; m++) {
      const float *t = T + (size_t)m * ld;
      g[0][m] = dot_from(t, r0, 0, n);
      g[1][m] = dot_from(t, r1, 0, n);
      g[2][m] = dot_from(t, r2, 0, n);
    }
    for (int c = 0; c < BMFR_CHANNELS; c++) {
      double u[BMFR_MAX_FEATURES], d[BMFR_MAX_FEATURES];
      forward_substitute(A, ld, count, tol, g[c], u);
      back_substitute(A, ld, count, tol, u, d);
      for (int m = 0; m < count; m++) w[c][m] = clamp_coef(w[c][m] + d[m]);
    }
  }
  for (int c = 0; c < BMFR_CHANNELS; c++)
    for (int k = 0; k < count; k++) coef[c][k] = (float)w[c][k];
}

void hush__bmfr_synthesize(const float *T, int count, int n, size_t ld,
                           const float coef[BMFR_CHANNELS][BMFR_MAX_FEATURES],
                           float *const y[BMFR_CHANNELS]) {
  float *restrict y0 = y[0], *restrict y1 = y[1], *restrict y2 = y[2];
  for (int i = 0; i < n; i++) y0[i] = y1[i] = y2[i] = 0.0f;
  for (int m = 0; m < count; m++) {
    const float *restrict t = T + (size_t)m * ld;
    const float c0 = coef[0][m], c1 = coef[1][m], c2 = coef[2][m];
#pragma omp simd
    for (int i = 0; i < n; i++) {
      y0[i] += c0 * t[i];
      y1[i] += c1 * t[i];
      y2[i] += c2 * t[i];
    }
  }
  /* > 0 also maps a NaN (impossible with finite inputs) to 0 */
#pragma omp simd
  for (int i = 0; i < n; i++) {
    y0[i] = y0[i] > 0.0f ? y0[i] : 0.0f;
    y1[i] = y1[i] > 0.0f ? y1[i] : 0.0f;
    y2[i] = y2[i] > 0.0f ? y2[i] : 0.0f;
  }
}
