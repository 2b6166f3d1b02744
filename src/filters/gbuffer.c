/*
 * gbuffer.c — the G-buffer import and reprojection shared by the temporal
 * filters (accumulate, svgf, taa, ...): see gbuffer.h. The reprojection
 * itself is src/temporal/reproject.c.
 */
#include "filters/gbuffer.h"

#include "core/hmath.h"
#include "core/vecmath.h"

#include <math.h>
#include <stdlib.h>

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

/* A normal whose squared length is more than HUSH_UNIT_TOLERANCE (image.h)
 * from 1 is rescaled to unit length. The dot product of two normals then
 * exceeds 1 by at most 1e-3: svgf's normal weight by at most 2^(sigma_n
 * 1e-3 log2 e), 1.14 at sigma_n 128. */

/* Squared lengths outside this range (|n| below 1e-15 or above 1e15) are
 * rescaled in double: their float squares may have underflowed or lost
 * precision. */
#define UNIT_FLOAT_MIN 1e-30f
#define UNIT_FLOAT_MAX 1e30f

/* Rescales the row's normals that are not of unit length (0 stays 0; to
 * within 3e-7: rows of them are common enough, e.g. 8-bit normals, to want
 * the vectorised reciprocal square root); returns whether one needs the
 * double-precision path. */
static int unit_row(float *restrict a, float *restrict b, float *restrict c, size_t w) {
  int extreme = 0;
#pragma omp simd reduction(| : extreme)
  for (size_t x = 0; x < w; x++) {
    const float d = a[x] * a[x] + b[x] * b[x] + c[x] * c[x];
    const int rescale = !(fabsf(d - 1.0f) <= HUSH_UNIT_TOLERANCE) & (d >= UNIT_FLOAT_MIN) &
                        (d <= UNIT_FLOAT_MAX);
    const float s = hush__rsqrt_vec(rescale ? d : 1.0f);
    a[x] = rescale ? a[x] * s : a[x];
    b[x] = rescale ? b[x] * s : b[x];
    c[x] = rescale ? c[x] * s : c[x];
    extreme |= (d < UNIT_FLOAT_MIN) & ((a[x] != 0.0f) | (b[x] != 0.0f) | (c[x] != 0.0f));
    extreme |= d > UNIT_FLOAT_MAX;
  }
  return extreme;
}

/* The row's normals too short or too long to square in float, in double. */
static void unit_row_double(float *a, float *b, float *c, size_t w) {
  for (size_t x = 0; x < w; x++) {
    const double p = a[x], q = b[x], r = c[x];
    const double len2 = p * p + q * q + r * r;
    if (len2 == 0.0 || fabs(len2 - 1.0) <= HUSH_UNIT_TOLERANCE) continue;
    const double s = 1.0 / sqrt(len2);
    a[x] = (float)(p * s);
    b[x] = (float)(q * s);
    c[x] = (float)(r * s);
  }
}

/*
 * Normals of any length become unit normals (gbuffer.h). Every consumer
 * assumes them: the reprojection's normal test compares a dot product with
 * a cosine (normals of length 0.9 failed it everywhere: no history), and
 * svgf's normal weight exp(sigma_n (n.n' - 1)) overflowed to Inf, then NaN,
 * for a dot product of 9. A read-only pass over the three planes; a row
 * with such a normal is rescaled while it is in L1.
 */
/* Rescales the rows y with odd[y] set (NULL: every row found by
 * hush__normals_odd). */
static void unit_rows(hush_planar *n, const uint8_t *odd, int threads) {
  const int H = (int)n->height;
  const size_t W = n->width;
  float *const p[3] = {n->plane[0], n->plane[1], n->plane[2]};
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < H; y++) {
    const size_t i0 = (size_t)y * W;
    float *a = p[0] + i0, *b = p[1] + i0, *c = p[2] + i0;
    if (!(odd ? odd[y] : hush__normals_odd(a, b, c, W))) continue;
    if (unit_row(a, b, c, W)) unit_row_double(a, b, c, W);
  }
}

void hush__unit_normals(hush_planar *n, int threads) { unit_rows(n, NULL, threads); }

