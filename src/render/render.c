/*
 * render.c — one frame: noisy radiance plus G-buffer, motion and
 * visibility buffer (see render.h). The 1 spp input of
 * bmfr-koskela-2019.md §3.1 with the feature buffers of
 * realtime-denoising-comparison-higginson-2023.md §1.2.1.
 */
#include "render/render.h"

#include "core/device.h"
#include "io/frame.h"
#include "render/bsdf.h"

#include <math.h>
#include <omp.h>
#include <string.h>

void hush__render_defaults(hush_render_params *p) {
  memset(p, 0, sizeof *p);
  p->width = 640;
  p->height = 360;
  p->spp = 1;
  p->bounces = 1;
  p->seed = 1;
  p->sampler = HUSH_SAMPLER_RANDOM;
  p->jitter = 1;
}

void hush__render_ctx_init(hush_render_ctx *ctx, const hush_scene *scene, const hush_lights *lights,
                           const hush_render_params *params, const hush_render_camera *cam,
                           const hush_render_camera *prev_cam, uint32_t frame) {
  memset(ctx, 0, sizeof *ctx);
  ctx->scene = scene;
  ctx->lights = lights;
  ctx->params = *params;
  if (ctx->params.spp == 0) ctx->params.spp = 1;
  ctx->cam = *cam;
  ctx->have_prev = prev_cam != NULL;
  ctx->prev_cam = prev_cam ? *prev_cam : *cam;
  ctx->frame = frame;
  hush__integrator_defaults(&ctx->it, scene, lights);
  ctx->it.bounces = params->bounces < 0 ? 0 : params->bounces;
  ctx->it.clamp = params->clamp;
  ctx->it.vertex_fn = params->vertex_fn;
  ctx->it.path_end_fn = params->path_end_fn;
  ctx->it.vertex_user = params->vertex_user;
}

void hush__render_pixel(const hush_render_ctx *ctx, uint32_t x, uint32_t y, uint32_t seed_frame,
                        hush_pixel_result *out) {
  memset(out, 0, sizeof *out);
  const hush_render_params *p = &ctx->params;
  double mean = 0.0, m2 = 0.0, sum[3] = {0, 0, 0}, dsum[3] = {0, 0, 0};
  for (uint32_t s = 0; s < p->spp; s++) {
    hush_rand rng;
    hush__rand_init(&rng, p->sampler, p->seed, seed_frame, x, y, s, p->spp);
    /* sample 0 goes through the frame's jitter (the G-buffer's ray); the
     * others spread over the pixel, a box filter, when jitter is on */
    float jx = ctx->cam.jitter[0], jy = ctx->cam.jitter[1];
    if (s > 0 && p->jitter) {
      jx = hush__rand(&rng, 0) - 0.5f;
      jy = hush__rand(&rng, 1) - 0.5f;
    }
    const hush_vec3 d = hush__camera_ray(&ctx->cam, (float)x + 0.5f + jx, (float)y + 0.5f + jy);
    hush_path_result r;
    hush_first_hit first;
    hush__integrator_trace(&ctx->it, ctx->cam.eye, d, &rng, x, y, s == 0 ? &out->first : &first,
                           &r);
    out->rays += r.rays;
    for (int k = 0; k < 3; k++) {
      sum[k] += r.radiance[k];
      dsum[k] += r.direct[k];
    }
    /* Welford, in double: the same numbers in the same order, any thread */
    const double l = hush_luminance(r.radiance[0], r.radiance[1], r.radiance[2]);
    const double delta = l - mean;
    mean += delta / (double)(s + 1);
    m2 += delta * (l - mean);
  }
  for (int k = 0; k < 3; k++) {
    out->color[k] = (float)(sum[k] / p->spp);
    out->direct[k] = (float)(dsum[k] / p->spp);
  }
  out->variance = p->spp > 1 ? (float)(m2 / (p->spp - 1)) : 0.0f;
}

/* Tile edge in pixels (see hush__render_frame). */
#define TILE 16u

/* ---- G-buffer ------------------------------------------------------------------ */

typedef struct layers {
  float *color, *albedo, *normal, *position, *depth, *dgrad, *motion, *id, *vis;
  float *spp, *variance, *direct, *indirect;
} layers;

static float view_depth(const hush_render_camera *cam, hush_vec3 p) {
  const hush_vec4 v = hush_m4_mul_v4(cam->world_to_view, p.x, p.y, p.z, 1.0f);
  return -v.z;
}

