/*
 * test_bmfr.c — the "bmfr" filter (bmfr-koskela-2019.md): the block fit on
 * its own (src/filters/bmfr/regression.h, features.h, blocks.h) and the
 * whole pipeline through the public API, on synthetic G-buffers seen by a
 * static camera; temporal_gradients (adaptive BMFR): off is plain bmfr even
 * with a gradient bound, an all-zero gradient changes no bit, a gradient
 * of lambda 1 everywhere makes every frame a first frame (no history), and
 * the option without the image is an error naming it.
 */
#include "hush.h"

#include "check.h"
#include "core/hmath.h"
#include "core/image.h"
#include "filters/bmfr/blocks.h"
#include "filters/bmfr/features.h"
#include "filters/bmfr/regression.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Not multiples of 32: the grid has partial, mirrored blocks. */
#define W 80
#define H 56
#define N (W * H)

static uint32_t rng_state = 12345u;
static float rnd(void) { /* uniform in [0, 1), xorshift32 */
  rng_state ^= rng_state << 13;
  rng_state ^= rng_state >> 17;
  rng_state ^= rng_state << 5;
  return (float)(rng_state >> 8) / 16777216.0f;
}

/* ---- the block fit on its own ------------------------------------------------ */

#define BS 32
#define BN (BS * BS)

typedef struct block {
  float base[BMFR_BASE_COUNT * BN];
  float mask[BN];
  float T[BMFR_MAX_FEATURES * BN];
  float A[(BMFR_MAX_FEATURES + BMFR_CHANNELS) * BN];
  float noise[BMFR_MAX_FEATURES * BN];
  float z[BMFR_CHANNELS][BN];
  float y[BMFR_CHANNELS][BN];
  float scratch[BN];
} block;

static void default_set(bmfr_feature_set *set) {
  const float e[BMFR_SRC_COUNT][2] = {{1, 0}, {1, 2}, {0, 0}, {0, 0}};
  hush__bmfr_features_build(set, e, 0);
}

/* Fits b->z with the set (the noise table of `frame`, amplitude eps) into b->y. */
static void fit_refined(block *b, const bmfr_feature_set *set, uint64_t frame, float eps,
                        int refine) {
  int nvalid = 0;
  for (int i = 0; i < BN; i++) nvalid += b->mask[i] > 0.5f;
  float coef[BMFR_CHANNELS][BMFR_MAX_FEATURES];
  const float *z[BMFR_CHANNELS] = {b->z[0], b->z[1], b->z[2]};
  float *y[BMFR_CHANNELS] = {b->y[0], b->y[1], b->y[2]};
  hush__bmfr_noise_table(b->noise, set->count, BN, BN, frame, eps);
  hush__bmfr_features_block(set, b->base, b->mask, BN, BN, b->T, b->scratch);
  hush__bmfr_fit(b->T, set->count, z, b->noise, b->mask, BN, nvalid, BN, b->A, refine, coef);
  hush__bmfr_synthesize(b->T, set->count, BN, BN, (const float(*)[BMFR_MAX_FEATURES])coef, y);
}

/* With the filter's default refinement (bmfr.c's table: refine 2). */
static void fit(block *b, const bmfr_feature_set *set, uint64_t frame, float eps) {
  fit_refined(b, set, frame, eps, 2);
}

/* A curved surface in world units far from the origin (positions of about
 * 100, so w^2 would be nearly collinear with w unless scaled first), with a
 * bumpy normal map. The normals vary independently of the positions: a
 * feature that is, within a block, a combination of the others up to the
 * noise level (say a normal that is a quadratic in the position) is
 * regularised by design (§3.4) and not reproduced exactly. */
static void busy_block(block *b) {
  rng_state = 31337u;
  for (int i = 0; i < BN; i++) {
    const float u = (float)(i % BS) / BS, v = (float)(i / BS) / BS;
    hush_vec3 n = hush_v3_normalize(hush_v3(0.4f * (rnd() - 0.5f), 0.4f * (rnd() - 0.5f), 1.0f));
    b->base[(BMFR_BASE_NORMAL + 0) * BN + i] = n.x;
    b->base[(BMFR_BASE_NORMAL + 1) * BN + i] = n.y;
    b->base[(BMFR_BASE_NORMAL + 2) * BN + i] = n.z;
    b->base[(BMFR_BASE_POSITION + 0) * BN + i] = 100.0f + 2.0f * u + 0.1f * v * v;
    b->base[(BMFR_BASE_POSITION + 1) * BN + i] = -50.0f + 1.5f * v;
    b->base[(BMFR_BASE_POSITION + 2) * BN + i] = 20.0f + 0.3f * sinf(4 * u + v);
    b->mask[i] = 1.0f;
  }
}

/* The radiance an exact linear combination of [1, n, w, w^2]. */
static float exact_radiance(const block *b, int c, int i) {
  const float *nb = b->base + BMFR_BASE_NORMAL * BN, *wb = b->base + BMFR_BASE_POSITION * BN;
  const float nx = nb[i], ny = nb[BN + i], nz = nb[2 * BN + i];
  const float wx = wb[i] - 100.0f, wy = wb[BN + i] + 50.0f, wz = wb[2 * BN + i] - 20.0f;
  const float k = 1.0f + 0.5f * (float)c;
  return 1.0f + k * (0.3f * nx - 0.2f * ny + 0.1f * nz + 0.4f * wx + 0.1f * wy - 0.2f * wz +
                     0.05f * wx * wx + 0.1f * wy * wy + 0.3f * wz * wz);
}

static void test_exact_block(void) {
  static block b;
  bmfr_feature_set set;
  default_set(&set);
  CHECK(set.count == 10);
  busy_block(&b);
  for (int c = 0; c < 3; c++)
    for (int i = 0; i < BN; i++) b.z[c][i] = exact_radiance(&b, c, i);
  fit(&b, &set, 7, 0.01f);
  double worst = 0.0;
  for (int c = 0; c < 3; c++)
    for (int i = 0; i < BN; i++) {
      const double e = fabs(b.y[c][i] - b.z[c][i]) / fabs(b.z[c][i]);
      worst = e > worst ? e : worst;
    }
  CHECK_MSG(worst <= 1e-3, "exact fit: worst relative error %g", worst);
}

/* Constant normal and position: every feature but the constant is flat, so
 * the fit is the block mean (the noise columns are zero-mean). */
static void test_rank_deficient_block(void) {
  static block b;
  bmfr_feature_set set;
  default_set(&set);
  busy_block(&b);
  for (int k = 0; k < 6; k++)
    for (int i = 0; i < BN; i++) b.base[k * BN + i] = k == 2 ? 1.0f : 3.0f + (float)k;
  rng_state = 99u;
  double mean[3] = {0, 0, 0};
  for (int c = 0; c < 3; c++) {
    for (int i = 0; i < BN; i++) {
      b.z[c][i] = (float)(c + 1) * rnd();
      mean[c] += b.z[c][i];
    }
    mean[c] /= BN;
  }
  fit(&b, &set, 3, 0.01f);
  double worst = 0.0;
  for (int c = 0; c < 3; c++)
    for (int i = 0; i < BN; i++) {
      const double e = fabs(b.y[c][i] - mean[c]) / mean[c];
      worst = e > worst ? e : worst;
    }
  CHECK_MSG(worst <= 1e-4, "rank-deficient block: worst relative distance to the mean %g", worst);

  /* without the noise the flat features have zero pivots: the same */
  fit(&b, &set, 3, 0.0f);
  worst = 0.0;
  for (int c = 0; c < 3; c++)
    for (int i = 0; i < BN; i++) {
      const double e = fabs(b.y[c][i] - mean[c]) / mean[c];
      worst = e > worst ? e : worst;
    }
  CHECK_MSG(worst <= 1e-4, "no noise: worst relative distance to the mean %g", worst);

  /* two identical features (normal x == position x up to scale): rank
   * deficient, cured by the noise, and the fit stays finite and close */
  busy_block(&b);
  for (int i = 0; i < BN; i++)
    b.base[(BMFR_BASE_POSITION + 0) * BN + i] = 5.0f * b.base[BMFR_BASE_NORMAL * BN + i];
  for (int c = 0; c < 3; c++)
    for (int i = 0; i < BN; i++) b.z[c][i] = exact_radiance(&b, c, i);
  fit(&b, &set, 4, 0.01f);
  int finite = 1;
  double worst_abs = 0.0;
  for (int c = 0; c < 3; c++)
    for (int i = 0; i < BN; i++) {
      finite &= isfinite(b.y[c][i]);
      const double e = fabs(b.y[c][i] - b.z[c][i]);
      worst_abs = e > worst_abs ? e : worst_abs;
    }
  CHECK(finite);
  CHECK_MSG(worst_abs <= 1e-2, "collinear features: worst error %g", worst_abs);
}

