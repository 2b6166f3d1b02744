/*
 * gbuffer.c — the G-buffer import and reprojection shared by the temporal
 * filters (accumulate, svgf, taa, ...): see gbuffer.h. The reprojection
 * itself is src/temporal/reproject.c.
 */
#include "filters/gbuffer.h"

static const hush_image_view *bound(hush_filter f, int image) {
  return image >= 0 ? hush__filter_view(f, image) : NULL;
}

/* Without a normal image every normal is the same, so the test passes. */
static void constant_normal(hush_planar *n) {
  const size_t count = hush__planar_pixels(n);
  for (size_t i = 0; i < count; i++) {
    n->plane[0][i] = 0.0f;
    n->plane[1][i] = 0.0f;
    n->plane[2][i] = 1.0f;
  }
}

hush_status hush__gbuffer_import(hush_filter f, const hush_gbuffer_images *im, int use_id,
                                 const hush_frame_info *info, hush_reprojector *rp,
                                 hush_gbuffer_inputs *in) {
  const int has_motion = bound(f, im->motion) != NULL;
  if (info->motion == HUSH_MOTION_VECTORS && !has_motion)
    return hush__fail(f->device, HUSH_ERROR_INVALID_OPERATION,
                      "%s: the motion source is HUSH_MOTION_VECTORS but the 'motion' image is "
                      "not bound",
                      f->cls->info->name);
  const int has_normal = bound(f, im->normal) != NULL;
  const int with_id = use_id && bound(f, im->id) != NULL;
  in->has_position = bound(f, im->position) != NULL;
  in->use_motion = has_motion && info->motion == HUSH_MOTION_VECTORS;

  hush_status s;
  if (in->has_position && (s = hush__filter_scratch(f, &in->position, 3))) return s;
  if (in->use_motion && (s = hush__filter_scratch(f, &in->motion, 2))) return s;
  if (with_id && (s = hush__reprojector_want_id(f->device, rp))) return s;

  hush_gbuffer_store *g = hush__reprojector_next(rp);
  if ((s = hush__filter_import(f, im->depth, &g->depth))) return s;
  if (has_normal && (s = hush__filter_import(f, im->normal, &g->normal))) return s;
  if (!has_normal) constant_normal(&g->normal);
  if (with_id && (s = hush__filter_import(f, im->id, &g->id))) return s;
  if (in->has_position && (s = hush__filter_import(f, im->position, &in->position))) return s;
  if (in->use_motion && (s = hush__filter_import(f, im->motion, &in->motion))) return s;
  g->has_id = with_id;
  return HUSH_OK;
}

hush_status hush__gbuffer_reproject(hush_filter f, hush_reprojector *rp,
                                    const hush_gbuffer_inputs *in, const hush_frame_info *info,
                                    const hush_reproject_params *params, int threads) {
  return hush__reprojector_build(
      f->device, rp, in->has_position ? (const float *const *)in->position.plane : NULL,
      in->use_motion ? (const float *const *)in->motion.plane : NULL, info, params, threads);
}

void hush__gbuffer_inputs_free(hush_gbuffer_inputs *in) {
  hush__planar_free(&in->position);
  hush__planar_free(&in->motion);
}
