/*
 * taa.c — temporal anti-aliasing resolve; see taa.h. Karis 2014 (neighbourhood
 * clamp/clip in YCoCg, constant blend), as papers/NOTES.md summarises it.
 *
 * One pass over memory, per row: the rows the 3x3 box needs, modulated
 * and tone-mapped if asked, to YCoCg in a per-thread ring of three rows
 * (each source row converted once per band); then the history gathered
 * through the plan's 2x2 blocks, the box, clamp or clip, blend and inverse
 * tone mapping, in one vectorised loop over the interior columns (the two
 * border columns and the rare 3X3-footprint pixels go through the same
 * per-pixel function afterwards).
 */
#include "temporal/taa.h"

#include "filters/albedo.h"

#include <omp.h>
#include <string.h>

hush_status hush__taa_init(hush_device device, hush_taa *taa, uint32_t width, uint32_t height) {
  memset(taa, 0, sizeof *taa);
  hush_status s = hush__planar_init(device, &taa->history[0], 3, width, height);
  if (!s) s = hush__planar_init(device, &taa->history[1], 3, width, height);
  if (!s) s = hush__planar_init(device, &taa->current, 3, width, height);
  if (s) hush__taa_free(taa);
  return s;
}

void hush__taa_free(hush_taa *taa) {
  hush__planar_free(&taa->history[0]);
  hush__planar_free(&taa->history[1]);
  hush__planar_free(&taa->current);
  memset(taa, 0, sizeof *taa);
}

/* Tone mapping c / (1 + l) with l the Rec. 709 luminance, and its inverse
 * c / (1 - l) (l of the mapped colour, below 1). Scaling all channels by one
 * factor keeps the hue. */
static inline float tonemap_scale(float r, float g, float b) {
  const float l = 0.2126f * r + 0.7152f * g + 0.0722f * b;
  return 1.0f / (1.0f + (l > 0.0f ? l : 0.0f));
}
static inline float untonemap_scale(float r, float g, float b) {
  float l = 0.2126f * r + 0.7152f * g + 0.0722f * b;
  l = l > 0.0f ? l : 0.0f;
  l = l < 0.999999f ? l : 0.999999f; /* radiance luminance up to 1e6 */
  return 1.0f / (1.0f - l);
}

/* YCoCg (not normalised: Y = (r + 2g + b) / 4, Co = (r - b) / 2,
 * Cg = (-r + 2g - b) / 4) and back; a linear map, so a blend in either
 * space is the same. Scalars, not arrays: a per-lane array keeps a simd
 * loop from vectorising. */
static inline float ycocg_y(float r, float g, float b) { return 0.25f * r + 0.5f * g + 0.25f * b; }
static inline float ycocg_co(float r, float g, float b) { (void)g; return 0.5f * r - 0.5f * b; }
static inline float ycocg_cg(float r, float g, float b) { return -0.25f * r + 0.5f * g - 0.25f * b; }

static inline float minf(float a, float b) { return b < a ? b : a; }
static inline float maxf(float a, float b) { return b > a ? b : a; }
/* v < lo ? lo : v > hi ? hi : v for lo <= hi (the box's), signed zeros
 * included, as a min and a max: gcc made the nested selects compares and
 * masked moves */
static inline float clampf(float v, float lo, float hi) { return maxf(minf(v, hi), lo); }

/* What the per-pixel resolve of one row reads: the YCoCg planes' rows
 * above, at and below (clamped at the image border), the output rows. */
typedef struct taa_row {
  const float *up[3], *mid[3], *dn[3];
  float *out[3];
  float alpha;
  int tonemap, clip;
} taa_row;

/* The 3x3 box of component k around x (xl, xr its neighbours). */
static HUSH_ALWAYS_INLINE float box_min(const taa_row *t, int k, int x, int xl, int xr) {
  const float *u = t->up[k], *m = t->mid[k], *d = t->dn[k];
  return minf(minf(minf(u[xl], u[x]), minf(u[xr], m[xl])),
              minf(minf(m[x], m[xr]), minf(minf(d[xl], d[x]), d[xr])));
}
static HUSH_ALWAYS_INLINE float box_max(const taa_row *t, int k, int x, int xl, int xr) {
  const float *u = t->up[k], *m = t->mid[k], *d = t->dn[k];
  return maxf(maxf(maxf(u[xl], u[x]), maxf(u[xr], m[xl])),
              maxf(maxf(m[x], m[xr]), maxf(maxf(d[xl], d[x]), d[xr])));
}