/* Depth of the first hit's tangent plane one pixel to the right and below. */
static void depth_gradient(const hush_render_ctx *ctx, float px, float py, hush_vec3 p, hush_vec3 n,
                           float z, float out[2]) {
  out[0] = out[1] = 0.0f;
  const hush_vec3 eye = ctx->cam.eye;
  const float pn = hush_v3_dot(hush_v3_sub(p, eye), n);
  for (int k = 0; k < 2; k++) {
    const hush_vec3 d = hush__camera_ray(&ctx->cam, px + (k == 0), py + (k == 1));
    const float dn = hush_v3_dot(d, n);
    if (fabsf(dn) < 1e-6f) continue;
    const float t = pn / dn;
    if (!(t > 0.0f) || !isfinite(t)) continue;
    out[k] = view_depth(&ctx->cam, hush_v3_add(eye, hush_v3_scale(d, t))) - z;
  }
}

/* Where the first hit was in the previous frame, minus where it is now
 * (both without jitter). Off-screen or behind the camera: (-1, -1) pixel. */
static void motion_of(const hush_render_ctx *ctx, const hush_first_hit *f, float out[2]) {
  out[0] = out[1] = 0.0f;
  if (!ctx->have_prev) return;
  const hush_scene *sc = ctx->scene;
  hush_vec3 now = f->dir, prev = f->dir;
  float w = 0.0f;
  if (f->kind == HUSH_FIRST_TRIANGLE) {
    w = 1.0f;
    now = f->p;
    prev = f->p;
    const uint32_t o = sc->triangle_object[f->hit.triangle];
    if (sc->objects[o].motion.animated && ctx->frame > 0)
      prev = hush__scene_point(sc, f->hit.triangle, f->hit.u, f->hit.v, ctx->frame - 1);
  } else if (f->kind == HUSH_FIRST_SPHERE) {
    w = 1.0f;
    now = f->p;
    float c0[3], c1[3];
    hush__scene_sphere_at(sc, f->sphere, ctx->frame, c1);
    hush__scene_sphere_at(sc, f->sphere, ctx->frame > 0 ? ctx->frame - 1 : 0, c0);
    prev = hush_v3_sub(now, hush_v3(c1[0] - c0[0], c1[1] - c0[1], c1[2] - c0[2]));
  }
  float cx, cy, px, py;
  if (!hush__camera_project(&ctx->cam, now, w, &cx, &cy)) return;
  if (!hush__camera_project(&ctx->prev_cam, prev, w, &px, &py)) {
    px = -1.0f;
    py = -1.0f;
  }
  out[0] = px - cx;
  out[1] = py - cy;
}

static void write_pixel(const hush_render_ctx *ctx, const layers *L, uint32_t x, uint32_t y,
                        const hush_pixel_result *r) {
  const size_t i = (size_t)y * ctx->params.width + x;
  const hush_first_hit *f = &r->first;
  const hush_scene *sc = ctx->scene;
  memcpy(L->color + 3 * i, r->color, 3 * sizeof(float));
  if (L->direct)
    for (int k = 0; k < 3; k++) {
      L->direct[3 * i + k] = r->direct[k];
      L->indirect[3 * i + k] = r->color[k] - r->direct[k];
    }
  if (L->spp) L->spp[i] = (float)ctx->params.spp;
  if (L->variance) L->variance[i] = r->variance;
  motion_of(ctx, f, L->motion + 2 * i);
  float *alb = L->albedo + 3 * i;
  alb[0] = alb[1] = alb[2] = 1.0f;
  if (f->kind == HUSH_FIRST_SKY) {
    L->vis[3 * i] = -1.0f;
    return; /* normal, position, depth, gradient and id stay 0 */
  }
  const float px = (float)x + 0.5f + ctx->cam.jitter[0];
  const float py = (float)y + 0.5f + ctx->cam.jitter[1];
  const float z = view_depth(&ctx->cam, f->p);
  L->depth[i] = z;
  memcpy(L->position + 3 * i, &f->p, 3 * sizeof(float));
  memcpy(L->normal + 3 * i, &f->n, 3 * sizeof(float));
  if (f->kind == HUSH_FIRST_SPHERE) {
    L->id[i] = (float)(sc->material_count + 1 + f->sphere);
    L->vis[3 * i] = -2.0f - (float)f->sphere;
    depth_gradient(ctx, px, py, f->p, f->n, z, L->dgrad + 2 * i);
    return;
  }
  const hush_material *m = &sc->materials[f->surface.material];
  hush__bsdf_albedo(m, &f->surface, alb);
  L->id[i] = (float)(f->surface.material + 1);
  L->vis[3 * i] = (float)f->hit.triangle;
  L->vis[3 * i + 1] = f->hit.u;
  L->vis[3 * i + 2] = f->hit.v;
  depth_gradient(ctx, px, py, f->p, f->surface.ng, z, L->dgrad + 2 * i);
}

