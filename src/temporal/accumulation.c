/*
 * accumulation.c — colour and luminance-moment accumulation with a history
 * length, through a reprojection plan. Dundr 2018 §4.1.3, Koskela et al.
 * 2019 §3.2, Higginson 2023 §1.3 (eqs. 1.2, 1.3); see accumulation.h.
 */
#include "temporal/accumulation.h"

#include "core/device.h"
#include "core/stream.h"

#include <math.h>
#include <string.h>

static hush_status accum_init(hush_device device, hush_accum *acc, int channels,
                              int with_moments, uint32_t width, uint32_t height) {
  memset(acc, 0, sizeof *acc);
  if (channels < 1 || channels > 4)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                      "accumulation of %d channels (1..4 supported)", channels);
  acc->width = width;
  acc->height = height;
  acc->channels = channels;
  acc->with_moments = with_moments;
  hush_status s = HUSH_OK;
  for (int k = 0; k < 2 && !s; k++) {
    s = hush__planar_init(device, &acc->color[k], channels, width, height);
    if (!s && with_moments) s = hush__planar_init(device, &acc->moments[k], 2, width, height);
    if (!s) s = hush__planar_init(device, &acc->age[k], 1, width, height);
  }
  if (s) hush__accum_free(acc);
  return s;
}

hush_status hush__accum_init(hush_device device, hush_accum *acc, int channels, uint32_t width,
                             uint32_t height) {
  return accum_init(device, acc, channels, 1, width, height);
}

hush_status hush__accum_init_color(hush_device device, hush_accum *acc, int channels,
                                   uint32_t width, uint32_t height) {
  return accum_init(device, acc, channels, 0, width, height);
}

void hush__accum_free(hush_accum *acc) {
  for (int k = 0; k < 2; k++) {
    hush__planar_free(&acc->color[k]);
    hush__planar_free(&acc->moments[k]);
    hush__planar_free(&acc->age[k]);
  }
  memset(acc, 0, sizeof *acc);
}

void hush__accum_reset(hush_accum *acc) { acc->has_history = 0; }

/* Everything a blend reads and writes, resolved once per call. */
typedef struct blend_ctx {
  const hush_reproject_plan *plan; /* NULL: no history anywhere */
  size_t W;
  size_t size; /* W * height: floats per plane */
  const float *sample[4];
  const float *pc[4], *pm1, *pm2, *pa; /* history: the previous set */
  float *oc[4], *om1, *om2, *oa;       /* this frame's set */
  float *variance;                     /* may be NULL; NULL without moments */
  int mom;                             /* the moments are kept (else pm*, om* NULL) */
  int stream;                          /* outputs streamed past the caches */
  float alpha_min, alpha_mom_min, max_age;
} blend_ctx;

/* The blend's per-call constants. */
typedef struct blend_params {
  float alpha_min, alpha_mom_min, max_age;
} blend_params;

/* One pixel: its samples and gathered history (colour, moments, age) in,
 * its results out. Scalars, not arrays: the row loop vectorises. */
typedef struct blend_px {
  float s0, s1, s2, s3; /* samples (channels >= nc unused) */
  float h0, h1, h2, h3; /* history colour */
  float hm1, hm2, ha;   /* history moments and age */
  float c0, c1, c2, c3; /* out: colour */
  float m1, m2, age, var;
} blend_px;

/*
 * The blend of one pixel (has: there is history, else the history values
 * are ignored), as accumulation.h gives it. Branch-free and inlined into
 * the row loop (nc a constant there) and into the per-pixel path, so both
 * give the same bits.
 */
static HUSH_ALWAYS_INLINE void blend_compute(const blend_params *p, blend_px *q, int has,
                                             const int nc) {
  const float l = nc >= 3 ? hush_luminance(q->s0, q->s1, q->s2) : q->s0;
  float age = hush__floorf_vec(q->ha + 0.5f) + 1.0f;
  age = age > p->max_age ? p->max_age : age;
  age = has ? age : 1.0f; /* also keeps the divide below away from garbage */
  const float inv_age = 1.0f / age;
  const float a = p->alpha_min > inv_age ? p->alpha_min : inv_age;
  const float am = p->alpha_mom_min > inv_age ? p->alpha_mom_min : inv_age;
  q->c0 = has ? (1.0f - a) * q->h0 + a * q->s0 : q->s0;
  q->c1 = has ? (1.0f - a) * q->h1 + a * q->s1 : q->s1;
  q->c2 = has ? (1.0f - a) * q->h2 + a * q->s2 : q->s2;
  q->c3 = has ? (1.0f - a) * q->h3 + a * q->s3 : q->s3;
  const float l2 = l * l;
  q->m1 = has ? (1.0f - am) * q->hm1 + am * l : l;
  q->m2 = has ? (1.0f - am) * q->hm2 + am * l2 : l2;
  q->age = age;
  /* separate statements: no fused multiply-add, so one sample gives
   * exactly 0 with every compiler */
  const float m1sq = q->m1 * q->m1;
  const float v = q->m2 - m1sq;
  q->var = v > 0.0f ? v : 0.0f;
}

/* Pixel i through hush__reproject_taps: any footprint, any plan. */
/* Writes pixel i's blended colour, moments, age (and variance, if asked). */
static HUSH_ALWAYS_INLINE void blend_store(const blend_ctx *b, size_t i, const blend_px *q,
                                           const int nc) {
  const float out[4] = {q->c0, q->c1, q->c2, q->c3};
  for (int c = 0; c < nc; c++) b->oc[c][i] = out[c];
  if (b->mom) {
    b->om1[i] = q->m1;
    b->om2[i] = q->m2;
  }
  b->oa[i] = q->age;
  if (b->variance) b->variance[i] = q->var;
}