/* Karis's clip_aabb, one axis: the fraction of the way from the box
 * centre to h that stays inside [lo, hi] (1: inside). */
static inline float clip_fraction(float h, float lo, float hi) {
  const float c = 0.5f * (lo + hi), e = 0.5f * (hi - lo) + 1e-7f;
  const float d = h - c;
  const float a = d > 0.0f ? d : -d;
  return a > e ? e / a : 1.0f;
}
static inline float clip_to(float h, float lo, float hi, float f) {
  const float c = 0.5f * (lo + hi);
  return c + (h - c) * f;
}

/* One pixel x of the row, its left and right neighbours xl and xr (x
 * itself at the border); has: the history (hr, hg, hb, linear) is valid.
 * Everything is computed and selected, without branches, so the interior
 * loop vectorises. */
static HUSH_ALWAYS_INLINE void resolve_pixel(const taa_row *t, const int clip, const int tonemap,
                                             int x, int xl, int xr, int has, float hr, float hg,
                                             float hb) {
  const float c0 = t->mid[0][x], c1 = t->mid[1][x], c2 = t->mid[2][x];
  const float lo0 = box_min(t, 0, x, xl, xr), lo1 = box_min(t, 1, x, xl, xr),
              lo2 = box_min(t, 2, x, xl, xr);
  const float hi0 = box_max(t, 0, x, xl, xr), hi1 = box_max(t, 1, x, xl, xr),
              hi2 = box_max(t, 2, x, xl, xr);
  /* the history is stored linear: map it like the current frame */
  const float s = tonemap ? tonemap_scale(hr, hg, hb) : 1.0f;
  hr *= s;
  hg *= s;
  hb *= s;
  float h0 = ycocg_y(hr, hg, hb), h1 = ycocg_co(hr, hg, hb), h2 = ycocg_cg(hr, hg, hb);
  if (clip) {
    const float f = minf(minf(clip_fraction(h0, lo0, hi0), clip_fraction(h1, lo1, hi1)),
                         minf(clip_fraction(h2, lo2, hi2), 1.0f));
    h0 = clip_to(h0, lo0, hi0, f);
    h1 = clip_to(h1, lo1, hi1, f);
    h2 = clip_to(h2, lo2, hi2, f);
  } else {
    h0 = clampf(h0, lo0, hi0);
    h1 = clampf(h1, lo1, hi1);
    h2 = clampf(h2, lo2, hi2);
  }
  const float a = t->alpha;
  const float m0 = has ? h0 + a * (c0 - h0) : c0, m1 = has ? h1 + a * (c1 - h1) : c1,
              m2 = has ? h2 + a * (c2 - h2) : c2;
  const float r = m0 + m1 - m2, g = m0 + m2, b = m0 - m1 - m2;
  const float u = tonemap ? untonemap_scale(r, g, b) : 1.0f;
  t->out[0][x] = r * u;
  t->out[1][x] = g * u;
  t->out[2][x] = b * u;
}

/* Pixel x of row y through the plan's taps (any footprint; NULL plan or
 * no taps: no history). */
static void resolve_taps(const taa_row *t, const hush_reproject_plan *plan, const float *const *prev,
                         int x, int y, int W) {
  float h[3] = {0.0f, 0.0f, 0.0f};
  int n = 0;
  if (plan) {
    int32_t idx[9];
    float w[9];
    n = hush__reproject_taps(plan, (size_t)y * W + x, idx, w);
    for (int k = 0; k < 3 && n; k++) h[k] = hush__reproject_apply(prev[k], idx, w, n);
  }
  resolve_pixel(t, t->clip, t->tonemap, x, x > 0 ? x - 1 : 0, x + 1 < W ? x + 1 : W - 1, n > 0,
                h[0], h[1], h[2]);
}