/* Row y of the normals, known to hold one to rescale. */
static void unit_one_row(hush_planar *n, int y) {
  const size_t i0 = (size_t)y * n->width;
  float *a = n->plane[0] + i0, *b = n->plane[1] + i0, *c = n->plane[2] + i0;
  if (unit_row(a, b, c, n->width)) unit_row_double(a, b, c, n->width);
}

hush_status hush__gbuffer_import_begin(hush_filter f, const hush_gbuffer_images *im, int use_id,
                                       const hush_frame_info *info, hush_reprojector *rp,
                                       hush_gbuffer_inputs *in, hush_gbuffer_import_job *job) {
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
  memset(job, 0, sizeof *job);
  job->normals = -1;
  job->images[job->count] = im->depth;
  job->dst[job->count++] = &g->depth;
  if (has_normal) {
    job->normals = job->count;
    job->images[job->count] = im->normal;
    job->dst[job->count++] = &g->normal;
  }
  if (with_id) {
    job->images[job->count] = im->id;
    job->dst[job->count++] = &g->id;
  }
  if (in->has_position) {
    job->images[job->count] = im->position;
    job->dst[job->count++] = &in->position;
  }
  if (in->use_motion) {
    job->images[job->count] = im->motion;
    job->dst[job->count++] = &in->motion;
  }
  for (int j = 0; j < job->count; j++) job->views[j] = bound(f, job->images[j]);
  if (has_normal && !in->odd_normals &&
      !(in->odd_normals = hush__alloc_counted(f->height, sizeof *in->odd_normals)))
    return hush__fail(f->device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory for %u row flags",
                      f->height);
  if (!has_normal) constant_normal(&g->normal);
  g->has_id = with_id;
  return HUSH_OK;
}

size_t hush__gbuffer_import_rows(const hush_gbuffer_import_job *job, int y0, int y1) {
  size_t bad = 0;
  for (int y = y0; y < y1; y++)
    for (int j = 0; j < job->count; j++) {
      if (j != job->normals) {
        bad += hush__view_import_row(job->views[j], (uint32_t)y, job->dst[j]);
        continue;
      }
      int odd = 0;
      bad += hush__view_import_row_normals(job->views[j], (uint32_t)y, job->dst[j], &odd);
      if (odd) unit_one_row(job->dst[j], y);
    }
  return bad;
}

hush_status hush__gbuffer_import(hush_filter f, const hush_gbuffer_images *im, int use_id,
                                 const hush_frame_info *info, hush_reprojector *rp,
                                 hush_gbuffer_inputs *in) {
  hush_gbuffer_import_job job;
  hush_status s = hush__gbuffer_import_begin(f, im, use_id, info, rp, in, &job);
  if (s) return s;
  /* the normals' rows to rescale are found as they are imported (a
   * separate pass read the three planes back: import 1.57 -> 1.40 ms,
   * 1280x720, 2 threads) */
  if ((s = hush__filter_import_many(f, job.count, job.images, job.dst, job.normals,
                                    in->odd_normals)))
    return s;
  if (job.normals >= 0)
    unit_rows(&hush__reprojector_next(rp)->normal, in->odd_normals, hush__filter_threads(f));
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

hush_status hush__gbuffer_reproject_begin(hush_filter f, hush_reprojector *rp,
                                          const hush_gbuffer_inputs *in,
                                          const hush_frame_info *info,
                                          const hush_reproject_params *params,
                                          hush_reproject_job *job) {
  const int position = in->has_position && !in->has_holes;
  return hush__reprojector_begin(
      f->device, rp, position ? (const float *const *)in->position.plane : NULL,
      in->use_motion ? (const float *const *)in->motion.plane : NULL, info, params, job);
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
  free(in->odd_normals);
  in->odd_normals = NULL;
  hush__planar_free(&in->depth_data);
  hush__planar_free(&in->surface);
  hush__planar_free(&in->position);
  hush__planar_free(&in->motion);
  hush__planar_free(&in->spp);
  hush__holes_free(&in->holes);
}