/* Holes: an all-hole block fits nothing (all zero, finite); a block with a
 * few valid pixels stays finite; black radiance gives black. */
static void test_holes_block(void) {
  static block b;
  bmfr_feature_set set;
  default_set(&set);
  busy_block(&b);
  for (int i = 0; i < BN; i++) b.mask[i] = 0.0f;
  for (int c = 0; c < 3; c++)
    for (int i = 0; i < BN; i++) b.z[c][i] = 1.0f;
  fit(&b, &set, 1, 0.01f);
  int ok = 1;
  for (int c = 0; c < 3; c++)
    for (int i = 0; i < BN; i++) ok &= b.y[c][i] == 0.0f;
  CHECK(ok);

  for (int valid = 1; valid <= 12; valid++) {
    for (int i = 0; i < BN; i++) b.mask[i] = i % 97 == 0 && i / 97 < valid ? 1.0f : 0.0f;
    fit(&b, &set, (uint64_t)valid, 0.01f);
    ok = 1;
    for (int c = 0; c < 3; c++)
      for (int i = 0; i < BN; i++) ok &= isfinite(b.y[c][i]) && b.y[c][i] >= 0.0f;
    CHECK_MSG(ok, "%d valid pixels", valid);
  }

  busy_block(&b);
  for (int c = 0; c < 3; c++)
    for (int i = 0; i < BN; i++) b.z[c][i] = 0.0f;
  fit(&b, &set, 2, 0.01f);
  ok = 1;
  for (int c = 0; c < 3; c++)
    for (int i = 0; i < BN; i++) ok &= b.y[c][i] == 0.0f;
  CHECK(ok);
}

/* A non-integer exponent and the optional sources build and fit finitely. */
static void test_feature_sets(void) {
  bmfr_feature_set set;
  const float e[BMFR_SRC_COUNT][2] = {{1, 0.5f}, {1, 2}, {1.5f, 0}, {1, 0}};
  hush__bmfr_features_build(&set, e, 1);
  CHECK(set.count == 1 + 6 + 6 + 1 + 3 + 2);
  CHECK(set.needs == 15u && set.gradients);
  static block b;
  busy_block(&b);
  for (int i = 0; i < BN; i++) {
    b.base[BMFR_BASE_DEPTH * BN + i] = 4.0f + (float)(i % 7);
    for (int c = 0; c < 3; c++) b.base[(BMFR_BASE_ALBEDO + c) * BN + i] = 0.2f * (float)c;
    b.base[BMFR_BASE_GRADIENT * BN + i] = (float)(i % BS);
    b.base[(BMFR_BASE_GRADIENT + 1) * BN + i] = (float)(i / BS);
  }
  for (int c = 0; c < 3; c++)
    for (int i = 0; i < BN; i++) b.z[c][i] = exact_radiance(&b, c, i);
  fit(&b, &set, 5, 0.01f);
  int ok = 1;
  for (int m = 0; m < set.count; m++)
    for (int i = 0; i < BN; i++) ok &= b.T[m * BN + i] >= -1.0f && b.T[m * BN + i] <= 1.0f;
  CHECK(ok); /* every feature scaled to [-1, 1] */
  double worst = 0.0;
  for (int c = 0; c < 3; c++)
    for (int i = 0; i < BN; i++) {
      const double err = fabs(b.y[c][i] - b.z[c][i]) / fabs(b.z[c][i]);
      worst = err > worst ? err : worst;
    }
  CHECK_MSG(worst <= 1e-3, "larger set: worst relative error %g", worst);
}

/* x = G^-1 b for a symmetric positive definite m x m G (Cholesky, double). */
static void spd_solve(const double *G, int m, const double *b, double *x) {
  double L[BMFR_MAX_FEATURES * BMFR_MAX_FEATURES], y[BMFR_MAX_FEATURES];
  for (int i = 0; i < m; i++)
    for (int j = 0; j <= i; j++) {
      double s = G[i * m + j];
      for (int k = 0; k < j; k++) s -= L[i * m + k] * L[j * m + k];
      L[i * m + j] = i == j ? sqrt(s) : s / L[j * m + j];
    }
  for (int i = 0; i < m; i++) {
    double s = b[i];
    for (int k = 0; k < i; k++) s -= L[i * m + k] * y[k];
    y[i] = s / L[i * m + i];
  }
  for (int i = m - 1; i >= 0; i--) {
    double s = y[i];
    for (int k = i + 1; k < m; k++) s -= L[k * m + i] * x[k];
    x[i] = s / L[i * m + i];
  }
}

/* The zeroed columns (ld floats each) of one block's fit: the base
 * channels, mask, features, noise, augmented matrix, radiance, fit and
 * scratch, in one struct so that each test allocates and frees them once. */
typedef struct fit_bufs {
  float *base, *mask, *T, *noise, *A, *z, *y, *scratch;
} fit_bufs;

static void fit_bufs_alloc(fit_bufs *b, size_t ld) {
  b->base = calloc(BMFR_BASE_COUNT * ld, sizeof(float));
  b->mask = calloc(ld, sizeof(float));
  b->T = calloc(BMFR_MAX_FEATURES * ld, sizeof(float));
  b->noise = calloc(BMFR_MAX_FEATURES * ld, sizeof(float));
  b->A = calloc((BMFR_MAX_FEATURES + BMFR_CHANNELS) * ld, sizeof(float));
  b->z = calloc(BMFR_CHANNELS * ld, sizeof(float));
  b->y = calloc(BMFR_CHANNELS * ld, sizeof(float));
  b->scratch = calloc(3 * ld, sizeof(float));
  REQUIRE(b->base && b->mask && b->T && b->noise && b->A && b->z && b->y && b->scratch);
}

static void fit_bufs_free(fit_bufs *b) {
  free(b->base), free(b->mask), free(b->T), free(b->noise);
  free(b->A), free(b->z), free(b->y), free(b->scratch);
}

/*
 * The block fit (vectorised Householder on R only, FMA, refinement) against
 * its definition solved in double: the least-squares weights of the
 * regularised features [T + N] (eq. 7; R^T R = (T + N)^T (T + N), so the
 * normal equations give the same weights as R alpha = r), refined by
 * alpha += ((T + N)^T (T + N))^-1 T^T (z - T alpha), and y = max(T alpha, 0).
 * Noisy radiance (a real residual), blocks of 32x32 and 17x17 (n not a
 * multiple of the vector width, ld padded), with and without holes,
 * refine 0, 1 and 2 (the default).
 */