/* Columns x0..x0+n-1 of a row at offset row (interior: 1 <= x0,
 * x0 + n <= W - 1), every pixel as a 2x2 block: j[l] its block origin
 * (hush__reproject_block_origin), has[l] its kind is BILINEAR (else its
 * weights are 0 and it takes no history); the history gathered through
 * j, vectorised. clip and tonemap are constants in each instantiation, so
 * the loop computes only the variant asked for. */
static HUSH_ALWAYS_INLINE void span_gather(const taa_row *t, const hush_reproject_plan *plan,
                                           const float *const *prev, size_t row, int W, int x0,
                                           int n, const int32_t *restrict j,
                                           const int32_t *restrict has, const int clip,
                                           const int tonemap) {
  const int32_t Wi = (int32_t)W;
  const float *p0 = prev[0], *p1 = prev[1], *p2 = prev[2];
  const float *w0 = plan->w[0] + row + x0, *w1 = plan->w[1] + row + x0,
              *w2 = plan->w[2] + row + x0, *w3 = plan->w[3] + row + x0;
#pragma omp simd
  for (int l = 0; l < n; l++) {
    const int32_t i = j[l];
    const float hr = w0[l] * p0[i] + w1[l] * p0[i + 1] + w2[l] * p0[i + Wi] + w3[l] * p0[i + Wi + 1];
    const float hg = w0[l] * p1[i] + w1[l] * p1[i + 1] + w2[l] * p1[i + Wi] + w3[l] * p1[i + Wi + 1];
    const float hb = w0[l] * p2[i] + w1[l] * p2[i + 1] + w2[l] * p2[i + Wi] + w3[l] * p2[i + Wi + 1];
    resolve_pixel(t, clip, tonemap, x0 + l, x0 + l - 1, x0 + l + 1, has[l], hr, hg, hb);
  }
}

/* TAA_RUN columns from x0 whose block origins are b0, b0 + 1, ... (the
 * common case of smooth motion: the history's 2x2 taps are contiguous
 * vector loads instead of gathers), or with `two` each on one of two such
 * diagonals, b0 + l or b1 + l (reproject.h; each tap picked from two
 * vector loads). `every`: every pixel is BILINEAR (has[] is not read).
 * The same arithmetic as span_gather (a pixel without history weighs some
 * tap by 0, and resolve_pixel ignores it), so the same result bit for
 * bit. */
enum { TAA_RUN = 16 };
static HUSH_ALWAYS_INLINE void span_run(const taa_row *t, const hush_reproject_plan *plan,
                                        const float *const *prev, size_t row, int W, int x0,
                                        int32_t b0, int32_t b1, const int32_t *restrict has,
                                        const int two, const int every, const int clip,
                                        const int tonemap) {
  const int32_t Wi = (int32_t)W;
  const float *p0 = prev[0], *p1 = prev[1], *p2 = prev[2];
  const int32_t *origin = plan->origin + row + x0;
  const float *w0 = plan->w[0] + row + x0, *w1 = plan->w[1] + row + x0,
              *w2 = plan->w[2] + row + x0, *w3 = plan->w[3] + row + x0;
#pragma omp simd
  for (int l = 0; l < TAA_RUN; l++) {
    const int second = two & (origin[l] == b1 + l);
    const int32_t i = b0 + l, s = b1 + l;
#define TAP(p, d) (two ? hush__select_bits(second, (p)[s + (d)], (p)[i + (d)]) : (p)[i + (d)])
    const float hr = w0[l] * TAP(p0, 0) + w1[l] * TAP(p0, 1) + w2[l] * TAP(p0, Wi) + w3[l] * TAP(p0, Wi + 1);
    const float hg = w0[l] * TAP(p1, 0) + w1[l] * TAP(p1, 1) + w2[l] * TAP(p1, Wi) + w3[l] * TAP(p1, Wi + 1);
    const float hb = w0[l] * TAP(p2, 0) + w1[l] * TAP(p2, 1) + w2[l] * TAP(p2, Wi) + w3[l] * TAP(p2, Wi + 1);
#undef TAP
    resolve_pixel(t, clip, tonemap, x0 + l, x0 + l - 1, x0 + l + 1, every ? 1 : has[l], hr, hg,
                  hb);
  }
}

