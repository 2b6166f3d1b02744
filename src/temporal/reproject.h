/*
 * reproject.h — back-projection of every pixel into the previous frame and a
 * per-tap consistency test, producing a "reprojection plan": for each pixel
 * the taps of the previous frame its history is gathered from, with their
 * renormalised weights. Any number of history buffers (colour, moments,
 * history length, a filter's own second history) can then be gathered with
 * the same plan, so the geometry work is done once per frame.
 *
 * Follows: Higginson 2023 §1.3.1 (naive back-projection, then a 2x2
 * bilinear footprint of the consistent taps renormalised by the sum of their
 * weights, then a 3x3 footprint weighted by the kernel k, else no history);
 * Koskela et al. 2019 §3.2 (per-tap discard test, normalisation by the
 * accepted weights only); Dundr 2018 §4.1.3 (motion vectors or camera
 * matrices; disocclusion by predicted vs actual depth); SVGF (Schied 2017,
 * see papers/NOTES.md: depth, normal and mesh-id tests per tap).
 *
 * Conventions are hush.h's. The tap grid is at pixel centres: pixel (x, y)
 * of the previous frame is sampled at continuous coordinate (x+0.5, y+0.5).
 * The coordinate a pixel is back-projected to is that of its pixel CENTRE:
 *   - HUSH_MOTION_VECTORS: (x + 0.5, y + 0.5) + motion;
 *   - HUSH_MOTION_CAMERA without "position": the point at the pixel's depth
 *     on the ray through its centre (unjittered), projected with the
 *     previous matrices. Exact for any camera rotation; under translation
 *     the only error is the parallax of the depth difference between the
 *     jittered sample and the centre (as in TAA's depth reprojection);
 *   - HUSH_MOTION_CAMERA with "position": the hit point of the jittered
 *     sample projected with the previous matrices, minus this frame's
 *     jitter (exact for a static camera, first order otherwise);
 *   - background pixels (depth <= 0), CAMERA: the direction of the centre
 *     ray, projected as a point at infinity.
 * The previous frame's jitter is ignored: a history buffer holds values for
 * pixel centres. The expected previous depth of a surface (for the depth
 * test) is the view depth of that point in the previous camera; with
 * VECTORS, of this frame's point (position, or reconstructed from depth),
 * falling back to this frame's depth when the camera cannot be inverted.
 *
 * Perspective and orthographic projections (view_to_clip's z and w rows
 * depending on view z only) take a vectorised path: one matrix maps the
 * pixel's homogeneous clip vector to the previous clip space. Any other
 * invertible projection takes a general per-pixel path.
 *
 * Every function is deterministic and independent of the thread count
 * (each pixel is computed on its own; rows are split statically).
 */
#ifndef HUSH_TEMPORAL_REPROJECT_H
#define HUSH_TEMPORAL_REPROJECT_H

#include "hush.h"
#include "core/image.h"
#include "core/stream.h" /* hush__prefetch */
#include "core/vecmath.h" /* HUSH_ALWAYS_INLINE, hush__select_bits, hush__floorf_vec */

#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

/* Whether two ids match: equal, or either NaN. Imported ids are never NaN
 * (image import rejects NaN); a filter marks pixels whose history may mix
 * across ids with NaN (hush__emission_wildcard_ids: the pixels of a light
 * seen directly, whose emission it accumulates apart). */
static inline int hush__id_match(float a, float b) { return (a == b) | (a != a) | (b != b); }

/* One frame's geometry as planes (width * height floats each, not owned).
 * NULL members are absent. */
typedef struct hush_gbuffer {
  const float *depth;     /* linear view depth; <= 0 is background. Required. */
  const float *normal[3]; /* world-space unit normal. Required. */
  const float *id;        /* mesh/material id; compared only when both frames have it */
} hush_gbuffer;

/* What the plan is built from, besides the previous frame's hush_gbuffer. */
typedef struct hush_reproject_input {
  hush_gbuffer cur;          /* this frame */
  const float *position[3];  /* optional world positions (all three or none) */
  const float *motion[2];    /* required for HUSH_MOTION_VECTORS, else ignored */
} hush_reproject_input;

typedef struct hush_reproject_params {
  /* Depth test: a tap is consistent when
   *   |z_tap - z_expected| <= depth_tolerance * z_expected
   *                           + depth_gradient * |grad z . (tap - p)|,
   * z_expected being the view depth of the back-projected point p in the
   * previous camera, grad z this pixel's screen-space depth gradient (the
   * smaller one-sided difference per axis, so a depth edge does not widen
   * it; scaled by z_expected / z) and tap - p the tap's offset in pixels.
   * The gradient term (SVGF's "relative to the depth derivative") keeps
   * surfaces seen at grazing angles; depth_gradient = 0 gives the plain
   * relative test. */
  float depth_tolerance;
  float depth_gradient;
  /* Normal test: dot(n, n_tap) >= normal_threshold (a cosine; -1 disables). */
  float normal_threshold;
  int use_id;       /* compare ids when both frames have them */
  int fallback_3x3; /* search the 3x3 neighbourhood when no bilinear tap is consistent */
} hush_reproject_params;

/* Default parameters: depth_tolerance 0.1, depth_gradient 1, normal_threshold
 * 0.9, use_id 1, fallback_3x3 1. */
void hush__reproject_params_default(hush_reproject_params *p);

typedef enum hush_footprint {
  HUSH_FOOTPRINT_NONE = 0,     /* no consistent tap: history dropped */
  HUSH_FOOTPRINT_BILINEAR = 1, /* 2x2 taps at origin + {0,1} x {0,1} */
  HUSH_FOOTPRINT_3X3 = 2       /* 3x3 taps at origin + {0,1,2} x {0,1,2} */
} hush_footprint;

