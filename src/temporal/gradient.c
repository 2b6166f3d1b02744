/*
 * gradient.c — temporal gradients of A-SVGF (gradient.h): the stratum grid
 * gathered from the renderer's gradient samples, its edge-avoiding a-trous
 * reconstruction, lambda per pixel, and the history-length rule.
 *
 * Schied, Peters, Dachsbacher 2018 §4.2-4.3; Higginson 2023 §2.3.1
 * (papers/NOTES.md "A-SVGF"); docs/asvgf.md.
 *
 * The grid is 1/9 of the pixels, so three 3x3 levels cost 3 taps per pixel
 * (one full-resolution SVGF level: 25). Its inner loops run along a grid
 * row, one tap at a time, on planar rows with no branch: the row range of a
 * tap that stays inside the grid is computed before the loop, and the
 * weight is one base-2 exponential by a polynomial (expf/powf would keep
 * errno branches and stop the vectoriser). The upsampling to pixels is
 * vectorised the same way (expand). 1280x720, one thread: about 8 ms.
 */
#include "temporal/gradient.h"

#include "temporal/reproject.h" /* HUSH_ALWAYS_INLINE, hush__select_bits, hush__floorf_vec */

#include <math.h>
#include <string.h>

/* Stratum grid planes in the scratch, in this order. */
enum {
  G_Z = 0, /* depth */
  G_NX,
  G_NY,
  G_NZ,
  G_GX, /* depth gradient per stratum (x 3 pixels) */
  G_GY,
  G_IL,    /* 1 / (sigma_l max(l, 0) + eps): the luminance weight's denominator inverted */
  G_D0,    /* delta, norm, valid: ping */
  G_N0,
  G_V0,
  G_D1, /* pong */
  G_N1,
  G_V1,
  G_LAMBDA, /* per stratum */
  G_PLANES
};

#define GRADIENT_EPS_Z 1e-3f
#define GRADIENT_EPS_L 1e-4f
#define GRADIENT_NORM_MIN 1e-6f
/* A weight below 2^-40 of the centre is 0: keeps products normal floats. */
#define GRADIENT_LOG2_FLOOR (-40.0f)

static void grid_size(uint32_t W, uint32_t H, int *ws, int *hs) {
  *ws = (int)((W + 2) / 3);
  *hs = (int)((H + 2) / 3);
}

/* The upsampling's rows: per stratum row, its depth and lambda repeated
 * over the 3 pixels of each stratum, padded by one stratum each side. */
#define GRADIENT_REP_PAD 3
static size_t rep_row(uint32_t width) { return (size_t)width + 2 * GRADIENT_REP_PAD; }

size_t hush__gradient_scratch_floats(uint32_t width, uint32_t height) {
  int ws, hs;
  grid_size(width, height, &ws, &hs);
  return (size_t)G_PLANES * (size_t)ws * (size_t)hs + 2 * (size_t)hs * rep_row(width);
}

/* 2^t for t in [-126, 0] (callers clamp): t = i + f, 2^f by its degree-5
 * polynomial (relative error ~2e-7), 2^i by the exponent bits. */
static HUSH_ALWAYS_INLINE float exp2_neg(float t) {
  t = hush__select_bits(t > -126.0f, t, -126.0f);
  const float i = hush__floorf_vec(t);
  const float f = t - i;
  const float p =
      1.0f +
      f * (0.693147182f +
           f * (0.240226507f + f * (0.0555041087f + f * (0.00961812911f + f * 0.00133335581f))));
  const int32_t bits = ((int32_t)i + 127) << 23;
  float scale;
  memcpy(&scale, &bits, sizeof scale);
  return p * scale;
}

/* log2(d) for d > 0 (d <= 1e-30 taken as 1e-30). */
static HUSH_ALWAYS_INLINE float log2_pos(float d) { return hush__ln_pos(d) * 1.44269504f; }

/* ---- 1. gather ---------------------------------------------------------- */