#ifdef HUSH_HAVE_WINDOW
_Static_assert(TAA_RUN == HUSH_WINDOW_MAX, "a TAA chunk is one window");
/* TAA_RUN columns from x0 whose 2x2 blocks form a window (reproject.h):
 * the history's taps read with vector loads and permutes (tb[c][tap][l])
 * instead of gathers. The same arithmetic as span_gather (a pixel without
 * history, has 0, weighs its window value by 0 as span_gather its tap at
 * index 0, and resolve_pixel ignores it), so the same result bit for bit. */
static HUSH_ALWAYS_INLINE void span_window(const taa_row *t, const hush_reproject_plan *plan,
                                           size_t row, int x0, const float (*tb)[4][TAA_RUN],
                                           const int32_t *restrict has, const int clip,
                                           const int tonemap) {
  const float *w0 = plan->w[0] + row + x0, *w1 = plan->w[1] + row + x0,
              *w2 = plan->w[2] + row + x0, *w3 = plan->w[3] + row + x0;
#pragma omp simd
  for (int l = 0; l < TAA_RUN; l++) {
    const float hr = w0[l] * tb[0][0][l] + w1[l] * tb[0][1][l] + w2[l] * tb[0][2][l] + w3[l] * tb[0][3][l];
    const float hg = w0[l] * tb[1][0][l] + w1[l] * tb[1][1][l] + w2[l] * tb[1][2][l] + w3[l] * tb[1][3][l];
    const float hb = w0[l] * tb[2][0][l] + w1[l] * tb[2][1][l] + w2[l] * tb[2][2][l] + w3[l] * tb[2][3][l];
    resolve_pixel(t, clip, tonemap, x0 + l, x0 + l - 1, x0 + l + 1, has[l], hr, hg, hb);
  }
}

#endif

/* The interior columns 1..W-2 of a row, in chunks of TAA_RUN: a chunk
 * whose block origins run consecutively takes span_run, one whose blocks
 * form a window span_window, the others span_gather. */