/* A bilinear tap whose weight is below this is not used (the back-projected
 * point sits on another tap's centre): float noise of ~1e-5 pixel must not
 * decide whether a neighbour's history is taken. */
#define HUSH_REPROJECT_MIN_WEIGHT 1e-3f

/* The 3x3 fallback kernel k of Higginson 2023 §1.3.1, row-major. */
extern const float hush__reproject_k3x3[9];

/*
 * A reprojection plan: per pixel i (row-major, i = y * width + x),
 *   kind[i]   hush_footprint;
 *   mask[i]   the consistent taps: bit (j * 2 + i) of the 2x2 footprint,
 *             bit (j * 3 + i) of the 3x3 one (i across, j down); 0 with NONE;
 *   origin[i] previous-frame pixel index of the footprint's top-left tap.
 *             BILINEAR (in images at least 2x2): the 2x2 block origin,
 *             origin + 1, origin + width, origin + width + 1 always lies
 *             inside the image: a footprint that overhangs the border is
 *             moved inside, with its mask bits and fractions (fx = 0 or 1,
 *             fy likewise, see w), so the taps and weights stay the same. 3X3 (and
 *             BILINEAR in a 1-pixel-wide or -high image): the top-left tap
 *             may lie outside the image and the index even be negative;
 *             only masked taps are ever read;
 *   w[t][i]   BILINEAR: the renormalised weight of tap t = 0..3 (the
 *             bilinear weight (1-fx)(1-fy), fx(1-fy), (1-fx)fy or fx fy of
 *             the footprint's fractions fx, fy if t is in the mask, else 0,
 *             divided by the sum of the four: hush__reproject_renormalised),
 *             exactly hush__reproject_weights4's; 0 for every other kind. A
 *             tap is in the mask only if it is on-screen, consistent and its
 *             bilinear weight is at least HUSH_REPROJECT_MIN_WEIGHT.
 *             Computed once at build time, so a block gather is origin +
 *             four weights, with no branch or divide, and a NONE pixel
 *             gathers 0. (The fractions themselves are not stored: 8 bytes
 *             a pixel less to write per frame.)
 *   blocks    width >= 2 && height >= 2: BILINEAR pixels may be gathered as
 *             blocks (hush__reproject_weights4).
 * Built by hush__reproject_build; read with hush__reproject_taps /
 * hush__reproject_weights4 or gathered with hush__reproject_gather.
 *
 * A fast gather over a row (see hush__reproject_gather) handles every pixel
 * as a block, with origin hush__reproject_block_origin (a safe index for
 * non-BILINEAR pixels, whose weights are 0), then redoes the rare 3X3
 * pixels with hush__reproject_taps.
 */
typedef struct hush_reproject_plan {
  uint32_t width, height;
  int blocks;
  int32_t *origin;
  uint16_t *mask;
  uint8_t *kind;
  float *w[4];
} hush_reproject_plan;

hush_status hush__reproject_plan_init(hush_device device, hush_reproject_plan *plan,
                                      uint32_t width, uint32_t height);
void hush__reproject_plan_free(hush_reproject_plan *plan);
/* Marks every pixel NONE (no history). */
void hush__reproject_plan_clear(hush_reproject_plan *plan, int threads);

/*
 * A plan built in pieces: hush__reproject_begin resolves the frame's
 * constants (and fails as hush__reproject_build does), hush__reproject_rows
 * builds rows y0..y1-1 (rows in any order, from any thread: each row is
 * computed on its own). Together they give hush__reproject_build's plan.
 * The job copies in and prev (their planes are only pointed to).
 */
typedef struct hush_reproject_job {
  hush_reproject_input in;
  hush_gbuffer prev;
  int clear;        /* no history: the rows are cleared */
  int W, H;
  int vectors;      /* HUSH_MOTION_VECTORS */
  int has_position; /* in.position usable */
  int inv_ok;       /* the current camera can be inverted */
  int std_proj;     /* view_to_clip's z and w rows depend on view z only */
  int use_id;       /* both frames have ids and the test is on */
  int fallback;
  float tol, grad, cos_min;
  float jx, jy;
  /* std_proj: clip = (nx w, ny w, p10 (-z) + p14, w), w = p11 (-z) + p15 */
  float p10, p11, p14, p15;
  float cur_to_prev[16]; /* prev_vp * inverse(view_to_clip * world_to_view) */
  float cur_to_prev_view_z[4]; /* row 2 of prev_world_to_view * that inverse */
  /* generic projections */
  float inv_v2c[16], inv_w2v[16];
  float prev_vp[16];  /* prev_view_to_clip * prev_world_to_view */
  float prev_w2v[16]; /* for the expected depth */
} hush_reproject_job;

hush_status hush__reproject_begin(hush_device device, const hush_reproject_plan *plan,
                                  const hush_reproject_input *in, const hush_gbuffer *prev,
                                  const hush_frame_info *info, const hush_reproject_params *params,
                                  hush_reproject_job *job);
void hush__reproject_rows(const hush_reproject_job *job, hush_reproject_plan *plan, int y0,
                          int y1);

/*
 * Builds the plan of this frame against the previous frame's G-buffer prev.
 * With prev == NULL or info->history == HUSH_HISTORY_RESET the plan is
 * cleared. Fails (and leaves the plan untouched) with
 * HUSH_ERROR_INVALID_OPERATION when info->motion is VECTORS and no motion is
 * given, or with HUSH_ERROR_INVALID_ARGUMENT when the CAMERA source has no
 * position and this frame's matrices cannot be inverted.
 */
hush_status hush__reproject_build(hush_device device, hush_reproject_plan *plan,
                                  const hush_reproject_input *in, const hush_gbuffer *prev,
                                  const hush_frame_info *info, const hush_reproject_params *params,
                                  int threads);