/* The stratum's sample (c, p, landing index) and its guides. */
static void gather(const float *const gradient[3], const hush_gradient_guides *gd, uint32_t W,
                   uint32_t H, float sigma_l, float *const *g, int threads) {
  int ws, hs;
  grid_size(W, H, &ws, &hs);
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int sy = 0; sy < hs; sy++) {
    for (int sx = 0; sx < ws; sx++) {
      const size_t s = (size_t)sy * ws + sx;
      const size_t base = (size_t)(3 * sy) * W + (size_t)(3 * sx);
      const float c = gradient[0][base], p = gradient[1][base], k = gradient[2][base];
      const int valid = k > -0.5f && k < 8.5f;
      int x, y;
      if (valid) {
        const int ki = (int)(k + 0.5f);
        x = 3 * sx + ki % 3;
        y = 3 * sy + ki / 3;
      } else {
        x = 3 * sx + 1;
        y = 3 * sy + 1;
      }
      x = x < (int)W ? x : (int)W - 1;
      y = y < (int)H ? y : (int)H - 1;
      const size_t i = (size_t)y * W + (size_t)x;
      g[G_Z][s] = gd->depth[i];
      for (int a = 0; a < 3; a++) g[G_NX + a][s] = gd->normal[a][i];
      /* one stratum step is 3 pixels */
      g[G_GX][s] = gd->depth_grad[0] ? 3.0f * gd->depth_grad[0][i] : 0.0f;
      g[G_GY][s] = gd->depth_grad[1] ? 3.0f * gd->depth_grad[1][i] : 0.0f;
      const float l = gd->luminance ? gd->luminance[i] : (valid ? c : 0.0f);
      g[G_LAMBDA][s] = l; /* the guide luminance until lambda is computed */
      g[G_IL][s] = 1.0f / (sigma_l * fmaxf(l, 0.0f) + GRADIENT_EPS_L);
      const float norm = fmaxf(fmaxf(c, p), 0.0f);
      g[G_D0][s] = valid ? c - p : 0.0f;
      g[G_N0][s] = valid ? norm : 0.0f;
      g[G_V0][s] = valid ? 1.0f : 0.0f;
    }
  }
}

/* ---- 2. reconstruction --------------------------------------------------- */

typedef struct level_ctx {
  int ws, hs, step;
  float sigma_z, sigma_n;
  int pow2;              /* sigma_n = 2^pow2, or -1 */
  const float *l;        /* guide luminance (in the lambda plane while it is free) */
  const float *const *g; /* the guide planes */
  const float *d, *n, *v; /* in */
  float *od, *on, *ov;    /* out */
} level_ctx;

/* Adds tap (dx, dy) * step of kernel weight h to output row sy, for the
 * grid columns x0 <= x < x1 whose tap is inside the grid. The luminance
 * weight's 1 / (sigma_l max(l_p, l_q) + eps) is min(il_p, il_q). The normal
 * weight max(0, dot)^sigma_n is, for sigma_n = 2^pow2 (pow2 = 0..10, a
 * constant where inlined: 128 by default), pow2 squarings of the dot, with
 * dots below 2^(-60 / sigma_n) made 0 first so no product goes subnormal;
 * for any other sigma_n (pow2 < 0) it joins the exponent as
 * sigma_n log2(dot). A weight below 2^-40 of h is 0. */