/* A pixel the progressive pattern skips this frame: the layers are zero
 * from hush_frame_add_layer, spp included; vis says "no triangle", since 0
 * would name triangle 0. */
static void write_hole(const hush_render_ctx *ctx, const layers *L, uint32_t x, uint32_t y) {
  const size_t i = (size_t)y * ctx->params.width + x;
  L->vis[3 * i] = -1.0f;
}

static hush_status add_layer(hush_frame out, const char *name, int channels, float **data) {
  hush_image_view v;
  const hush_status st = hush_frame_add_layer(out, name, channels, &v);
  *data = st == HUSH_OK ? (float *)v.data : NULL;
  return st;
}

hush_status hush__render_frame(hush_device device, const hush_render_ctx *ctx, hush_frame out,
                               hush_render_progress_fn progress, void *user, uint64_t *rays) {
  const hush_render_params *p = &ctx->params;
  if (!out || hush_frame_width(out) != p->width || hush_frame_height(out) != p->height)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                      "render: the frame is not %ux%u", p->width, p->height);
  if (ctx->scene->triangle_count > (1u << 24))
    return hush__fail(device, HUSH_ERROR_UNSUPPORTED,
                      "render: %u triangles: the visibility buffer holds triangle indices as "
                      "floats, exact only up to 2^24 = 16777216",
                      ctx->scene->triangle_count);
  layers L;
  memset(&L, 0, sizeof L);
  hush_status st = HUSH_OK;
  const struct {
    const char *name;
    int channels;
    float **data;
    int on;
  } table[] = {
      {"color", 3, &L.color, 1},        {"albedo", 3, &L.albedo, 1},
      {"normal", 3, &L.normal, 1},      {"position", 3, &L.position, 1},
      {"depth", 1, &L.depth, 1},        {"depth_gradient", 2, &L.dgrad, 1},
      {"motion", 2, &L.motion, 1},      {"id", 1, &L.id, 1},
      {"vis", 3, &L.vis, 1},            {"spp", 1, &L.spp, p->spp > 1 || p->progressive},
      {"variance", 1, &L.variance, p->spp > 1}, {"direct", 3, &L.direct, p->split},
      {"indirect", 3, &L.indirect, p->split},
  };
  for (size_t k = 0; k < sizeof table / sizeof table[0] && st == HUSH_OK; k++)
    if (table[k].on) st = add_layer(out, table[k].name, table[k].channels, table[k].data);
  if (st != HUSH_OK) return st;

  const int threads = p->threads > 0 ? p->threads : hush_device_threads(device);
  const uint32_t H = p->height, W = p->width;
  /* Square tiles instead of rows: neighbouring rays of a tile hit the same
   * BVH nodes, triangles and texels, so they stay in cache. Every pixel's
   * random numbers depend only on (x, y), so the order does not matter. */
  const uint32_t tx = (W + TILE - 1) / TILE, ty = (H + TILE - 1) / TILE;
  const uint32_t tiles = tx * ty;
  uint64_t total = 0;
  uint32_t tiles_done = 0;
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads) reduction(+ : total)
  for (uint32_t t = 0; t < tiles; t++) {
    const uint32_t x0 = (t % tx) * TILE, y0 = (t / tx) * TILE;
    const uint32_t x1 = x0 + TILE < W ? x0 + TILE : W, y1 = y0 + TILE < H ? y0 + TILE : H;
    for (uint32_t y = y0; y < y1; y++)
      for (uint32_t x = x0; x < x1; x++) {
        if (p->progressive && !hush__progressive_traced(p->progressive, x, y, ctx->frame)) {
          write_hole(ctx, &L, x, y);
          continue;
        }
        hush_pixel_result r;
        hush__render_pixel(ctx, x, y, ctx->frame, &r);
        write_pixel(ctx, &L, x, y, &r);
        total += r.rays;
      }
    uint32_t done;
#pragma omp atomic capture
    done = ++tiles_done;
    /* progress counts rows; a tile stands for its share of them */
    if (progress && omp_get_thread_num() == 0)
      progress(user, (uint32_t)((uint64_t)done * H / tiles), H);
  }
  if (progress) progress(user, H, H);
  if (rays) *rays = total;
  return HUSH_OK;
}