static void blend_pixel(const blend_ctx *b, size_t i, const int nc) {
  const blend_params p = {b->alpha_min, b->alpha_mom_min, b->max_age};
  int32_t idx[9];
  float w[9];
  const int n = b->plan ? hush__reproject_taps(b->plan, i, idx, w) : 0;
  float s[4] = {0.0f, 0.0f, 0.0f, 0.0f}, h[4] = {0.0f, 0.0f, 0.0f, 0.0f};
  for (int c = 0; c < nc; c++) {
    s[c] = b->sample[c][i];
    if (n) h[c] = hush__reproject_apply(b->pc[c], idx, w, n);
  }
  blend_px q = {s[0], s[1], s[2], s[3], h[0], h[1], h[2], h[3], 0.0f, 0.0f, 0.0f,
                0.0f, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f};
  if (n && b->mom) {
    q.hm1 = hush__reproject_apply(b->pm1, idx, w, n);
    q.hm2 = hush__reproject_apply(b->pm2, idx, w, n);
  }
  if (n) q.ha = hush__reproject_apply(b->pa, idx, w, n);
  blend_compute(&p, &q, n > 0, nc);
  blend_store(b, i, &q, nc);
}

/* Pixels per chunk of a blended row: a chunk of BILINEAR pixels whose
 * blocks follow each other (origin + 1 per pixel, as under smooth motion)
 * loads its taps as vectors; one whose blocks form a window (reproject.h)
 * loads the window and permutes; any other chunk gathers them. */
#define CHUNK HUSH_CHUNK
_Static_assert(CHUNK == HUSH_WINDOW_MAX, "a window is one chunk");

/* How blend_pixels reads a chunk's taps: gathered one by one, as vectors
 * (the footprints follow each other), from a window of 1 or 2 rows
 * (hush__reproject_window; AVX-512 builds), or as two vectors per tap
 * picked per pixel (hush__reproject_diagonals; the others). */
enum { MODE_GATHER, MODE_CONTIGUOUS, MODE_WINDOW, MODE_DIAGONALS };

#ifdef HUSH_HAVE_DIAGONAL_READS
/* How a full chunk from pixel x0 of a row that is not contiguous reads
 * its taps (x86-64-v3 builds): from two diagonals (reproject.h; base[0],
 * base[1] relative to the row) when its BILINEAR footprints lie on them,
 * else gathered. */
static HUSH_ALWAYS_INLINE int chunk_diagonals(const hush_reproject_plan *plan, size_t row, int x0,
                                              int32_t base[2]) {
  _Static_assert(CHUNK == HUSH_DIAGONAL_CHUNK, "a chunk is the diagonals' chunk");
  int32_t b[2];
  const int n = hush__reproject_diagonals(plan->origin + row + x0, plan->kind + row + x0, NULL,
                                          (int32_t)plan->width, (size_t)plan->width * plan->height,
                                          b);
  if (!n) return MODE_GATHER;
  base[0] = b[0] - x0;
  base[1] = b[1] - x0;
  return n == 1 ? MODE_CONTIGUOUS : MODE_DIAGONALS;
}
#endif

/* A blend's outputs, staged in L1 (plane t at st + t * stride: colour
 * 0..3, moments 4 and 5, variance 6, age 7), streamed out to pixels
 * x..x+len-1 of their rows (core/stream.h): a history is read again only
 * after the whole frame's blend, so reading its lines for ownership first
 * would only cost bandwidth. out[t] NULL: not written. */
static HUSH_ALWAYS_INLINE void stream_staged(float *const out[8], const float *st, size_t stride,
                                             int x, int len, int stream) {
  for (int t = 0; t < 8; t++) {
    if (!out[t]) continue;
    if (stream)
      hush__stream_copy(out[t] + x, st + (size_t)t * stride, (size_t)len * sizeof(float));
    else if (len == CHUNK) /* a copy of known size, inlined */
      memcpy(out[t] + x, st + (size_t)t * stride, CHUNK * sizeof(float));
    else
      memcpy(out[t] + x, st + (size_t)t * stride, (size_t)len * sizeof(float));
  }
}

/*
 * Pixels row + x_begin .. row + x_begin + len - 1 of a plan with blocks, each
 * gathered as a block (origin and the plan's four weights; all 0 for a
 * pixel without a BILINEAR footprint, whose origin is then 0), in a loop
 * the compiler vectorises. MODE_CONTIGUOUS: the block of pixel row + x
 * starts at base + x (plain vector loads); MODE_WINDOW: the taps were read
 * from a window (tb[plane][tap][x - x_begin], planes: colour 0..3, moments
 * 4, 5, age 6); MODE_GATHER: each block at its origin (gathers).
 * Every pointer is a plain local, so the vectoriser sees loop invariants
 * (and the omp simd: no dependence between pixels; the history read is
 * never written here).
 */
