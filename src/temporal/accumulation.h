/*
 * accumulation.h — temporal accumulation of a 1..4 channel signal and of
 * the first two moments of its luminance, with a per-pixel history length
 * ("age"), through a reprojection plan (reproject.h).
 *
 * Follows Dundr 2018 §4.1.3 (c = lerp(history, new, r), r = max(r0, 1/age);
 * moments sum x, sum x^2 with the same rule; variance = m2 - m1^2),
 * Koskela et al. 2019 §3.2 (cumulative average first, exponential average
 * once 1/age < alpha_min; the sample count is gathered with the same
 * renormalised bilinear weights and rounded to the nearest integer),
 * Higginson 2023 §1.3 (eqs. 1.2 and 1.3) and SVGF (papers/NOTES.md).
 *
 * Per pixel, with the plan's taps t and weights w_t (summing to 1):
 *   no tap:   age = 1, c = new, m = (l, l^2)             (history dropped)
 *   else:     age = min(round(sum w_t age_t) + 1, max_age)
 *             a  = max(alpha_min, 1 / age),  am = max(alpha_moments_min, 1 / age)
 *             c  = (1 - a) sum w_t c_t + a new
 *             m  = (1 - am) sum w_t m_t + am (l, l^2)
 *   variance = max(0, m2 - m1^2)
 * (frames with holes: hush__accum_blend_holes below).
 * l is the luminance of the new sample: Rec. 709 of the first three channels
 * for 3 or 4 channels, channel 0 for 1 or 2.
 *
 * Buffers are ping-ponged (no per-frame allocation): a blend reads the
 * previous frame's set and writes the other one, which then becomes the
 * latest. Deterministic whatever the thread count.
 */
#ifndef HUSH_TEMPORAL_ACCUMULATION_H
#define HUSH_TEMPORAL_ACCUMULATION_H

#include "hush.h"
#include "core/hmath.h"
#include "core/image.h"
#include "temporal/reproject.h"

typedef struct hush_accum_params {
  float alpha_min;         /* colour: minimum weight of the new sample, [0, 1] */
  float alpha_moments_min; /* moments: the same for the luminance moments */
  int max_age;             /* history length cap, >= 1 */
} hush_accum_params;

typedef struct hush_accum {
  uint32_t width, height;
  int channels;           /* 1..4 */
  hush_planar color[2];   /* `channels` planes */
  hush_planar moments[2]; /* 2 planes: E[l], E[l^2]; none without moments */
  int with_moments;       /* 0: colour and age only (hush__accum_init_color) */
  hush_planar age[2];     /* 1 plane: history length, >= 1 (a float) */
  int latest;             /* the set written by the last blend */
  int has_history;        /* set[latest] holds a frame */
  int empty;              /* set[latest] has pixels of age 0 (never sampled) */
} hush_accum;

hush_status hush__accum_init(hush_device device, hush_accum *acc, int channels, uint32_t width,
                             uint32_t height);
/* As hush__accum_init without the luminance moments, for a caller that
 * never reads them (BMFR): the blends neither gather nor write them (two of
 * the seven history planes) and ignore `variance`; the colour and the age
 * are the same bits as with them. */
hush_status hush__accum_init_color(hush_device device, hush_accum *acc, int channels,
                                   uint32_t width, uint32_t height);
void hush__accum_free(hush_accum *acc);
/* Forgets the history: the next blend starts over (age 1 everywhere). */
void hush__accum_reset(hush_accum *acc);

/*
 * Blends this frame's samples (acc->channels planes) with the history
 * gathered through plan (plan may be NULL: no history anywhere). Writes the
 * luminance variance to `variance` when not NULL. Afterwards
 * hush__accum_color/moments/age give this frame's result, which is the
 * history of the next blend (a caller such as SVGF may overwrite the colour
 * before then).
 */
void hush__accum_blend(hush_accum *acc, const hush_reproject_plan *plan,
                       const float *const *sample, const hush_accum_params *params,
                       float *variance, int threads);