static HUSH_ALWAYS_INLINE void interior_span(const taa_row *t, const hush_reproject_plan *plan,
                                             const float *const *prev, size_t row, int W,
                                             const int clip, const int tonemap) {
  const uint8_t *kind = plan->kind + row;
  const int32_t *origin = plan->origin + row;
  int32_t j[TAA_RUN], has[TAA_RUN];
  for (int x = 1; x < W - 1; x += TAA_RUN) {
    const int n = W - 1 - x < TAA_RUN ? W - 1 - x : TAA_RUN;
    hush__prefetch_taps(prev, 3, hush__prefetch_origin(origin, x, W), W);
    hush__prefetch_row(plan, NULL, 0, row + (size_t)x);
    /* the output's lines asked for ahead, for writing: the history planes
     * were last touched a frame ago, and each chunk's stores waited for
     * their reads for ownership (taa 1.69 -> 1.64 ms, p5 1.58 -> 1.53, six
     * alternated runs; 256 and 1024 bytes ahead alike) */
    for (int k = 0; k < 3; k++)
      __builtin_prefetch((const void *)((uintptr_t)(t->out[k] + x) + 512), 1, 3);
    int run = n == TAA_RUN;
#if defined(__AVX512F__) && defined(__AVX512BW__) && defined(__AVX512VL__)
    if (run) {
      /* in mask registers: with the kind bytes in it, gcc vectorised the
       * loop below at 16 bytes, four pieces an operation */
      _Static_assert(TAA_RUN == 16, "a chunk is one vector of origins");
      const __mmask16 bil =
          _mm_cmpeq_epi8_mask(_mm_loadu_si128((const __m128i *)(const void *)(kind + x)),
                              _mm_set1_epi8((char)HUSH_FOOTPRINT_BILINEAR));
      const __m512i o = _mm512_loadu_si512((const void *)(origin + x));
      _mm512_storeu_si512((void *)has, _mm512_maskz_mov_epi32(bil, _mm512_set1_epi32(1)));
      _mm512_storeu_si512((void *)j, _mm512_maskz_mov_epi32(bil, o));
      run = (bil & hush__run_mask16(o, origin[x])) == 0xFFFF;
    } else
#endif
    for (int l = 0; l < n; l++) {
      has[l] = kind[x + l] == HUSH_FOOTPRINT_BILINEAR;
      j[l] = origin[x + l] & -has[l];
      run &= has[l] & (j[l] == origin[x] + l);
    }
    if (run) {
      span_run(t, plan, prev, row, W, x, j[0], j[0], has, 0, 1, clip, tonemap);
      continue;
    }
    if (n < TAA_RUN) {
      span_gather(t, plan, prev, row, W, x, n, j, has, clip, tonemap);
      continue;
    }
#ifdef HUSH_HAVE_DIAGONAL_READS
    _Static_assert(TAA_RUN == HUSH_DIAGONAL_CHUNK, "a TAA chunk is the diagonals' chunk");
    int32_t base[2];
    const int diagonals = hush__reproject_diagonals(origin + x, kind + x, NULL, (int32_t)W,
                                                    (size_t)W * plan->height, base);
    if (diagonals == 2) {
      span_run(t, plan, prev, row, W, x, base[0], base[1], has, 1, 0, clip, tonemap);
      continue;
    }
    if (diagonals == 1) {
      span_run(t, plan, prev, row, W, x, base[0], base[0], has, 0, 0, clip, tonemap);
      continue;
    }
#endif
#ifdef HUSH_HAVE_WINDOW
    float tb[3][4][TAA_RUN] __attribute__((aligned(64)));
    if (hush__window_read(plan, row + (size_t)x, prev, 3, tb)) {
      span_window(t, plan, row, x, (const float(*)[4][TAA_RUN])tb, has, clip, tonemap);
      continue;
    }
#endif
    span_gather(t, plan, prev, row, W, x, TAA_RUN, j, has, clip, tonemap);
  }
}

static void interior_row(const taa_row *t, const hush_reproject_plan *plan,
                         const float *const *prev, size_t row, int W) {
  if (t->clip) {
    if (t->tonemap) interior_span(t, plan, prev, row, W, 1, 1);
    else interior_span(t, plan, prev, row, W, 1, 0);
  } else {
    if (t->tonemap) interior_span(t, plan, prev, row, W, 0, 1);
    else interior_span(t, plan, prev, row, W, 0, 0);
  }
}

/* Row `row` of this frame, modulated by the albedo's row at arow (albedo
 * NULL: none) and tone-mapped if asked, to YCoCg in v[0..2] (W floats
 * each). */
static void ycocg_row(const float *const *color, const float *const *albedo, size_t row,
                      size_t arow, int W, int tonemap, float *const v[3]) {
  const float *restrict cr = color[0] + row, *restrict cg = color[1] + row,
                        *restrict cb = color[2] + row;
  float *restrict v0 = v[0], *restrict v1 = v[1], *restrict v2 = v[2];
  if (albedo) {
    const float *restrict ar = albedo[0] + arow, *restrict ag = albedo[1] + arow,
                          *restrict ab = albedo[2] + arow;
    /* as hush__remodulate: filtered * max(albedo, eps) */
#pragma omp simd
    for (int x = 0; x < W; x++) {
      const float r = cr[x] * maxf(ar[x], HUSH_ALBEDO_EPS), g = cg[x] * maxf(ag[x], HUSH_ALBEDO_EPS),
                  b = cb[x] * maxf(ab[x], HUSH_ALBEDO_EPS);
      const float s = tonemap ? tonemap_scale(r, g, b) : 1.0f;
      v0[x] = ycocg_y(r * s, g * s, b * s);
      v1[x] = ycocg_co(r * s, g * s, b * s);
      v2[x] = ycocg_cg(r * s, g * s, b * s);
    }
  } else {
#pragma omp simd
    for (int x = 0; x < W; x++) {
      const float r = cr[x], g = cg[x], b = cb[x];
      const float s = tonemap ? tonemap_scale(r, g, b) : 1.0f;
      v0[x] = ycocg_y(r * s, g * s, b * s);
      v1[x] = ycocg_co(r * s, g * s, b * s);
      v2[x] = ycocg_cg(r * s, g * s, b * s);
    }
  }
}

