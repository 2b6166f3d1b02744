/*
 * atrous.c — one edge-avoiding a-trous level of SVGF (see atrous.h;
 * Dundr 2018 §4.1.4, Schied et al. 2017).
 */
#include "filters/svgf/atrous.h"

#include "core/hmath.h"
#include "core/stream.h"
#include "core/timer.h"

#include <omp.h>
#include <sched.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

const svgf_kernel svgf_kernel_5x5 = {2, {1.0f / 16, 1.0f / 4, 3.0f / 8, 1.0f / 4, 1.0f / 16}};
const svgf_kernel svgf_kernel_3x3 = {1, {1.0f / 4, 1.0f / 2, 1.0f / 4, 0.0f, 0.0f}};

/* (2 * 2 + 1)^2 - 1 taps in mirrored pairs */
#define MAX_PAIRS 12
/* A weight is 0 when its exponent s (of 2^-s, the kernel weight h folded
 * in as -log2 h) is past the floor plus -log2 h: at or below e^-20 times h
 * (weights.h on why a floor). */
#define S_FLOOR (20.0f * SVGF_LOG2E)

typedef struct tap_pair {
  int dx, dy;   /* tap a = (x + dx, y + dy), tap b = (x - dx, y - dy) */
  float fdx, fdy;
  float h;      /* kernel weight, the same for both */
  float nlh;    /* -log2 h */
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
      t->nlh = -log2f(t->h);
    }
  return n;
}

static inline int clampi(int v, int lo, int hi) { return v < lo ? lo : v > hi ? hi : v; }

/* What the pixel loop of a level reads, resolved once per level. */
typedef struct level_ctx {
  const svgf_guide *g;
  const svgf_padded *in;
  const svgf_level_out *out;
  float sigma_l;
  const float *eps_l;
  float h0;          /* centre kernel weight */
  float bias;        /* exp normal weight: sigma_n log2 e; else 0 */
  float nscale;      /* exp normal weight: sigma_n log2 e; else 1 */
  tap_pair pairs[MAX_PAIRS];
  int npairs;
  int two; /* AVX-512 loop: two vectors of pixels at a time (avx_vectors) */
} level_ctx;

/* Pixels per pass of the portable row loop (its stack buffers). */
#define ROW_CHUNK 512

/* Per row: the offsets of both taps of every pair from the pixel, in
 * floats (rows clamped at the frame's border; columns by the padding). The
 * guide and the signal share the stride (svgf.c pads them alike). */
typedef struct row_offsets {
  ptrdiff_t a[MAX_PAIRS], b[MAX_PAIRS];
} row_offsets;

static void offsets_of(const level_ctx *c, int npairs, int y, row_offsets *o) {
  const int H = c->g->height;
  const ptrdiff_t stride = (ptrdiff_t)c->in->stride;
  for (int k = 0; k < npairs; k++) {
    const tap_pair *t = &c->pairs[k];
    o->a[k] = (ptrdiff_t)(clampi(y + t->dy, 0, H - 1) - y) * stride + t->dx;
    o->b[k] = (ptrdiff_t)(clampi(y - t->dy, 0, H - 1) - y) * stride - t->dx;
  }
}

/* The pads of the written part [xa, xb) of output row o (a float offset):
 * the left one from the part holding pixel 0, the right one from the part
 * holding pixel W-1 (the wavefront splits rows between threads). */
static void pad_written(const svgf_level_out *out, size_t o, int W, int xa, int xb) {
  if (out->pad <= 0) return;
  for (int ch = 0; ch < SVGF_SIGNAL_CHANNELS; ch++)
    if (out->plane[ch]) svgf_pad_row_sides(out->plane[ch] + o, W, out->pad, xa == 0, xb == W);
}

/*
 * One tap: its exponent s = (|dz| rdd + |dl| inv_l) + -log2 h (+ the normal
 * term with NORMAL_EXP), then the weight. NORMAL_EXP: w_n =
 * 2^(-sigma_n log2 e (1 - n_p . n_q)), the first-order form of max(0, n_p .
 * n_q)^sigma_n (both vanish away from dot 1; they differ by at most 0.0021
 * at sigma_n 128): the dot joins the exponent's fma chain, with the normal
 * at p pre-scaled by sigma_n log2 e, and costs no power; NORMAL_EXP 2: the
 * same with the fast weight (weight_exp=fast, svgf_exp2_neg_fast). Else the
 * exact power as weights.h's svgf_tap_weight.
 */
#define TAP(OFF)                                                                            \
  do {                                                                                      \
    const ptrdiff_t q = x + (OFF);                                                          \
    float s = fmaf(fabsf(zp - z[q]), rdd, fmaf(fabsf(lp - l[q]), inv_l, t_bias));           \
    float w;                                                                                \
    if (NORMAL_EXP) {                                                                       \
      s = fmaf(-n0p, n0[q], fmaf(-n1p, n1[q], fmaf(-n2p, n2[q], s)));                       \
      const float e = NORMAL_EXP == 2 ? svgf_exp2_neg_fast(s) : svgf_exp2_neg4(s);          \
      w = hush__select_bits(s < t_floor, e, 0.0f);                                          \
    } else {                                                                                \
      const float dot = fmaf(n0p, n0[q], fmaf(n1p, n1[q], n2p * n2[q]));                    \
      w = svgf_tap_weight(s, dot, SQUARINGS, sigma_n_log2e, dot_floor, &unit_poly);         \
    }                                                                                       \
    if (VALIDITY) w *= ok[q];                                                               \
    sw += w;                                                                                \
    s0 = fmaf(w, c0[q], s0);                                                                \
    s1 = fmaf(w, c1[q], s1);                                                                \
    s2 = fmaf(w, c2[q], s2);                                                                \
    sv = fmaf(w * w, v[q], sv);                                                             \
  } while (0)

/*
 * Row y of one level: per pixel, every tap of the kernel with the sums in
 * registers (no block arrays: the loads are the 9 tap planes only). NPAIRS,
 * NORMAL_EXP, SQUARINGS and VALIDITY are literals at every call, so the pair
 * loop unrolls into straight-line code that the pixel loop vectorises.
 */