static void test_fit_reference(void) {
  bmfr_feature_set set;
  default_set(&set);
  const int M = set.count;
  for (int cfg = 0; cfg < 12; cfg++) {
    const int B = cfg < 6 ? 32 : 17, n = B * B, holes = cfg % 2, refine = (cfg / 2) % 3;
    const size_t ld = ((size_t)n + 15) & ~(size_t)15;
    fit_bufs fb;
    fit_bufs_alloc(&fb, ld);
    float *base = fb.base, *mask = fb.mask, *T = fb.T, *noise = fb.noise, *A = fb.A, *z = fb.z,
          *y = fb.y, *scratch = fb.scratch;
    rng_state = 777u + (uint32_t)cfg;
    int nvalid = 0;
    for (int i = 0; i < n; i++) {
      const float u = (float)(i % B) / B, v = (float)(i / B) / B;
      hush_vec3 nn = hush_v3_normalize(hush_v3(0.4f * (rnd() - 0.5f), 0.4f * (rnd() - 0.5f), 1));
      base[(BMFR_BASE_NORMAL + 0) * ld + i] = nn.x;
      base[(BMFR_BASE_NORMAL + 1) * ld + i] = nn.y;
      base[(BMFR_BASE_NORMAL + 2) * ld + i] = nn.z;
      base[(BMFR_BASE_POSITION + 0) * ld + i] = 10.0f + 2.0f * u + 0.1f * v * v;
      base[(BMFR_BASE_POSITION + 1) * ld + i] = -5.0f + 1.5f * v;
      base[(BMFR_BASE_POSITION + 2) * ld + i] = 2.0f + 0.3f * sinf(4 * u + v);
      mask[i] = holes && rnd() < 0.3f ? 0.0f : 1.0f;
      nvalid += mask[i] > 0.0f;
      for (int c = 0; c < 3; c++) z[c * ld + i] = (0.5f + u * v + 0.2f * (float)c) * (0.5f + rnd());
    }
    const float *zc[3] = {z, z + ld, z + 2 * ld};
    float *yc[3] = {y, y + ld, y + 2 * ld};
    float coef[BMFR_CHANNELS][BMFR_MAX_FEATURES];
    hush__bmfr_noise_table(noise, M, n, ld, 11, 0.01f);
    hush__bmfr_features_block(&set, base, mask, n, ld, T, scratch);
    hush__bmfr_fit(T, M, zc, noise, mask, n, nvalid, ld, A, refine, coef);
    hush__bmfr_synthesize(T, M, n, ld, (const float(*)[BMFR_MAX_FEATURES])coef, yc);

    /* the definition, in double */
    static double Ad[BMFR_MAX_FEATURES][64 * 64];
    double G[BMFR_MAX_FEATURES * BMFR_MAX_FEATURES];
    for (int m = 0; m < M; m++) {
      double mean = 0.0;
      if (m > 0 && nvalid < n) {
        for (int i = 0; i < n; i++) mean += (double)(mask[i] * noise[m * ld + i]);
        mean /= nvalid;
      }
      for (int i = 0; i < n; i++)
        Ad[m][i] = T[m * ld + i] + (m > 0 ? mask[i] * (noise[m * ld + i] - mean) : 0.0);
    }
    for (int a = 0; a < M; a++)
      for (int b = 0; b < M; b++) {
        double sum = 0.0;
        for (int i = 0; i < n; i++) sum += Ad[a][i] * Ad[b][i];
        G[a * M + b] = sum;
      }
    double worst = 0.0, zmax = 0.0;
    for (int c = 0; c < 3; c++) {
      double rhs[BMFR_MAX_FEATURES], alpha[BMFR_MAX_FEATURES];
      for (int m = 0; m < M; m++) {
        double sum = 0.0;
        for (int i = 0; i < n; i++) sum += Ad[m][i] * mask[i] * z[c * ld + i];
        rhs[m] = sum;
      }
      spd_solve(G, M, rhs, alpha);
      for (int it = 0; it < refine; it++) {
        double g[BMFR_MAX_FEATURES], d[BMFR_MAX_FEATURES];
        for (int m = 0; m < M; m++) g[m] = 0.0;
        for (int i = 0; i < n; i++) {
          double r = mask[i] * z[c * ld + i];
          for (int m = 0; m < M; m++) r -= alpha[m] * T[m * ld + i];
          for (int m = 0; m < M; m++) g[m] += T[m * ld + i] * r;
        }
        spd_solve(G, M, g, d);
        /* kept only if it lowers the residual */
        double before = 0.0, after = 0.0;
        for (int i = 0; i < n; i++) {
          double r0 = mask[i] * z[c * ld + i], r1 = r0;
          for (int m = 0; m < M; m++) {
            r0 -= alpha[m] * T[m * ld + i];
            r1 -= (alpha[m] + d[m]) * T[m * ld + i];
          }
          before += r0 * r0;
          after += r1 * r1;
        }
        if (!(after < before)) break;
        for (int m = 0; m < M; m++) alpha[m] += d[m];
      }
      for (int i = 0; i < n; i++) {
        double e = 0.0;
        for (int m = 0; m < M; m++) e += alpha[m] * T[m * ld + i];
        e = e > 0.0 ? e : 0.0;
        worst = fmax(worst, fabs(e - yc[c][i]));
        zmax = fmax(zmax, fabs(z[c * ld + i]));
      }
    }
    /* float rounding: about 2e-7 of max z measured, before and after the
     * vectorised kernels */
    CHECK_MSG(worst <= 4e-6 * zmax, "B %d holes %d refine %d: worst |y - y_ref| %g of max z %g",
              B, holes, refine, worst, zmax);
    fit_bufs_free(&fb);
  }
}

/* The fit of one 32x32 block laid out with column stride ld (rows 1024..ld-1
 * of the inputs zero, as bmfr.c leaves them): coef and the fitted rows. */
static void fit_with_ld(size_t ld, int refine, float coef[BMFR_CHANNELS][BMFR_MAX_FEATURES],
                        float *y_out) {
  bmfr_feature_set set;
  default_set(&set);
  const int M = set.count, n = 32 * 32;
  fit_bufs fb;
  fit_bufs_alloc(&fb, ld);
  float *base = fb.base, *mask = fb.mask, *T = fb.T, *noise = fb.noise, *A = fb.A, *z = fb.z,
        *y = fb.y, *scratch = fb.scratch;
  rng_state = 4242u;
  int nvalid = 0;
  for (int i = 0; i < n; i++) {
    const float u = (float)(i % 32) / 32, v = (float)(i / 32) / 32;
    for (int c = 0; c < 3; c++) {
      base[(BMFR_BASE_NORMAL + c) * ld + i] = rnd() - 0.5f;
      base[(BMFR_BASE_POSITION + c) * ld + i] = (float)c + u * (1.0f + (float)c) - v * v;
    }
    mask[i] = rnd() < 0.2f ? 0.0f : 1.0f;
    nvalid += mask[i] > 0.0f;
    for (int c = 0; c < 3; c++) z[c * ld + i] = (0.5f + u * v + 0.2f * (float)c) * (0.5f + rnd());
  }
  const float *zc[3] = {z, z + ld, z + 2 * ld};
  float *yc[3] = {y, y + ld, y + 2 * ld};
  hush__bmfr_noise_table(noise, M, n, ld, 5, 0.01f);
  hush__bmfr_features_block(&set, base, mask, n, ld, T, scratch);
  hush__bmfr_fit(T, M, zc, noise, mask, n, nvalid, ld, A, refine, coef);
  hush__bmfr_synthesize(T, M, n, ld, (const float(*)[BMFR_MAX_FEATURES])coef, yc);
  for (int c = 0; c < 3; c++) memcpy(y_out + c * n, yc[c], (size_t)n * sizeof *y_out);
  fit_bufs_free(&fb);
}

/*
 * A block with only a few valid pixels (an object's corner against the
 * sky): with about as many pixels as features, the refinement's iteration
 * can diverge (the noise's cross terms in R^T R), which gave weights of
 * 1e4 to 1e12 and fitted values hundreds of times the radiance. A step is
 * kept only when it lowers the residual, so the refined fit is never
 * further from the data than the plain solve (up to rounding), and stays
 * in its range.
 */
static void test_few_valid_block(void) {
  bmfr_feature_set set;
  default_set(&set);
  const int M = set.count, n = 32 * 32;
  const size_t ld = 1040;
  const int counts[] = {3, 6, 9, 10, 12, 16, 20, 40};
  for (size_t t = 0; t < sizeof counts / sizeof *counts; t++) {
    fit_bufs fb;
    fit_bufs_alloc(&fb, ld);
    rng_state = 31u + (uint32_t)t;
    int nvalid = 0;
    for (int i = 0; i < n; i++) {
      const float u = (float)(i % 32) / 32, v = (float)(i / 32) / 32;
      hush_vec3 nn = hush_v3_normalize(hush_v3(rnd() - 0.5f, rnd() - 0.5f, 1));
      fb.base[(BMFR_BASE_NORMAL + 0) * ld + i] = nn.x;
      fb.base[(BMFR_BASE_NORMAL + 1) * ld + i] = nn.y;
      fb.base[(BMFR_BASE_NORMAL + 2) * ld + i] = nn.z;
      fb.base[(BMFR_BASE_POSITION + 0) * ld + i] = 3.0f + u;
      fb.base[(BMFR_BASE_POSITION + 1) * ld + i] = 1.0f - v + 0.2f * u * u;
      fb.base[(BMFR_BASE_POSITION + 2) * ld + i] = 0.5f * sinf(3 * u + 2 * v);
      /* the valid pixels in the block's top-left corner, 6 a row */
      const int valid = i % 32 < 6 && (i / 32) * 6 + i % 32 < counts[t];
      fb.mask[i] = valid ? 1.0f : 0.0f;
      nvalid += valid;
      for (int c = 0; c < 3; c++) fb.z[c * ld + i] = valid ? (0.6f + 0.1f * (float)c) * (0.5f + rnd()) : 0.0f;
    }
    REQUIRE(nvalid == counts[t]);
    const float *zc[3] = {fb.z, fb.z + ld, fb.z + 2 * ld};
    float *yc[3] = {fb.y, fb.y + ld, fb.y + 2 * ld};
    hush__bmfr_noise_table(fb.noise, M, n, ld, 3, 0.01f);
    hush__bmfr_features_block(&set, fb.base, fb.mask, n, ld, fb.T, fb.scratch);
    double residual[3] = {0, 0, 0}, ymax = 0.0, zmax = 0.0;
    for (int refine = 0; refine <= 2; refine += 2) {
      float coef[BMFR_CHANNELS][BMFR_MAX_FEATURES];
      hush__bmfr_fit(fb.T, M, zc, fb.noise, fb.mask, n, nvalid, ld, fb.A, refine, coef);
      hush__bmfr_synthesize(fb.T, M, n, ld, (const float(*)[BMFR_MAX_FEATURES])coef, yc);
      for (int c = 0; c < 3; c++) {
        double r = 0.0;
        for (int i = 0; i < n; i++)
          if (fb.mask[i] > 0.0f) {
            const double e = (double)yc[c][i] - zc[c][i];
            r += e * e;
            zmax = fmax(zmax, zc[c][i]);
            if (refine) ymax = fmax(ymax, yc[c][i]);
          }
        if (!refine)
          residual[c] = r;
        else
          /* (the step's test uses the Gram's float sums: near singular
           * blocks may keep a step that changes the residual by its
           * rounding, 2e-4 of it with clang -O1 -ffp-contract=off; the
           * divergence this guards against multiplied it by up to 1e10) */
          CHECK_MSG(r <= residual[c] * 1.01 + 1e-9,
                    "%d valid pixels, channel %d: residual %g refined, %g plain", nvalid, c, r,
                    residual[c]);
      }
    }
    CHECK_MSG(ymax <= 4.0 * zmax, "%d valid pixels: fitted up to %g, radiance up to %g", nvalid,
              ymax, zmax);
    fit_bufs_free(&fb);
  }
}