/*
 * One pass over the frame: each thread resolves bands of rows, keeping the
 * YCoCg of the three rows the 3x3 box reads in a ring of its own (rows of
 * taa->current: thread t owns rows 3t..3t+2 of each plane, so at most H / 3
 * threads), converting each source row once as a band moves down (the
 * rows just above and below a band are converted again by its neighbours).
 * No whole-frame intermediate is written or read back. TAA_BANDS bands a
 * thread, handed out as threads finish: with one band each, the half of
 * the frame with more history to gather (the ground under the bench's sky,
 * the classroom's) kept one thread 20-36 % longer than the other. Every
 * pixel is computed the same way whatever the banding, so the result does
 * not depend on the thread count.
 */
#define TAA_BANDS 8

/* What every row of hush__taa_resolve_modulated reads and writes
 * (taa.h). */
typedef hush_taa_job taa_pass;

/* Rows y0..y1-1, the thread's ring in slot (its held rows start over). */
static void resolve_band(const taa_pass *p, float *slot[3][3], int y0, int y1) {
  const int W = p->W, H = p->H, tonemap = p->params->tonemap;
  const hush_reproject_plan *plan = p->plan;
  int held[3] = {-1, -1, -1}; /* the source row in each slot */
  for (int y = y0; y < y1; y++) {
    const int yu = y > 0 ? y - 1 : 0, yd = y + 1 < H ? y + 1 : y;
    const int need[3] = {yu, y, yd};
    for (int q = 0; q < 3; q++)
      if (held[need[q] % 3] != need[q]) {
        ycocg_row(p->color, p->albedo, (size_t)need[q] * W,
                  (size_t)(need[q] - p->albedo_row0) * W, W, tonemap, slot[need[q] % 3]);
        held[need[q] % 3] = need[q];
      }
    const size_t row = (size_t)y * W;
    taa_row t;
    for (int k = 0; k < 3; k++) {
      t.up[k] = slot[yu % 3][k];
      t.mid[k] = slot[y % 3][k];
      t.dn[k] = slot[yd % 3][k];
      t.out[k] = p->out->plane[k] + row;
    }
    t.alpha = p->params->alpha;
    t.tonemap = tonemap;
    t.clip = p->params->box == HUSH_TAA_CLIP;
    if (!plan || !plan->blocks) {
      for (int x = 0; x < W; x++) resolve_taps(&t, plan, p->prev, x, y, W);
    } else {
      interior_row(&t, plan, p->prev, row, W);
      /* the border columns and the 3X3 footprints, through the taps */
      resolve_taps(&t, plan, p->prev, 0, y, W);
      if (W > 1) resolve_taps(&t, plan, p->prev, W - 1, y, W);
      const size_t last = row + (size_t)W - 1;
      for (size_t i = hush__reproject_next_3x3(plan, row + 1, last); i < last;
           i = hush__reproject_next_3x3(plan, i + 1, last))
        resolve_taps(&t, plan, p->prev, (int)(i - row), y, W);
    }
    if (p->params->out_view)
      hush__view_export_span((const float *const *)t.out, 3, p->params->out_view, (uint32_t)y, 0,
                             (uint32_t)W);
  }
}

void hush__taa_begin(const hush_taa *taa, const hush_reproject_plan *plan,
                     const float *const *color, const float *const *albedo,
                     const hush_taa_params *params, hush_taa_job *job) {
  const hush_planar *cur = &taa->current;
  const taa_pass p = {color,
                      albedo,
                      (const float *const *)taa->history[taa->latest].plane,
                      taa->has_history ? plan : NULL,
                      params,
                      (hush_planar *)&taa->history[1 - taa->latest],
                      cur->plane,
                      (int)cur->width,
                      (int)cur->height,
                      0};
  *job = p;
}