static HUSH_ALWAYS_INLINE void level_row(const level_ctx *c, int y, int xa, int xb,
                                         const int NPAIRS, const int NORMAL_EXP,
                                         const int SQUARINGS, const int VALIDITY) {
  const svgf_guide *g = c->g;
  const svgf_padded *in = c->in;
  const int W = g->width, H = g->height;
  row_offsets off;
  offsets_of(c, NPAIRS, y, &off);
  const size_t gi = (size_t)y * g->zn->stride, si = (size_t)y * in->stride;
  const float *restrict z = g->zn->plane[0] + gi, *restrict n0 = g->zn->plane[1] + gi,
                        *restrict n1 = g->zn->plane[2] + gi, *restrict n2 = g->zn->plane[3] + gi;
  const float *restrict l = in->plane[SVGF_LUM] + si, *restrict c0 = in->plane[SVGF_R] + si,
                        *restrict c1 = in->plane[SVGF_G] + si, *restrict c2 = in->plane[SVGF_B] + si,
                        *restrict v = in->plane[SVGF_VAR] + si;
  const float *restrict ok = VALIDITY ? in->plane[SVGF_VALID] + si : NULL;
  const float *restrict vu = svgf_padded_row(in, SVGF_VAR, y > 0 ? y - 1 : y);
  const float *restrict vd = svgf_padded_row(in, SVGF_VAR, y < H - 1 ? y + 1 : y);
  const size_t pi = (size_t)y * W;
  const float *restrict gx = g->gx + pi, *restrict gy = g->gy + pi, *restrict zon = g->zon + pi;
  const float *restrict eps = c->eps_l ? c->eps_l + pi : NULL;
  const size_t o = svgf_level_out_row(c->out, y);
  float *restrict out_r = c->out->plane[SVGF_R] + o, *restrict out_g = c->out->plane[SVGF_G] + o,
                  *restrict out_b = c->out->plane[SVGF_B] + o;
  float *restrict out_v = c->out->plane[SVGF_VAR] ? c->out->plane[SVGF_VAR] + o : NULL;
  float *restrict also_r = c->out->also[0] ? c->out->also[0] + pi : NULL;
  float *restrict also_g = c->out->also[0] ? c->out->also[1] + pi : NULL;
  float *restrict also_b = c->out->also[0] ? c->out->also[2] + pi : NULL;
  float *restrict out_l = c->out->plane[SVGF_LUM] ? c->out->plane[SVGF_LUM] + o : NULL;
  float *restrict out_ok =
      VALIDITY && c->out->plane[SVGF_VALID] ? c->out->plane[SVGF_VALID] + o : NULL;
  const float sigma_l = c->sigma_l, sigma_z = g->sigma_z, h0 = c->h0, nscale = c->nscale;
  const float bias = c->bias;
  const float sigma_n_log2e = g->np.sigma_n_log2e, dot_floor = g->np.dot_floor;
  const svgf_exp2_poly unit_poly = svgf_exp2_poly_scaled(1.0f);
  float fdx[MAX_PAIRS], fdy[MAX_PAIRS], nlh[MAX_PAIRS];
  for (int k = 0; k < NPAIRS; k++) {
    fdx[k] = c->pairs[k].fdx;
    fdy[k] = c->pairs[k].fdy;
    nlh[k] = c->pairs[k].nlh;
  }
  /* The pixel loop has no branch (gcc vectorises no loop with one, which
   * without AVX-512's masked stores left it scalar): the optional outputs
   * go to chunk buffers copied out after it, the optional epsilon comes
   * from a buffer of the constant. */
  float eps_k[ROW_CHUNK], ok_b[ROW_CHUNK], var_b[ROW_CHUNK];
  if (!eps)
    for (int i = 0; i < ROW_CHUNK; i++) eps_k[i] = SVGF_EPS_L;
  for (int x0 = xa; x0 < xb; x0 += ROW_CHUNK) {
    const int x1 = xb - x0 > ROW_CHUNK ? x0 + ROW_CHUNK : xb;
    const float *restrict ep = eps ? eps + x0 : eps_k;
#pragma omp simd
    for (int x = x0; x < x1; x++) {
      /* the luminance weight's scale: the 3x3 Gaussian of the variance */
      const float hu = fmaf(0.5f, vu[x], 0.25f * (vu[x - 1] + vu[x + 1]));
      const float hm = fmaf(0.5f, v[x], 0.25f * (v[x - 1] + v[x + 1]));
      const float hd = fmaf(0.5f, vd[x], 0.25f * (vd[x - 1] + vd[x + 1]));
      const float var3 = fmaf(0.5f, hm, 0.25f * (hu + hd));
      const float dl = fmaf(sigma_l, svgf_sqrt_pos(var3), ep[x - x0]);
      float inv_l = SVGF_LOG2E * svgf_rcp_pos(dl < 1e30f ? dl : 1e30f);
      /* a pixel without data has no luminance to compare: weight 1 */
      if (VALIDITY) inv_l *= ok[x];
      /* the gradient within +-1e20 (NaN taken as 1e20): every denominator,
       * at most 1e20 times the largest offset, is in svgf_rcp2_pos's range */
      const float ax = sigma_z * gx[x], ay = sigma_z * gy[x];
      const float cx = ax < 1e20f ? ax : 1e20f, cy = ay < 1e20f ? ay : 1e20f;
      const float sgx = cx > -1e20f ? cx : -1e20f, sgy = cy > -1e20f ? cy : -1e20f;
      const float zl = zon[x] * SVGF_LOG2E;
      const float zp = z[x], lp = l[x];
      const float n0p = nscale * n0[x], n1p = nscale * n1[x], n2p = nscale * n2[x];
      /* the centre tap: every edge-stopping weight is 1 */
      const float hp = VALIDITY ? h0 * ok[x] : h0;
      float sw = hp, s0 = hp * c0[x], s1 = hp * c1[x], s2 = hp * c2[x], sv = hp * hp * v[x];
#pragma GCC unroll 12
      for (int k = 0; k < NPAIRS; k++) {
        /* both taps of a pair see the same |grad z . (q - p)| */
        const float rdd = zl * svgf_rcp2_pos(fabsf(fmaf(sgx, fdx[k], sgy * fdy[k])) + SVGF_EPS_Z);
        const float t_bias = bias + nlh[k], t_floor = S_FLOOR + nlh[k];
        TAP(off.a[k]);
        TAP(off.b[k]);
      }
      int some = 1;
      if (VALIDITY) {
        /* nothing valid in reach: stays a hole (0, not valid) */
        some = sw > 0.0f;
        ok_b[x - x0] = hush__select_bits(some, 1.0f, 0.0f);
        sw = hush__select_bits(some, sw, 1.0f);
        sv = hush__select_bits(some, sv, 0.0f);
      }
      const float inv = 1.0f / sw;
      const float r = s0 * inv, gr = s1 * inv, b = s2 * inv;
      out_r[x] = r;
      out_g[x] = gr;
      out_b[x] = b;
      var_b[x - x0] = sv * inv * inv;
    }
    if (out_ok) memcpy(out_ok + x0, ok_b, (size_t)(x1 - x0) * sizeof *out_ok);
    if (out_v) memcpy(out_v + x0, var_b, (size_t)(x1 - x0) * sizeof *out_v);
  }
  const size_t n = (size_t)(xb - xa);
  if (also_r) {
    memcpy(also_r + xa, out_r + xa, n * sizeof *also_r);
    memcpy(also_g + xa, out_g + xa, n * sizeof *also_g);
    memcpy(also_b + xa, out_b + xa, n * sizeof *also_b);
  }
  if (out_l)
    for (int x = xa; x < xb; x++) out_l[x] = hush_luminance(out_r[x], out_g[x], out_b[x]);
  pad_written(c->out, o, W, xa, xb);
}

#if (defined(__AVX512F__) || (defined(__AVX2__) && defined(__FMA__))) && defined(__x86_64__)
/* What the intrinsic loops below (AVX-512, else AVX2) read for a row. */
#include <immintrin.h>

typedef struct avx_pair {
  ptrdiff_t a, b;       /* tap offsets in floats (row_offsets) */
  float fdx, fdy;
  float nbias, nfloor;  /* -(bias - log2 h), -(S_FLOOR - log2 h) */
  int32_t bfloor;       /* the fast weight's bits at nfloor (svgf_avx2_exp2_fast) */
  float ubias;          /* nbias in the fast weight's units, biased (avx_setup) */
  float ufloor;         /* bfloor as a float, the AVX-512 loop's fast floor */
} avx_pair;

/* The planes of a row, at pixel 0 of that row. */
typedef struct avx_row {
  const float *z, *n0, *n1, *n2, *l, *c0, *c1, *c2, *v, *ok;
} avx_row;

/* The row planes advanced to pixel x. */
static HUSH_ALWAYS_INLINE avx_row avx_row_at(const avx_row *r, int x, const int VALIDITY) {
  avx_row rx = *r;
  rx.z += x; rx.n0 += x; rx.n1 += x; rx.n2 += x; rx.l += x;
  rx.c0 += x; rx.c1 += x; rx.c2 += x; rx.v += x;
  if (VALIDITY) rx.ok += x;
  return rx;
}

/* Row y of a level as the vector loops take it. */
typedef struct avx_args {
  avx_row r;
  const float *vu, *vd, *gx, *gy, *zon, *eps;
  float *out[SVGF_SIGNAL_CHANNELS];
  float *also[3];
  size_t o; /* the row's offset in the output planes */
  avx_pair pairs[MAX_PAIRS];
  int npairs;
} avx_args;

static void avx_args_of(const level_ctx *c, int y, int validity, avx_args *a) {
  const svgf_guide *g = c->g;
  const svgf_padded *in = c->in;
  const int W = g->width, H = g->height;
  a->npairs = c->npairs;
  row_offsets off;
  offsets_of(c, a->npairs, y, &off);
  for (int k = 0; k < a->npairs; k++) {
    a->pairs[k].a = off.a[k];
    a->pairs[k].b = off.b[k];
    a->pairs[k].fdx = c->pairs[k].fdx;
    a->pairs[k].fdy = c->pairs[k].fdy;
    a->pairs[k].nbias = -(c->bias + c->pairs[k].nlh);
    a->pairs[k].nfloor = -(S_FLOOR + c->pairs[k].nlh);
    a->pairs[k].bfloor = svgf_fast_exp_bits(a->pairs[k].nfloor);
    a->pairs[k].ubias = fmaf(a->pairs[k].nbias, SVGF_FAST_EXP_UNIT, SVGF_FAST_EXP_BIAS);
    a->pairs[k].ufloor = (float)a->pairs[k].bfloor;
  }
  const size_t gi = (size_t)y * g->zn->stride, si = (size_t)y * in->stride;
  a->r.z = g->zn->plane[0] + gi;
  a->r.n0 = g->zn->plane[1] + gi;
  a->r.n1 = g->zn->plane[2] + gi;
  a->r.n2 = g->zn->plane[3] + gi;
  a->r.l = in->plane[SVGF_LUM] + si;
  a->r.c0 = in->plane[SVGF_R] + si;
  a->r.c1 = in->plane[SVGF_G] + si;
  a->r.c2 = in->plane[SVGF_B] + si;
  a->r.v = in->plane[SVGF_VAR] + si;
  a->r.ok = validity ? in->plane[SVGF_VALID] + si : NULL;
  a->vu = svgf_padded_row(in, SVGF_VAR, y > 0 ? y - 1 : y);
  a->vd = svgf_padded_row(in, SVGF_VAR, y < H - 1 ? y + 1 : y);
  const size_t pi = (size_t)y * W;
  a->gx = g->gx + pi;
  a->gy = g->gy + pi;
  a->zon = g->zon + pi;
  a->eps = c->eps_l ? c->eps_l + pi : NULL;
  a->o = svgf_level_out_row(c->out, y);
  for (int ch = 0; ch < SVGF_SIGNAL_CHANNELS; ch++)
    a->out[ch] = c->out->plane[ch] ? c->out->plane[ch] + a->o : NULL;
  for (int ch = 0; ch < 3; ch++) a->also[ch] = c->out->also[0] ? c->out->also[ch] + pi : NULL;
}

/* the variance is carried only where the level writes it (not the last);
 * FAST: the fast weight (weight_exp=fast) */