/* bmfr.c pads the block's column stride past a multiple of 1 KiB (4K
 * aliasing): the zero rows it adds must not change a bit of the fit. */
static void test_fit_padded_ld(void) {
  for (int refine = 0; refine <= 2; refine++) {
    float c0[BMFR_CHANNELS][BMFR_MAX_FEATURES], c1[BMFR_CHANNELS][BMFR_MAX_FEATURES];
    static float y0[3 * 1024], y1[3 * 1024];
    memset(c0, 0, sizeof c0);
    memset(c1, 0, sizeof c1);
    fit_with_ld(1024, refine, c0, y0);
    for (size_t ld = 1040; ld <= 1072; ld += 16) {
      fit_with_ld(ld, refine, c1, y1);
      CHECK_MSG(memcmp(c0, c1, sizeof c0) == 0, "refine %d: weights differ with ld %zu", refine, ld);
      CHECK_MSG(memcmp(y0, y1, sizeof y0) == 0, "refine %d: fit differs with ld %zu", refine, ld);
    }
  }
}

/* 16 distinct offsets in [0, B)^2, period 16, for every block size. */
static void test_offsets(void) {
  for (int B = 16; B <= 64; B += 8) {
    int seen[64][64];
    memset(seen, 0, sizeof seen);
    int distinct = 0, in_range = 1, periodic = 1;
    for (uint64_t f = 0; f < 16; f++) {
      int ox, oy, px, py;
      hush__bmfr_block_offset(f, B, 1, &ox, &oy);
      hush__bmfr_block_offset(f + 16 * 1000003ull, B, 1, &px, &py);
      periodic &= ox == px && oy == py;
      in_range &= ox >= 0 && ox < B && oy >= 0 && oy < B;
      if (in_range && !seen[oy][ox]++) distinct++;
    }
    CHECK_MSG(distinct == 16 && in_range && periodic, "B = %d: %d distinct offsets", B, distinct);
    /* consecutive frames are at least a quarter block apart in x or y */
    int ox0, oy0, ox1, oy1;
    hush__bmfr_block_offset(0, B, 1, &ox0, &oy0);
    hush__bmfr_block_offset(1, B, 1, &ox1, &oy1);
    CHECK(abs(ox1 - ox0) >= B / 4 || abs(oy1 - oy0) >= B / 4);
  }
  int ox, oy;
  hush__bmfr_block_offset(5, 32, 0, &ox, &oy);
  CHECK(ox == 0 && oy == 0);
  /* the grid covers the image, and mirroring stays inside it */
  bmfr_grid g;
  hush__bmfr_grid(&g, W, H, 32, 12, 28);
  CHECK(g.x0 <= 0 && g.x0 + g.nx * 32 >= W && g.x0 + 32 > 0 && g.x0 + (g.nx - 1) * 32 < W);
  CHECK(g.y0 <= 0 && g.y0 + g.ny * 32 >= H && g.y0 + 32 > 0 && g.y0 + (g.ny - 1) * 32 < H);
  int ok = 1;
  for (int x = -200; x < 200; x++) {
    const int m = hush__bmfr_mirror(x, 7);
    ok &= m >= 0 && m < 7;
  }
  CHECK(ok && hush__bmfr_mirror(-1, 7) == 0 && hush__bmfr_mirror(7, 7) == 6);
}

/* ---- the filter through the API ---------------------------------------------- */

typedef struct scene {
  float color[N * 3];
  float depth[N];
  float normal[N * 3];
  float position[N * 3];
  float albedo[N * 3];
  float output[N * 3];
  float fitted[N * 3];
} scene;

/* The camera: at (0, 0, 5) looking down -z at the plane z = 0. */
static void frame_info(hush_frame_info *fi, uint64_t index) {
  hush_frame_info_init(fi);
  fi->frame_index = index;
  float w2v[16], v2c[16];
  hush_m4_look_at(w2v, hush_v3(0, 0, 5), hush_v3(0, 0, 0), hush_v3(0, 1, 0));
  hush_m4_perspective(v2c, 60.0f, (float)W / H, 0.1f, 100.0f);
  memcpy(fi->world_to_view, w2v, sizeof w2v);
  memcpy(fi->prev_world_to_view, w2v, sizeof w2v);
  memcpy(fi->view_to_clip, v2c, sizeof v2c);
  memcpy(fi->prev_view_to_clip, v2c, sizeof v2c);
}

/* The plane z = 0 as the camera sees it (consistent position and depth, so
 * the history is reused), constant colour and albedo 1. */
static void plane(scene *s, float r, float g, float b) {
  const float t = tanf(30.0f * 3.14159265f / 180.0f) * 5.0f;
  for (int y = 0; y < H; y++)
    for (int x = 0; x < W; x++) {
      const int i = y * W + x;
      const float nx = 2.0f * ((float)x + 0.5f) / W - 1.0f, ny = 1.0f - 2.0f * ((float)y + 0.5f) / H;
      s->position[3 * i + 0] = nx * t * (float)W / H;
      s->position[3 * i + 1] = ny * t;
      s->position[3 * i + 2] = 0.0f;
      s->depth[i] = 5.0f;
      s->normal[3 * i + 0] = 0.0f;
      s->normal[3 * i + 1] = 0.0f;
      s->normal[3 * i + 2] = 1.0f;
      s->color[3 * i + 0] = r;
      s->color[3 * i + 1] = g;
      s->color[3 * i + 2] = b;
      for (int c = 0; c < 3; c++) s->albedo[3 * i + c] = 1.0f;
    }
}

static hush_image_view view_of(void *data, hush_format format) {
  hush_image_view v;
  memset(&v, 0, sizeof v);
  v.data = data;
  v.format = format;
  v.width = W;
  v.height = H;
  return v;
}

static void bind(hush_filter f, const char *name, void *data, hush_format format) {
  hush_image_view v = view_of(data, format);
  REQUIRE(hush_filter_set_image(f, name, &v) == HUSH_OK);
}

static hush_filter make(hush_device dev, scene *s, int with_albedo) {
  hush_filter f = hush_filter_new(dev, "bmfr");
  REQUIRE(f);
  bind(f, "color", s->color, HUSH_FORMAT_FLOAT3);
  bind(f, "depth", s->depth, HUSH_FORMAT_FLOAT);
  bind(f, "normal", s->normal, HUSH_FORMAT_FLOAT3);
  bind(f, "position", s->position, HUSH_FORMAT_FLOAT3);
  if (with_albedo) bind(f, "albedo", s->albedo, HUSH_FORMAT_FLOAT3);
  bind(f, "output", s->output, HUSH_FORMAT_FLOAT3);
  bind(f, "fitted", s->fitted, HUSH_FORMAT_FLOAT3);
  REQUIRE(hush_filter_commit(f) == HUSH_OK);
  return f;
}

static hush_status run(hush_filter f, uint64_t index) {
  hush_frame_info fi;
  frame_info(&fi, index);
  return hush_filter_execute(f, &fi);
}

static float max_abs_diff(const float *a, const float *b, int n) {
  float m = 0.0f;
  for (int i = 0; i < n; i++) {
    const float d = fabsf(a[i] - b[i]);
    m = d > m ? d : m;
  }
  return m;
}

static int all_finite(const float *a, int n) {
  for (int i = 0; i < n; i++)
    if (!isfinite(a[i])) return 0;
  return 1;
}

/* A textured wall under constant light stays exactly that, every frame
 * (different grid offsets), with demodulation, both accumulations and TAA. */
