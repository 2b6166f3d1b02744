/*
 * adaptive.h — the adaptive temporal stage of A-SVGF (Schied, Peters,
 * Dachsbacher 2018 §4.3-4.4; Higginson 2023 §2.3.1; docs/asvgf.md), as the
 * "asvgf" class inserts it into the SVGF pipeline (svgf.h):
 *
 *   import the layer `gradient` -> lambda per pixel from the stratum grid
 *   (src/temporal/gradient.h) -> after each temporal blend, the history
 *   length lowered by lambda (history_rule) and, where it was, the colour
 *   and the luminance moments blended again with the new frame's weight
 *   max(alpha, 1 / lowered age) (the blend's result rescaled: no second
 *   gather of the history).
 *
 * The lowered age is also the history length the next frame gathers and
 * the one SVGF's variance estimate sees (spatial estimate below 4 frames).
 * Where lambda is 0 nothing is touched: an unchanged scene gives svgf's
 * output bit for bit.
 */
#ifndef HUSH_FILTERS_SVGF_ADAPTIVE_H
#define HUSH_FILTERS_SVGF_ADAPTIVE_H

#include "filters/filter.h"
#include "temporal/accumulation.h"
#include "temporal/gradient.h"
#include "temporal/reproject.h"

typedef struct svgf_adaptive {
  int image;                  /* class index of the image 'gradient' */
  hush_gradient_params params; /* set by the class before each frame */
  hush_history_rule rule;
  /* allocated on the first frame (hush__filter_scratch), owned here: */
  hush_planar gradient; /* 3: the imported layer */
  hush_planar lambda;   /* 1: per pixel */
  hush_planar lum;      /* 1: luminance guide of this frame's colour */
  hush_planar lowered;  /* 1: the lowered ages */
  float *scratch;       /* hush__gradient_scratch_floats */
} svgf_adaptive;

void svgf_adaptive_free(svgf_adaptive *ad);

/* Allocates on first use and imports 'gradient' (nonfinite policy of the
 * filter; a missing layer is an error naming it). */
hush_status svgf_adaptive_import(hush_filter f, svgf_adaptive *ad);

/* lambda <- from the imported layer and this frame's guides (depth, normal,
 * depth gradient: W x H planes) and colour (3 planes; a second signal, when
 * not NULL, is added: direct + indirect). */
void svgf_adaptive_lambda(svgf_adaptive *ad, const float *depth, const float *const normal[3],
                          const float *gx, const float *gy, const float *const color[3],
                          const float *const second[3], int threads);

/*
 * After hush__accum_blend of acc with `sample` (3 planes) and ap: lowers the
 * ages by lambda and redoes the colour and moment blends with the lowered
 * ages where they were lowered; variance (the blend's m2 - m1^2 plane) is
 * updated there too. had_history: the blend had a previous frame to
 * read (else nothing to do).
 */
void svgf_adaptive_history(svgf_adaptive *ad, hush_accum *acc, int had_history,
                           const float *const sample[3], const hush_accum_params *ap,
                           float *variance, int threads);

#endif
