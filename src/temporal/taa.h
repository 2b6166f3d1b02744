/*
 * taa.h — temporal anti-aliasing resolve (Karis 2014, as summarised in
 * papers/NOTES.md "TAA"): the previous output, reprojected through a plan
 * (reproject.h), is clamped or clipped to the min/max box of the current
 * 3x3 neighbourhood in YCoCg, then blended with the current frame with a
 * constant weight alpha; optionally on tone-mapped values
 * (c / (1 + luma), inverted after), so that a few very bright samples do
 * not dominate the box or the blend.
 *
 * Used by the "taa" filter on its own and by "svgf" as its last stage. The
 * history is the module's own (its last output), ping-ponged; a pixel with
 * no history in the plan takes the current frame.
 */
#ifndef HUSH_TEMPORAL_TAA_H
#define HUSH_TEMPORAL_TAA_H

#include "hush.h"
#include "core/image.h"
#include "temporal/reproject.h"

typedef enum hush_taa_box {
  HUSH_TAA_CLAMP = 0, /* clamp each YCoCg component to the box */
  HUSH_TAA_CLIP = 1   /* move the history towards the box centre until it is inside */
} hush_taa_box;

typedef struct hush_taa_params {
  float alpha;      /* weight of the current frame, (0, 1] */
  hush_taa_box box;
  int tonemap;      /* resolve on c / (1 + luma(c)) */
  /* NULL, or the filter's output view (frame-sized, 3 channels or more):
   * hush__taa_resolve and _modulated also write each resolved row there
   * while it is in cache (hush__view_export_span), which saves the caller
   * a pass over the output; hush__taa_resolve_holes ignores it */
  const hush_image_view *out_view;
} hush_taa_params;

typedef struct hush_taa {
  hush_planar history[2]; /* 3 planes: the last outputs */
  hush_planar current;    /* 3 planes: this frame (tone-mapped when asked) in YCoCg, whole
                           * (hush__taa_resolve_holes) or as per-thread rings of three
                           * rows (hush__taa_resolve, _modulated) */
  int latest;
  int has_history;
} hush_taa;

hush_status hush__taa_init(hush_device device, hush_taa *taa, uint32_t width, uint32_t height);
void hush__taa_free(hush_taa *taa);

/* Resolves this frame's colour (3 planes) with the history through plan
 * (NULL: no history); the result, hush__taa_output(), is also the next
 * frame's history. */
void hush__taa_resolve(hush_taa *taa, const hush_reproject_plan *plan, const float *const *color,
                       const hush_taa_params *params, int threads);

/* As hush__taa_resolve, the colour being color * max(albedo, HUSH_ALBEDO_EPS)
 * per channel (albedo NULL: color), the remodulation of albedo.h fused
 * into the resolve's first pass. */
void hush__taa_resolve_modulated(hush_taa *taa, const hush_reproject_plan *plan,
                                 const float *const *color, const float *const *albedo,
                                 const hush_taa_params *params, int threads);

/*
 * hush__taa_resolve_modulated in pieces, for a caller that interleaves it
 * with other work in its own threads: hush__taa_begin, then
 * hush__taa_rows for bands of rows (any order; rows y - 1 .. y + 1 of
 * color must be final for row y; thread `me` of at most H / 3 uses its own
 * ring of rows in taa->current), then hush__taa_done once all rows are
 * resolved. The same bits as the whole resolve.
 */
typedef struct hush_taa_job {
  const float *const *color, *const *albedo, *const *prev;
  const hush_reproject_plan *plan; /* NULL: no history */
  const hush_taa_params *params;
  hush_planar *out;
  float *const *ring; /* taa->current's planes */
  int W, H;
  int albedo_row0; /* albedo holds the rows from this one on (hush__taa_begin: 0) */
} hush_taa_job;

void hush__taa_begin(const hush_taa *taa, const hush_reproject_plan *plan,
                     const float *const *color, const float *const *albedo,
                     const hush_taa_params *params, hush_taa_job *job);
void hush__taa_rows(const hush_taa_job *job, int me, int y0, int y1);
void hush__taa_done(hush_taa *taa);

/*
 * A frame with holes (spp not > 0; docs/holes.md), as Dundr 2018 §4.2.6
 * asks ("an additional buffer for blending: only new samples would get
 * updated there"): a traced pixel blends as usual; a hole keeps its
 * history, clamped or clipped to the box. Without hole_color (a raw frame:
 * the colour of a hole is 0, ignored) the box is that of the traced pixels
 * of the 3x3 neighbourhood, a hole without history takes the box's mean,
 * and with neither it gets 0 and valid[i] = 0 (else 1) for the caller to
 * fill (holes.h) in the output, which is the next history; returns 1 when
 * some valid[i] is 0. With hole_color (a filtered frame, whole: svgf) the
 * box is the whole 3x3 neighbourhood and a hole without history takes its
 * colour. Per pixel (not vectorised).
 */
int hush__taa_resolve_holes(hush_taa *taa, const hush_reproject_plan *plan,
                            const float *const *color, const float *spp, int hole_color,
                            const hush_taa_params *params, float *valid, int threads);

static inline const hush_planar *hush__taa_output(const hush_taa *taa) {
  return &taa->history[taa->latest];
}

#endif