static HUSH_ALWAYS_INLINE void level_tap(const level_ctx *L, int sy, int dx, int dy, float h,
                                         int x0, int x1, const int pow2) {
  const int ws = L->ws;
  const size_t row = (size_t)sy * ws;
  const ptrdiff_t off = (ptrdiff_t)(dy * L->step) * ws + dx * L->step;
  const float *restrict z = L->g[G_Z] + row, *restrict nx = L->g[G_NX] + row,
                        *restrict ny = L->g[G_NY] + row, *restrict nz = L->g[G_NZ] + row,
                        *restrict gx = L->g[G_GX] + row, *restrict gy = L->g[G_GY] + row,
                        *restrict il = L->g[G_IL] + row;
  const float *restrict qz = L->g[G_Z] + row + off, *restrict qnx = L->g[G_NX] + row + off,
                        *restrict qny = L->g[G_NY] + row + off,
                        *restrict qnz = L->g[G_NZ] + row + off,
                        *restrict qil = L->g[G_IL] + row + off, *restrict qd = L->d + row + off,
                        *restrict qn = L->n + row + off, *restrict qv = L->v + row + off;
  const float *restrict l = L->l + row, *restrict ql = L->l + row + off;
  float *restrict od = L->od + row, *restrict on = L->on + row, *restrict ov = L->ov + row;
  const float fdx = (float)(dx * L->step), fdy = (float)(dy * L->step);
  const float log2e = 1.44269504f, log2h = log2_pos(h);
  const float sz = L->sigma_z, sn = L->sigma_n;
  const int sn_off = sn == 0.0f; /* max(0, dot)^0 = 1 */
  const float dot_min = pow2 >= 0 ? exp2_neg(-60.0f / (float)(1 << (pow2 > 0 ? pow2 : 0))) : 0.0f;
#pragma omp simd
  for (int x = x0; x < x1; x++) {
    const float dz = fabsf(z[x] - qz[x]);
    const float denz = sz * fabsf(gx[x] * fdx + gy[x] * fdy) + GRADIENT_EPS_Z;
    const float dl = fabsf(l[x] - ql[x]);
    const float inv_l = hush__select_bits(il[x] < qil[x], il[x], qil[x]);
    const float dot = nx[x] * qnx[x] + ny[x] * qny[x] + nz[x] * qnz[x];
    float e = log2h - log2e * (dz / denz + dl * inv_l), wn;
    if (pow2 >= 0) {
      wn = hush__select_bits(dot > dot_min, dot, 0.0f);
      wn = hush__pow2_squarings(wn, pow2);
    } else {
      e += sn * log2_pos(dot);
      wn = hush__select_bits((dot > 0.0f) | sn_off, 1.0f, 0.0f);
    }
    const float w = hush__select_bits(e > GRADIENT_LOG2_FLOOR, exp2_neg(e), 0.0f) * wn * qv[x];
    od[x] += w * qd[x];
    on[x] += w * qn[x];
    ov[x] += w;
  }
}

/* level_tap with the normal power a compile-time constant where it can be. */
static void level_tap_any(const level_ctx *L, int sy, int dx, int dy, float h, int x0, int x1) {
  switch (L->pow2) {
#define GRADIENT_TAP_CASE(k) \
  case k: level_tap(L, sy, dx, dy, h, x0, x1, k); break;
    GRADIENT_TAP_CASE(0)
    GRADIENT_TAP_CASE(1)
    GRADIENT_TAP_CASE(2)
    GRADIENT_TAP_CASE(3)
    GRADIENT_TAP_CASE(4)
    GRADIENT_TAP_CASE(5)
    GRADIENT_TAP_CASE(6)
    GRADIENT_TAP_CASE(7)
    GRADIENT_TAP_CASE(8)
    GRADIENT_TAP_CASE(9)
    GRADIENT_TAP_CASE(10)
#undef GRADIENT_TAP_CASE
  default: level_tap(L, sy, dx, dy, h, x0, x1, -1); break;
  }
}

/* sigma_n = 2^k with k in 0..10: k; else -1. */
static int power_of_two(float sigma_n) {
  for (int k = 0; k <= 10; k++)
    if (sigma_n == (float)(1 << k)) return k;
  return -1;
}

/* One a-trous level: out = sum w q / sum w, valid where sum w > 0. */
static void level(const level_ctx *L, int threads) {
  static const float b2[3] = {1.0f / 4, 1.0f / 2, 1.0f / 4};
  const int ws = L->ws, hs = L->hs, step = L->step;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int sy = 0; sy < hs; sy++) {
    const size_t row = (size_t)sy * ws;
    memset(L->od + row, 0, (size_t)ws * sizeof(float));
    memset(L->on + row, 0, (size_t)ws * sizeof(float));
    memset(L->ov + row, 0, (size_t)ws * sizeof(float));
    for (int dy = -1; dy <= 1; dy++) {
      const int qy = sy + dy * step;
      if (qy < 0 || qy >= hs) continue;
      for (int dx = -1; dx <= 1; dx++) {
        const int o = dx * step;
        const int x0 = o < 0 ? -o : 0, x1 = o > 0 ? ws - o : ws;
        if (x0 >= x1) continue;
        level_tap_any(L, sy, dx, dy, b2[dy + 1] * b2[dx + 1], x0, x1);
      }
    }
    float *restrict od = L->od + row, *restrict on = L->on + row, *restrict ov = L->ov + row;
#pragma omp simd
    for (int x = 0; x < ws; x++) {
      const float sum = ov[x];
      const int any = sum > 0.0f;
      const float inv = 1.0f / hush__select_bits(any, sum, 1.0f);
      od[x] = hush__select_bits(any, od[x] * inv, 0.0f);
      on[x] = hush__select_bits(any, on[x] * inv, 0.0f);
      ov[x] = hush__select_bits(any, 1.0f, 0.0f);
    }
  }
}