#define AVX_ROW(NAME, VALIDITY, WITH_VAR, FAST)                                              \
  static void NAME(const level_ctx *c, int y, int xa, int xb) {                              \
    avx_level_row(c, y, xa, xb, VALIDITY, WITH_VAR, FAST);                                   \
  }
#define AVX_ROWS                                                                             \
  AVX_ROW(avx_row_plain, 0, 1, 0)                                                            \
  AVX_ROW(avx_row_valid, 1, 1, 0)                                                            \
  AVX_ROW(avx_row_novar, 0, 0, 0)                                                            \
  AVX_ROW(avx_row_valid_novar, 1, 0, 0)                                                      \
  AVX_ROW(avx_row_plain_fast, 0, 1, 1)                                                       \
  AVX_ROW(avx_row_valid_fast, 1, 1, 1)                                                       \
  AVX_ROW(avx_row_novar_fast, 0, 0, 1)                                                       \
  AVX_ROW(avx_row_valid_novar_fast, 1, 0, 1)
#endif

#if defined(__AVX512F__) && defined(__x86_64__)
/*
 * The default level (exp normal weight) in AVX-512 intrinsics. The portable
 * loop above is what GCC makes of it: with every tap unrolled it keeps 216
 * tap addresses on the stack and reloads one per vector load, and each
 * select costs two operations. Here the pair loop stays a loop (9 plane
 * bases in registers, one offset per tap), the weight floor is the zero
 * mask of the last operation of the exp, 2^x is vreduceps + a degree-3
 * polynomial + vscalefps (weights.h), and the depth denominators use
 * vrcp14ps (relative error 2^-14 in an exponent). The exponent is carried
 * negated, t = -s. Same weights as the portable loop within 1e-4 relative
 * (tests/test_svgf.c compares both with the formulas).
 */
/* The sums of one vector of 16 pixels. */
typedef struct avx_sums {
  __m512 sw, s0, s1, s2, sv;
} avx_sums;

/* One vector of 16 pixels: what its taps need, and its sums. */
typedef struct avx_px {
  __m512 zp, lp, n0p, n1p, n2p, inv_l, sgx, sgy, zl;
  __mmask16 surface; /* lanes with a surface (normal not 0) */
  avx_sums acc;
} avx_px;

/* The exponent t (of the weight 2^t) of the tap at offset off from the
 * vector at x. FULL: all 16 lanes in the row (plain loads); else the loads
 * are masked by m. With the fast weight t is in its units (avx_setup). */
static HUSH_ALWAYS_INLINE __m512 avx_tap_exponent(const avx_row *r, ptrdiff_t off, __m512 rdd,
                                                  const avx_px *p, __m512 nbias, __mmask16 m,
                                                  const int FULL) {
#define LD(P) (FULL ? _mm512_loadu_ps((P) + off) : _mm512_maskz_loadu_ps(m, (P) + off))
  const __m512 dz = _mm512_abs_ps(_mm512_sub_ps(p->zp, LD(r->z)));
  const __m512 dl = _mm512_abs_ps(_mm512_sub_ps(p->lp, LD(r->l)));
  __m512 t = _mm512_fnmadd_ps(dl, p->inv_l, nbias);
  t = _mm512_fnmadd_ps(dz, rdd, t);
  t = _mm512_fmadd_ps(p->n0p, LD(r->n0), t);
  t = _mm512_fmadd_ps(p->n1p, LD(r->n1), t);
  return _mm512_fmadd_ps(p->n2p, LD(r->n2), t);
#undef LD
}

/* The weight of the tap at offset off from its exponent t, added to the
 * sums. */
static HUSH_ALWAYS_INLINE void avx_tap_add(const avx_row *r, ptrdiff_t off, __m512 t,
                                           const avx_pair *pr, avx_px *p, __mmask16 m,
                                           const int FULL, const int VALIDITY,
                                           const int WITH_VAR, const int FAST) {
#define LD(P) (FULL ? _mm512_loadu_ps((P) + off) : _mm512_maskz_loadu_ps(m, (P) + off))
  /* NaN compares false: weight 0 */
  __m512 w;
  if (FAST) {
    w = svgf_avx_exp2_fast_biased(_mm512_cmp_ps_mask(t, _mm512_set1_ps(pr->ufloor), _CMP_GT_OQ), t);
  } else {
    const __mmask16 keep = _mm512_cmp_ps_mask(t, _mm512_set1_ps(pr->nfloor), _CMP_GT_OQ);
    w = _mm512_maskz_scalef_ps(keep, svgf_avx_exp2_frac(t), t);
  }
  if (VALIDITY) w = _mm512_mul_ps(w, LD(r->ok));
  p->acc.sw = _mm512_add_ps(p->acc.sw, w);
  p->acc.s0 = _mm512_fmadd_ps(w, LD(r->c0), p->acc.s0);
  p->acc.s1 = _mm512_fmadd_ps(w, LD(r->c1), p->acc.s1);
  p->acc.s2 = _mm512_fmadd_ps(w, LD(r->c2), p->acc.s2);
  if (WITH_VAR) p->acc.sv = _mm512_fmadd_ps(_mm512_mul_ps(w, w), LD(r->v), p->acc.sv);
#undef LD
}

/* One tap: its exponent, then its weight and sums. */
static HUSH_ALWAYS_INLINE void avx_tap(const avx_row *r, ptrdiff_t off, __m512 rdd, avx_px *p,
                                       const avx_pair *pr, __mmask16 m, const int FULL,
                                       const int VALIDITY, const int WITH_VAR, const int FAST) {
  const __m512 bias = _mm512_set1_ps(FAST ? pr->ubias : pr->nbias);
  const __m512 t = avx_tap_exponent(r, off, rdd, p, bias, m, FULL);
  avx_tap_add(r, off, t, pr, p, m, FULL, VALIDITY, WITH_VAR, FAST);
}

/* The per-pixel terms of the 16 pixels from x (n of them, n < 16 only at
 * the row's end, m their mask) and the centre tap's sums. */
static HUSH_ALWAYS_INLINE void avx_setup(const level_ctx *c, const avx_row *r, const float *vu,
                                         const float *vd, const float *gx, const float *gy,
                                         const float *zon, const float *eps, int x,
                                         __mmask16 m, const int FULL, const int VALIDITY,
                                         const int FAST, avx_px *p) {
#define LDX(P, OFF) (FULL ? _mm512_loadu_ps((P) + x + (OFF)) : _mm512_maskz_loadu_ps(m, (P) + x + (OFF)))
  const __m512 q = _mm512_set1_ps(0.25f), h = _mm512_set1_ps(0.5f);
  const __m512 hu = _mm512_fmadd_ps(h, LDX(vu, 0), _mm512_mul_ps(q, _mm512_add_ps(LDX(vu, -1), LDX(vu, 1))));
  const __m512 hm = _mm512_fmadd_ps(h, LDX(r->v, 0), _mm512_mul_ps(q, _mm512_add_ps(LDX(r->v, -1), LDX(r->v, 1))));
  const __m512 hd = _mm512_fmadd_ps(h, LDX(vd, 0), _mm512_mul_ps(q, _mm512_add_ps(LDX(vd, -1), LDX(vd, 1))));
  const __m512 var3 = _mm512_max_ps(_mm512_fmadd_ps(h, hm, _mm512_mul_ps(q, _mm512_add_ps(hu, hd))),
                                    _mm512_setzero_ps());
  const __m512 e = eps ? LDX(eps, 0) : _mm512_set1_ps(SVGF_EPS_L);
  /* sqrt(v) = v / sqrt(v) by vrsqrt14ps and a Newton step (0 for 0: v is
   * kept above 1e-30 inside the reciprocal only) */
  const __m512 vs = _mm512_max_ps(var3, _mm512_set1_ps(1e-30f));
  __m512 rs = _mm512_rsqrt14_ps(vs);
  rs = _mm512_mul_ps(_mm512_mul_ps(_mm512_set1_ps(0.5f), rs),
                     _mm512_fnmadd_ps(_mm512_mul_ps(vs, rs), rs, _mm512_set1_ps(3.0f)));
  const __m512 sd = _mm512_mul_ps(var3, rs);
  const __m512 dl = _mm512_min_ps(_mm512_fmadd_ps(_mm512_set1_ps(c->sigma_l), sd, e),
                                  _mm512_set1_ps(1e30f));
  /* FAST: the exponent's terms in the fast weight's units, so that the tap
   * sums u = t 2^23 + bias directly (the bias in the pair's ubias): one
   * fused multiply-add fewer per tap (as the AVX2 loop's) */
  const float unit = FAST ? SVGF_FAST_EXP_UNIT : 1.0f;
  p->inv_l = _mm512_mul_ps(_mm512_set1_ps(SVGF_LOG2E * unit), svgf_avx_rcp(dl));
  if (VALIDITY) p->inv_l = _mm512_mul_ps(p->inv_l, LDX(r->ok, 0));
  const __m512 sz = _mm512_set1_ps(c->g->sigma_z);
  p->sgx = _mm512_max_ps(_mm512_min_ps(_mm512_mul_ps(sz, LDX(gx, 0)), _mm512_set1_ps(1e20f)),
                         _mm512_set1_ps(-1e20f));
  p->sgy = _mm512_max_ps(_mm512_min_ps(_mm512_mul_ps(sz, LDX(gy, 0)), _mm512_set1_ps(1e20f)),
                         _mm512_set1_ps(-1e20f));
  p->zl = _mm512_mul_ps(LDX(zon, 0), _mm512_set1_ps(SVGF_LOG2E * unit));
  p->zp = LDX(r->z, 0);
  p->lp = LDX(r->l, 0);
  const __m512 ns = _mm512_set1_ps(c->nscale * unit);
  p->n0p = _mm512_mul_ps(ns, LDX(r->n0, 0));
  p->n1p = _mm512_mul_ps(ns, LDX(r->n1, 0));
  p->n2p = _mm512_mul_ps(ns, LDX(r->n2, 0));
  p->surface = (_mm512_cmp_ps_mask(p->n0p, _mm512_setzero_ps(), _CMP_NEQ_UQ) |
                _mm512_cmp_ps_mask(p->n1p, _mm512_setzero_ps(), _CMP_NEQ_UQ) |
                _mm512_cmp_ps_mask(p->n2p, _mm512_setzero_ps(), _CMP_NEQ_UQ)) & m;
  const __m512 h0 = _mm512_set1_ps(c->h0);
  const __m512 hp = VALIDITY ? _mm512_mul_ps(h0, LDX(r->ok, 0)) : h0;
  p->acc.sw = hp;
  p->acc.s0 = _mm512_mul_ps(hp, LDX(r->c0, 0));
  p->acc.s1 = _mm512_mul_ps(hp, LDX(r->c1, 0));
  p->acc.s2 = _mm512_mul_ps(hp, LDX(r->c2, 0));
  p->acc.sv = _mm512_mul_ps(_mm512_mul_ps(hp, hp), LDX(r->v, 0));
#undef LDX
}