static void test_constant(hush_device dev) {
  static scene s;
  plane(&s, 0, 0, 0);
  for (int i = 0; i < N; i++)
    for (int c = 0; c < 3; c++) {
      s.albedo[3 * i + c] = 0.2f + 0.6f * (float)(((i % W) / 3 + (i / W) / 5 + c) % 4) / 3.0f;
      s.color[3 * i + c] = 0.7f * s.albedo[3 * i + c];
    }
  hush_filter f = make(dev, &s, 1);
  float worst = 0.0f;
  for (uint64_t k = 0; k < 20; k++) {
    REQUIRE(run(f, k) == HUSH_OK);
    const float d = max_abs_diff(s.output, s.color, N * 3);
    worst = d > worst ? d : worst;
  }
  CHECK_MSG(worst <= 1e-4f, "constant image: worst deviation %g", (double)worst);
  hush_filter_release(f);
}

/* Through the API: radiance an exact combination of [1, n, w, w^2] over the
 * whole frame (so in every block, whatever the offset, mirrored margins
 * included) is reproduced by the fit to 1e-3 relative. Bumpy normals, as
 * in busy_block. */
static void test_exact_api(hush_device dev) {
  static scene s;
  plane(&s, 0, 0, 0);
  rng_state = 2024u;
  for (int y = 0; y < H; y++)
    for (int x = 0; x < W; x++) {
      const int i = y * W + x;
      const float u = (float)x / W, v = (float)y / H;
      hush_vec3 n = hush_v3_normalize(hush_v3(0.5f * (rnd() - 0.5f), 0.5f * (rnd() - 0.5f), 1.0f));
      s.normal[3 * i + 0] = n.x;
      s.normal[3 * i + 1] = n.y;
      s.normal[3 * i + 2] = n.z;
      /* a bumpy surface, depth and position consistent so that the
       * history is gathered from the same pixel */
      const float h = 0.2f * sinf(3 * u + 2 * v);
      s.depth[i] = 5.0f - h;
      s.position[3 * i + 0] *= s.depth[i] / 5.0f;
      s.position[3 * i + 1] *= s.depth[i] / 5.0f;
      s.position[3 * i + 2] = h;
      const float *w = s.position + 3 * i;
      for (int c = 0; c < 3; c++)
        s.color[3 * i + c] = 2.0f + (float)(c + 1) * (0.3f * n.x - 0.2f * n.y + 0.1f * w[0] -
                                                      0.2f * w[1] + 0.5f * w[2] +
                                                      0.02f * w[0] * w[0] + 0.03f * w[1] * w[1] +
                                                      0.4f * w[2] * w[2]);
    }
  hush_filter f = make(dev, &s, 0);
  REQUIRE(hush_filter_set_int(f, "taa", 0) == HUSH_OK);
  for (uint64_t k = 0; k < 3; k++) {
    REQUIRE(run(f, k * 5) == HUSH_OK);
    double worst = 0.0;
    for (int i = 0; i < N * 3; i++) {
      const double e = fabs(s.fitted[i] - s.color[i]) / fabs(s.color[i]);
      worst = e > worst ? e : worst;
    }
    CHECK_MSG(worst <= 1e-3, "frame %d: worst relative error %g", (int)k * 5, worst);
  }
  hush_filter_release(f);
}

/* Without displacement the grid is aligned: on a flat wall (all features
 * flat) each 32x32 block's fit is that block's mean of the input. */
static void test_block_mean_api(hush_device dev) {
  static scene s;
  plane(&s, 0, 0, 0);
  /* flatten the position too */
  for (int i = 0; i < N; i++) s.position[3 * i + 0] = s.position[3 * i + 1] = 1.0f;
  rng_state = 4242u;
  for (int i = 0; i < N * 3; i++) s.color[i] = rnd();
  hush_filter f = make(dev, &s, 0);
  REQUIRE(hush_filter_set_int(f, "displace", 0) == HUSH_OK);
  REQUIRE(run(f, 3) == HUSH_OK);
  double worst = 0.0;
  for (int by = 0; by * 32 < H; by++)
    for (int bx = 0; bx * 32 < W; bx++)
      for (int c = 0; c < 3; c++) {
        /* the block with mirrored margins, as the filter reads it */
        double mean = 0.0;
        for (int r = 0; r < 32; r++)
          for (int q = 0; q < 32; q++) {
            const int x = hush__bmfr_mirror(bx * 32 + q, W), y = hush__bmfr_mirror(by * 32 + r, H);
            mean += s.color[3 * (y * W + x) + c];
          }
        mean /= 1024.0;
        for (int r = 0; r < 32 && by * 32 + r < H; r++)
          for (int q = 0; q < 32 && bx * 32 + q < W; q++) {
            const int i = (by * 32 + r) * W + bx * 32 + q;
            const double e = fabs(s.fitted[3 * i + c] - mean);
            worst = e > worst ? e : worst;
          }
      }
  CHECK_MSG(worst <= 1e-4, "flat blocks: worst distance to the block mean %g", worst);
  hush_filter_release(f);
}

/* A noisy plane lit by a smooth gradient: bmfr's output is much closer to
 * the truth than the input after a few frames. */
static void test_denoises(hush_device dev) {
  static scene s;
  static float truth[N * 3];
  plane(&s, 0, 0, 0);
  for (int i = 0; i < N; i++)
    for (int c = 0; c < 3; c++) truth[3 * i + c] = 0.5f + 0.1f * s.position[3 * i] + 0.1f * (float)c;
  hush_filter f = make(dev, &s, 0);
  rng_state = 5u;
  double in_err = 0.0, out_err = 0.0;
  for (uint64_t k = 0; k < 8; k++) {
    for (int i = 0; i < N * 3; i++) s.color[i] = truth[i] * 2.0f * rnd();
    REQUIRE(run(f, k) == HUSH_OK);
    if (k == 7)
      for (int i = 0; i < N * 3; i++) {
        in_err += (s.color[i] - truth[i]) * (s.color[i] - truth[i]);
        out_err += (s.output[i] - truth[i]) * (s.output[i] - truth[i]);
      }
  }
  CHECK_MSG(out_err < 0.01 * in_err, "rmse in %g, out %g", sqrt(in_err / (N * 3)),
            sqrt(out_err / (N * 3)));
  hush_filter_release(f);
}

static void busy(scene *s, int k) {
  plane(s, 0, 0, 0);
  rng_state = 777u + (uint32_t)k;
  for (int y = 0; y < H; y++)
    for (int x = 0; x < W; x++) {
      const int i = y * W + x;
      for (int c = 0; c < 3; c++) s->color[3 * i + c] = (x < W / 3 ? 2.0f : 0.3f) * rnd();
      s->depth[i] = y < H / 2 ? 5.0f : 0.0f; /* sky in the lower half */
      s->normal[3 * i + 1] = x > 2 * W / 3 ? 1.0f : 0.0f;
      s->normal[3 * i + 2] = x > 2 * W / 3 ? 0.0f : 1.0f;
    }
}

static void test_determinism(void) {
  static scene a, b;
  hush_device d1 = hush_device_new("threads=1"), d2 = hush_device_new("threads=2");
  REQUIRE(d1 && d2);
  busy(&a, 0);
  busy(&b, 0);
  hush_filter fa = make(d1, &a, 1), fb = make(d2, &b, 1);
  for (int k = 0; k < 5; k++) {
    busy(&a, k);
    busy(&b, k);
    REQUIRE(run(fa, (uint64_t)k) == HUSH_OK);
    REQUIRE(run(fb, (uint64_t)k) == HUSH_OK);
    CHECK_MSG(memcmp(a.output, b.output, sizeof a.output) == 0, "frame %d differs", k);
    CHECK(all_finite(a.output, N * 3));
  }
  hush_filter_release(fa);
  hush_filter_release(fb);
  /* a second run of the same frames gives the same bits */
  static float first[N * 3];
  memcpy(first, a.output, sizeof first);
  fa = make(d1, &a, 1);
  for (int k = 0; k < 5; k++) {
    busy(&a, k);
    REQUIRE(run(fa, (uint64_t)k) == HUSH_OK);
  }
  CHECK(memcmp(first, a.output, sizeof first) == 0);
  hush_filter_release(fa);
  hush_device_release(d1);
  hush_device_release(d2);
}

/* The camera of frame_info moved along x by 0.03 per frame. */
static void frame_info_moving(hush_frame_info *fi, uint64_t index) {
  frame_info(fi, index);
  float w2v[16];
  hush_m4_look_at(w2v, hush_v3(0.03f * (float)index, 0, 5), hush_v3(0.03f * (float)index, 0, 0),
                  hush_v3(0, 1, 0));
  memcpy(fi->world_to_view, w2v, sizeof w2v);
  const float p = 0.03f * (float)(index ? index - 1 : 0);
  hush_m4_look_at(w2v, hush_v3(p, 0, 5), hush_v3(p, 0, 0), hush_v3(0, 1, 0));
  memcpy(fi->prev_world_to_view, w2v, sizeof w2v);
}