/* The four bilinear weights (1-fx)(1-fy), fx(1-fy), (1-fx)fy, fx fy. */
static inline void hush__reproject_bilinear(float fx, float fy, float w[4]) {
  w[0] = (1.0f - fx) * (1.0f - fy);
  w[1] = fx * (1.0f - fy);
  w[2] = (1.0f - fx) * fy;
  w[3] = fx * fy;
}

/* The first pixel in [i, end) with a 3X3 footprint, or end. The rows'
 * passes redo those few pixels after their vector loops; memchr finds them
 * about 20x faster than a byte-by-byte test of every pixel (that loop was
 * a sixth of the phase I blend). */
static inline size_t hush__reproject_next_3x3(const hush_reproject_plan *plan, size_t i,
                                              size_t end) {
  const void *p = i < end ? memchr(plan->kind + i, HUSH_FOOTPRINT_3X3, end - i) : NULL;
  return p ? (size_t)((const uint8_t *)p - plan->kind) : end;
}

/* Whether pixel i is gathered as a 2x2 block (the common case): then its
 * taps are origin, origin + 1, origin + width, origin + width + 1, all inside
 * the image, with the weights of hush__reproject_weights4. */
static inline int hush__reproject_is_block(const hush_reproject_plan *plan, size_t i) {
  return plan->kind[i] == HUSH_FOOTPRINT_BILINEAR && plan->blocks;
}

/* The renormalised weights of the four taps of a BILINEAR pixel with mask m
 * and fractions fx, fy: the bilinear weights of the taps in the mask (0 for
 * the others) divided by their sum. Branch-free; the build stores them in
 * plan->w. */
static inline void hush__reproject_renormalised(unsigned m, float fx, float fy, float w[4]) {
  hush__reproject_bilinear(fx, fy, w);
  w[0] = (m & 1u) ? w[0] : 0.0f;
  w[1] = (m & 2u) ? w[1] : 0.0f;
  w[2] = (m & 4u) ? w[2] : 0.0f;
  w[3] = (m & 8u) ? w[3] : 0.0f;
  const float inv = 1.0f / (w[0] + w[1] + w[2] + w[3]);
  w[0] *= inv;
  w[1] *= inv;
  w[2] *= inv;
  w[3] *= inv;
}

/* The renormalised weights of a block pixel's four taps (0 for the taps not
 * in the mask), summing to 1 up to rounding: plan->w, computed by the build
 * with hush__reproject_renormalised. */
static inline void hush__reproject_weights4(const hush_reproject_plan *plan, size_t i,
                                            float w[4]) {
  w[0] = plan->w[0][i];
  w[1] = plan->w[1][i];
  w[2] = plan->w[2][i];
  w[3] = plan->w[3][i];
}

/* The origin a row-wide block gather uses for pixel i: plan->origin for
 * BILINEAR pixels (in a plan with blocks), 0 for the others, whose weights
 * are all 0 (so the gather reads inside the image and yields 0). */
static inline int32_t hush__reproject_block_origin(const hush_reproject_plan *plan, size_t i) {
  const int32_t o = plan->origin[i]; /* loaded unconditionally: no masked load */
  return o & -(int32_t)(plan->kind[i] == HUSH_FOOTPRINT_BILINEAR);
}

/* Pixels per chunk of the temporal blends' row loops (accumulation.c),
 * which read the history by footprint. */
#define HUSH_CHUNK 16

/* 1 if the HUSH_CHUNK pixels from origin/kind all have BILINEAR footprints
 * that follow each other (origin[k] = origin[0] + k, as under smooth
 * motion), so their taps load as vectors. A fixed count, so that it
 * vectorises: the loop to a variable end ran scalar, about 5 % of
 * accumulate's blend (docs/svgf-speed.md, twenty-sixth round). */
#if defined(__AVX512F__)
/* The lanes k of the 16 origins o whose origin is first + k: a chunk's
 * footprints that follow each other (the common case of smooth motion). */
static HUSH_ALWAYS_INLINE __mmask16 hush__run_mask16(__m512i o, int32_t first) {
  const __m512i want = _mm512_add_epi32(
      _mm512_set1_epi32(first),
      _mm512_set_epi32(15, 14, 13, 12, 11, 10, 9, 8, 7, 6, 5, 4, 3, 2, 1, 0));
  return _mm512_cmpeq_epi32_mask(o, want);
}
#endif

static HUSH_ALWAYS_INLINE int hush__chunk_contiguous(const int32_t *origin, const uint8_t *kind) {
#if defined(__AVX512F__) && defined(__AVX512BW__) && defined(__AVX512VL__) && HUSH_CHUNK == 16
  /* two compares into mask registers: with the bytes in it, gcc vectorised
   * the loop below at 16 bytes, the origins' compares in four pieces */
  const __mmask16 run =
      hush__run_mask16(_mm512_loadu_si512((const void *)origin), origin[0]);
  const __mmask16 bil = _mm_cmpeq_epi8_mask(_mm_loadu_si128((const __m128i *)(const void *)kind),
                                            _mm_set1_epi8((char)HUSH_FOOTPRINT_BILINEAR));
  return (run & bil) == 0xFFFF;
#else
  const int32_t o0 = origin[0];
  int contiguous = 1;
  for (int k = 0; k < HUSH_CHUNK; k++)
    contiguous &= (kind[k] == HUSH_FOOTPRINT_BILINEAR) & (origin[k] == o0 + k);
  return contiguous;
#endif
}

/*
 * The taps of pixel i and their renormalised weights (summing to 1 up to
 * rounding): writes up to 9 previous-frame pixel indices to idx and weights
 * to w, returns the count (0: no history): the weights of the valid taps
 * divided by their sum (for BILINEAR, those of hush__reproject_weights4).
 */