static HUSH_ALWAYS_INLINE void blend_pixels(const blend_ctx *b, size_t row, int x_begin,
                                            int len, int32_t base, int32_t base1, const int mode,
                                            const float (*restrict tb)[4][CHUNK],
                                            const int nc, const int mom) {
  const int contiguous = mode == MODE_CONTIGUOUS;
  const int window = mode == MODE_WINDOW;
  const int diagonals = mode == MODE_DIAGONALS;
  const int x_end = x_begin + len;
  const hush_reproject_plan *plan = b->plan;
  const blend_params p = {b->alpha_min, b->alpha_mom_min, b->max_age};
  const int W = (int)b->W;
  const int32_t *origin = plan->origin + row;
  const uint8_t *kind = plan->kind + row;
  const float *w0 = plan->w[0] + row, *w1 = plan->w[1] + row;
  const float *w2 = plan->w[2] + row, *w3 = plan->w[3] + row;
  const float *pm1 = b->pm1, *pm2 = b->pm2, *pa = b->pa;
  float *om1 = mom ? b->om1 + row : NULL, *om2 = mom ? b->om2 + row : NULL;
  float *oa = b->oa + row;
  float *var = mom && b->variance ? b->variance + row : NULL;
  /* channels as scalars (channel 0 stands in for the missing ones, never
   * read or written): arrays of pointers indexed in the loop would not
   * vectorise */
  const float *p0 = b->pc[0], *p1 = b->pc[nc > 1], *p2 = b->pc[nc > 2 ? 2 : 0];
  const float *p3 = b->pc[nc > 3 ? 3 : 0];
  const float *s0 = b->sample[0] + row, *s1 = b->sample[nc > 1] + row;
  const float *s2 = b->sample[nc > 2 ? 2 : 0] + row, *s3 = b->sample[nc > 3 ? 3 : 0] + row;
  float *o0 = b->oc[0] + row, *o1 = b->oc[nc > 1] + row;
  float *o2 = b->oc[nc > 2 ? 2 : 0] + row, *o3 = b->oc[nc > 3 ? 3 : 0] + row;
  float st[8][CHUNK] __attribute__((aligned(64)));
  /* the plan's kinds and masks widened first: with byte and 16-bit arrays
   * in the loop below, gcc gave it 16- and 32-byte vectors (a chunk of 16
   * of its smallest type), two to four registers for every float
   * operation (as tblend_pixels) */
  /* (a pixel has history where its footprint is BILINEAR: its mask is not
   * 0 then, and a 3X3 pixel, whose mask is not 0 either, is blended again
   * by blend_pixel after the chunk) */
  int32_t bils[CHUNK];
  for (int k = 0; k < len; k++) bils[k] = kind[x_begin + k] == HUSH_FOOTPRINT_BILINEAR;
#pragma omp simd
  for (int x = x_begin; x < x_end; x++) {
    const int32_t o = contiguous | diagonals ? base + x : origin[x] & -bils[x - x_begin];
    /* MODE_DIAGONALS: the footprint on the second diagonal */
    const int second = diagonals & (origin[x] == base1 + x);
    const int32_t os = base1 + x;
    const float a0 = w0[x], a1 = w1[x], a2 = w2[x], a3 = w3[x];
    const int k = x - x_begin;
    /* tap (tx, ty) of plane t, window plane index pi; with diagonals,
     * both loaded and one picked */
#define HUSH_TAP(t, pi, tx, ty)                                                                 \
  (window      ? tb[pi][(ty) * 2 + (tx)][k]                                                     \
   : diagonals ? hush__select_bits(second, (t)[os + (ty) * W + (tx)], (t)[o + (ty) * W + (tx)])  \
               : (t)[o + (ty) * W + (tx)])
#define HUSH_APPLY4(t, pi)                                                                      \
  (a0 * HUSH_TAP(t, pi, 0, 0) + a1 * HUSH_TAP(t, pi, 1, 0) + a2 * HUSH_TAP(t, pi, 0, 1) +      \
   a3 * HUSH_TAP(t, pi, 1, 1))
    blend_px q;
    q.s0 = s0[x];
    q.s1 = nc > 1 ? s1[x] : 0.0f;
    q.s2 = nc > 2 ? s2[x] : 0.0f;
    q.s3 = nc > 3 ? s3[x] : 0.0f;
    q.h0 = HUSH_APPLY4(p0, 0);
    q.h1 = nc > 1 ? HUSH_APPLY4(p1, 1) : 0.0f;
    q.h2 = nc > 2 ? HUSH_APPLY4(p2, 2) : 0.0f;
    q.h3 = nc > 3 ? HUSH_APPLY4(p3, 3) : 0.0f;
    q.hm1 = mom ? HUSH_APPLY4(pm1, 4) : 0.0f;
    q.hm2 = mom ? HUSH_APPLY4(pm2, 5) : 0.0f;
    q.ha = HUSH_APPLY4(pa, 6);
#undef HUSH_APPLY4
#undef HUSH_TAP
    blend_compute(&p, &q, bils[k], nc);
    st[0][k] = q.c0;
    if (nc > 1) st[1][k] = q.c1;
    if (nc > 2) st[2][k] = q.c2;
    if (nc > 3) st[3][k] = q.c3;
    if (mom) {
      st[4][k] = q.m1;
      st[5][k] = q.m2;
      if (var) st[6][k] = q.var;
    }
    st[7][k] = q.age;
  }
  float *const outs[8] = {o0, nc > 1 ? o1 : NULL, nc > 2 ? o2 : NULL,
                          nc > 3 ? o3 : NULL, om1, om2, var, oa}; /* NULL: not written */
  stream_staged(outs, st[0], CHUNK, x_begin, len, b->stream);
}

/* Rows per chunk of the parallel blend (see hush__accum_blend). */
#define BLEND_ROWS 4

/* One row of a plan with blocks, chunk by chunk, then the rare 3X3 pixels
 * redone through their taps. */
static HUSH_ALWAYS_INLINE void blend_row(const blend_ctx *b, size_t row, const int nc,
                                         const int mom) {
  const int W = (int)b->W;
  const int32_t *origin = b->plan->origin + row;
  const uint8_t *kind = b->plan->kind + row;
  const float *const history[7] = {b->pc[0], nc > 1 ? b->pc[1] : NULL, nc > 2 ? b->pc[2] : NULL,
                                   nc > 3 ? b->pc[3] : NULL, mom ? b->pm1 : NULL,
                                   mom ? b->pm2 : NULL, b->pa};
  const float *const samples[4] = {b->sample[0], nc > 1 ? b->sample[1] : NULL,
                                   nc > 2 ? b->sample[2] : NULL, nc > 3 ? b->sample[3] : NULL};
  for (int x0 = 0; x0 < W; x0 += CHUNK) {
    const int x1 = W - x0 < CHUNK ? W : x0 + CHUNK;
    hush__prefetch_taps(history, 7, hush__prefetch_origin(origin, x0, W), W);
    hush__prefetch_row(b->plan, samples, nc, row + (size_t)x0);
    /* a constant length for full chunks: one vector iteration, no
     * alignment peeling or scalar epilogue */
    if (x1 - x0 < CHUNK) {
      blend_pixels(b, row, x0, x1 - x0, 0, 0, MODE_GATHER, NULL, nc, mom);
      continue;
    }
    if (hush__chunk_contiguous(origin + x0, kind + x0)) {
      blend_pixels(b, row, x0, CHUNK, origin[x0] - x0, 0, MODE_CONTIGUOUS, NULL, nc, mom);
      continue;
    }
#ifdef HUSH_HAVE_WINDOW
    {
      int32_t base[2];
      if (chunk_diagonals(b->plan, row, x0, base) == MODE_DIAGONALS) {
        blend_pixels(b, row, x0, CHUNK, base[0], base[1], MODE_DIAGONALS, NULL, nc, mom);
        continue;
      }
    }
    /* the taps of the 7 history planes (colour, moments, age; NULL: unused) */
    float tb[7][4][CHUNK] __attribute__((aligned(64)));
    const float *planes[7] = {b->pc[0],           nc > 1 ? b->pc[1] : NULL,
                              nc > 2 ? b->pc[2] : NULL, nc > 3 ? b->pc[3] : NULL,
                              mom ? b->pm1 : NULL, mom ? b->pm2 : NULL,
                              b->pa};
    if (hush__window_read(b->plan, row + (size_t)x0, planes, 7, tb)) {
      blend_pixels(b, row, x0, CHUNK, 0, 0, MODE_WINDOW, (const float(*)[4][CHUNK])tb, nc, mom);
      continue;
    }
#elif defined(HUSH_HAVE_DIAGONALS)
    int32_t base[2];
    switch (chunk_diagonals(b->plan, row, x0, base)) {
    case MODE_CONTIGUOUS:
      blend_pixels(b, row, x0, CHUNK, base[0], 0, MODE_CONTIGUOUS, NULL, nc, mom);
      continue;
    case MODE_DIAGONALS:
      blend_pixels(b, row, x0, CHUNK, base[0], base[1], MODE_DIAGONALS, NULL, nc, mom);
      continue;
    default: break;
    }
#endif
    blend_pixels(b, row, x0, CHUNK, 0, 0, MODE_GATHER, NULL, nc, mom);
  }
  const size_t end = row + (size_t)W;
  for (size_t i = hush__reproject_next_3x3(b->plan, row, end); i < end;
       i = hush__reproject_next_3x3(b->plan, i + 1, end))
    blend_pixel(b, i, nc);
}