/* The depth factor of pair t for the vector p (both taps of a pair see the
 * same |grad z . (q - p)|). */
static HUSH_ALWAYS_INLINE __m512 avx_rdd(const avx_px *p, const avx_pair *t) {
  const __m512 a = _mm512_fmadd_ps(p->sgx, _mm512_set1_ps(t->fdx), _mm512_mul_ps(p->sgy, _mm512_set1_ps(t->fdy)));
  return _mm512_mul_ps(p->zl, _mm512_rcp14_ps(_mm512_add_ps(_mm512_abs_ps(a), _mm512_set1_ps(SVGF_EPS_Z))));
}

/* The sums of p normalised and stored for the pixels from x (mask m). */
static HUSH_ALWAYS_INLINE void avx_finish(const avx_px *p, int x, __mmask16 m,
                                          float *const out[SVGF_SIGNAL_CHANNELS],
                                          float *const also[3], const int VALIDITY,
                                          const int WITH_VAR) {
  __m512 sw = p->acc.sw, sv = p->acc.sv;
  if (VALIDITY) {
    /* nothing valid in reach: stays a hole (0, not valid) */
    const __mmask16 some = _mm512_cmp_ps_mask(sw, _mm512_setzero_ps(), _CMP_GT_OQ);
    if (out[SVGF_VALID])
      _mm512_mask_storeu_ps(out[SVGF_VALID] + x, m, _mm512_maskz_mov_ps(some, _mm512_set1_ps(1.0f)));
    sw = _mm512_mask_mov_ps(_mm512_set1_ps(1.0f), some, sw);
    sv = _mm512_maskz_mov_ps(some, sv);
  }
  const __m512 inv = svgf_avx_rcp(sw);
  const __m512 rr = _mm512_mul_ps(p->acc.s0, inv), gg = _mm512_mul_ps(p->acc.s1, inv),
               bb = _mm512_mul_ps(p->acc.s2, inv);
  _mm512_mask_storeu_ps(out[SVGF_R] + x, m, rr);
  _mm512_mask_storeu_ps(out[SVGF_G] + x, m, gg);
  _mm512_mask_storeu_ps(out[SVGF_B] + x, m, bb);
  if (also[0]) {
    /* the colour history: read again only by the next frame's
     * accumulation, so whole aligned lines are streamed (no read for
     * ownership; core/stream.h); avx_level_row fences the row */
    if (m == (__mmask16)0xffff && (((uintptr_t)(also[0] + x) | (uintptr_t)(also[1] + x) |
                                    (uintptr_t)(also[2] + x)) % 64) == 0) {
      _mm512_stream_ps(also[0] + x, rr);
      _mm512_stream_ps(also[1] + x, gg);
      _mm512_stream_ps(also[2] + x, bb);
    } else {
      _mm512_mask_storeu_ps(also[0] + x, m, rr);
      _mm512_mask_storeu_ps(also[1] + x, m, gg);
      _mm512_mask_storeu_ps(also[2] + x, m, bb);
    }
  }
  if (WITH_VAR)
    _mm512_mask_storeu_ps(out[SVGF_VAR] + x, m, _mm512_mul_ps(_mm512_mul_ps(sv, inv), inv));
  if (out[SVGF_LUM]) {
    const __m512 lum = _mm512_add_ps(
        _mm512_add_ps(_mm512_mul_ps(_mm512_set1_ps(0.2126f), rr), _mm512_mul_ps(_mm512_set1_ps(0.7152f), gg)),
        _mm512_mul_ps(_mm512_set1_ps(0.0722f), bb));
    _mm512_mask_storeu_ps(out[SVGF_LUM] + x, m, lum);
  }
}

/*
 * The vectors of 16 pixels at x and, with TWO, at x + 16 (both full), their
 * taps interleaved pair by pair: each tap is a chain of about 15 dependent
 * operations, and two independent vectors in flight keep more of them
 * ready for the two vector ports (same operations per lane: same bits).
 * That pays on Intel's cores with two 512-bit FMA ports; on AMD's Zen 4,
 * which runs a 512-bit operation on both halves of its 256-bit pipes, one
 * vector at a time is faster (avx_two_vectors).
 * Else the 16 pixels at x (n of them, n < 16 only at the row's end).
 * A vector with no surface under any pixel (the sky: normal 0) skips its
 * taps when sigma_n log2 e >= S_FLOOR (sigma_n >= 20): each tap's exponent
 * is then at most nbias, below its weight floor, so every tap would weigh
 * exactly 0 and leave the sums as they are (same bits).
 */
static HUSH_ALWAYS_INLINE void avx_vectors(const level_ctx *c, const avx_row *r, const float *vu,
                                           const float *vd, const float *gx, const float *gy,
                                           const float *zon, const float *eps,
                                           const avx_pair *pairs, int npairs, int x, int n,
                                           float *const out[SVGF_SIGNAL_CHANNELS],
                                           float *const also[3], const int TWO, const int FULL,
                                           const int VALIDITY, const int WITH_VAR,
                                           const int FAST) {
  const __mmask16 m = FULL ? (__mmask16)0xffff : (__mmask16)((1u << n) - 1u);
  avx_px p0, p1;
  avx_setup(c, r, vu, vd, gx, gy, zon, eps, x, m, FULL, VALIDITY, FAST, &p0);
  if (TWO) avx_setup(c, r, vu, vd, gx, gy, zon, eps, x + 16, m, 1, VALIDITY, FAST, &p1);
  const int sky_skip = c->bias >= S_FLOOR;
  const avx_row rx = avx_row_at(r, x, VALIDITY);
  /* the bottom tap row's lines ahead, as the AVX2 loop's (avx_vector):
   * a-trous 11.1 -> 10.0 ms at 640x360 on one thread on Zen 4 (16 or 64
   * pixels ahead the same; docs/svgf-speed.md, twenty-fifth round) */
  const ptrdiff_t ahead = (pairs[npairs - 1].a + SVGF_PREFETCH_AHEAD) * (ptrdiff_t)sizeof(float);
  const float *const ahead_of[9] = {rx.z, rx.n0, rx.n1, rx.n2, rx.l, rx.c0, rx.c1, rx.c2, rx.v};
  hush__prefetch_planes(ahead_of, 9, ahead);
  if (VALIDITY) hush__prefetch(rx.ok, ahead);
  if (TWO && (p0.surface || p1.surface || !sky_skip)) {
    for (int k = 0; k < npairs; k++) {
      const avx_pair *t = &pairs[k];
      const __m512 rdd0 = avx_rdd(&p0, t), rdd1 = avx_rdd(&p1, t);
      avx_tap(&rx, t->a, rdd0, &p0, t, m, 1, VALIDITY, WITH_VAR, FAST);
      avx_tap(&rx, t->a + 16, rdd1, &p1, t, m, 1, VALIDITY, WITH_VAR, FAST);
      avx_tap(&rx, t->b, rdd0, &p0, t, m, 1, VALIDITY, WITH_VAR, FAST);
      avx_tap(&rx, t->b + 16, rdd1, &p1, t, m, 1, VALIDITY, WITH_VAR, FAST);
    }
  } else if (!TWO && (p0.surface || !sky_skip)) {
    for (int k = 0; k < npairs; k++) {
      const avx_pair *t = &pairs[k];
      const __m512 rdd0 = avx_rdd(&p0, t);
      avx_tap(&rx, t->a, rdd0, &p0, t, m, FULL, VALIDITY, WITH_VAR, FAST);
      avx_tap(&rx, t->b, rdd0, &p0, t, m, FULL, VALIDITY, WITH_VAR, FAST);
    }
  }
  avx_finish(&p0, x, m, out, also, VALIDITY, WITH_VAR);
  if (TWO) avx_finish(&p1, x + 16, m, out, also, VALIDITY, WITH_VAR);
}

