/*
 * gbuffer.c — the G-buffer import and reprojection shared by the temporal
 * filters (accumulate, svgf, taa, ...): see gbuffer.h. The reprojection
 * itself is src/temporal/reproject.c.
 */
#include "filters/gbuffer.h"

#include "core/hmath.h"

#include <math.h>

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
  int images[5], count = 0;
  hush_planar *dst[5];
  images[count] = im->depth;
  dst[count++] = &g->depth;
  if (has_normal) {
    images[count] = im->normal;
    dst[count++] = &g->normal;
  }
  if (with_id) {
    images[count] = im->id;
    dst[count++] = &g->id;
  }
  if (in->has_position) {
    images[count] = im->position;
    dst[count++] = &in->position;
  }
  if (in->use_motion) {
    images[count] = im->motion;
    dst[count++] = &in->motion;
  }
  if ((s = hush__filter_import_many(f, count, images, dst))) return s;
  if (!has_normal) constant_normal(&g->normal);
  g->has_id = with_id;
  return HUSH_OK;
}

hush_status hush__gbuffer_reproject(hush_filter f, hush_reprojector *rp,
                                    const hush_gbuffer_inputs *in, const hush_frame_info *info,
                                    const hush_reproject_params *params, int threads) {
  const int position = in->has_position && !in->has_holes;
  return hush__reprojector_build(
      f->device, rp, position ? (const float *const *)in->position.plane : NULL,
      in->use_motion ? (const float *const *)in->motion.plane : NULL, info, params, threads);
}

/*
 * A surface hole's normal: the previous frame's at the pixel its centre
 * back-projects to (as reproject.h: motion vectors, or the filled depth on
 * the centre ray and the previous matrices), where that pixel was a surface
 * too. Normals are world-space, so this holds under any camera; under a
 * still camera it is the hole's own normal from when it was traced (or
 * carried), where the fill's average failed the normal test at edges and
 * on curved surfaces. Otherwise the fill's.
 */
static void carry_normals(const hush_reprojector *rp, const hush_gbuffer_inputs *in,
                          hush_gbuffer_store *g, const hush_frame_info *info, int threads) {
  if (!rp->has_history || info->history == HUSH_HISTORY_RESET) return;
  const hush_gbuffer_store *prev = hush__reprojector_latest(rp);
  const int W = (int)rp->width, H = (int)rp->height;
  const int camera = !in->use_motion;
  float inv_v2c[16], inv_w2v[16], prev_vp[16];
  if (camera && (!hush_m4_invert(inv_v2c, info->view_to_clip) ||
                 !hush_m4_invert(inv_w2v, info->world_to_view)))
    return;
  if (camera) hush_m4_mul(prev_vp, info->prev_view_to_clip, info->prev_world_to_view);
  const float *spp = in->spp.plane[0], *z = g->depth.plane[0];
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < H; y++)
    for (int x = 0; x < W; x++) {
      const size_t i = (size_t)y * W + x;
      if (!hush__holes_is_hole(spp[i]) || !(z[i] > 0.0f)) continue;
      float px, py;
      if (!camera) {
        px = (float)x + 0.5f + in->motion.plane[0][i];
        py = (float)y + 0.5f + in->motion.plane[1][i];
      } else {
        const float nx = 2.0f * ((float)x + 0.5f) / (float)W - 1.0f;
        const float ny = 1.0f - 2.0f * ((float)y + 0.5f) / (float)H;
        const hush_vec4 v = hush_m4_mul_v4(inv_v2c, nx, ny, 1.0f, 1.0f);
        if (!(v.w != 0.0f)) continue;
        const float vx = v.x / v.w, vy = v.y / v.w, vz = v.z / v.w;
        if (!(vz < 0.0f)) continue;
        const float t = z[i] / -vz; /* view depth z on the centre ray */
        const hush_vec4 w = hush_m4_mul_v4(inv_w2v, vx * t, vy * t, vz * t, 1.0f);
        const hush_vec4 c = hush_m4_mul_v4(prev_vp, w.x, w.y, w.z, 1.0f);
        if (!(c.w > 0.0f)) continue;
        px = (c.x / c.w + 1.0f) * 0.5f * (float)W;
        py = (1.0f - c.y / c.w) * 0.5f * (float)H;
      }
      if (!(px >= 0.0f && py >= 0.0f && px < (float)W && py < (float)H)) continue;
      const size_t j = (size_t)(int)py * W + (size_t)(int)px;
      if (!(prev->depth.plane[0][j] > 0.0f)) continue;
      for (int k = 0; k < 3; k++) g->normal.plane[k][i] = prev->normal.plane[k][j];
    }
}