/* Rows y of the image, with nc and mom constants. */
static HUSH_ALWAYS_INLINE void blend_rows(const blend_ctx *b, int y, const int nc,
                                          const int mom) {
  const size_t row = (size_t)y * b->W;
  if (b->plan && b->plan->blocks) {
    blend_row(b, row, nc, mom);
    hush__stream_fence();
  } else {
    for (size_t i = row; i < row + b->W; i++) blend_pixel(b, i, nc);
  }
}

/* The blend's inputs: from the latest history into the other buffer. */
static void blend_setup(blend_ctx *b, const hush_accum *acc, const hush_reproject_plan *plan,
                        const float *const *sample, const hush_accum_params *params,
                        float *variance) {
  const int src = acc->latest, dst = 1 - acc->latest;
  memset(b, 0, sizeof *b);
  b->plan = acc->has_history ? plan : NULL;
  b->W = acc->width;
  b->size = (size_t)acc->width * acc->height;
  for (int c = 0; c < acc->channels; c++) {
    b->sample[c] = sample[c];
    b->pc[c] = acc->color[src].plane[c];
    b->oc[c] = acc->color[dst].plane[c];
  }
  b->mom = acc->with_moments;
  if (b->mom) {
    b->pm1 = acc->moments[src].plane[0];
    b->pm2 = acc->moments[src].plane[1];
    b->om1 = acc->moments[dst].plane[0];
    b->om2 = acc->moments[dst].plane[1];
  }
  b->pa = acc->age[src].plane[0];
  b->oa = acc->age[dst].plane[0];
  b->variance = b->mom ? variance : NULL;
  b->stream = 1;
  b->alpha_min = params->alpha_min;
  b->alpha_mom_min = params->alpha_moments_min;
  b->max_age = (float)(params->max_age < 1 ? 1 : params->max_age);
}

/* The rows of a blend, in small dynamic chunks: rows cost very different
 * amounts (a chunk whose footprints do not follow each other gathers its
 * taps one by one, ~3x the time of one that loads them as vectors) and
 * such rows cluster in bands (the sky under a turning camera, an object's
 * silhouette): a static split in halves left one thread with most of them
 * (2 threads: 1.2x faster than 1). Each pixel is computed on its own, so
 * the result does not depend on which thread blends it. With and without
 * moments in separate functions, each with MOM a literal: a parallel loop
 * outlined from an inlined function sees its constant parameters as
 * variables (bmfr's blend 8.7 -> 12.7 ms), and one loop over all eight
 * variants made accumulate's blend 3-4 % slower. */
#define BLEND_ALL(NAME, MOM)                                                                 \
  static void NAME(const blend_ctx *b, int nc, int H, int threads) {                         \
    _Pragma("omp parallel for schedule(dynamic, BLEND_ROWS) num_threads(threads)")           \
    for (int y = 0; y < H; y++) {                                                            \
      switch (nc) {                                                                          \
      case 1: blend_rows(b, y, 1, MOM); break;                                               \
      case 2: blend_rows(b, y, 2, MOM); break;                                               \
      case 3: blend_rows(b, y, 3, MOM); break;                                               \
      default: blend_rows(b, y, 4, MOM); break;                                              \
      }                                                                                      \
    }                                                                                        \
  }
BLEND_ALL(blend_all, 1)
BLEND_ALL(blend_all_color, 0)

void hush__accum_blend(hush_accum *acc, const hush_reproject_plan *plan,
                       const float *const *sample, const hush_accum_params *params,
                       float *variance, int threads) {
  if (threads < 1) threads = 1;
  const int dst = 1 - acc->latest;
  blend_ctx b;
  blend_setup(&b, acc, plan, sample, params, variance);
  if (b.mom)
    blend_all(&b, acc->channels, (int)acc->height, threads);
  else
    blend_all_color(&b, acc->channels, (int)acc->height, threads);
  acc->latest = dst;
  acc->has_history = 1;
  acc->empty = 0;
}

void hush__accum_blend_rows(const hush_accum *acc, const hush_reproject_plan *plan,
                            const float *const *sample, const hush_accum_params *params, int y0,
                            int y1, int stream) {
  blend_ctx b;
  blend_setup(&b, acc, plan, sample, params, NULL);
  b.stream = stream;
  for (int y = y0; y < y1; y++) {
    if (b.mom) {
      switch (acc->channels) {
      case 1: blend_rows(&b, y, 1, 1); break;
      case 2: blend_rows(&b, y, 2, 1); break;
      case 3: blend_rows(&b, y, 3, 1); break;
      default: blend_rows(&b, y, 4, 1); break;
      }
    } else {
      switch (acc->channels) {
      case 1: blend_rows(&b, y, 1, 0); break;
      case 2: blend_rows(&b, y, 2, 0); break;
      case 3: blend_rows(&b, y, 3, 0); break;
      default: blend_rows(&b, y, 4, 0); break;
      }
    }
  }
}