/* ---- 3. lambda ----------------------------------------------------------- */

static void stratum_lambda(const float *d, const float *n, const float *v, size_t count,
                           float exponent, float threshold, float *lambda, int threads) {
  const float t = threshold > 0.0f ? (threshold < 0.99f ? threshold : 0.99f) : 0.0f;
  const float inv_range = 1.0f / (1.0f - t);
#pragma omp parallel for simd schedule(static) num_threads(threads)
  for (size_t s = 0; s < count; s++) {
    const int ok = (v[s] > 0.0f) & (n[s] > GRADIENT_NORM_MIN);
    const float q = fabsf(d[s]) / hush__select_bits(ok, n[s], 1.0f);
    /* the noise floor (t = 0: r0 = q exactly) */
    const float r0 = hush__select_bits(q > t, (q - t) * inv_range, 0.0f);
    const float r = hush__select_bits(ok & !(r0 < 1.0f), 1.0f, hush__select_bits(ok, r0, 0.0f));
    /* r^exponent, r in [0, 1]; exactly 0 and 1 kept */
    const float pw = exp2_neg(exponent * log2_pos(r));
    lambda[s] = hush__select_bits(r > 0.0f, hush__select_bits(r < 1.0f, pw, 1.0f), 0.0f);
  }
}

/* Per pixel, joint nearest-neighbour upsampling: of its stratum and the 8
 * around it, the lambda of the one whose guide depth is nearest the pixel's
 * (its own on ties), so that a pixel of another surface than its stratum's
 * sample (a silhouette, the sky beside a lit wall) takes the lambda of its
 * own surface. The strata's depth and lambda are first repeated over their
 * 3 pixel columns (rows zr, lr, padded by the edge stratum), so that the
 * candidates of pixel x are at x - 3, x, x + 3 of three such rows: the
 * pixel loop is branch-free and vectorises. */
static void expand(const float *ls, const float *zs, int ws, int hs, const float *depth,
                   uint32_t W, uint32_t H, float *zr, float *lr, float *lambda, int threads) {
  const size_t rw = rep_row(W);
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int sy = 0; sy < hs; sy++) {
    float *z = zr + (size_t)sy * rw + GRADIENT_REP_PAD,
          *l = lr + (size_t)sy * rw + GRADIENT_REP_PAD;
    for (int x = -GRADIENT_REP_PAD; x < (int)W + GRADIENT_REP_PAD; x++) {
      /* the pads repeat the edge strata (the last one may be partial) */
      const int sx = x < 0 ? 0 : x >= (int)W ? ws - 1 : x / 3;
      z[x] = zs[(size_t)sy * ws + sx];
      l[x] = ls[(size_t)sy * ws + sx];
    }
  }
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < (int)H; y++) {
    const int sy = y / 3;
    const int up = sy > 0 ? sy - 1 : sy, down = sy < hs - 1 ? sy + 1 : sy;
    const float *restrict z0 = zr + (size_t)sy * rw + GRADIENT_REP_PAD,
                          *restrict l0 = lr + (size_t)sy * rw + GRADIENT_REP_PAD;
    const float *restrict zu = zr + (size_t)up * rw + GRADIENT_REP_PAD,
                          *restrict lu = lr + (size_t)up * rw + GRADIENT_REP_PAD;
    const float *restrict zd = zr + (size_t)down * rw + GRADIENT_REP_PAD,
                          *restrict ld = lr + (size_t)down * rw + GRADIENT_REP_PAD;
    const float *restrict d = depth + (size_t)y * W;
    float *restrict out = lambda + (size_t)y * W;
#pragma omp simd
    for (int x = 0; x < (int)W; x++) {
      const float p = d[x];
      float best = fabsf(p - z0[x]), l = l0[x];
#define GRADIENT_CANDIDATE(zrow, lrow, o)                   \
  {                                                         \
    const float dist = fabsf(p - zrow[x + (o)]);            \
    const int nearer = dist < best;                         \
    l = hush__select_bits(nearer, lrow[x + (o)], l);        \
    best = hush__select_bits(nearer, dist, best);           \
  }
      GRADIENT_CANDIDATE(zu, lu, -3)
      GRADIENT_CANDIDATE(zu, lu, 0)
      GRADIENT_CANDIDATE(zu, lu, 3)
      GRADIENT_CANDIDATE(z0, l0, -3)
      GRADIENT_CANDIDATE(z0, l0, 3)
      GRADIENT_CANDIDATE(zd, ld, -3)
      GRADIENT_CANDIDATE(zd, ld, 0)
      GRADIENT_CANDIDATE(zd, ld, 3)
#undef GRADIENT_CANDIDATE
      out[x] = l;
    }
  }
}