static inline int hush__reproject_taps(const hush_reproject_plan *plan, size_t i, int32_t idx[9],
                                       float w[9]) {
  const unsigned mask = plan->mask[i];
  if (!mask) return 0;
  const int32_t o = plan->origin[i];
  const int32_t W = (int32_t)plan->width;
  int n = 0;
  if (plan->kind[i] == HUSH_FOOTPRINT_BILINEAR) {
    float bw[4];
    hush__reproject_weights4(plan, i, bw);
    for (int t = 0; t < 4; t++)
      if (mask & (1u << t)) {
        idx[n] = o + (t >> 1) * W + (t & 1);
        w[n] = bw[t];
        n++;
      }
  } else {
    float sum = 0.0f;
    for (int t = 0; t < 9; t++)
      if (mask & (1u << t)) sum += hush__reproject_k3x3[t];
    const float inv = 1.0f / sum;
    for (int t = 0; t < 9; t++)
      if (mask & (1u << t)) {
        idx[n] = o + (t / 3) * W + (t % 3);
        w[n] = hush__reproject_k3x3[t] * inv;
        n++;
      }
  }
  return n;
}

/* sum_t w_t p[idx_t] over n taps. */
static inline float hush__reproject_apply(const float *p, const int32_t *idx, const float *w,
                                          int n) {
  float s = 0.0f;
  for (int t = 0; t < n; t++) s += w[t] * p[idx[t]];
  return s;
}

/* The block gather: w from hush__reproject_weights4. */
static inline float hush__reproject_apply4(const float *p, size_t o, size_t width,
                                           const float w[4]) {
  return w[0] * p[o] + w[1] * p[o + 1] + w[2] * p[o + width] + w[3] * p[o + width + 1];
}

/* ---- prefetching the history's taps ----------------------------------------
 * A row's chunk loops (the plan's tap tests, the blends, TAA) read the
 * previous frame's planes at each footprint's two rows: with 5 to 7 planes
 * that is 10 to 14 streams at once beside the current frame's, more than
 * the hardware prefetchers follow, and the loads waited on L2 and L3 (the
 * samples of a profile of the plan's tap tests piled on them). Each chunk
 * asks for the lines of the chunk HUSH_PREFETCH_AHEAD pixels further on
 * (1280x720, 2 threads, Zen 3, medians of alternated runs; docs/svgf-speed.md,
 * twenty-first round): svgf's reprojection 7.9 -> 7.6 ms, its blend 5.3 ->
 * 4.9, TAA's resolve 5.8 -> 4.9, bmfr's phase III 3.0 -> 2.75. 16 pixels
 * ahead was slower, 48 or 64 the same. On Zen 5, whose chunks run faster,
 * 32 was too close: 64 took svgf's reprojection 4.50 -> 4.27 ms and bmfr's
 * phase I 5.44 -> 5.14 (three alternated pairs); 128 was in between. */
#define HUSH_PREFETCH_AHEAD 64

/* Prefetches rows j, j + W and j + 2W of planes[0..n-1] (NULL: skipped),
 * the line of pixel j and the next. A chunk that is not contiguous reads up
 * to 32 pixels of each row (a window's two loads, the diagonals' two
 * bases), and a window whose footprints start on two rows reads three; on
 * the classroom's frames a profile put a third of window_read's samples on
 * the loads of those lines. With the next line: bmfr's phase I 8.9-9.1 ->
 * 8.2-8.5 ms, phase III 2.64-2.69 -> 2.46-2.54; with the third row too,
 * phase I 8.7-9.3 -> 7.9-8.0, phase III 2.6-3.1 -> 2.3-2.4, TAA 3.9-4.0 ->
 * 3.4 (2 threads, three alternated runs each); the bench frames' phase I
 * 5.0-5.07 -> 4.73-4.87 and TAA 2.47-2.52 -> 2.31-2.38, svgf 24.3 -> 23.8
 * ms. j may lie outside the planes (hush__prefetch). */
static HUSH_ALWAYS_INLINE void hush__prefetch_taps(const float *const *planes, int n, int64_t j,
                                                   int32_t W) {
  const ptrdiff_t top = (ptrdiff_t)j * (ptrdiff_t)sizeof(float);
  const ptrdiff_t bottom = top + (ptrdiff_t)W * (ptrdiff_t)sizeof(float);
  for (int p = 0; p < n; p++)
    if (planes[p]) {
      hush__prefetch(planes[p], top);
      hush__prefetch(planes[p], bottom);
      hush__prefetch(planes[p], top + 64);
      hush__prefetch(planes[p], bottom + 64);
      hush__prefetch(planes[p], bottom + (ptrdiff_t)W * (ptrdiff_t)sizeof(float));
      hush__prefetch(planes[p], bottom + (ptrdiff_t)W * (ptrdiff_t)sizeof(float) + 64);
    }
}

/* Pixels ahead of a row's chunk loop whose plan entries and samples
 * (sequential streams, but a dozen of them beside the history's) are
 * prefetched (hush__prefetch_row): svgf's blend 4.77 -> 4.62 ms, TAA's
 * resolve 4.69 -> 4.62 (medians of five alternated pairs, 2 threads,
 * 1280x720, Zen 3; docs/svgf-speed.md, twenty-first round). 128 on the
 * Zen 5, where bmfr's blends read the plan back from memory right after
 * its streamed stores: bmfr 12.08 -> 11.97 ms, p5 11.50 -> 11.36 (eight
 * alternated runs; 256 no better than 64), svgf unchanged. */
#define HUSH_PREFETCH_ROW_AHEAD 128

/* Prefetches pixel i + HUSH_PREFETCH_ROW_AHEAD of the plan's origins and
 * weights and of planes[0..n-1] (NULL: skipped); near the frame's end it
 * lies past them (hush__prefetch). */