void hush__accum_blend_done(hush_accum *acc) {
  acc->latest = 1 - acc->latest;
  acc->has_history = 1;
  acc->empty = 0;
}

/* Pixel i of a frame with holes: the history gathered from the non-empty
 * taps (renormalised), then a blend (traced) or the history kept (hole). */
static int blend_pixel_holes(const blend_ctx *b, size_t i, const float *spp, const int nc) {
  const blend_params p = {b->alpha_min, b->alpha_mom_min, b->max_age};
  int32_t idx[9];
  float w[9];
  const int n = b->plan ? hush__reproject_taps(b->plan, i, idx, w) : 0;
  float wsum = 0.0f;
  for (int t = 0; t < n; t++) {
    w[t] = b->pa[idx[t]] > 0.0f ? w[t] : 0.0f;
    wsum += w[t];
  }
  const int has = wsum > 0.0f;
  const float inv = has ? 1.0f / wsum : 0.0f;
  float s[4] = {0.0f, 0.0f, 0.0f, 0.0f}, h[4] = {0.0f, 0.0f, 0.0f, 0.0f};
  for (int c = 0; c < nc; c++) {
    s[c] = b->sample[c][i];
    if (has) h[c] = hush__reproject_apply(b->pc[c], idx, w, n) * inv;
  }
  blend_px q = {s[0], s[1], s[2], s[3], h[0], h[1], h[2], h[3], 0.0f, 0.0f, 0.0f,
                0.0f, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f};
  if (has && b->mom) {
    q.hm1 = hush__reproject_apply(b->pm1, idx, w, n) * inv;
    q.hm2 = hush__reproject_apply(b->pm2, idx, w, n) * inv;
  }
  if (has) q.ha = hush__reproject_apply(b->pa, idx, w, n) * inv;
  if (!spp || spp[i] > 0.0f) {
    blend_compute(&p, &q, has, nc); /* traced */
  } else {
    /* a hole: no new sample; the history as it was, or nothing */
    float age = has ? hush__floorf_vec(q.ha + 0.5f) : 0.0f;
    age = age > p.max_age ? p.max_age : age;
    age = has && age < 1.0f ? 1.0f : age;
    q.c0 = q.h0;
    q.c1 = q.h1;
    q.c2 = q.h2;
    q.c3 = q.h3;
    q.m1 = q.hm1;
    q.m2 = q.hm2;
    q.age = age;
    const float m1sq = q.m1 * q.m1;
    const float v = q.m2 - m1sq;
    q.var = v > 0.0f ? v : 0.0f;
  }
  blend_store(b, i, &q, nc);
  return !(q.age > 0.0f);
}

/*
 * blend_pixel_holes for a whole row of a plan with blocks, in a loop the
 * compiler vectorises (has_spp, nc constants): every pixel as a block
 * (non-BILINEAR pixels have weights 0 and origin 0, so no history, as
 * their taps give for NONE), the weights of empty taps zeroed and the sums
 * taken over all four taps in tap order from 0 — the masked-out taps add
 * +-0, which leaves every sum's bits as the per-pixel loop's over the
 * valid taps only — then the traced and the hole results selected. The
 * rare 3X3 pixels are redone by the caller (and left out of the returned
 * "some pixel is empty" flag here).
 */