/*
 * Where nothing needs a whole-frame pass between them, the import of the
 * inputs, phase I's plan and blend, the fit, phase III and TAA run block
 * row by block row (bmfr.c, fused_frame; the colour imported into the
 * blend's output and blended in place, the albedo into its thread's own
 * rows, TAA's box reading the two rows above imported again there); an
 * 'spp' image
 * bound without holes takes the pass-by-pass path (its demodulation is a
 * pass of its own). Both give the same bits, under a moving camera, over
 * all 16 grid offsets, for blocks of 16 and 32 and 1 to 3 threads (the
 * block rows wait for each other's rows); also for frames with NaN/Inf in
 * the colour, the albedo, the normal or the position, which the fused
 * frame hands back to the pass-by-pass path: replaced (nonfinite=replace),
 * or failing the frame with the history kept (nonfinite=error, frame 13).
 */
static void test_fused_path(void) {
  static scene a, b;
  static float spp[N], fitted_a[N * 3];
  for (int i = 0; i < N; i++) spp[i] = 1.0f;
  const int blocks[2] = {32, 16};
  for (int threads = 1; threads <= 3; threads++)
    for (int bs = 0; bs < 2; bs++) {
      char cfg[32];
      snprintf(cfg, sizeof cfg, "threads=%d", threads);
      hush_device dev = hush_device_new(cfg);
      REQUIRE(dev);
      busy(&a, 0);
      busy(&b, 0);
      hush_filter fa = make(dev, &a, 1), fb = make(dev, &b, 1);
      REQUIRE(hush_filter_set_int(fa, "block_size", blocks[bs]) == HUSH_OK);
      REQUIRE(hush_filter_set_int(fb, "block_size", blocks[bs]) == HUSH_OK);
      bind(fb, "spp", spp, HUSH_FORMAT_FLOAT);
      REQUIRE(hush_filter_commit(fa) == HUSH_OK && hush_filter_commit(fb) == HUSH_OK);
      int same = 1;
      for (int k = 0; k < 18; k++) {
        busy(&a, k);
        busy(&b, k);
        const char *policy = k == 13 ? "error" : "replace";
        REQUIRE(hush_filter_set_string(fa, "nonfinite", policy) == HUSH_OK);
        REQUIRE(hush_filter_set_string(fb, "nonfinite", policy) == HUSH_OK);
        if (k == 7 || k == 13) a.color[3 * (N / 2) + 1] = b.color[3 * (N / 2) + 1] = NAN;
        if (k == 9) a.albedo[3 * (N - 5)] = b.albedo[3 * (N - 5)] = INFINITY;
        if (k == 11) a.normal[3 * 7 + 2] = b.normal[3 * 7 + 2] = NAN;
        if (k == 15) a.position[3 * (N - 1)] = b.position[3 * (N - 1)] = -INFINITY;
        hush_frame_info fi;
        frame_info_moving(&fi, (uint64_t)k);
        if (k == 13) {
          CHECK(hush_filter_execute(fa, &fi) == HUSH_ERROR_NONFINITE);
          CHECK(hush_filter_execute(fb, &fi) == HUSH_ERROR_NONFINITE);
          continue;
        }
        REQUIRE(hush_filter_execute(fa, &fi) == HUSH_OK);
        REQUIRE(hush_filter_execute(fb, &fi) == HUSH_OK);
        memcpy(fitted_a, a.fitted, sizeof fitted_a);
        same &= memcmp(a.output, b.output, sizeof a.output) == 0 &&
                memcmp(fitted_a, b.fitted, sizeof fitted_a) == 0;
      }
      CHECK_MSG(same, "threads %d, blocks of %d: the fused and pass-by-pass paths differ",
                threads, blocks[bs]);
      CHECK(all_finite(a.output, N * 3));
      hush_filter_release(fa);
      hush_filter_release(fb);
      hush_device_release(dev);
    }
}

/* All holes (sky everywhere) and black inputs: finite, and the sky keeps
 * its (accumulated) radiance. */
static void test_holes_api(hush_device dev) {
  static scene s;
  plane(&s, 0.25f, 0.5f, 1.0f);
  for (int i = 0; i < N; i++) s.depth[i] = 0.0f;
  hush_filter f = make(dev, &s, 1);
  for (uint64_t k = 0; k < 4; k++) REQUIRE(run(f, k) == HUSH_OK);
  CHECK(all_finite(s.output, N * 3));
  CHECK(max_abs_diff(s.output, s.color, N * 3) <= 1e-5f);
  hush_filter_release(f);

  plane(&s, 0, 0, 0);
  for (int i = 0; i < N * 3; i++) s.albedo[i] = 0.0f;
  f = make(dev, &s, 1);
  for (uint64_t k = 0; k < 4; k++) REQUIRE(run(f, k) == HUSH_OK);
  CHECK(all_finite(s.output, N * 3) && all_finite(s.fitted, N * 3));
  float m = 0.0f;
  for (int i = 0; i < N * 3; i++) m = fabsf(s.output[i]) > m ? fabsf(s.output[i]) : m;
  CHECK(m == 0.0f);
  hush_filter_release(f);
}

static void test_misuse(hush_device dev) {
  static scene s;
  plane(&s, 1, 1, 1);
  hush_filter f = hush_filter_new(dev, "bmfr");
  REQUIRE(f);
  bind(f, "color", s.color, HUSH_FORMAT_FLOAT3);
  bind(f, "output", s.output, HUSH_FORMAT_FLOAT3);
  CHECK(hush_filter_commit(f) != HUSH_OK); /* no depth, no normal */
  hush_device_get_error(dev, NULL);
  bind(f, "depth", s.depth, HUSH_FORMAT_FLOAT);
  bind(f, "normal", s.normal, HUSH_FORMAT_FLOAT3);
  REQUIRE(hush_filter_commit(f) == HUSH_OK);
  /* the default features need the world position */
  CHECK(run(f, 0) == HUSH_ERROR_INVALID_OPERATION);
  const char *msg = NULL;
  hush_device_get_error(dev, &msg);
  CHECK(msg && strstr(msg, "position"));
  REQUIRE(hush_filter_set_float(f, "position_exponent1", 0.0f) == HUSH_OK);
  REQUIRE(hush_filter_set_float(f, "position_exponent2", 0.0f) == HUSH_OK);
  CHECK(run(f, 0) == HUSH_OK); /* [1, n] only */
  REQUIRE(hush_filter_set_float(f, "albedo_exponent1", 1.0f) == HUSH_OK);
  CHECK(run(f, 1) == HUSH_ERROR_INVALID_OPERATION); /* albedo features, no albedo */
  hush_device_get_error(dev, NULL);
  CHECK(hush_filter_set_int(f, "block_size", 8) == HUSH_ERROR_OUT_OF_RANGE);
  CHECK(hush_filter_set_int(f, "block_size", 65) == HUSH_ERROR_OUT_OF_RANGE);
  CHECK(hush_filter_set_float(f, "noise", -0.1f) == HUSH_ERROR_OUT_OF_RANGE);
  CHECK(hush_filter_set_float(f, "normal_exponent1", -1.0f) == HUSH_ERROR_OUT_OF_RANGE);
  hush_device_get_error(dev, NULL);
  hush_filter_release(f);

  f = make(dev, &s, 0);
  hush_frame_info fi;
  frame_info(&fi, 0);
  fi.motion = HUSH_MOTION_VECTORS; /* without a 'motion' image */
  CHECK(hush_filter_execute(f, &fi) == HUSH_ERROR_INVALID_OPERATION);
  hush_device_get_error(dev, NULL);
  s.color[5] = NAN;
  CHECK(run(f, 1) == HUSH_ERROR_NONFINITE);
  hush_device_get_error(dev, NULL);
  REQUIRE(hush_filter_set_int(f, "nonfinite", 1) == HUSH_OK); /* replace */
  CHECK(run(f, 2) == HUSH_OK);
  CHECK(all_finite(s.output, N * 3));
  hush_filter_release(f);
}

/* A light seen directly (a small patch 200x brighter) stays out of its
 * block's fit: the rest of the block keeps its level and the patch its
 * radiance. With the guard off, the fit spreads the patch over the block. */