static HUSH_ALWAYS_INLINE void avx_level_row(const level_ctx *c, int y, int xa, int xb,
                                             const int VALIDITY, const int WITH_VAR,
                                             const int FAST) {
  avx_args a;
  avx_args_of(c, y, VALIDITY, &a);
  const int npairs = a.npairs;
  int x = xa;
  if (c->two)
    for (; x + 32 <= xb; x += 32)
      avx_vectors(c, &a.r, a.vu, a.vd, a.gx, a.gy, a.zon, a.eps, a.pairs, npairs, x, 32, a.out,
                  a.also, 1, 1, VALIDITY, WITH_VAR, FAST);
  for (; x + 16 <= xb; x += 16)
    avx_vectors(c, &a.r, a.vu, a.vd, a.gx, a.gy, a.zon, a.eps, a.pairs, npairs, x, 16, a.out,
                a.also, 0, 1, VALIDITY, WITH_VAR, FAST);
  if (x < xb)
    avx_vectors(c, &a.r, a.vu, a.vd, a.gx, a.gy, a.zon, a.eps, a.pairs, npairs, x, xb - x, a.out,
                a.also, 0, 0, VALIDITY, WITH_VAR, FAST);
  pad_written(c->out, a.o, c->g->width, xa, xb);
  if (a.also[0]) hush__stream_fence(); /* the streamed history before the row is done */
}

/* Whether the AVX-512 loop takes two vectors of pixels at a time (lp's
 * vectors: 0 this CPU's choice). On Intel's Sapphire Rapids two were 3 %
 * faster (docs/svgf-speed.md, sixth round); on AMD's Zen 4 one at a time
 * is 18-25 % faster (eighth round). The result is the same bits. */
static int avx_two_vectors(int vectors) {
  return vectors ? vectors == 2 : !__builtin_cpu_is("amd");
}

AVX_ROWS
#define HAVE_AVX_LEVEL 1
#elif defined(__AVX2__) && defined(__FMA__) && defined(__x86_64__)
/*
 * The default level (exp normal weight) in AVX2 + FMA intrinsics, for
 * x86-64-v3 builds (AVX2 CPUs without AVX-512): the AVX-512 loop above on
 * vectors of 8 pixels, with what AVX2 lacks spelled out: the weight floor
 * as a compare and an AND, 2^floor(t) added into the exponent bits
 * (vscalefps), the fraction t - floor(t) by vroundps (vreduceps), masked
 * loads and stores at a row's end; the per-pixel square root and the depth
 * denominators are exact (vsqrtps, vdivps: on Zen 3 the divider is idle
 * otherwise, where vrcpps with a Newton step took three operations of the
 * FMA pipes per pair). In a v3 build on
 * the Zen 4 VM the a-trous stage went from 98-108 to 83-84 ms (2 threads,
 * 1280x720; docs/svgf-speed.md, tenth round). The same formulas as the
 * portable loop within the tests' tolerance (tests/test_svgf.c), not its
 * bits.
 */

/* One vector of 8 pixels: what its taps need, and its sums. */
typedef struct avx_px {
  __m256 zp, lp, n0p, n1p, n2p, inv_l, sgx, sgy, zl;
  int surface; /* some lane has a surface (normal not 0) */
  __m256 sw, s0, s1, s2, sv;
} avx_px;

/* The exponent t (of the weight 2^t) of the tap at offset off. FULL: all 8
 * lanes in the row; else the loads are masked by m (lanes with the sign bit
 * set). */
static HUSH_ALWAYS_INLINE __m256 avx_tap_exponent(const avx_row *r, ptrdiff_t off, __m256 rdd,
                                                  const avx_px *p, __m256 nbias, __m256i m,
                                                  const int FULL) {
#define LD(P) (FULL ? _mm256_loadu_ps((P) + off) : _mm256_maskload_ps((P) + off, m))
  const __m256 dz = svgf_avx2_abs(_mm256_sub_ps(p->zp, LD(r->z)));
  const __m256 dl = svgf_avx2_abs(_mm256_sub_ps(p->lp, LD(r->l)));
  __m256 t = _mm256_fnmadd_ps(dl, p->inv_l, nbias);
  t = _mm256_fnmadd_ps(dz, rdd, t);
  t = _mm256_fmadd_ps(p->n0p, LD(r->n0), t);
  t = _mm256_fmadd_ps(p->n1p, LD(r->n1), t);
  return _mm256_fmadd_ps(p->n2p, LD(r->n2), t);
#undef LD
}

/* The weight of the tap at offset off from its exponent t, added to the
 * sums. */
static HUSH_ALWAYS_INLINE void avx_tap_add(const avx_row *r, ptrdiff_t off, __m256 t,
                                           const avx_pair *pr, avx_px *p, __m256i m,
                                           const int FULL, const int VALIDITY,
                                           const int WITH_VAR, const int FAST) {
#define LD(P) (FULL ? _mm256_loadu_ps((P) + off) : _mm256_maskload_ps((P) + off, m))
  __m256 w = FAST ? svgf_avx2_exp2_fast_biased(t, _mm256_set1_epi32(pr->bfloor))
                  : svgf_avx2_exp2_floored(t, _mm256_set1_ps(pr->nfloor));
  if (VALIDITY) w = _mm256_mul_ps(w, LD(r->ok));
  p->sw = _mm256_add_ps(p->sw, w);
  p->s0 = _mm256_fmadd_ps(w, LD(r->c0), p->s0);
  p->s1 = _mm256_fmadd_ps(w, LD(r->c1), p->s1);
  p->s2 = _mm256_fmadd_ps(w, LD(r->c2), p->s2);
  if (WITH_VAR) p->sv = _mm256_fmadd_ps(_mm256_mul_ps(w, w), LD(r->v), p->sv);
#undef LD
}

/* The per-pixel terms of the 8 pixels from x and the centre tap's sums. */
static HUSH_ALWAYS_INLINE void avx_setup(const level_ctx *c, const avx_row *r, const float *vu,
                                         const float *vd, const float *gx, const float *gy,
                                         const float *zon, const float *eps, int x, __m256i m,
                                         const int FULL, const int VALIDITY, const int FAST,
                                         avx_px *p) {
#define LDX(P, OFF) (FULL ? _mm256_loadu_ps((P) + x + (OFF)) : _mm256_maskload_ps((P) + x + (OFF), m))
  const __m256 q = _mm256_set1_ps(0.25f), h = _mm256_set1_ps(0.5f);
  const __m256 hu = _mm256_fmadd_ps(h, LDX(vu, 0), _mm256_mul_ps(q, _mm256_add_ps(LDX(vu, -1), LDX(vu, 1))));
  const __m256 hm = _mm256_fmadd_ps(h, LDX(r->v, 0), _mm256_mul_ps(q, _mm256_add_ps(LDX(r->v, -1), LDX(r->v, 1))));
  const __m256 hd = _mm256_fmadd_ps(h, LDX(vd, 0), _mm256_mul_ps(q, _mm256_add_ps(LDX(vd, -1), LDX(vd, 1))));
  const __m256 var3 = _mm256_max_ps(_mm256_fmadd_ps(h, hm, _mm256_mul_ps(q, _mm256_add_ps(hu, hd))),
                                    _mm256_setzero_ps());
  const __m256 e = eps ? LDX(eps, 0) : _mm256_set1_ps(SVGF_EPS_L);
  /* an exact square root and division: each one operation on its own
   * unit, where vrsqrtps with two Newton steps and vrcpps with one took 11
   * operations of the FMA pipes at every vector's start (a-trous 4.1 ->
   * 3.9 ms at 320x180 on one thread; docs/svgf-speed.md, eighteenth
   * round) */
  const __m256 sd = _mm256_sqrt_ps(var3);
  const __m256 dl = _mm256_min_ps(_mm256_fmadd_ps(_mm256_set1_ps(c->sigma_l), sd, e),
                                  _mm256_set1_ps(1e30f));
  /* FAST: the exponent's terms in the fast weight's units, so that the tap
   * sums u = t 2^23 + bias directly (the bias in the pair's ubias): one
   * fused multiply-add fewer per tap (docs/svgf-speed.md, twenty-fourth
   * round) */
  const float unit = FAST ? SVGF_FAST_EXP_UNIT : 1.0f;
  p->inv_l = _mm256_div_ps(_mm256_set1_ps(SVGF_LOG2E * unit), dl);
  if (VALIDITY) p->inv_l = _mm256_mul_ps(p->inv_l, LDX(r->ok, 0));
  const __m256 sz = _mm256_set1_ps(c->g->sigma_z);
  p->sgx = _mm256_max_ps(_mm256_min_ps(_mm256_mul_ps(sz, LDX(gx, 0)), _mm256_set1_ps(1e20f)),
                         _mm256_set1_ps(-1e20f));
  p->sgy = _mm256_max_ps(_mm256_min_ps(_mm256_mul_ps(sz, LDX(gy, 0)), _mm256_set1_ps(1e20f)),
                         _mm256_set1_ps(-1e20f));
  p->zl = _mm256_mul_ps(LDX(zon, 0), _mm256_set1_ps(SVGF_LOG2E * unit));
  p->zp = LDX(r->z, 0);
  p->lp = LDX(r->l, 0);
  const __m256 ns = _mm256_set1_ps(c->nscale * unit);
  p->n0p = _mm256_mul_ps(ns, LDX(r->n0, 0));
  p->n1p = _mm256_mul_ps(ns, LDX(r->n1, 0));
  p->n2p = _mm256_mul_ps(ns, LDX(r->n2, 0));
  const __m256 zero = _mm256_setzero_ps();
  const __m256 surf = _mm256_or_ps(_mm256_or_ps(_mm256_cmp_ps(p->n0p, zero, _CMP_NEQ_UQ),
                                                _mm256_cmp_ps(p->n1p, zero, _CMP_NEQ_UQ)),
                                   _mm256_cmp_ps(p->n2p, zero, _CMP_NEQ_UQ));
  p->surface = _mm256_movemask_ps(_mm256_and_ps(surf, _mm256_castsi256_ps(m))) != 0;
  const __m256 h0 = _mm256_set1_ps(c->h0);
  const __m256 hp = VALIDITY ? _mm256_mul_ps(h0, LDX(r->ok, 0)) : h0;
  p->sw = hp;
  p->s0 = _mm256_mul_ps(hp, LDX(r->c0, 0));
  p->s1 = _mm256_mul_ps(hp, LDX(r->c1, 0));
  p->s2 = _mm256_mul_ps(hp, LDX(r->c2, 0));
  p->sv = _mm256_mul_ps(_mm256_mul_ps(hp, hp), LDX(r->v, 0));
#undef LDX
}