static HUSH_ALWAYS_INLINE void hush__prefetch_row(const hush_reproject_plan *plan,
                                                  const float *const *planes, int n, size_t i) {
  const ptrdiff_t q = (ptrdiff_t)(i + HUSH_PREFETCH_ROW_AHEAD);
  _Static_assert(sizeof *plan->origin == sizeof(float), "origins and weights alike");
  const ptrdiff_t bytes = q * (ptrdiff_t)sizeof(float);
  hush__prefetch(plan->origin, bytes);
  for (int t = 0; t < 4; t++) hush__prefetch(plan->w[t], bytes);
  hush__prefetch_planes(planes, n, bytes);
}

/* The footprint origin HUSH_PREFETCH_AHEAD pixels after pixel k of a run
 * of n origins: its own, or past the run's end the last one's moved on by
 * as many pixels (the next run, under smooth motion). A pixel without a
 * footprint has origin 0 (the plan's NONE; the span test's outside), which
 * would ask for the frame's first row: pixel k's moved on instead
 * (disocclusions are common on rendered frames). */
static inline int64_t hush__prefetch_origin(const int32_t *origin, int k, int n) {
  const int kp = k + HUSH_PREFETCH_AHEAD;
  if (kp < n && origin[kp] != 0) return (int64_t)origin[kp];
  if (kp < n) return (int64_t)origin[k] + HUSH_PREFETCH_AHEAD;
  return (int64_t)origin[n - 1] + (kp - (n - 1));
}

/* ---- a chunk of footprints on two diagonals --------------------------------
 * Under smooth motion a chunk's footprints mostly follow each other
 * (origin = base + k for pixel k), and where the motion carries them a
 * column or a row further part of the chunk follows a second such diagonal
 * (28 % of the chunks of `hush bench`'s orbiting camera, 40 % of the
 * classroom path's). Each tap is then one of two plain vector loads, picked
 * per pixel: two loads and a blend where a gather of 8 floats costs gcc's
 * 8 loads and 7 inserts (AVX2 without fast gathers). The value picked is
 * the tap itself, so the results are a gather's, bit for bit. */

/* Pixels per chunk of hush__reproject_diagonals. */
#define HUSH_DIAGONAL_CHUNK 16

/*
 * Whether the footprint origins origin[0..15] of the pixels in use lie on
 * at most two diagonals, origin[k] = b + k, with every tap b + k + {0, 1,
 * W, W + 1} (k = 0..15) of both inside a plane of `size` floats: returns
 * the number of diagonals (1 or 2; 0: no, or no pixel in use), their b in
 * base[0] <= base[1] (equal with one). The pixels in use: those whose
 * kind[k] is HUSH_FOOTPRINT_BILINEAR, or with kind NULL those whose
 * flag[k] is not 0. Pixels not in use may read either diagonal's taps (in
 * the plane, their values to be ignored).
 */
static inline int hush__reproject_diagonals_scalar(const int32_t *origin, const uint8_t *kind,
                                                   const int32_t *flag, int32_t W, size_t size,
                                                   int32_t base[2]) {
  int32_t lo = INT32_MAX, hi = INT32_MIN;
  for (int k = 0; k < HUSH_DIAGONAL_CHUNK; k++) {
    const int32_t d = origin[k] - k;
    if (kind ? kind[k] == HUSH_FOOTPRINT_BILINEAR : flag[k] != 0) {
      lo = d < lo ? d : lo;
      hi = d > hi ? d : hi;
    }
  }
  if (lo > hi) return 0;
  for (int k = 0; k < HUSH_DIAGONAL_CHUNK; k++) {
    const int32_t d = origin[k] - k;
    const int use = kind ? kind[k] == HUSH_FOOTPRINT_BILINEAR : flag[k] != 0;
    if (use && d != lo && d != hi) return 0;
  }
  if (lo < 0 || (int64_t)hi + HUSH_DIAGONAL_CHUNK + W >= (int64_t)size) return 0;
  base[0] = lo;
  base[1] = hi;
  return lo == hi ? 1 : 2;
}

#if defined(__AVX2__)
#  include <immintrin.h>
/* The extremum of the 8 lanes of v, in every lane (op: min or max). */
#  define HUSH_HREDUCE8(op, v)                                                              \
    do {                                                                                    \
      v = op(v, _mm256_permute2x128_si256(v, v, 1));                                        \
      v = op(v, _mm256_shuffle_epi32(v, 0x4e));                                             \
      v = op(v, _mm256_shuffle_epi32(v, 0xb1));                                             \
    } while (0)

/* hush__reproject_diagonals_scalar from AVX2 operations on the 16 origins
 * at once, the pixels not in use given as all bits set in off0 (pixels
 * 0..7) and off1 (8..15): the scalar loops' branches on each pixel would
 * cost a chunk more than its gather saves. */
static HUSH_ALWAYS_INLINE int hush__diagonals_avx2(const int32_t *origin, __m256i off0,
                                                   __m256i off1, int32_t W, size_t size,
                                                   int32_t base[2]) {
  const __m256i lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
  const __m256i d0 = _mm256_sub_epi32(_mm256_loadu_si256((const __m256i *)(const void *)origin),
                                      lane);
  const __m256i d1 = _mm256_sub_epi32(
      _mm256_loadu_si256((const __m256i *)(const void *)(origin + 8)),
      _mm256_add_epi32(lane, _mm256_set1_epi32(8)));
  const __m256i big = _mm256_set1_epi32(INT32_MAX), small = _mm256_set1_epi32(INT32_MIN);
  __m256i lo =
      _mm256_min_epi32(_mm256_blendv_epi8(d0, big, off0), _mm256_blendv_epi8(d1, big, off1));
  __m256i hi = _mm256_max_epi32(_mm256_blendv_epi8(d0, small, off0),
                                _mm256_blendv_epi8(d1, small, off1));
  HUSH_HREDUCE8(_mm256_min_epi32, lo);
  HUSH_HREDUCE8(_mm256_max_epi32, hi);
  const int32_t l = _mm256_cvtsi256_si32(lo), h = _mm256_cvtsi256_si32(hi);
  if (l > h) return 0;
  const __m256i on0 = _mm256_or_si256(
      off0, _mm256_or_si256(_mm256_cmpeq_epi32(d0, lo), _mm256_cmpeq_epi32(d0, hi)));
  const __m256i on1 = _mm256_or_si256(
      off1, _mm256_or_si256(_mm256_cmpeq_epi32(d1, lo), _mm256_cmpeq_epi32(d1, hi)));
  if (_mm256_movemask_epi8(_mm256_and_si256(on0, on1)) != -1) return 0;
  if (l < 0 || (int64_t)h + HUSH_DIAGONAL_CHUNK + W >= (int64_t)size) return 0;
  base[0] = l;
  base[1] = h;
  return l == h ? 1 : 2;
}
#  undef HUSH_HREDUCE8

