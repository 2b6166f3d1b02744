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
#include "filters/holes.h"
#include "temporal/reproject.h"

/* Class image indices of the G-buffer inputs; -1 where the class has none. */
typedef struct hush_gbuffer_images {
  int depth, normal, position, id, motion;
} hush_gbuffer_images;

/* The position and motion planes between import and build (allocated on
 * first use, freed with hush__gbuffer_inputs_free), and what was bound;
 * the 'spp' plane and the pyramid of hush__gbuffer_fill_holes. */
typedef struct hush_gbuffer_inputs {
  hush_planar position, motion;
  int has_position, use_motion;
  hush_planar spp;  /* 1: this frame's 'spp' (allocated when bound) */
  hush_holes holes; /* pyramid scratch */
  int has_holes;    /* this frame has pixels with spp 0 */
  hush_planar depth_data; /* 1, allocated with the first holes: see below */
  hush_planar surface;    /* 3, frames with holes: hush__holes_split_background's scratch */
  uint8_t *odd_normals;   /* per row: it holds a normal to rescale (height bytes) */
} hush_gbuffer_inputs;

/* Rescales the normals (3 planes) whose squared length is not within 2e-3
 * of 1 to unit length; 0 stays 0, unit normals keep their bits. */
void hush__unit_normals(hush_planar *normal, int threads);

/*
 * Imports this frame's G-buffer into hush__reprojector_next(rp). Fails with
 * HUSH_ERROR_INVALID_OPERATION when info->motion is VECTORS and no motion
 * image is bound. Ids are compared only when use_id is set and an id image is
 * bound. Normals are made unit (hush__unit_normals). Without a normal image
 * (normal index unbound or -1) every normal is +Z, so the normal test always
 * passes.
 */
hush_status hush__gbuffer_import(hush_filter f, const hush_gbuffer_images *images, int use_id,
                                 const hush_frame_info *info, hush_reprojector *rp,
                                 hush_gbuffer_inputs *in);

/*
 * hush__gbuffer_import in pieces, for a caller that imports the rows where
 * it uses them: _begin checks and allocates (failing as hush__gbuffer_import
 * does, before anything is read) and fills the job; _rows imports rows
 * y0..y1-1 on the calling thread, the normals of each row made unit at
 * once, and returns the count of NaN/Inf values. The rows are final only
 * when the whole frame's count is 0; otherwise the caller imports the frame
 * again with hush__gbuffer_import, which applies the policy.
 */
typedef struct hush_gbuffer_import_job {
  int count;   /* images imported, up to 5 */
  int normals; /* the normals' index among them, or -1 */
  int images[5];
  const hush_image_view *views[5];
  hush_planar *dst[5];
} hush_gbuffer_import_job;

hush_status hush__gbuffer_import_begin(hush_filter f, const hush_gbuffer_images *images,
                                       int use_id, const hush_frame_info *info,
                                       hush_reprojector *rp, hush_gbuffer_inputs *in,
                                       hush_gbuffer_import_job *job);
size_t hush__gbuffer_import_rows(const hush_gbuffer_import_job *job, int y0, int y1);

/* Builds the plan from what hush__gbuffer_import read; this frame becomes the
 * previous one of the next. */
hush_status hush__gbuffer_reproject(hush_filter f, hush_reprojector *rp,
                                    const hush_gbuffer_inputs *in, const hush_frame_info *info,
                                    const hush_reproject_params *params, int threads);
/* The same, its rows left to the caller (hush__reprojector_begin). */
hush_status hush__gbuffer_reproject_begin(hush_filter f, hush_reprojector *rp,
                                          const hush_gbuffer_inputs *in,
                                          const hush_frame_info *info,
                                          const hush_reproject_params *params,
                                          hush_reproject_job *job);

/*
 * Holes (docs/holes.md): imports image spp_image (-1 or unbound: no holes)
 * and, where some pixel has spp 0, fills the holes of the imported
 * G-buffer (depth, normal, position, motion) and of the `extra` planes
 * (e.g. albedo, emission; NULL entries skipped) by the pyramid of Dundr 2018
 * §4.2.1 (holes.h), so that a hole reprojects and is tested like a traced
 * pixel. A hole is background (depth, normal, position 0) where most of
 * the pixels its fill averaged are, else a surface with their average
 * depth, normal and position (never a mix of the two: a depth between an
 * object's and the sky's is a surface that is nowhere); hole normals are
 * renormalised and every background normal is +z; a surface hole's normal
 * is then the previous frame's where its centre came from a surface (world
 * normals do not depend on the camera: "keep the history")
 * (so that the background's holes fill from around it). In such a frame
 * the plan reprojects from depth (the filled depth keeps a hole on its own
 * pixel under a still camera; a filled position, an average of its
 * neighbours', would not) and the id test is off (ids do not average).
 * Sets in->has_holes; without holes nothing changes (bit for bit).
 * Call after hush__gbuffer_import and the filter's own imports.
 */
hush_status hush__gbuffer_fill_holes(hush_filter f, int spp_image, hush_reprojector *rp,
                                     hush_gbuffer_inputs *in, hush_planar *const *extra,
                                     int extra_count, const hush_frame_info *info,
                                     int threads);

/* this frame's 'spp' plane when it has holes, else NULL */
static inline const float *hush__gbuffer_holes_spp(const hush_gbuffer_inputs *in) {
  return in->has_holes ? in->spp.plane[0] : NULL;
}

/* depth where the pixel has data (age > 0), else 0, in in->depth_data:
 * the pixels a fit may use. Returns depth itself when age is NULL (or no
 * frame with holes was seen). */
const float *hush__gbuffer_depth_with_data(hush_gbuffer_inputs *in, const float *depth,
                                           const float *age, int threads);

void hush__gbuffer_inputs_free(hush_gbuffer_inputs *in);

#endif