static void test_outliers(hush_device dev) {
  static scene s;
  plane(&s, 0.5f, 0.5f, 0.5f);
  for (int y = 20; y < 23; y++)
    for (int x = 30; x < 33; x++)
      for (int c = 0; c < 3; c++) s.color[3 * (y * W + x) + c] = 100.0f;
  for (int guard = 1; guard >= 0; guard--) {
    hush_filter f = make(dev, &s, 0);
    REQUIRE(hush_filter_set_int(f, "taa", 0) == HUSH_OK);
    if (!guard) REQUIRE(hush_filter_set_float(f, "outlier", 0.0f) == HUSH_OK);
    REQUIRE(run(f, 0) == HUSH_OK);
    float far_dev = 0.0f, patch_dev = 0.0f;
    for (int i = 0; i < N; i++) {
      const int x = i % W, y = i / W;
      const int in_patch = x >= 30 && x < 33 && y >= 20 && y < 23;
      for (int c = 0; c < 3; c++) {
        const float d = fabsf(s.fitted[3 * i + c] - s.color[3 * i + c]);
        if (in_patch) patch_dev = d > patch_dev ? d : patch_dev;
        else far_dev = d > far_dev ? d : far_dev;
      }
    }
    if (guard)
      CHECK_MSG(far_dev <= 1e-4f && patch_dev <= 1e-3f, "guard on: %g around, %g on the patch",
                (double)far_dev, (double)patch_dev);
    else
      CHECK_MSG(far_dev > 0.1f, "guard off: the patch should spread (%g)", (double)far_dev);
    hush_filter_release(f);
  }
}

/* An isolated firefly stays in the fit: on a flat wall with the grid
 * aligned, its block's fit is the block mean, firefly included (its energy
 * is spread, not kept in one pixel nor lost). */
static void test_firefly(hush_device dev) {
  static scene s;
  plane(&s, 0.5f, 0.5f, 0.5f);
  for (int i = 0; i < N; i++) s.position[3 * i + 0] = s.position[3 * i + 1] = 1.0f;
  for (int c = 0; c < 3; c++) s.color[3 * (10 * W + 10) + c] = 100.0f;
  hush_filter f = make(dev, &s, 0);
  REQUIRE(hush_filter_set_int(f, "displace", 0) == HUSH_OK);
  REQUIRE(run(f, 0) == HUSH_OK);
  const float mean = 0.5f + 99.5f / 1024.0f; /* block (0, 0) is inside the image */
  float worst = 0.0f;
  for (int y = 0; y < 32; y++)
    for (int x = 0; x < 32; x++)
      for (int c = 0; c < 3; c++) {
        const float d = fabsf(s.fitted[3 * (y * W + x) + c] - mean);
        worst = d > worst ? d : worst;
      }
  CHECK_MSG(worst <= 1e-4f, "firefly block: worst distance to the mean %g", (double)worst);
  hush_filter_release(f);
}

/* A band whose albedo is nearly 0 in one channel but which reflects some
 * light there anyway (an orange plastic's blue under its white coat) must
 * not light the wall around it in that channel: demodulation divides the
 * band's light by the albedo's floor, and the block's fit, which cannot
 * tell band from wall on one plane, spreads what it gets. At a floor of
 * 0.001 the wall's blue came out 25x too bright, at 0.02 1.6x. */
static void test_dark_albedo_channel(hush_device dev) {
  static scene s;
  plane(&s, 0.3f, 0.3f, 0.3f);
  for (int i = 0; i < N; i++)
    for (int c = 0; c < 3; c++) s.albedo[3 * i + c] = 0.3f;
  for (int y = 0; y < H; y++)
    for (int x = 38; x < 42; x++) {
      float *a = s.albedo + 3 * (y * W + x), *col = s.color + 3 * (y * W + x);
      a[2] = 0.001f;
      col[2] = 0.001f + 0.04f; /* the base's blue plus the coat's */
    }
  hush_filter f = make(dev, &s, 1);
  REQUIRE(hush_filter_set_int(f, "taa", 0) == HUSH_OK);
  REQUIRE(run(f, 0) == HUSH_OK);
  float worst = 0.0f;
  for (int y = 0; y < H; y++)
    for (int x = 0; x < W; x++)
      if (x < 38 || x >= 42) {
        const float r = s.output[3 * (y * W + x) + 2] / 0.3f;
        worst = r > worst ? r : worst;
      }
  CHECK_MSG(worst < 2.0f, "the wall's blue is %.2fx its input beside a dark-blue band", (double)worst);
  CHECK(all_finite(s.output, N * 3));
  hush_filter_release(f);
}

/* Every block size in range, odd ones included, runs and keeps a constant
 * image constant. */
static void test_block_sizes(hush_device dev) {
  static scene s;
  plane(&s, 0.3f, 0.6f, 0.9f);
  for (int B = 16; B <= 64; B += 7) {
    hush_filter f = make(dev, &s, 0);
    REQUIRE(hush_filter_set_int(f, "block_size", B) == HUSH_OK);
    for (uint64_t k = 0; k < 3; k++) REQUIRE(run(f, k) == HUSH_OK);
    CHECK_MSG(max_abs_diff(s.output, s.color, N * 3) <= 1e-4f, "block_size %d", B);
    hush_filter_release(f);
  }
}

/* ---- emission ------------------------------------------------------------ */

/* A dark wall with a lamp on it, both in one block: the lamp (10 x 10
 * pixels at (8, 8)) has the wall's position and normal, so no feature
 * separates it, and the block's least-squares fit (outlier guard off, as
 * the paper) smears it over the wall. With 'emission' bound, the lamp's
 * output is its emission (plus at most the wall's radiance the fit may
 * spread onto it) and none of its radiance reaches the wall: the wall
 * stays within twice its radiance (the fit of the step between the
 * lamp's 0 reflected light and the wall overshoots a little, 400 times
 * below the lamp); a lamp that also reflects the wall's light comes out
 * exactly. Unbound, the same frame leaks (the control). */
#define LAMP_E 20.0f
static int in_lamp(int i) {
  const int x = i % W, y = i / W;
  return x >= 8 && x < 18 && y >= 8 && y < 18;
}

static void lamp_scene(scene *s, float *emission, float wall, int lamp_reflects) {
  plane(s, wall, wall, wall);
  for (int i = 0; i < N; i++)
    for (int c = 0; c < 3; c++) {
      emission[3 * i + c] = in_lamp(i) ? LAMP_E : 0.0f;
      if (in_lamp(i)) s->color[3 * i + c] = LAMP_E + (lamp_reflects ? wall : 0.0f);
    }
}

static hush_filter make_emission(hush_device dev, scene *s, float *emission) {
  hush_filter f = hush_filter_new(dev, "bmfr");
  REQUIRE(f);
  bind(f, "color", s->color, HUSH_FORMAT_FLOAT3);
  bind(f, "depth", s->depth, HUSH_FORMAT_FLOAT);
  bind(f, "normal", s->normal, HUSH_FORMAT_FLOAT3);
  bind(f, "position", s->position, HUSH_FORMAT_FLOAT3);
  bind(f, "albedo", s->albedo, HUSH_FORMAT_FLOAT3);
  if (emission) bind(f, "emission", emission, HUSH_FORMAT_FLOAT3);
  bind(f, "output", s->output, HUSH_FORMAT_FLOAT3);
  REQUIRE(hush_filter_commit(f) == HUSH_OK);
  return f;
}

static void test_emission(hush_device dev) {
  static scene s;
  static float emission[N * 3];
  const float wall = 0.05f;
  for (int bound = 1; bound >= 0; bound--)
    for (int taa = 0; taa < 2; taa++) {
      lamp_scene(&s, emission, wall, 0);
      hush_filter f = make_emission(dev, &s, bound ? emission : NULL);
      REQUIRE(hush_filter_set_int(f, "displace", 0) == HUSH_OK); /* lamp and wall in block (0, 0) */
      REQUIRE(hush_filter_set_bool(f, "taa", taa) == HUSH_OK);
      REQUIRE(hush_filter_set_float(f, "outlier", 0.0f) == HUSH_OK);
      for (uint64_t k = 0; k < 6; k++) REQUIRE(run(f, k) == HUSH_OK);
      float lamp_dev = 0.0f, wall_max = 0.0f;
      for (int i = 0; i < N; i++)
        for (int c = 0; c < 3; c++) {
          const float o = s.output[3 * i + c];
          if (in_lamp(i)) {
            const float d = o < LAMP_E ? LAMP_E - o : o - LAMP_E - wall;
            lamp_dev = d > lamp_dev ? d : lamp_dev;
          } else {
            wall_max = o > wall_max ? o : wall_max;
          }
        }
      CHECK(all_finite(s.output, N * 3));
      if (bound) {
        CHECK_MSG(lamp_dev <= 1e-4f * LAMP_E, "taa %d: lamp output off its emission by %g", taa,
                  (double)lamp_dev);
        CHECK_MSG(wall_max <= 2.0f * wall, "taa %d: lamp leaks into the wall: %g (wall %g)", taa,
                  (double)wall_max, (double)wall);
      } else {
        CHECK_MSG(wall_max > 10.0f * wall, "taa %d: unbound, the fit should smear the lamp (%g)",
                  taa, (double)wall_max);
      }
      hush_filter_release(f);
      if (!bound) continue;
      lamp_scene(&s, emission, wall, 1);
      f = make_emission(dev, &s, emission);
      REQUIRE(hush_filter_set_bool(f, "taa", taa) == HUSH_OK);
      REQUIRE(hush_filter_set_float(f, "outlier", 0.0f) == HUSH_OK);
      for (uint64_t k = 0; k < 6; k++) REQUIRE(run(f, k) == HUSH_OK);
      CHECK_MSG(max_abs_diff(s.output, s.color, N * 3) <= 1e-5f * LAMP_E,
                "taa %d: reflecting lamp off by %g", taa,
                (double)max_abs_diff(s.output, s.color, N * 3));
      hush_filter_release(f);
    }
}