static HUSH_ALWAYS_INLINE int hush__reproject_diagonals(const int32_t *origin, const uint8_t *kind,
                                                        const int32_t *flag, int32_t W,
                                                        size_t size, int32_t base[2]) {
  __m256i off0, off1;
  if (kind) {
    const __m128i bil = _mm_cmpeq_epi8(_mm_loadu_si128((const __m128i *)(const void *)kind),
                                       _mm_set1_epi8(HUSH_FOOTPRINT_BILINEAR));
    /* -1 (in use) or 0 per pixel, widened; then inverted */
    const __m256i ones = _mm256_set1_epi32(-1);
    off0 = _mm256_xor_si256(_mm256_cvtepi8_epi32(bil), ones);
    off1 = _mm256_xor_si256(_mm256_cvtepi8_epi32(_mm_srli_si128(bil, 8)), ones);
  } else {
    const __m256i zero = _mm256_setzero_si256();
    off0 = _mm256_cmpeq_epi32(_mm256_loadu_si256((const __m256i *)(const void *)flag), zero);
    off1 = _mm256_cmpeq_epi32(_mm256_loadu_si256((const __m256i *)(const void *)(flag + 8)),
                              zero);
  }
  return hush__diagonals_avx2(origin, off0, off1, W, size, base);
}
#else
static inline int hush__reproject_diagonals(const int32_t *origin, const uint8_t *kind,
                                            const int32_t *flag, int32_t W, size_t size,
                                            int32_t base[2]) {
  return hush__reproject_diagonals_scalar(origin, kind, flag, W, size, base);
}
#endif

/* ---- a chunk of footprints as one window ----------------------------------
 * Under camera motion the 2x2 footprints of neighbouring pixels rarely
 * follow each other exactly (origin + 1 per pixel): the offset drifts by a
 * pixel now and then, or crosses a row. A chunk of n pixels whose footprint
 * origins all lie, relative to the diagonal base + k (k: the pixel in the
 * chunk), within 16 columns of 1 or 2 rows ("a window") reads every tap with
 * plain vector loads of the window and a per-pixel selection instead of a
 * gather of scattered floats (which gcc emits as scalar loads here, ~3x the
 * time). The value selected is the tap itself, so results are bit for bit
 * those of a gather. The window's two 16-float loads per row reach 15
 * columns past the diagonal, so 16 columns cost what 3 did; under a fast
 * camera (the classroom's path at 1280x720) the wider windows took 45 % of
 * the gathered chunks (docs/svgf-speed.md, twelfth round). */

/* Most pixels a window covers (the chunk size of the callers). */
#define HUSH_WINDOW_MAX 16

/*
 * Whether the footprint origins origin[0..n-1] (n <= HUSH_WINDOW_MAX) of
 * the pixels with use[k] != 0 form a window of a plane of `size` floats
 * with rows of W: returns 0 (no), 1 (one row: every footprint's top taps
 * in the same row) or 2 (two rows). Then the top-left tap of pixel k is
 * base + k + dy[k] * W + e[k] (e 0..15, dy 0..1), and every load of
 * hush__window_tap lies inside the plane; pixels without use get e = dy =
 * 0 (their loads are inside the window, their values to be ignored).
 */
static inline int hush__reproject_window(const int32_t *origin, const uint8_t *use, int n,
                                         int32_t W, size_t size, int32_t *base, int32_t *e,
                                         int32_t *dy) {
  int first = -1;
  for (int k = 0; k < n && first < 0; k++)
    if (use[k]) first = k;
  if (first < 0) return 0;
  const int32_t rowstart = origin[first] / W * W;
  int ymin = 1, ymax = -1, ok = 1;
  int32_t xmin = INT32_MAX, xmax = INT32_MIN;
  int8_t d[HUSH_WINDOW_MAX];
  int32_t ox[HUSH_WINDOW_MAX];
  for (int k = 0; k < n; k++) {
    const int32_t o = origin[k];
    const int dk = (o >= rowstart + W) - (o < rowstart); /* the row, if within one */
    const int32_t col = o - rowstart - dk * W;
    const int u = use[k] != 0;
    ok &= (u == 0) | ((col >= 0) & (col < W));
    d[k] = (int8_t)dk;
    ox[k] = col - k;
    if (u) {
      ymin = dk < ymin ? dk : ymin;
      ymax = dk > ymax ? dk : ymax;
      xmin = ox[k] < xmin ? ox[k] : xmin;
      xmax = ox[k] > xmax ? ox[k] : xmax;
    }
  }
  if (!ok || ymax - ymin > 1 || xmax - xmin > 15) return 0;
  const int rows = ymax > ymin ? 2 : 1;
  const int64_t b = (int64_t)rowstart + (int64_t)ymin * W + xmin;
  /* the loads of hush__window_taps: base + r * W + 0..31, r 0..rows */
  if (b < 0 || b + (int64_t)rows * W + 31 >= (int64_t)size) return 0;
  for (int k = 0; k < n; k++) {
    e[k] = use[k] ? ox[k] - xmin : 0;
    dy[k] = use[k] ? d[k] - ymin : 0;
  }
  *base = (int32_t)b;
  return rows;
}