void hush__gradient_lambda(const float *const gradient[3], const hush_gradient_guides *guides,
                           uint32_t width, uint32_t height, const hush_gradient_params *params,
                           float *scratch, float *lambda, int threads) {
  if (threads < 1) threads = 1;
  int ws, hs;
  grid_size(width, height, &ws, &hs);
  const size_t S = (size_t)ws * hs;
  float *g[G_PLANES];
  for (int k = 0; k < G_PLANES; k++) g[k] = scratch + (size_t)k * S;
  gather(gradient, guides, width, height, params->sigma_l, g, threads);

  int iterations = params->iterations;
  iterations = iterations < 0 ? 0 : iterations;
  iterations =
      iterations > HUSH_GRADIENT_MAX_ITERATIONS ? HUSH_GRADIENT_MAX_ITERATIONS : iterations;
  level_ctx L;
  L.ws = ws;
  L.hs = hs;
  L.sigma_z = params->sigma_z;
  L.sigma_n = params->sigma_n;
  L.pow2 = power_of_two(params->sigma_n);
  L.l = g[G_LAMBDA];
  L.g = (const float *const *)g;
  int cur = 0; /* 0: G_D0.., 1: G_D1.. */
  for (int i = 0; i < iterations; i++) {
    const int in = cur ? G_D1 : G_D0, out = cur ? G_D0 : G_D1;
    L.step = 1 << i;
    L.d = g[in];
    L.n = g[in + 1];
    L.v = g[in + 2];
    L.od = g[out];
    L.on = g[out + 1];
    L.ov = g[out + 2];
    level(&L, threads);
    cur = 1 - cur;
  }
  const int fin = cur ? G_D1 : G_D0;
  stratum_lambda(g[fin], g[fin + 1], g[fin + 2], S, params->exponent, params->threshold,
                 g[G_LAMBDA], threads);
  float *zr = scratch + (size_t)G_PLANES * S, *lr = zr + (size_t)hs * rep_row(width);
  expand(g[G_LAMBDA], g[G_Z], ws, hs, guides->depth, width, height, zr, lr, lambda, threads);
}

/* ---- history --------------------------------------------------------------- */

size_t hush__gradient_lower_age(const float *lambda, const float *age, float *lowered, size_t n,
                                hush_history_rule rule, float alpha, int max_age, int threads) {
  if (threads < 1) threads = 1;
  const float cap = (float)(max_age < 1 ? 1 : max_age);
  const int higginson = rule == HUSH_HISTORY_HIGGINSON;
  size_t count = 0;
#pragma omp parallel for simd schedule(static) num_threads(threads) reduction(+ : count)
  for (size_t i = 0; i < n; i++) {
    const float N = age[i];
    const float Nc = N > 1.0f ? N : 1.0f; /* an age below 1 (no data) counts as 1 */
    float l = lambda[i];
    l = l > 0.0f ? (l < 1.0f ? l : 1.0f) : 0.0f;
    const float base = alpha > 1.0f / Nc ? alpha : 1.0f / Nc;
    /* schied */
    const float a_s = (1.0f - l) * base + l;
    /* higginson: N' = (N - 1)(1 - l)^10 + 1 (N counts this frame already) */
    const float t = 1.0f - l, t2 = t * t, t4 = t2 * t2, t10 = t4 * t4 * t2;
    float Np = (Nc - 1.0f) * t10 + 1.0f;
    Np = Np < cap ? Np : cap;
    const float a_h = t / Np + l;
    const float a = higginson ? a_h : a_s;
    const int lower = a > base;
    const float inv = 1.0f / a; /* a > base > 0 where used */
    lowered[i] = lower ? (inv < N ? inv : N) : N;
    count += (size_t)lower;
  }
  return count;
}