/* The depth factor of pair t (a division: a-trous 4.0 -> 3.8 ms at 320x180
 * on one thread against vrcpps and a Newton step). */
static HUSH_ALWAYS_INLINE __m256 avx_rdd(const avx_px *p, const avx_pair *t) {
  const __m256 a = _mm256_fmadd_ps(p->sgx, _mm256_set1_ps(t->fdx), _mm256_mul_ps(p->sgy, _mm256_set1_ps(t->fdy)));
  return _mm256_div_ps(p->zl, _mm256_add_ps(svgf_avx2_abs(a), _mm256_set1_ps(SVGF_EPS_Z)));
}

static HUSH_ALWAYS_INLINE void avx2_store(float *p, __m256 v, __m256i m, const int FULL) {
  if (FULL)
    _mm256_storeu_ps(p, v);
  else
    _mm256_maskstore_ps(p, m, v);
}

/* The sums of p normalised and stored for the pixels from x (mask m). */
static HUSH_ALWAYS_INLINE void avx_finish(const avx_px *p, int x, __m256i m,
                                          float *const out[SVGF_SIGNAL_CHANNELS],
                                          float *const also[3], const int FULL,
                                          const int VALIDITY, const int WITH_VAR) {
  __m256 sw = p->sw, sv = p->sv;
  if (VALIDITY) {
    /* nothing valid in reach: stays a hole (0, not valid) */
    const __m256 some = _mm256_cmp_ps(sw, _mm256_setzero_ps(), _CMP_GT_OQ);
    if (out[SVGF_VALID])
      avx2_store(out[SVGF_VALID] + x, _mm256_and_ps(some, _mm256_set1_ps(1.0f)), m, FULL);
    sw = _mm256_blendv_ps(_mm256_set1_ps(1.0f), sw, some);
    sv = _mm256_and_ps(sv, some);
  }
  const __m256 inv = svgf_avx2_rcp(sw);
  const __m256 rr = _mm256_mul_ps(p->s0, inv), gg = _mm256_mul_ps(p->s1, inv),
               bb = _mm256_mul_ps(p->s2, inv);
  avx2_store(out[SVGF_R] + x, rr, m, FULL);
  avx2_store(out[SVGF_G] + x, gg, m, FULL);
  avx2_store(out[SVGF_B] + x, bb, m, FULL);
  if (also[0]) {
    avx2_store(also[0] + x, rr, m, FULL);
    avx2_store(also[1] + x, gg, m, FULL);
    avx2_store(also[2] + x, bb, m, FULL);
  }
  if (WITH_VAR) avx2_store(out[SVGF_VAR] + x, _mm256_mul_ps(_mm256_mul_ps(sv, inv), inv), m, FULL);
  if (out[SVGF_LUM]) {
    const __m256 lum = _mm256_add_ps(
        _mm256_add_ps(_mm256_mul_ps(_mm256_set1_ps(0.2126f), rr), _mm256_mul_ps(_mm256_set1_ps(0.7152f), gg)),
        _mm256_mul_ps(_mm256_set1_ps(0.0722f), bb));
    avx2_store(out[SVGF_LUM] + x, lum, m, FULL);
  }
}

/* The 8 pixels from x (n of them, n < 8 only at the row's end). A vector
 * without a surface skips its taps as the AVX-512 loop's does. */