#if defined(__AVX512BW__) && defined(__AVX512VL__)
#  include <immintrin.h>
/*
 * hush__reproject_window for n = HUSH_WINDOW_MAX: the same results from
 * AVX-512 operations on the 16 origins at once (the scalar loop's
 * per-pixel tests and running extrema cost a window chunk about a quarter
 * of its time).
 */
static HUSH_ALWAYS_INLINE int hush__reproject_window16(const int32_t *origin, const uint8_t *use,
                                                       int32_t W, size_t size, int32_t *base,
                                                       int32_t *e, int32_t *dy) {
  const __mmask16 u = _mm_test_epi8_mask(_mm_loadu_si128((const __m128i *)(const void *)use),
                                         _mm_set1_epi8(-1));
  if (!u) return 0;
  const int32_t rowstart = origin[__builtin_ctz(u)] / W * W;
  const __m512i o = _mm512_loadu_si512(origin), rs = _mm512_set1_epi32(rowstart);
  const __m512i Wv = _mm512_set1_epi32(W), one = _mm512_set1_epi32(1);
  /* the row against rowstart's (-1, 0 or 1, if within one) and the column */
  const __mmask16 below = _mm512_cmpge_epi32_mask(o, _mm512_add_epi32(rs, Wv));
  const __mmask16 above = _mm512_cmplt_epi32_mask(o, rs);
  const __m512i dk = _mm512_sub_epi32(_mm512_maskz_mov_epi32(below, one),
                                     _mm512_maskz_mov_epi32(above, one));
  const __m512i col = _mm512_add_epi32(
      _mm512_sub_epi32(_mm512_sub_epi32(o, rs), _mm512_maskz_mov_epi32(below, Wv)),
      _mm512_maskz_mov_epi32(above, Wv));
  if (_mm512_mask_cmplt_epi32_mask(u, col, _mm512_setzero_si512()) |
      _mm512_mask_cmpge_epi32_mask(u, col, Wv))
    return 0;
  const __m512i lane = _mm512_set_epi32(15, 14, 13, 12, 11, 10, 9, 8, 7, 6, 5, 4, 3, 2, 1, 0);
  const __m512i ox = _mm512_sub_epi32(col, lane);
  const int ymin = _mm512_mask_reduce_min_epi32(u, dk), ymax = _mm512_mask_reduce_max_epi32(u, dk);
  const int32_t xmin = _mm512_mask_reduce_min_epi32(u, ox);
  const int32_t xmax = _mm512_mask_reduce_max_epi32(u, ox);
  if (ymax - ymin > 1 || xmax - xmin > 15) return 0;
  const int rows = ymax > ymin ? 2 : 1;
  const int64_t b = (int64_t)rowstart + (int64_t)ymin * W + xmin;
  if (b < 0 || b + (int64_t)rows * W + 31 >= (int64_t)size) return 0;
  _mm512_storeu_si512(e, _mm512_maskz_sub_epi32(u, ox, _mm512_set1_epi32(xmin)));
  _mm512_storeu_si512(dy, _mm512_maskz_sub_epi32(u, dk, _mm512_set1_epi32(ymin)));
  *base = (int32_t)b;
  return rows;
}
#else
static inline int hush__reproject_window16(const int32_t *origin, const uint8_t *use, int32_t W,
                                           size_t size, int32_t *base, int32_t *e, int32_t *dy) {
  return hush__reproject_window(origin, use, HUSH_WINDOW_MAX, W, size, base, e, dy);
}
#endif

/* With AVX-512 (one vpermt2ps per tap and plane); elsewhere gcc would
 * emulate the permutes, and the gathers stay. */
#if defined(__GNUC__) && !defined(__clang__) && defined(__AVX512F__)
#  define HUSH_HAVE_WINDOW 1
typedef float hush_v16f __attribute__((vector_size(64)));
typedef int32_t hush_v16i __attribute__((vector_size(64)));

/*
 * The four taps of every pixel k of a window of HUSH_WINDOW_MAX pixels
 * (hush__reproject_window's base, e, dy; rows 1 or 2, a constant at each
 * call) of plane p: out[ty * 2 + tx][k] = p[base + k + (dy[k] + ty) W +
 * e[k] + tx]. Per row of the window two vector loads hold the 32 floats
 * its pixels can need; a two-source permute (vpermt2ps with AVX-512)
 * picks each pixel's tap.
 */
static HUSH_ALWAYS_INLINE void hush__window_taps(const float *p, int32_t base, int32_t W,
                                                 const int32_t *e, const int32_t *dy,
                                                 const int rows, float out[4][HUSH_WINDOW_MAX]) {
  hush_v16i ev, dv;
  memcpy(&ev, e, sizeof ev);
  memcpy(&dv, dy, sizeof dv);
  const hush_v16i lane = {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15};
  const hush_v16i i0 = lane + ev, i1 = i0 + 1;
  const hush_v16i second = dv != 0; /* -1 (all bits) where the top taps are in row 1 */
  for (int ty = 0; ty < 2; ty++) {
    const float *r = p + base + (size_t)ty * (size_t)W;
    hush_v16f lo, hi; /* any alignment */
    memcpy(&lo, r, sizeof lo);
    memcpy(&hi, r + 16, sizeof hi);
    hush_v16f t0 = __builtin_shuffle(lo, hi, i0), t1 = __builtin_shuffle(lo, hi, i1);
    if (rows == 2) {
      hush_v16f lo2, hi2;
      memcpy(&lo2, r + W, sizeof lo2);
      memcpy(&hi2, r + W + 16, sizeof hi2);
      const hush_v16f u0 = __builtin_shuffle(lo2, hi2, i0), u1 = __builtin_shuffle(lo2, hi2, i1);
      hush_v16i a0, a1, b0, b1;
      memcpy(&a0, &t0, sizeof a0);
      memcpy(&a1, &t1, sizeof a1);
      memcpy(&b0, &u0, sizeof b0);
      memcpy(&b1, &u1, sizeof b1);
      a0 = (a0 & ~second) | (b0 & second);
      a1 = (a1 & ~second) | (b1 & second);
      memcpy(&t0, &a0, sizeof t0);
      memcpy(&t1, &a1, sizeof t1);
    }
    memcpy(out[ty * 2], &t0, sizeof t0);
    memcpy(out[ty * 2 + 1], &t1, sizeof t1);
  }
}