static HUSH_ALWAYS_INLINE int blend_row_holes(const blend_ctx *b, size_t row, const float *spp,
                                              const int has_spp, const int nc, const int mom) {
  const hush_reproject_plan *plan = b->plan;
  const blend_params p = {b->alpha_min, b->alpha_mom_min, b->max_age};
  const int W = (int)b->W;
  const int32_t *origin = plan->origin + row;
  const uint8_t *kind = plan->kind + row;
  const float *w0 = plan->w[0] + row, *w1 = plan->w[1] + row;
  const float *w2 = plan->w[2] + row, *w3 = plan->w[3] + row;
  const float *pm1 = b->pm1, *pm2 = b->pm2, *pa = b->pa;
  const float *sp = has_spp ? spp + row : NULL;
  float *om1 = mom ? b->om1 + row : NULL, *om2 = mom ? b->om2 + row : NULL;
  float *oa = b->oa + row;
  float *var = mom && b->variance ? b->variance + row : NULL;
  const float *p0 = b->pc[0], *p1 = b->pc[nc > 1], *p2 = b->pc[nc > 2 ? 2 : 0];
  const float *p3 = b->pc[nc > 3 ? 3 : 0];
  const float *s0 = b->sample[0] + row, *s1 = b->sample[nc > 1] + row;
  const float *s2 = b->sample[nc > 2 ? 2 : 0] + row, *s3 = b->sample[nc > 3 ? 3 : 0] + row;
  float *o0 = b->oc[0] + row, *o1 = b->oc[nc > 1] + row;
  float *o2 = b->oc[nc > 2 ? 2 : 0] + row, *o3 = b->oc[nc > 3 ? 3 : 0] + row;
  int empty = 0;
  /* the row in pieces staged in L1, each streamed out after its loop */
  enum { PIECE = 256 };
  float st[8][PIECE] __attribute__((aligned(64)));
  float *const outs[8] = {o0, nc > 1 ? o1 : NULL, nc > 2 ? o2 : NULL,
                          nc > 3 ? o3 : NULL, om1, om2, var, oa}; /* NULL: not written */
  for (int x0 = 0; x0 < W; x0 += PIECE) {
    const int x1 = W - x0 < PIECE ? W : x0 + PIECE;
#pragma omp simd reduction(| : empty)
    for (int x = x0; x < x1; x++) {
      const int bil = kind[x] == HUSH_FOOTPRINT_BILINEAR;
      const int32_t o = origin[x] & -(int32_t)bil;
      const int32_t t1 = o + 1, t2 = o + W, t3 = o + W + 1;
      const int k = x - x0;
      /* a tap of an empty pixel (age 0) takes no part */
      const float a0 = hush__select_bits(pa[o] > 0.0f, w0[x], 0.0f);
      const float a1 = hush__select_bits(pa[t1] > 0.0f, w1[x], 0.0f);
      const float a2 = hush__select_bits(pa[t2] > 0.0f, w2[x], 0.0f);
      const float a3 = hush__select_bits(pa[t3] > 0.0f, w3[x], 0.0f);
      const float wsum = 0.0f + a0 + a1 + a2 + a3;
      const int has = wsum > 0.0f;
      const float inv = has ? 1.0f / (has ? wsum : 1.0f) : 0.0f;
#define HUSH_APPLY4(t) ((0.0f + a0 * (t)[o] + a1 * (t)[t1] + a2 * (t)[t2] + a3 * (t)[t3]) * inv)
      blend_px q;
      q.s0 = s0[x];
      q.s1 = nc > 1 ? s1[x] : 0.0f;
      q.s2 = nc > 2 ? s2[x] : 0.0f;
      q.s3 = nc > 3 ? s3[x] : 0.0f;
      /* computed for every pixel, then selected: no load under a branch */
      q.h0 = hush__select_bits(has, HUSH_APPLY4(p0), 0.0f);
      q.h1 = nc > 1 ? hush__select_bits(has, HUSH_APPLY4(p1), 0.0f) : 0.0f;
      q.h2 = nc > 2 ? hush__select_bits(has, HUSH_APPLY4(p2), 0.0f) : 0.0f;
      q.h3 = nc > 3 ? hush__select_bits(has, HUSH_APPLY4(p3), 0.0f) : 0.0f;
      q.hm1 = mom ? hush__select_bits(has, HUSH_APPLY4(pm1), 0.0f) : 0.0f;
      q.hm2 = mom ? hush__select_bits(has, HUSH_APPLY4(pm2), 0.0f) : 0.0f;
      q.ha = hush__select_bits(has, HUSH_APPLY4(pa), 0.0f);
#undef HUSH_APPLY4
      const float h0 = q.h0, h1 = q.h1, h2 = q.h2, h3 = q.h3, hm1 = q.hm1, hm2 = q.hm2;
      /* a hole: no new sample; the history as it was, or nothing */
      float hage = has ? hush__floorf_vec(q.ha + 0.5f) : 0.0f;
      hage = hage > p.max_age ? p.max_age : hage;
      hage = has && hage < 1.0f ? 1.0f : hage;
      const float hm1sq = hm1 * hm1;
      const float hv = hm2 - hm1sq;
      const float hvar = hv > 0.0f ? hv : 0.0f;
      blend_compute(&p, &q, has, nc); /* traced */
      const int traced = has_spp ? sp[x] > 0.0f : 1;
      const float c0 = traced ? q.c0 : h0, c1 = traced ? q.c1 : h1;
      const float c2 = traced ? q.c2 : h2, c3 = traced ? q.c3 : h3;
      const float m1 = traced ? q.m1 : hm1, m2 = traced ? q.m2 : hm2;
      const float age = traced ? q.age : hage, v = traced ? q.var : hvar;
      st[0][k] = c0;
      if (nc > 1) st[1][k] = c1;
      if (nc > 2) st[2][k] = c2;
      if (nc > 3) st[3][k] = c3;
      if (mom) {
        st[4][k] = m1;
        st[5][k] = m2;
        if (var) st[6][k] = v;
      }
      st[7][k] = age;
      empty |= !(age > 0.0f) & (kind[x] != HUSH_FOOTPRINT_3X3);
    }
    stream_staged(outs, st[0], PIECE, x0, x1 - x0, b->stream);
  }
  return empty;
}

/* One row of hush__accum_blend_holes with nc a constant. */
static HUSH_ALWAYS_INLINE int blend_rows_holes(const blend_ctx *b, int y, const float *spp,
                                               const int nc, const int mom) {
  const size_t row = (size_t)y * b->W;
  int empty = 0;
  if (b->plan && b->plan->blocks) {
    empty = spp ? blend_row_holes(b, row, spp, 1, nc, mom)
                : blend_row_holes(b, row, NULL, 0, nc, mom);
    hush__stream_fence(); /* the row's streamed stores, before the barrier */
    const size_t end = row + b->W;
    for (size_t i = hush__reproject_next_3x3(b->plan, row, end); i < end;
         i = hush__reproject_next_3x3(b->plan, i + 1, end))
      empty |= blend_pixel_holes(b, i, spp, nc);
  } else {
    for (size_t i = row; i < row + b->W; i++) empty |= blend_pixel_holes(b, i, spp, nc);
  }
  return empty;
}

void hush__accum_blend_holes(hush_accum *acc, const hush_reproject_plan *plan,
                             const float *const *sample, const float *spp,
                             const hush_accum_params *params, float *variance, int threads) {
  if (!spp && !(acc->has_history && acc->empty)) {
    hush__accum_blend(acc, plan, sample, params, variance, threads);
    return;
  }
  if (threads < 1) threads = 1;
  const int dst = 1 - acc->latest;
  const int nc = acc->channels;
  const int H = (int)acc->height;
  blend_ctx b;
  blend_setup(&b, acc, plan, sample, params, variance);
  int empty = 0;
#pragma omp parallel for reduction(| : empty) schedule(dynamic, BLEND_ROWS) num_threads(threads)
  for (int y = 0; y < H; y++) {
    switch (nc * 2 + b.mom) {
    case 2: empty |= blend_rows_holes(&b, y, spp, 1, 0); break;
    case 3: empty |= blend_rows_holes(&b, y, spp, 1, 1); break;
    case 4: empty |= blend_rows_holes(&b, y, spp, 2, 0); break;
    case 5: empty |= blend_rows_holes(&b, y, spp, 2, 1); break;
    case 6: empty |= blend_rows_holes(&b, y, spp, 3, 0); break;
    case 7: empty |= blend_rows_holes(&b, y, spp, 3, 1); break;
    case 8: empty |= blend_rows_holes(&b, y, spp, 4, 0); break;
    default: empty |= blend_rows_holes(&b, y, spp, 4, 1); break;
    }
  }
  acc->latest = dst;
  acc->has_history = 1;
  acc->empty = empty;
}