/*
 * As hush__accum_blend, for frames with holes (docs/holes.md): spp (1
 * plane, NULL: none) marks the pixels without a sample this frame (spp not
 * > 0). Such a pixel takes no new sample: it keeps the history gathered
 * through the plan (colour, moments) and its age, rounded, not increased;
 * with no history it has none (age 0, colour and moments 0: "empty").
 * Every history is gathered from the taps of non-empty pixels only, their
 * weights renormalised, so that an empty pixel never darkens a neighbour.
 * With spp NULL and no empty pixel in the history this is exactly
 * hush__accum_blend (bit for bit); otherwise row by row, vectorised over
 * the plan's blocks (the rare 3X3 footprints and plans without blocks per
 * pixel), the same bits as the per-pixel rule.
 * acc->empty tells whether any pixel is left empty.
 */
void hush__accum_blend_holes(hush_accum *acc, const hush_reproject_plan *plan,
                             const float *const *sample, const float *spp,
                             const hush_accum_params *params, float *variance, int threads);

/*
 * hush__accum_blend in pieces, for a caller that interleaves it with other
 * work: rows y0..y1-1 (any order, any thread; each pixel is blended on its
 * own), then hush__accum_blend_done once all rows are done, which makes the
 * result the latest. For frames without holes (where hush__accum_blend_holes
 * would call hush__accum_blend); no variance. stream 1: the outputs bypass
 * the caches (hush__accum_blend's choice: nothing reads them before the
 * frame is done); 0: cached, for a caller that reads the rows right away.
 * sample may be this blend's own output (acc->color[1 - latest]), blended
 * in place: each pixel's sample is read before its result is written (a
 * 3X3 pixel's chunk result is its sample, which its own blend reads).
 */
void hush__accum_blend_rows(const hush_accum *acc, const hush_reproject_plan *plan,
                            const float *const *sample, const hush_accum_params *params, int y0,
                            int y1, int stream);
void hush__accum_blend_done(hush_accum *acc);

static inline hush_planar *hush__accum_color(hush_accum *acc) { return &acc->color[acc->latest]; }
static inline hush_planar *hush__accum_moments(hush_accum *acc) {
  return &acc->moments[acc->latest];
}
static inline hush_planar *hush__accum_age(hush_accum *acc) { return &acc->age[acc->latest]; }

/* Luminance of pixel i of a 1..4 channel planar signal (see above). */
static inline float hush__accum_luminance(const float *const *c, int channels, size_t i) {
  return channels >= 3 ? hush_luminance(c[0][i], c[1][i], c[2][i]) : c[0][i];
}

/*
 * One more history through an existing plan, with ages computed elsewhere
 * (e.g. BMFR's second accumulation, on the fitted result, with phase I's
 * plan and ages): per pixel with taps,
 *   out = (1 - a) sum w_t prev_t + a sample,  a = max(alpha_min, 1 / age[i]),
 * else out = sample (ages below 1 count as 1). channels 1..8; plan gives the
 * size; prev == NULL means no history anywhere (out = sample). out may alias
 * sample but not prev.
 */
void hush__temporal_blend(const hush_reproject_plan *plan, const float *const *prev,
                          const float *const *sample, int channels, const float *age,
                          float alpha_min, float *const *out, int threads);

/* hush__temporal_blend on the rows y with rows[y] != 0 only (rows NULL:
 * all); the other rows of out are not touched. */
void hush__temporal_blend_rows(const hush_reproject_plan *plan, const float *const *prev,
                               const float *const *sample, int channels, const float *age,
                               float alpha_min, float *const *out, const float *rows,
                               int threads);
/* hush__temporal_blend on rows y0..y1-1, on the calling thread (for a
 * caller that shares the rows among its own threads); stream as
 * hush__accum_blend_rows. */
void hush__temporal_blend_range(const hush_reproject_plan *plan, const float *const *prev,
                                const float *const *sample, int channels, const float *age,
                                float alpha_min, float *const *out, int y0, int y1,
                                int stream);

#endif