/* Thread me's ring: rows 3 me .. 3 me + 2 of the current planes. */
static void ring_of(const taa_pass *p, int me, float *slot[3][3]) {
  for (int s = 0; s < 3; s++) /* a frame of fewer than 3 rows uses slots 0..H-1 only */
    for (int k = 0; k < 3; k++)
      slot[s][k] = p->ring[k] + (size_t)(3 * me + (s < p->H ? s : 0)) * p->W;
}

void hush__taa_rows(const hush_taa_job *job, int me, int y0, int y1) {
  float *slot[3][3];
  ring_of(job, me, slot);
  resolve_band(job, slot, y0, y1);
}

void hush__taa_done(hush_taa *taa) {
  taa->latest = 1 - taa->latest;
  taa->has_history = 1;
}

void hush__taa_resolve_modulated(hush_taa *taa, const hush_reproject_plan *plan,
                                 const float *const *color, const float *const *albedo,
                                 const hush_taa_params *params, int threads) {
  taa_pass p;
  hush__taa_begin(taa, plan, color, albedo, params, &p);
  const int H = p.H;
  if (threads > H / 3) threads = H / 3;
  if (threads < 1) threads = 1;
  /* bands of at least 8 rows (each converts its two edge rows again) */
  int bands = threads * TAA_BANDS;
  if (bands > H / 8) bands = H / 8;
  if (bands < threads) bands = threads;
#pragma omp parallel num_threads(threads)
  {
    float *slot[3][3]; /* [row mod 3][component] */
    ring_of(&p, omp_get_thread_num(), slot);
#pragma omp for schedule(dynamic, 1)
    for (int band = 0; band < bands; band++)
      resolve_band(&p, slot, (int)((long)H * band / bands),
                   (int)((long)H * (band + 1) / bands));
  }
  hush__taa_done(taa);
}

void hush__taa_resolve(hush_taa *taa, const hush_reproject_plan *plan, const float *const *color,
                       const hush_taa_params *params, int threads) {
  hush__taa_resolve_modulated(taa, plan, color, NULL, params, threads);
}

/* ---- frames with holes (docs/holes.md; Dundr 2018 §4.2.6) ---------------- */

/* The box of the traced pixels (spp > 0; all with every_pixel) of the 3x3
 * neighbourhood of (x, y) in the YCoCg planes v: lo, hi and the sum;
 * returns how many. */
static int traced_box(const float *const v[3], const float *spp, int every_pixel, int x, int y,
                      int W, int H, float lo[3], float hi[3], float sum[3]) {
  int m = 0;
  for (int k = 0; k < 3; k++) {
    lo[k] = 3.0e38f;
    hi[k] = -3.0e38f;
    sum[k] = 0.0f;
  }
  for (int j = y - 1; j <= y + 1; j++)
    for (int i = x - 1; i <= x + 1; i++) {
      if (j < 0 || i < 0 || j >= H || i >= W) continue;
      const size_t q = (size_t)j * W + i;
      if (!every_pixel && !(spp[q] > 0.0f)) continue;
      for (int k = 0; k < 3; k++) {
        lo[k] = minf(lo[k], v[k][q]);
        hi[k] = maxf(hi[k], v[k][q]);
        sum[k] += v[k][q];
      }
      m++;
    }
  return m;
}

/* Pixel (x, y) of a frame with holes; returns 0 where it has nothing (no
 * history, no traced neighbour). */