#define BLEND_MAX 8

/* hush__temporal_blend's weight of the new sample for an age. */
static inline float blend_alpha(float age, float alpha_min) {
  const float inv = 1.0f / age; /* computed for every age: no branch */
  const float inv_age = age > 1.0f ? inv : 1.0f;
  return alpha_min > inv_age ? alpha_min : inv_age;
}

/* What hush__temporal_blend reads and writes, resolved once per call. */
typedef struct tblend_ctx {
  const hush_reproject_plan *plan;
  size_t W, size;
  const float *age;
  float alpha_min;
  int stream; /* outputs streamed past the caches */
} tblend_ctx;

/*
 * Pixels row + x_begin .. + len - 1 of hush__temporal_blend for nc (1..4,
 * a constant) channels in one pass: the plan's origin, weights, kind and
 * the age are read once for all channels (the per-channel loop read them
 * once per channel). Taps as in blend_pixels: MODE_CONTIGUOUS (base + x),
 * MODE_WINDOW (tb[channel][tap][x - x_begin]) or MODE_GATHER. The same
 * operations in the same order per channel as the per-pixel definition, so
 * the same bits. out may alias sample (pixel x is read before it is
 * written), so neither is restrict.
 */
static HUSH_ALWAYS_INLINE void tblend_pixels(const tblend_ctx *t, const float *const *prev,
                                             const float *const *sample, float *const *out,
                                             size_t row, int x_begin, int len, int32_t base,
                                             int32_t base1, const int mode,
                                             const float (*restrict tb)[4][CHUNK], const int nc) {
  const int contiguous = mode == MODE_CONTIGUOUS;
  const int window = mode == MODE_WINDOW;
  const int diagonals = mode == MODE_DIAGONALS;
  const int x_end = x_begin + len;
  const hush_reproject_plan *plan = t->plan;
  const int W = (int)t->W;
  const float alpha_min = t->alpha_min;
  const int32_t *origin = plan->origin + row;
  const uint8_t *kind = plan->kind + row;
  const float *w0 = plan->w[0] + row, *w1 = plan->w[1] + row;
  const float *w2 = plan->w[2] + row, *w3 = plan->w[3] + row;
  const float *age = t->age + row;
  /* channels as scalars (channel 0 stands in for the missing ones, never
   * read or written): see blend_pixels */
  const float *p0 = prev[0], *p1 = prev[nc > 1], *p2 = prev[nc > 2 ? 2 : 0];
  const float *p3 = prev[nc > 3 ? 3 : 0];
  const float *s0 = sample[0] + row, *s1 = sample[nc > 1] + row;
  const float *s2 = sample[nc > 2 ? 2 : 0] + row, *s3 = sample[nc > 3 ? 3 : 0] + row;
  float *o0 = out[0] + row, *o1 = out[nc > 1] + row;
  float *o2 = out[nc > 2 ? 2 : 0] + row, *o3 = out[nc > 3 ? 3 : 0] + row;
  float st[4][CHUNK] __attribute__((aligned(64)));
  /* the footprint kinds widened first: with a byte array in the loop
   * below, gcc gave it 16-byte vectors (a chunk of 16 bytes), four xmm
   * registers for every float operation */
  int32_t bils[CHUNK];
  for (int k = 0; k < len; k++) bils[k] = kind[x_begin + k] == HUSH_FOOTPRINT_BILINEAR;
#pragma omp simd
  for (int x = x_begin; x < x_end; x++) {
    const int bil = bils[x - x_begin];
    const int32_t o = contiguous | diagonals ? base + x : origin[x] & -(int32_t)bil;
    const int second = diagonals & (origin[x] == base1 + x); /* as blend_pixels */
    const int32_t os = base1 + x;
    const float a0 = w0[x], a1 = w1[x], a2 = w2[x], a3 = w3[x];
    const int k = x - x_begin;
    const float a = blend_alpha(age[x], alpha_min);
#define HUSH_TAP(p, c, tx, ty)                                                                  \
  (window      ? tb[c][(ty) * 2 + (tx)][k]                                                      \
   : diagonals ? hush__select_bits(second, (p)[os + (ty) * W + (tx)], (p)[o + (ty) * W + (tx)])  \
               : (p)[o + (ty) * W + (tx)])
    /* computed for every pixel, then selected: no load under a branch */
#define HUSH_BLEND(p, s, c)                                                                     \
  hush__select_bits(bil,                                                                        \
                    (1.0f - a) * (a0 * HUSH_TAP(p, c, 0, 0) + a1 * HUSH_TAP(p, c, 1, 0) +       \
                                  a2 * HUSH_TAP(p, c, 0, 1) + a3 * HUSH_TAP(p, c, 1, 1)) +      \
                        a * (s)[x],                                                             \
                    (s)[x])
    const float r0 = HUSH_BLEND(p0, s0, 0);
    const float r1 = nc > 1 ? HUSH_BLEND(p1, s1, 1) : 0.0f;
    const float r2 = nc > 2 ? HUSH_BLEND(p2, s2, 2) : 0.0f;
    const float r3 = nc > 3 ? HUSH_BLEND(p3, s3, 3) : 0.0f;
#undef HUSH_BLEND
#undef HUSH_TAP
    st[0][k] = r0;
    if (nc > 1) st[1][k] = r1;
    if (nc > 2) st[2][k] = r2;
    if (nc > 3) st[3][k] = r3;
  }
  float *const outs[8] = {o0, nc > 1 ? o1 : NULL, nc > 2 ? o2 : NULL, nc > 3 ? o3 : NULL,
                          NULL, NULL, NULL, NULL};
  stream_staged(outs, st[0], CHUNK, x_begin, len, t->stream);
}

/* One row of hush__temporal_blend for nc (1..4) channels, chunk by chunk
 * (the modes of blend_row), then the rare 3X3 pixels through their taps. */
