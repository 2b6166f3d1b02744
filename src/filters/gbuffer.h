/*
 * gbuffer.h — the reprojection step every temporal filter shares: import the
 * bound G-buffer images (depth, normal, optional id, position, motion) into a
 * hush_reprojector, then build this frame's reprojection plan. Split in two
 * so a filter can import its own further inputs in between: a failure
 * anywhere before the build leaves the history as it was.
 */
#ifndef HUSH_FILTERS_GBUFFER_H
#define HUSH_FILTERS_GBUFFER_H

#include "filters/filter.h"
#include "temporal/reproject.h"

/* Class image indices of the G-buffer inputs; -1 where the class has none. */
typedef struct hush_gbuffer_images {
  int depth, normal, position, id, motion;
} hush_gbuffer_images;

/* The position and motion planes between import and build (allocated on
 * first use, freed with hush__gbuffer_inputs_free), and what was bound. */
typedef struct hush_gbuffer_inputs {
  hush_planar position, motion;
  int has_position, use_motion;
} hush_gbuffer_inputs;

/*
 * Imports this frame's G-buffer into hush__reprojector_next(rp). Fails with
 * HUSH_ERROR_INVALID_OPERATION when info->motion is VECTORS and no motion
 * image is bound. Ids are compared only when use_id is set and an id image is
 * bound. Without a normal image (normal index unbound or -1) every normal is
 * +Z, so the normal test always passes.
 */
hush_status hush__gbuffer_import(hush_filter f, const hush_gbuffer_images *images, int use_id,
                                 const hush_frame_info *info, hush_reprojector *rp,
                                 hush_gbuffer_inputs *in);

/* Builds the plan from what hush__gbuffer_import read; this frame becomes the
 * previous one of the next. */
hush_status hush__gbuffer_reproject(hush_filter f, hush_reprojector *rp,
                                    const hush_gbuffer_inputs *in, const hush_frame_info *info,
                                    const hush_reproject_params *params, int threads);

void hush__gbuffer_inputs_free(hush_gbuffer_inputs *in);

#endif