/* A column beside the lamp lit every other frame (a light's edge at 1 spp):
 * its emission averages over frames in the emission history, and goes back
 * after TAA, so TAA's tone-mapped blend never touches it (before it did,
 * the bilinear history of a moving camera blended the lamp and the ceiling
 * in tone-mapped values and darkened the Cornell lamp's edges: RMSE 0.089
 * against 0.054 without TAA). With TAA the column is the column without
 * TAA, up to the wall's light. */
static void test_emission_after_taa(hush_device dev) {
  static scene s[2];
  static float emission[N * 3];
  const float wall = 0.05f;
  const int edge = 18;
  hush_filter f[2];
  for (int t = 0; t < 2; t++) {
    lamp_scene(&s[t], emission, wall, 0);
    f[t] = make_emission(dev, &s[t], emission);
    REQUIRE(hush_filter_set_bool(f[t], "taa", t) == HUSH_OK);
    REQUIRE(hush_filter_set_float(f[t], "outlier", 0.0f) == HUSH_OK);
  }
  float lo = INFINITY, hi = -INFINITY, diff = 0.0f;
  for (int k = 0; k < 16; k++) {
    for (int t = 0; t < 2; t++) {
      for (int i = 0; i < N; i++) {
        const int x = i % W, y = i / W;
        const int lit = in_lamp(i) || (k % 2 == 0 && x == edge && y >= 8 && y < 18);
        for (int c = 0; c < 3; c++) {
          emission[3 * i + c] = lit ? LAMP_E : 0.0f;
          s[t].color[3 * i + c] = lit ? LAMP_E : wall;
        }
      }
      REQUIRE(run(f[t], (uint64_t)k) == HUSH_OK);
    }
    if (k < 8) continue;
    for (int y = 8; y < 18; y++) {
      const int i = y * W + edge;
      const float o = s[1].output[3 * i];
      lo = o < lo ? o : lo;
      hi = o > hi ? o : hi;
      const float d = fabsf(o - s[0].output[3 * i]);
      diff = d > diff ? d : diff;
    }
  }
  printf("bmfr lamp edge with TAA: %g .. %g, off the edge without TAA by %g\n", (double)lo,
         (double)hi, (double)diff);
  CHECK_MSG(lo > 0.3f * LAMP_E && hi < 0.7f * LAMP_E, "lamp edge not averaged: %g .. %g",
            (double)lo, (double)hi);
  CHECK_MSG(diff <= 2.0f * wall, "TAA changes the lamp's edge by %g", (double)diff);
  for (int t = 0; t < 2; t++) hush_filter_release(f[t]);
}

/* ---- temporal_gradients ---------------------------------------------------- */

static float gradient_layer[N * 3];
static float history_length[N];

/* Every stratum's sample: current c, previous p, landing index 0. */
static void gradient_samples(float c, float p) {
  for (int i = 0; i < N; i++) {
    gradient_layer[3 * i + 0] = c;
    gradient_layer[3 * i + 1] = p;
    gradient_layer[3 * i + 2] = 0.0f;
  }
}

static void test_temporal_gradients(hush_device dev) {
  static scene a, b;
  busy(&a, 0);
  busy(&b, 0);
  hush_filter fa = make(dev, &a, 1), fb = make(dev, &b, 1);
  int on = 1;
  CHECK(hush_filter_get_bool(fa, "temporal_gradients", &on) == HUSH_OK && on == 0);
  /* off: a bound gradient (of lambda 1) is not read */
  gradient_samples(0.0f, 1.0f);
  bind(fb, "gradient", gradient_layer, HUSH_FORMAT_FLOAT3);
  REQUIRE(hush_filter_commit(fb) == HUSH_OK);
  int same = 1;
  for (int k = 0; k < 4; k++) {
    busy(&a, k);
    busy(&b, k);
    REQUIRE(run(fa, (uint64_t)k) == HUSH_OK);
    REQUIRE(run(fb, (uint64_t)k) == HUSH_OK);
    same &= memcmp(a.output, b.output, sizeof a.output) == 0;
  }
  CHECK_MSG(same, "temporal_gradients off: a bound gradient changed the output");
  /* on, all-zero gradient (no change anywhere): the same bits, history going on */
  gradient_samples(0.0f, 0.0f);
  REQUIRE(hush_filter_set_bool(fb, "temporal_gradients", 1) == HUSH_OK);
  for (int k = 4; k < 8; k++) {
    busy(&a, k);
    busy(&b, k);
    REQUIRE(run(fa, (uint64_t)k) == HUSH_OK);
    REQUIRE(run(fb, (uint64_t)k) == HUSH_OK);
    same &= memcmp(a.output, b.output, sizeof a.output) == 0;
  }
  CHECK_MSG(same, "temporal_gradients on with a zero gradient changed the output");
  hush_filter_release(fa);
  hush_filter_release(fb);

  /* lambda 1 everywhere (c = 0 < p = 1): each frame equals a new filter's
   * first frame at the same frame index (TAA, which keeps its own history,
   * off); phase I's counts are all 1 */
  busy(&a, 0);
  fa = make(dev, &a, 1);
  REQUIRE(hush_filter_set_bool(fa, "taa", 0) == HUSH_OK);
  REQUIRE(hush_filter_set_bool(fa, "temporal_gradients", 1) == HUSH_OK);
  gradient_samples(0.0f, 1.0f);
  bind(fa, "gradient", gradient_layer, HUSH_FORMAT_FLOAT3);
  bind(fa, "history_length", history_length, HUSH_FORMAT_FLOAT);
  REQUIRE(hush_filter_commit(fa) == HUSH_OK);
  int fresh = 1, ones = 1;
  for (int k = 0; k < 4; k++) {
    busy(&a, k);
    REQUIRE(run(fa, (uint64_t)k) == HUSH_OK);
    busy(&b, k);
    fb = make(dev, &b, 1);
    REQUIRE(hush_filter_set_bool(fb, "taa", 0) == HUSH_OK);
    REQUIRE(run(fb, (uint64_t)k) == HUSH_OK);
    fresh &= memcmp(a.output, b.output, sizeof a.output) == 0;
    for (int i = 0; i < N; i++) ones &= history_length[i] == 1.0f;
    hush_filter_release(fb);
  }
  CHECK_MSG(fresh, "lambda 1: not the first-frame result");
  CHECK(ones);
  /* lambda 0 again: the history grows back */
  gradient_samples(0.5f, 0.5f);
  for (int k = 4; k < 7; k++) {
    busy(&a, k);
    REQUIRE(run(fa, (uint64_t)k) == HUSH_OK);
  }
  CHECK_MSG(history_length[N / 4] == 4.0f, "history length %g after 3 unchanged frames",
            (double)history_length[N / 4]);
  /* on without the image: an error naming it */
  REQUIRE(hush_filter_unset_image(fa, "gradient") == HUSH_OK);
  CHECK(run(fa, 7) == HUSH_ERROR_INVALID_OPERATION);
  const char *msg = NULL;
  hush_device_get_error(dev, &msg);
  CHECK(msg && strstr(msg, "'gradient'") && strstr(msg, "temporal_gradients"));
  hush_filter_release(fa);
}

int main(void) {
  test_exact_block();
  test_rank_deficient_block();
  test_holes_block();
  test_feature_sets();
  test_fit_reference();
  test_fit_padded_ld();
  test_few_valid_block();
  test_offsets();
  hush_device dev = hush_device_new("threads=2");
  REQUIRE(dev);
  test_constant(dev);
  test_exact_api(dev);
  test_block_mean_api(dev);
  test_denoises(dev);
  test_determinism();
  test_fused_path();
  test_holes_api(dev);
  test_misuse(dev);
  test_block_sizes(dev);
  test_outliers(dev);
  test_firefly(dev);
  test_dark_albedo_channel(dev);
  test_emission(dev);
  test_emission_after_taa(dev);
  test_temporal_gradients(dev);
  hush_device_release(dev);
  return check_summary();
}