static HUSH_ALWAYS_INLINE void tblend_row(const tblend_ctx *t, const float *const *prev,
                                          const float *const *sample, float *const *out,
                                          size_t row, const int nc) {
  const int W = (int)t->W;
  const hush_reproject_plan *plan = t->plan;
  const int32_t *origin = plan->origin + row;
  const uint8_t *kind = plan->kind + row;
  for (int x0 = 0; x0 < W; x0 += CHUNK) {
    const int x1 = W - x0 < CHUNK ? W : x0 + CHUNK;
    hush__prefetch_taps(prev, nc, hush__prefetch_origin(origin, x0, W), W);
    hush__prefetch_row(plan, sample, nc, row + (size_t)x0);
    if (x1 - x0 < CHUNK) {
      tblend_pixels(t, prev, sample, out, row, x0, x1 - x0, 0, 0, MODE_GATHER, NULL, nc);
      continue;
    }
    if (hush__chunk_contiguous(origin + x0, kind + x0)) {
      tblend_pixels(t, prev, sample, out, row, x0, CHUNK, origin[x0] - x0, 0, MODE_CONTIGUOUS,
                    NULL, nc);
      continue;
    }
#ifdef HUSH_HAVE_WINDOW
    {
      int32_t base[2];
      if (chunk_diagonals(plan, row, x0, base) == MODE_DIAGONALS) {
        tblend_pixels(t, prev, sample, out, row, x0, CHUNK, base[0], base[1], MODE_DIAGONALS, NULL,
                      nc);
        continue;
      }
    }
    float tb[4][4][CHUNK] __attribute__((aligned(64)));
    if (hush__window_read(plan, row + (size_t)x0, prev, nc, tb)) {
      tblend_pixels(t, prev, sample, out, row, x0, CHUNK, 0, 0, MODE_WINDOW,
                    (const float(*)[4][CHUNK])tb, nc);
      continue;
    }
#elif defined(HUSH_HAVE_DIAGONALS)
    int32_t base[2];
    switch (chunk_diagonals(plan, row, x0, base)) {
    case MODE_CONTIGUOUS:
      tblend_pixels(t, prev, sample, out, row, x0, CHUNK, base[0], 0, MODE_CONTIGUOUS, NULL, nc);
      continue;
    case MODE_DIAGONALS:
      tblend_pixels(t, prev, sample, out, row, x0, CHUNK, base[0], base[1], MODE_DIAGONALS, NULL,
                    nc);
      continue;
    default: break;
    }
#endif
    tblend_pixels(t, prev, sample, out, row, x0, CHUNK, 0, 0, MODE_GATHER, NULL, nc);
  }
  const size_t end = row + (size_t)W;
  for (size_t i = hush__reproject_next_3x3(plan, row, end); i < end;
       i = hush__reproject_next_3x3(plan, i + 1, end)) {
    const float a = blend_alpha(t->age[i], t->alpha_min);
    int32_t idx[9];
    float w[9];
    const int n = hush__reproject_taps(plan, i, idx, w);
    for (int c = 0; c < nc; c++)
      out[c][i] = (1.0f - a) * hush__reproject_apply(prev[c], idx, w, n) + a * sample[c][i];
  }
}

void hush__temporal_blend(const hush_reproject_plan *plan, const float *const *prev,
                          const float *const *sample, int channels, const float *age,
                          float alpha_min, float *const *out, int threads) {
  hush__temporal_blend_rows(plan, prev, sample, channels, age, alpha_min, out, NULL, threads);
}

/* Row y of hush__temporal_blend. */
static void tblend_one_row(const tblend_ctx *t, const float *const *prev,
                           const float *const *sample, int channels, float *const *out, int y) {
  const hush_reproject_plan *plan = t->plan;
  const size_t W = t->W;
  const size_t row = (size_t)y * W;
  if (!prev) {
    for (int c = 0; c < channels; c++)
      for (size_t i = row; i < row + W; i++) out[c][i] = sample[c][i];
    return;
  }
  if (!plan->blocks) {
    /* per pixel through the taps */
    for (size_t i = row; i < row + W; i++) {
      const float a = blend_alpha(t->age[i], t->alpha_min);
      int32_t idx[9];
      float w[9];
      const int n = hush__reproject_taps(plan, i, idx, w);
      for (int c = 0; c < channels; c++)
        out[c][i] = n ? (1.0f - a) * hush__reproject_apply(prev[c], idx, w, n) + a * sample[c][i]
                      : sample[c][i];
    }
    return;
  }
  /* blocks (NONE pixels: the sample), then the 3X3 pixels; channels in
   * groups of up to 4 per pass */
  for (int c0 = 0; c0 < channels; c0 += 4) {
    const float *const *p = prev + c0, *const *s = sample + c0;
    float *const *o = out + c0;
    switch (channels - c0) {
    case 1: tblend_row(t, p, s, o, row, 1); break;
    case 2: tblend_row(t, p, s, o, row, 2); break;
    case 3: tblend_row(t, p, s, o, row, 3); break;
    default: tblend_row(t, p, s, o, row, 4); break;
    }
  }
  if (t->stream) hush__stream_fence();
}

void hush__temporal_blend_rows(const hush_reproject_plan *plan, const float *const *prev,
                               const float *const *sample, int channels, const float *age,
                               float alpha_min, float *const *out, const float *rows,
                               int threads) {
  if (threads < 1) threads = 1;
  if (channels > BLEND_MAX) channels = BLEND_MAX;
  const int H = (int)plan->height;
  const size_t W = plan->width;
  const tblend_ctx t = {plan, W, W * plan->height, age, alpha_min, 1};
  /* rows in small dynamic chunks, as hush__accum_blend: gathered chunks
   * cost ~3x contiguous ones and cluster in bands */
#pragma omp parallel for schedule(dynamic, BLEND_ROWS) num_threads(threads)
  for (int y = 0; y < H; y++) {
    if (rows && rows[y] == 0.0f) continue;
    tblend_one_row(&t, prev, sample, channels, out, y);
  }
}

void hush__temporal_blend_range(const hush_reproject_plan *plan, const float *const *prev,
                                const float *const *sample, int channels, const float *age,
                                float alpha_min, float *const *out, int y0, int y1,
                                int stream) {
  if (channels > BLEND_MAX) channels = BLEND_MAX;
  const size_t W = plan->width;
  const tblend_ctx t = {plan, W, W * plan->height, age, alpha_min, stream};
  for (int y = y0; y < y1; y++) tblend_one_row(&t, prev, sample, channels, out, y);
}