static HUSH_ALWAYS_INLINE void avx_vector(const level_ctx *c, const avx_row *r, const float *vu,
                                          const float *vd, const float *gx, const float *gy,
                                          const float *zon, const float *eps,
                                          const avx_pair *pairs, int npairs, int x, int n,
                                          float *const out[SVGF_SIGNAL_CHANNELS],
                                          float *const also[3], const int FULL,
                                          const int VALIDITY, const int WITH_VAR,
                                          const int FAST) {
  const __m256i m = _mm256_cmpgt_epi32(_mm256_set1_epi32(FULL ? 8 : n),
                                       _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
  avx_px p;
  avx_setup(c, r, vu, vd, gx, gy, zon, eps, x, m, FULL, VALIDITY, FAST, &p);
  const avx_row rx = avx_row_at(r, x, VALIDITY);
  /* The taps' bottom row (y + 2 step) is the one this row reads first of
   * all rows (the others were bottom rows of earlier ones); its lines
   * SVGF_PREFETCH_AHEAD pixels past the rightmost tap are asked for ahead
   * of its 9 streams, which the hardware prefetchers did not keep up
   * with: a-trous 40.3-40.6 -> 38.4-39.2 ms at 1280x720 on 2 threads
   * (Zen 3; docs/svgf-speed.md, twenty-first round; the tap rows y + step
   * as well, or 64 or 128 pixels ahead: no better). Past the last row the
   * address lies outside the planes (hush__prefetch). */
  const ptrdiff_t ahead = (pairs[npairs - 1].a + SVGF_PREFETCH_AHEAD) * (ptrdiff_t)sizeof(float);
  const float *const ahead_of[9] = {rx.z, rx.n0, rx.n1, rx.n2, rx.l, rx.c0, rx.c1, rx.c2, rx.v};
  hush__prefetch_planes(ahead_of, 9, ahead);
  if (VALIDITY) hush__prefetch(rx.ok, ahead);
  if (p.surface || c->bias < S_FLOOR) {
    /* Every tap's exponent first, then the weights and sums in the same
     * order: the same operations as one tap after another, so the same
     * bits. Each tap is a chain of about 20 dependent operations; in tap
     * order Zen 3 ran 20 cycles a tap in L1 (about 8 of operations), as
     * the out-of-order window filled with operations waiting on each
     * other. Pipelined one pair ahead, 15; with the 24 exponents apart,
     * which depend on nothing but loads, the window fills with independent
     * work (a-trous 4.9 -> 4.1 ms at 320x180 on one thread;
     * docs/svgf-speed.md, eighteenth round). */
    __m256 t[2 * MAX_PAIRS];
    for (int k = 0; k < npairs; k++) {
      const __m256 rdd = avx_rdd(&p, &pairs[k]);
      const __m256 bias = _mm256_set1_ps(FAST ? pairs[k].ubias : pairs[k].nbias);
      t[2 * k] = avx_tap_exponent(&rx, pairs[k].a, rdd, &p, bias, m, FULL);
      t[2 * k + 1] = avx_tap_exponent(&rx, pairs[k].b, rdd, &p, bias, m, FULL);
    }
    for (int k = 0; k < npairs; k++) {
      avx_tap_add(&rx, pairs[k].a, t[2 * k], &pairs[k], &p, m, FULL, VALIDITY, WITH_VAR, FAST);
      avx_tap_add(&rx, pairs[k].b, t[2 * k + 1], &pairs[k], &p, m, FULL, VALIDITY, WITH_VAR,
                  FAST);
    }
  }
  avx_finish(&p, x, m, out, also, FULL, VALIDITY, WITH_VAR);
}

static HUSH_ALWAYS_INLINE void avx_level_row(const level_ctx *c, int y, int xa, int xb,
                                             const int VALIDITY, const int WITH_VAR,
                                             const int FAST) {
  avx_args a;
  avx_args_of(c, y, VALIDITY, &a);
  int x = xa;
  for (; x + 8 <= xb; x += 8)
    avx_vector(c, &a.r, a.vu, a.vd, a.gx, a.gy, a.zon, a.eps, a.pairs, a.npairs, x, 8, a.out,
               a.also, 1, VALIDITY, WITH_VAR, FAST);
  if (x < xb)
    avx_vector(c, &a.r, a.vu, a.vd, a.gx, a.gy, a.zon, a.eps, a.pairs, a.npairs, x, xb - x, a.out,
               a.also, 0, VALIDITY, WITH_VAR, FAST);
  pad_written(c->out, a.o, c->g->width, xa, xb);
}

/* One vector of pixels at a time (lp's vectors is for the AVX-512 loop). */
static int avx_two_vectors(int vectors) {
  (void)vectors;
  return 0;
}

AVX_ROWS
#define HAVE_AVX_LEVEL 1
#else
#define HAVE_AVX_LEVEL 0
#endif

#define LEVEL_ROW(NAME, NPAIRS, NORMAL_EXP, SQUARINGS, VALIDITY)                             \
  static void NAME(const level_ctx *c, int y, int xa, int xb) {                               \
    level_row(c, y, xa, xb, NPAIRS, NORMAL_EXP, SQUARINGS, VALIDITY);                         \
  }
/* 5x5 (12 pairs) and 3x3 (4 pairs); the normal weight as exp (default;
 * with the fast weight: _fast), as the exact power 128 by squarings, or
 * any sigma_n through the log */
LEVEL_ROW(row5_exp, 12, 1, 0, 0)
LEVEL_ROW(row5_exp_valid, 12, 1, 0, 1)
LEVEL_ROW(row5_pow128, 12, 0, 7, 0)
LEVEL_ROW(row5_pow128_valid, 12, 0, 7, 1)
LEVEL_ROW(row5_any, 12, 0, -1, 0)
LEVEL_ROW(row5_any_valid, 12, 0, -1, 1)
LEVEL_ROW(row3_exp, 4, 1, 0, 0)
LEVEL_ROW(row3_exp_valid, 4, 1, 0, 1)
LEVEL_ROW(row3_pow128, 4, 0, 7, 0)
LEVEL_ROW(row3_pow128_valid, 4, 0, 7, 1)
LEVEL_ROW(row3_any, 4, 0, -1, 0)
LEVEL_ROW(row3_any_valid, 4, 0, -1, 1)
LEVEL_ROW(row5_exp_fast, 12, 2, 0, 0)
LEVEL_ROW(row5_exp_fast_valid, 12, 2, 0, 1)
LEVEL_ROW(row3_exp_fast, 4, 2, 0, 0)
LEVEL_ROW(row3_exp_fast_valid, 4, 2, 0, 1)

/* The first column of part `part` out of `parts` of a row of W pixels,
 * on a 32-pixel boundary (the AVX-512 loop's pairs of vectors). */
static int part_edge(int W, int part, int parts) {
  const long long x = ((long long)W * part / parts + 31) / 32 * 32;
  return x < W ? (int)x : W;
}

/* Pixels [xa, xb) of row y of a level. */
typedef void (*row_fn)(const level_ctx *c, int y, int xa, int xb);

/* c <- what level lp reads and writes; returns its row function. */
static row_fn level_init(level_ctx *c, const svgf_guide *g, const svgf_level_params *lp,
                         const svgf_padded *in, const svgf_level_out *out) {
  c->g = g;
  c->in = in;
  c->out = out;
  c->sigma_l = lp->sigma_l;
  c->eps_l = lp->eps_l;
  const float hc = lp->kernel->h[lp->kernel->radius];
  c->h0 = hc * hc;
  const int npairs = tap_pairs(lp->kernel, lp->step, c->pairs);
  c->npairs = npairs;
  c->two = 0;
  const int exp_form = lp->normal_exp;
  c->bias = exp_form ? g->np.sigma_n_log2e : 0.0f;
  c->nscale = exp_form ? g->np.sigma_n_log2e : 1.0f;
  const int pow128 = g->np.squarings == 7, v = lp->validity, fast = lp->fast_exp;
#if HAVE_AVX_LEVEL
  if (exp_form && !lp->portable) {
    c->two = avx_two_vectors(lp->vectors);
    if (out->plane[SVGF_VAR]) {
      if (fast) return v ? avx_row_valid_fast : avx_row_plain_fast;
      return v ? avx_row_valid : avx_row_plain;
    }
    if (fast) return v ? avx_row_valid_novar_fast : avx_row_novar_fast;
    return v ? avx_row_valid_novar : avx_row_novar;
  }
#endif
  if (npairs == 12) {
    if (exp_form && fast) return v ? row5_exp_fast_valid : row5_exp_fast;
    if (exp_form) return v ? row5_exp_valid : row5_exp;
    if (pow128) return v ? row5_pow128_valid : row5_pow128;
    return v ? row5_any_valid : row5_any;
  }
  if (exp_form && fast) return v ? row3_exp_fast_valid : row3_exp_fast;
  if (exp_form) return v ? row3_exp_valid : row3_exp;
  if (pow128) return v ? row3_pow128_valid : row3_pow128;
  return v ? row3_any_valid : row3_any;
}

void svgf_atrous_level(const svgf_guide *g, const svgf_level_params *lp, const svgf_padded *in,
                       const svgf_level_out *out, int threads) {
  level_ctx c;
  const row_fn row = level_init(&c, g, lp, in, out);
  const int W = g->width, H = g->height;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < H; y++) {
    row(&c, y, 0, W);
    if (out->span_done) out->span_done(out->span_ctx, y, 0, W);
  }
}

/*
 * The wavefront (atrous.h). Level k runs row y at time y + lag[k]; lag[k]
 * = lag[k-1] + reach + 1 + SVGF_WAVEFRONT_SLACK with reach = radius *
 * max(step k, step k-1), so that at that time level k-1 has written every
 * row level k reads (y +- radius * step k, and the variance's y +- 1) and
 * has read for the last time the rows of its input that level k
 * overwrites (level k writes the buffer level k-2 wrote), even in the part
 * of a thread up to SVGF_WAVEFRONT_SLACK times behind. The rows run at one
 * time are of different levels and touch disjoint rows, so they run
 * together; each is split into one column part per thread, thread i
 * always taking part i (it keeps its part's rows in its own L2). Instead
 * of a barrier per time, a thread starts the block of times t0..t1-1
 * once every other has finished time t1 - 2 - SVGF_WAVEFRONT_SLACK
 * (wave_wait: what a row of time t needs done in another part, the lags
 * put at time t - 1 - SVGF_WAVEFRONT_SLACK or before): the parts of a row
 * never take exactly the same time (the sky skips its taps, misses
 * differ), and with a barrier the faster thread waited at every row, 6-7 %
 * of the a-trous on the bench's frames (docs/svgf-speed.md, thirteenth
 * round); the slack lets the threads drift apart by a block instead and
 * the differences average out.
 *
 * Within a block a thread runs level after level, SVGF_WAVEFRONT_BLOCK
 * rows of each (any order of a time's rows is correct: every level reads
 * only rows its predecessor finished times before). One row of each level
 * in turn broke each level's 45 tap streams at every row; in blocks of 4
 * the a-trous took 5 % less on the Zen 3 (2 threads, 1280x720:
 * docs/svgf-speed.md, eighteenth round).
 *
 * The split moves (wave_edge): on a shared machine one core is often
 * slower than the other for seconds at a time (2 threads on the Zen 3 VM:
 * one thread waited 8-22 ms of a 60-75 ms a-trous in some runs, none in
 * others), and with fixed halves the faster one waits for it at every
 * row. Each part keeps its time per column (a running mean over the last
 * ~8 times); every WAVE_PERIOD times the split between two parts moves by
 * 32 columns towards the point where both would take as long, when that
 * is over WAVE_DEADBAND columns away (differences between the parts' rows
 * average out within the slack; following them cost more than it saved).
 * With one core slowed by 30 % (a spin in the thread, for the test): a-trous
 * 64.4 -> 59.0 ms; unloaded, the same as fixed halves within the noise
 * (docs/svgf-speed.md, seventeenth round). The rows of a time are split
 * alike for every level, and every pixel is computed the same way whatever
 * its part, so the split changes no bit.
 */

/* Times per decision on the split; how far (columns) the balance point
 * must be for the split to move. */
#define WAVE_PERIOD 8
#define WAVE_DEADBAND 64
_Static_assert(WAVE_PERIOD % SVGF_WAVEFRONT_BLOCK == 0, "a split holds for whole blocks");

/* One thread's progress, on a cache line of its own (no false sharing
 * between the spinning readers and the other threads' lines): the last
 * time it finished; its part's width then and its time per column (float
 * bits; 0 until measured). */
typedef struct wave_progress {
  _Alignas(64) atomic_int done;
  atomic_int width;
  atomic_uint cost;
} wave_progress;

/* The state the threads share. edge[e * (parts + 1) + i]: column where
 * part i starts at the times e * period .. (e + 1) * period - 1 (-1 until
 * decided; part parts starts at W). */
typedef struct wave_ctx {
  wave_progress *progress;
  atomic_int *edge;
  int parts, W;
  int period; /* times per decision */
  unsigned jitter;
} wave_ctx;

/* Spins until every part but `self` has finished time `t` (a no-op for t <
 * 0). The acquire pairs with the release in wavefront: the rows a part
 * wrote up to that time are visible here. */