static int resolve_hole_pixel(const hush_planar *cur, const hush_reproject_plan *plan,
                              const float *const *prev, const float *spp, int hole_color,
                              const hush_taa_params *params, hush_planar *out, int x, int y) {
  const int W = (int)cur->width, H = (int)cur->height;
  const size_t i = (size_t)y * W + x;
  const float *const v[3] = {cur->plane[0], cur->plane[1], cur->plane[2]};
  float lo[3], hi[3], sum[3], h[3] = {0.0f, 0.0f, 0.0f}, m[3];
  const int boxed = traced_box(v, spp, hole_color, x, y, W, H, lo, hi, sum);
  int n = 0;
  if (plan) {
    int32_t idx[9];
    float w[9];
    n = hush__reproject_taps(plan, i, idx, w);
    float hr = 0.0f, hg = 0.0f, hb = 0.0f;
    if (n) {
      hr = hush__reproject_apply(prev[0], idx, w, n);
      hg = hush__reproject_apply(prev[1], idx, w, n);
      hb = hush__reproject_apply(prev[2], idx, w, n);
    }
    const float s = params->tonemap ? tonemap_scale(hr, hg, hb) : 1.0f;
    h[0] = ycocg_y(hr * s, hg * s, hb * s);
    h[1] = ycocg_co(hr * s, hg * s, hb * s);
    h[2] = ycocg_cg(hr * s, hg * s, hb * s);
  }
  if (n && boxed) {
    if (params->box == HUSH_TAA_CLIP) {
      const float f = minf(minf(clip_fraction(h[0], lo[0], hi[0]), clip_fraction(h[1], lo[1], hi[1])),
                           minf(clip_fraction(h[2], lo[2], hi[2]), 1.0f));
      for (int k = 0; k < 3; k++) h[k] = clip_to(h[k], lo[k], hi[k], f);
    } else {
      for (int k = 0; k < 3; k++) h[k] = clampf(h[k], lo[k], hi[k]);
    }
  }
  const int traced = spp[i] > 0.0f;
  for (int k = 0; k < 3; k++) {
    if (traced) /* a new sample: the usual blend */
      m[k] = n ? h[k] + params->alpha * (v[k][i] - h[k]) : v[k][i];
    else if (hole_color) /* only new samples update the history: a hole keeps it */
      m[k] = n ? h[k] : v[k][i];
    else
      m[k] = n ? h[k] : boxed ? sum[k] / (float)boxed : 0.0f;
  }
  const float r = m[0] + m[1] - m[2], g = m[0] + m[2], b = m[0] - m[1] - m[2];
  const float u = params->tonemap ? untonemap_scale(r, g, b) : 1.0f;
  out->plane[0][i] = r * u;
  out->plane[1][i] = g * u;
  out->plane[2][i] = b * u;
  return traced || n || boxed;
}

int hush__taa_resolve_holes(hush_taa *taa, const hush_reproject_plan *plan,
                            const float *const *color, const float *spp, int hole_color,
                            const hush_taa_params *params, float *valid, int threads) {
  hush_planar *cur = &taa->current;
  const int W = (int)cur->width, H = (int)cur->height;
  const int tonemap = params->tonemap;
  const int use_history = taa->has_history && plan;
  const float *const *prev = (const float *const *)taa->history[taa->latest].plane;
  hush_planar *out = &taa->history[1 - taa->latest];
  if (threads < 1) threads = 1;
  int missing = 0;
#pragma omp parallel num_threads(threads)
  {
#pragma omp for schedule(static)
    for (int y = 0; y < H; y++) {
      const size_t row = (size_t)y * W;
      for (int x = 0; x < W; x++) {
        const float r = color[0][row + x], g = color[1][row + x], b = color[2][row + x];
        const float s = tonemap ? tonemap_scale(r, g, b) : 1.0f;
        cur->plane[0][row + x] = ycocg_y(r * s, g * s, b * s);
        cur->plane[1][row + x] = ycocg_co(r * s, g * s, b * s);
        cur->plane[2][row + x] = ycocg_cg(r * s, g * s, b * s);
      }
    }
#pragma omp for schedule(static) reduction(| : missing)
    for (int y = 0; y < H; y++)
      for (int x = 0; x < W; x++) {
        const int ok = resolve_hole_pixel(cur, use_history ? plan : NULL, prev, spp, hole_color,
                                          params, out, x, y);
        valid[(size_t)y * W + x] = ok ? 1.0f : 0.0f;
        missing |= !ok;
      }
  }
  taa->latest = 1 - taa->latest;
  taa->has_history = 1;
  return missing;
}