/*
 * The chunk of HUSH_WINDOW_MAX pixels from index i of plan: when the
 * footprints of its BILINEAR pixels form a window, the four taps of every
 * plane that is not NULL into out[p] (hush__window_taps) and the window's
 * rows (1 or 2) returned; else 0 and nothing read. A function of its own,
 * not inlined: in the callers' chunk loops its code cost the common
 * contiguous chunks more than the call costs the window ones.
 */
int hush__window_read(const hush_reproject_plan *plan, size_t i, const float *const *planes,
                      int nplanes, float (*out)[4][HUSH_WINDOW_MAX]);
#endif

/* Without windows, AVX2 builds read the chunks on two diagonals as such
 * (the chunk loops' HUSH_HAVE_DIAGONALS paths); narrower vectors keep the
 * gathers, which the diagonals' extra loads and selects would not repay. */
#if !defined(HUSH_HAVE_WINDOW) && defined(__AVX2__)
#  define HUSH_HAVE_DIAGONALS 1
#endif
/* TAA's resolve and the blends (accumulation.c) take a chunk on two
 * diagonals as such in every AVX2 build, the AVX-512 ones before trying a
 * window: for its three planes two loads and a blend a tap cost less than
 * the window's extent reductions, loads and permutes (TAA 2.83-2.87 ->
 * 2.71-2.76 ms, bmfr on the bench frames, 2 threads; docs/svgf-speed.md,
 * twenty-ninth round). The blends followed once their loops ran at 512
 * bits: bmfr's phase I 4.09 -> 4.00 ms, phase III 0.98 -> 0.94, svgf 23.86
 * -> 23.59 (alternated runs; with 256-bit halves it had been no gain for
 * bmfr's, svgf's seven planes slower). */
#if defined(__AVX2__)
#  define HUSH_HAVE_DIAGONAL_READS 1
#endif

/*
 * Gathers `channels` (1..8) previous-frame planes through the plan:
 * out[c][i] = sum_t w_t * prev[c][idx_t]; pixels with no history get
 * fill_value. out must not alias prev.
 */
void hush__reproject_gather(const hush_reproject_plan *plan, const float *const *prev,
                            int channels, float *const *out, float fill_value, int threads);

/*
 * A reprojector: the previous frame's G-buffer (ping-pong, so no copy per
 * frame) and the plan. Per frame:
 *   hush_gbuffer_store *g = hush__reprojector_next(r);  // import depth,
 *       // normal (and, after hush__reprojector_want_id, id) into g's planes,
 *       // set g->has_id
 *   hush__reprojector_build(...);  // builds r->plan; this frame becomes
 *                                  // the previous one of the next frame
 * A failure before build leaves the history as it was.
 */
typedef struct hush_gbuffer_store {
  hush_planar depth;  /* 1 channel */
  hush_planar normal; /* 3 channels */
  hush_planar id;     /* 1 channel, allocated by hush__reprojector_want_id */
  int has_id;         /* the id plane holds this frame's ids */
} hush_gbuffer_store;

typedef struct hush_reprojector {
  uint32_t width, height;
  hush_gbuffer_store store[2];
  int latest;      /* store holding the last built frame */
  int has_history; /* store[latest] is valid */
  hush_reproject_plan plan;
} hush_reprojector;

hush_status hush__reprojector_init(hush_device device, hush_reprojector *r, uint32_t width,
                                   uint32_t height);
void hush__reprojector_free(hush_reprojector *r);
/* Forgets the previous frame (the next build has no history). */
void hush__reprojector_reset(hush_reprojector *r);
/* The store this frame's G-buffer goes into. */
static inline hush_gbuffer_store *hush__reprojector_next(hush_reprojector *r) {
  return &r->store[1 - r->latest];
}
/* The store of the last built frame (after build: this frame's). */
static inline const hush_gbuffer_store *hush__reprojector_latest(const hush_reprojector *r) {
  return &r->store[r->latest];
}
/* Allocates the id planes (once); call before importing ids. */
hush_status hush__reprojector_want_id(hush_device device, hush_reprojector *r);
/* Builds r->plan for the G-buffer in hush__reprojector_next(r) plus the
 * optional position/motion planes (each array NULL or all its planes), then
 * makes this frame the previous one. On failure nothing changes. */
hush_status hush__reprojector_build(hush_device device, hush_reprojector *r,
                                    const float *const *position, const float *const *motion,
                                    const hush_frame_info *info,
                                    const hush_reproject_params *params, int threads);
/* As hush__reprojector_build, the plan's rows left to the caller: after
 * it, hush__reproject_rows(job, &r->plan, ...) over all rows gives the same
 * plan (the frame has already become the previous one). */
hush_status hush__reprojector_begin(hush_device device, hush_reprojector *r,
                                    const float *const *position, const float *const *motion,
                                    const hush_frame_info *info,
                                    const hush_reproject_params *params, hush_reproject_job *job);

#endif
