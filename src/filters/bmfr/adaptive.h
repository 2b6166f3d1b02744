/*
 * adaptive.h — adaptive BMFR: A-SVGF's temporal gradients (Schied, Peters,
 * Dachsbacher 2018 §4.3-4.4; Higginson 2023 §2.3.1; docs/asvgf.md "BMFR
 * with gradients") offered to BMFR's two accumulations, parameter
 * temporal_gradients of the "bmfr" filter. Neither paper's code has it.
 *
 * After phase I's blend (hush__accum_blend): lambda per pixel from the
 * renderer's gradient samples (src/temporal/gradient.h), the history length
 * lowered by it (hush__gradient_lower_age, the rule history_rule), and,
 * where it was lowered, the colour blended again from the same reprojected
 * history with the new frame's weight max(alpha, 1 / lowered age). The
 * lowered ages are phase I's result, so phase III (hush__temporal_blend of
 * the fit with phase I's counts) and the next frame's phase I both see the
 * shortened history: one lowered count plane serves both accumulations, as
 * docs/bmfr.md "For A-SVGF" planned. Where lambda is 0 nothing is touched:
 * an unchanged scene gives plain bmfr's output bit for bit. (BMFR reads no
 * luminance moments, so they are not blended again.)
 */
#ifndef HUSH_FILTERS_BMFR_ADAPTIVE_H
#define HUSH_FILTERS_BMFR_ADAPTIVE_H

#include "filters/filter.h"
#include "temporal/accumulation.h"
#include "temporal/gradient.h"
#include "temporal/reproject.h"

typedef struct bmfr_adaptive {
  hush_gradient_params params; /* set by the filter before each frame */
  hush_history_rule rule;
  /* allocated on first use, owned here (bmfr_adaptive_free): */
  hush_planar gradient; /* 3: the imported layer */
  hush_planar lambda;   /* 1: per pixel */
  hush_planar lowered;  /* 1: the lowered ages */
  hush_planar color;    /* 3: the colour blended again */
  float *scratch;       /* hush__gradient_scratch_floats */
} bmfr_adaptive;

void bmfr_adaptive_free(bmfr_adaptive *ad);

/* Allocates on first use and imports image `image` ("gradient"; the
 * filter's nonfinite policy); an unbound image is an error naming it. */
hush_status bmfr_adaptive_import(hush_filter f, bmfr_adaptive *ad, int image);

/*
 * After hush__accum_blend of acc with `sample` (3 planes) through plan:
 * lambda from the imported layer and this frame's depth and normal planes,
 * then the ages lowered and the colour blended again where they were.
 * had_history: the blend had a previous frame to read (else nothing to do).
 * Returns how many pixels were lowered.
 */
size_t bmfr_adaptive_history(bmfr_adaptive *ad, hush_accum *acc, int had_history,
                             const hush_reproject_plan *plan, const float *const sample[3],
                             const hush_accum_params *ap, const float *depth,
                             const float *const normal[3], int threads);

#endif