hush_status hush__gbuffer_fill_holes(hush_filter f, int spp_image, hush_reprojector *rp,
                                     hush_gbuffer_inputs *in, hush_planar *const *extra,
                                     int extra_count, const hush_frame_info *info,
                                     int threads) {
  in->has_holes = 0;
  if (!bound(f, spp_image)) return HUSH_OK;
  hush_status s;
  if ((s = hush__filter_scratch(f, &in->spp, 1))) return s;
  if ((s = hush__filter_import(f, spp_image, &in->spp))) return s;
  const size_t n = hush__planar_pixels(&in->spp);
  if (!hush__holes_any(in->spp.plane[0], n, threads)) return HUSH_OK;

  hush_gbuffer_store *g = hush__reprojector_next(rp);
  if ((s = hush__filter_scratch(f, &in->surface, 3))) return s;
  float *planes[HUSH_HOLES_MAX_PLANES];
  int count = 0;
  planes[count++] = g->depth.plane[0];
  for (int k = 0; k < 3; k++) planes[count++] = g->normal.plane[k];
  if (in->use_motion)
    for (int k = 0; k < 2; k++) planes[count++] = in->motion.plane[k];
  if (in->has_position)
    for (int k = 0; k < 3; k++) planes[count++] = in->position.plane[k];
  for (int e = 0; e < extra_count; e++)
    for (int k = 0; extra[e] && k < extra[e]->channels && count < HUSH_HOLES_MAX_PLANES; k++)
      planes[count++] = extra[e]->plane[k];
  if ((s = hush__holes_reserve(f->device, &in->holes, f->width, f->height, count))) return s;
  if ((s = hush__filter_scratch(f, &in->depth_data, 1))) return s;
  hush__holes_fill(in->holes.pyramid, f->width, f->height, in->spp.plane[0], planes, count,
                   threads);
  /* depth, normal (and position): a surface's average or the background */
  float *const geometry[7] = {g->depth.plane[0],    g->normal.plane[0], g->normal.plane[1],
                              g->normal.plane[2],   in->position.plane[0], in->position.plane[1],
                              in->position.plane[2]};
  hush__holes_split_background(in->holes.pyramid, f->width, f->height, in->spp.plane[0],
                               in->surface.plane, geometry, in->has_position ? 7 : 4,
                               in->use_motion ? in->motion.plane : NULL, threads);
  hush__holes_normalize_normals(in->spp.plane[0], g->depth.plane[0], g->normal.plane, n,
                                threads);
  carry_normals(rp, in, g, info, threads);
  g->has_id = 0;
  in->has_holes = 1;
  return HUSH_OK;
}

const float *hush__gbuffer_depth_with_data(hush_gbuffer_inputs *in, const float *depth,
                                           const float *age, int threads) {
  if (!age || !in->depth_data.plane[0]) return depth;
  float *out = in->depth_data.plane[0];
  const long long n = (long long)hush__planar_pixels(&in->depth_data);
#pragma omp parallel for simd schedule(static) num_threads(threads)
  for (long long i = 0; i < n; i++) out[i] = age[i] > 0.0f ? depth[i] : 0.0f;
  return out;
}

void hush__gbuffer_inputs_free(hush_gbuffer_inputs *in) {
  hush__planar_free(&in->depth_data);
  hush__planar_free(&in->surface);
  hush__planar_free(&in->position);
  hush__planar_free(&in->motion);
  hush__planar_free(&in->spp);
  hush__holes_free(&in->holes);
}