static void wave_wait(wave_progress *progress, int parts, int self, int t) {
  if (t < 0) return;
  for (int q = 0; q < parts; q++) {
    if (q == self) continue;
    for (unsigned spins = 0; atomic_load_explicit(&progress[q].done, memory_order_acquire) < t;
         spins++) {
#if defined(__x86_64__) || defined(__i386__)
      __builtin_ia32_pause();
#endif
      /* the other thread may have lost its core (more threads than cores,
       * or a busy host): do not keep this one from it */
      if (spins >= 4096) sched_yield();
    }
  }
}

static float bits_float(unsigned u) {
  float f;
  memcpy(&f, &u, sizeof f);
  return f;
}

static unsigned float_bits(float f) {
  unsigned u;
  memcpy(&u, &f, sizeof u);
  return u;
}

/* The middle of fixed part j, on a 32-column boundary. Edge i (0 < i <
 * parts) lies from the middle of part i - 1 to the middle of part i, so
 * the edges never cross, and on 32-column boundaries (every part keeps the
 * AVX-512 loop's pairs of vectors). */
static int part_middle(const wave_ctx *w, int j) {
  return (int)((long long)w->W * (2 * j + 1) / (2 * w->parts) / 32 * 32);
}

static int edge_clamped(const wave_ctx *w, int i, int x) {
  const int lo = part_middle(w, i - 1), hi = part_middle(w, i);
  return x < lo ? lo : x > hi ? hi : x;
}

/* A random edge of period e in its range (jitter: tests). */
static int edge_jittered(const wave_ctx *w, int e, int i) {
  uint32_t h = w->jitter * 0x9E3779B1u ^ (uint32_t)e * 0x85EBCA77u ^ (uint32_t)i * 0xC2B2AE3Du;
  h ^= h >> 15;
  h *= 0x2C1B3C6Du;
  h ^= h >> 12;
  const int lo = part_middle(w, i - 1), hi = part_middle(w, i);
  return lo + (int)(h % (uint32_t)((hi - lo) / 32 + 1)) * 32;
}

/* Edge i of period e > 0 as the first of its two parts to reach it
 * proposes it: the last period's edge moved by 32 columns towards where
 * the parts' times per column say both would take as long, when that is
 * over WAVE_DEADBAND columns away. */
static int edge_proposed(const wave_ctx *w, int e, int i) {
  const int last = atomic_load_explicit(&w->edge[(size_t)(e - 1) * (w->parts + 1) + i],
                                        memory_order_relaxed);
  const wave_progress *a = &w->progress[i - 1], *b = &w->progress[i];
  const float ca = bits_float(atomic_load_explicit(&a->cost, memory_order_relaxed));
  const float cb = bits_float(atomic_load_explicit(&b->cost, memory_order_relaxed));
  if (!(ca > 0.0f && cb > 0.0f)) return last;
  /* the two parts' columns, split in inverse proportion to their costs */
  const int wa = atomic_load_explicit(&a->width, memory_order_relaxed);
  const int wb = atomic_load_explicit(&b->width, memory_order_relaxed);
  const float target = (float)(last - wa) + (float)(wa + wb) * (cb / (ca + cb));
  if (target > (float)(last + WAVE_DEADBAND)) return last + 32;
  if (target < (float)(last - WAVE_DEADBAND)) return last - 32;
  return last;
}

/* Where part i starts at time t (i = parts: the row's end). Decided once
 * per period and edge, by the first of its two parts to ask (every part
 * asks at the start of every period). */
static int wave_edge(const wave_ctx *w, int t, int i) {
  if (i == 0) return 0;
  if (i == w->parts) return w->W;
  const int e = t / w->period;
  atomic_int *slot = &w->edge[(size_t)e * (w->parts + 1) + i];
  int x = atomic_load_explicit(slot, memory_order_relaxed);
  if (x >= 0) return x;
  int proposal;
  if (w->jitter)
    proposal = edge_jittered(w, e, i);
  else if (e == 0)
    proposal = edge_clamped(w, i, part_edge(w->W, i, w->parts));
  else
    proposal = edge_clamped(w, i, edge_proposed(w, e, i));
  if (atomic_compare_exchange_strong_explicit(slot, &x, proposal, memory_order_relaxed,
                                              memory_order_relaxed))
    return proposal;
  return x;
}

/* A part's time per column (ms: one block's), the running mean over about
 * WAVE_PERIOD times. */
static void wave_measured(wave_progress *p, int width, double ms) {
  if (width <= 0) return;
  const float now = (float)(ms / width);
  const float was = bits_float(atomic_load_explicit(&p->cost, memory_order_relaxed));
  const float mean = was > 0.0f ? was + ((float)SVGF_WAVEFRONT_BLOCK / WAVE_PERIOD) * (now - was) : now;
  atomic_store_explicit(&p->cost, float_bits(mean), memory_order_relaxed);
  atomic_store_explicit(&p->width, width, memory_order_relaxed);
}

static void wavefront(const svgf_guide *g, const svgf_level_params *lp,
                      const svgf_padded *const *in, const svgf_level_out *const *out, int n,
                      int threads, unsigned jitter) {
  level_ctx c[SVGF_WAVEFRONT_LEVELS];
  row_fn row[SVGF_WAVEFRONT_LEVELS];
  int lag[SVGF_WAVEFRONT_LEVELS];
  for (int k = 0; k < n; k++) {
    row[k] = level_init(&c[k], g, &lp[k], in[k], out[k]);
    if (k == 0) {
      lag[k] = 0;
      continue;
    }
    const int step = lp[k].step > lp[k - 1].step ? lp[k].step : lp[k - 1].step;
    const int radius = lp[k].kernel->radius > lp[k - 1].kernel->radius ? lp[k].kernel->radius
                                                                        : lp[k - 1].kernel->radius;
    lag[k] = lag[k - 1] + radius * step + 1 + SVGF_WAVEFRONT_SLACK;
  }
  const int W = g->width, H = g->height, times = H + lag[n - 1];
  if (threads < 1) threads = 1;
  wave_ctx w;
  w.W = W;
  w.jitter = jitter;
  w.period = jitter ? SVGF_WAVEFRONT_BLOCK : WAVE_PERIOD;
  w.progress = aligned_alloc(_Alignof(wave_progress), (size_t)threads * sizeof(wave_progress));
  /* one set of edges per period (wave_edge) */
  const size_t edges = (size_t)(times / w.period + 1) * (size_t)(threads + 1);
  w.edge = malloc(edges * sizeof *w.edge);
  if (!w.progress || !w.edge) threads = 1; /* nothing to wait for with one part */
  for (int q = 0; w.progress && q < threads; q++) {
    atomic_init(&w.progress[q].done, -1);
    atomic_init(&w.progress[q].width, 0);
    atomic_init(&w.progress[q].cost, 0u);
  }
  for (size_t i = 0; w.edge && i < edges; i++) atomic_init(&w.edge[i], -1);
#pragma omp parallel num_threads(threads)
  {
    const int parts = omp_get_num_threads(), part = omp_get_thread_num();
#pragma omp single
    w.parts = parts;
    int xa = 0, xb = W;
    for (int t0 = 0; t0 < times; t0 += SVGF_WAVEFRONT_BLOCK) {
      const int t1 = t0 + SVGF_WAVEFRONT_BLOCK < times ? t0 + SVGF_WAVEFRONT_BLOCK : times;
      if (parts > 1) {
        wave_wait(w.progress, parts, part, t1 - 2 - SVGF_WAVEFRONT_SLACK);
        if (t0 % w.period == 0) {
          xa = wave_edge(&w, t0, part);
          xb = wave_edge(&w, t0, part + 1);
        }
      }
      const double start = parts > 1 ? hush__now_ms() : 0.0;
      for (int k = 0; k < n; k++)
        for (int t = t0; t < t1; t++) {
          const int y = t - lag[k];
          if (y >= 0 && y < H && xa < xb) {
            row[k](&c[k], y, xa, xb);
            if (out[k]->span_done) out[k]->span_done(out[k]->span_ctx, y, xa, xb);
          }
        }
      if (parts > 1) {
        wave_measured(&w.progress[part], xb - xa, hush__now_ms() - start);
        atomic_store_explicit(&w.progress[part].done, t1 - 1, memory_order_release);
      }
    }
  }
  free(w.progress);
  free(w.edge);
}

void svgf_atrous_wavefront(const svgf_guide *g, const svgf_level_params *lp,
                           const svgf_padded *const *in, const svgf_level_out *const *out, int n,
                           int threads, unsigned jitter) {
  for (int k = 0; k < n; k += SVGF_WAVEFRONT_LEVELS)
    wavefront(g, lp + k, in + k, out + k,
              n - k < SVGF_WAVEFRONT_LEVELS ? n - k : SVGF_WAVEFRONT_LEVELS, threads, jitter);
}

void svgf_atrous_levels(const svgf_guide *g, const svgf_level_params *lp,
                        const svgf_padded *const *in, const svgf_level_out *const *out, int n,
                        int threads) {
  if (svgf_atrous_levels_wavefront(g->width, g->height)) {
    svgf_atrous_wavefront(g, lp, in, out, n, threads, 0);
    return;
  }
  for (int k = 0; k < n; k++) svgf_atrous_level(g, &lp[k], in[k], out[k], threads);
}
