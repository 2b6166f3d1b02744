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
#include "render/gradients.h"
#include "render/mirror.h"

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
  p->mirror_depth = HUSH_RENDER_MIRROR_DEPTH_MAX;
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
  ctx->it.split_lobes = params->split_lobes;
  ctx->it.mirror_depth = params->mirror_depth;
}

/* Sample 0's primary rays are traced as packets of BLOCK x BLOCK pixels
 * (hush__scene_intersect_packet), blocks aligned to multiples of BLOCK.
 * A packet's hits may depend on its other lanes (ties), so re-rendering one
 * pixel traces its whole block again: a packet is a pure function of the
 * camera and the block. The block's paths are then shaded together,
 * stage by stage (shade_block), each exactly as it would be alone. */
#define BLOCK 4u
_Static_assert(BLOCK * BLOCK == HUSH_PACKET, "a block is one packet");

typedef struct primary_block {
  float dir[HUSH_PACKET][3];
  hush_hit hit[HUSH_PACKET];
} primary_block;

/* Sample 0's primary rays of the block whose corner is (x0, y0): lane
 * i is pixel (x0 + i % BLOCK, y0 + i / BLOCK); lanes outside the image
 * stay empty. */
static void trace_block(const hush_render_ctx *ctx, uint32_t x0, uint32_t y0, primary_block *b) {
  const hush_render_params *p = &ctx->params;
  uint32_t lanes = 0;
  memset(b->dir, 0, sizeof b->dir);
  for (uint32_t i = 0; i < HUSH_PACKET; i++) {
    const uint32_t x = x0 + i % BLOCK, y = y0 + i / BLOCK;
    if (x >= p->width || y >= p->height) continue;
    const hush_vec3 d = hush__camera_ray(&ctx->cam, (float)x + 0.5f + ctx->cam.jitter[0],
                                         (float)y + 0.5f + ctx->cam.jitter[1]);
    b->dir[i][0] = d.x;
    b->dir[i][1] = d.y;
    b->dir[i][2] = d.z;
    lanes |= 1u << i;
  }
  const float eye[3] = {ctx->cam.eye.x, ctx->cam.eye.y, ctx->cam.eye.z};
  hush__scene_intersect_packet(ctx->scene, eye, (const float(*)[3])b->dir, lanes, b->hit);
}

/* Pixel (x, y) from its sample 0 (r0, first hit first0, shaded with its
 * block: shade_block) and its other samples, traced here. */
static void finish_pixel(const hush_render_ctx *ctx, uint32_t x, uint32_t y, uint32_t seed_frame,
                         const hush_path_result *r0, const hush_first_hit *first0,
                         hush_pixel_result *out) {
  memset(out, 0, sizeof *out);
  out->first = *first0;
  const hush_render_params *p = &ctx->params;
  double mean = 0.0, m2 = 0.0, sum[3] = {0, 0, 0}, dsum[3] = {0, 0, 0}, esum[3] = {0, 0, 0};
  double diff_sum[3] = {0, 0, 0}, spec_sum[3] = {0, 0, 0};
  for (uint32_t s = 0; s < p->spp; s++) {
    hush_path_result rs;
    const hush_path_result *r = r0;
    if (s > 0) {
      /* the other samples spread over the pixel, a box filter, when jitter
       * is on; they are single rays */
      hush_rand rng;
      hush__rand_init(&rng, p->sampler, p->seed, seed_frame, x, y, s, p->spp);
      float jx = ctx->cam.jitter[0], jy = ctx->cam.jitter[1];
      if (p->jitter) {
        jx = hush__rand(&rng, 0) - 0.5f;
        jy = hush__rand(&rng, 1) - 0.5f;
      }
      const hush_vec3 d = hush__camera_ray(&ctx->cam, (float)x + 0.5f + jx, (float)y + 0.5f + jy);
      hush_first_hit first;
      hush__integrator_trace(&ctx->it, ctx->cam.eye, d, &rng, x, y, &first, &rs);
      r = &rs;
    }
    out->rays += r->rays;
    for (int k = 0; k < 3; k++) {
      sum[k] += r->radiance[k];
      dsum[k] += r->direct[k];
      esum[k] += r->emission[k];
      diff_sum[k] += r->diffuse[k];
      spec_sum[k] += r->specular[k];
    }
    /* Welford, in double: the same numbers in the same order, any thread */
    const double l = hush_luminance(r->radiance[0], r->radiance[1], r->radiance[2]);
    const double delta = l - mean;
    mean += delta / (double)(s + 1);
    m2 += delta * (l - mean);
  }
  for (int k = 0; k < 3; k++) {
    out->color[k] = (float)(sum[k] / p->spp);
    out->direct[k] = (float)(dsum[k] / p->spp);
    out->emission[k] = (float)(esum[k] / p->spp);
    if (p->split_lobes) {
      /* the colour is the layers' sum, so that it holds exactly */
      out->diffuse[k] = (float)(diff_sum[k] / p->spp);
      out->specular[k] = (float)(spec_sum[k] / p->spp);
      out->color[k] = out->diffuse[k] + out->specular[k];
    }
  }
  out->variance = p->spp > 1 ? (float)(m2 / (p->spp - 1)) : 0.0f;
}

/* The pixels of `lanes` of the traced block b (corner x0, y0) with the
 * numbers of frame seed_frame: sample 0 of all of them together
 * (hush__integrator_trace_block; each lane's result is its own, whatever
 * the other lanes), then each pixel's other samples. */
static void shade_block(const hush_render_ctx *ctx, const primary_block *b, uint32_t x0,
                        uint32_t y0, uint32_t lanes, uint32_t seed_frame,
                        hush_pixel_result out[HUSH_PACKET]) {
  const hush_render_params *p = &ctx->params;
  hush_rand rng[HUSH_PACKET];
  uint32_t xs[HUSH_PACKET], ys[HUSH_PACKET];
  hush_first_hit first[HUSH_PACKET];
  hush_path_result r0[HUSH_PACKET];
  for (uint32_t i = 0; i < HUSH_PACKET; i++) {
    xs[i] = x0 + i % BLOCK;
    ys[i] = y0 + i / BLOCK;
    if ((lanes >> i) & 1u)
      hush__rand_init(&rng[i], p->sampler, p->seed, seed_frame, xs[i], ys[i], 0, p->spp);
  }
  hush__integrator_trace_block(&ctx->it, ctx->cam.eye, (const float(*)[3])b->dir, b->hit, rng, xs,
                               ys, lanes, first, r0);
  for (uint32_t i = 0; i < HUSH_PACKET; i++)
    if ((lanes >> i) & 1u) finish_pixel(ctx, xs[i], ys[i], seed_frame, &r0[i], &first[i], &out[i]);
}

/* The lanes of the block at (x0, y0) that a frame shades: inside the image
 * and, with a progressive pattern, traced this frame. */
static uint32_t block_lanes(const hush_render_ctx *ctx, uint32_t x0, uint32_t y0) {
  const hush_render_params *p = &ctx->params;
  uint32_t lanes = 0;
  for (uint32_t i = 0; i < HUSH_PACKET; i++) {
    const uint32_t x = x0 + i % BLOCK, y = y0 + i / BLOCK;
    if (x >= p->width || y >= p->height) continue;
    if (p->progressive && !hush__progressive_traced(p->progressive, x, y, ctx->frame)) continue;
    lanes |= 1u << i;
  }
  return lanes;
}

void hush__render_pixel(const hush_render_ctx *ctx, uint32_t x, uint32_t y, uint32_t seed_frame,
                        hush_pixel_result *out) {
  primary_block b;
  const uint32_t x0 = x - x % BLOCK, y0 = y - y % BLOCK;
  const uint32_t lane = (y - y0) * BLOCK + (x - x0);
  trace_block(ctx, x0, y0, &b);
  hush_pixel_result r[HUSH_PACKET];
  shade_block(ctx, &b, x0, y0, 1u << lane, seed_frame, r);
  *out = r[lane];
}

/* Tile edge in pixels (see hush__render_frame), a multiple of BLOCK. */
#define TILE 16u
_Static_assert(TILE % BLOCK == 0, "tiles hold whole blocks");

/* ---- G-buffer ------------------------------------------------------------------ */

typedef struct layers {
  float *color, *albedo, *normal, *position, *depth, *dgrad, *motion, *id, *vis;
  float *spp, *variance, *direct, *indirect, *diffuse, *specular, *emission;
} layers;

static float view_depth(const hush_render_camera *cam, hush_vec3 p) {
  const hush_vec4 v = hush_m4_mul_v4(cam->world_to_view, p.x, p.y, p.z, 1.0f);
  return -v.z;
}

/* Depth of the first hit's tangent plane one pixel to the right and below,
 * minus z. In view space the ray through image point (px, py) runs along
 * D = (ndc_x tan_half_x, ndc_y tan_half_y, -1), so the point at view depth
 * s is s D, and the plane n . X = n . P meets it at s = (n . P) / (n . D):
 * one dot product per neighbour instead of a camera ray and a projection.
 * A plane seen edge-on (|n . D| < 1e-6 |D|) or behind the eye gives 0. */
static void depth_gradient(const hush_render_ctx *ctx, float px, float py, hush_vec3 p, hush_vec3 n,
                           float z, float out[2]) {
  out[0] = out[1] = 0.0f;
  const hush_render_camera *cam = &ctx->cam;
  const hush_vec4 pv = hush_m4_mul_v4(cam->world_to_view, p.x, p.y, p.z, 1.0f);
  const hush_vec4 nv = hush_m4_mul_v4(cam->world_to_view, n.x, n.y, n.z, 0.0f);
  const float k = nv.x * pv.x + nv.y * pv.y + nv.z * pv.z;
  for (int i = 0; i < 2; i++) {
    const float qx = px + (float)(i == 0), qy = py + (float)(i == 1);
    const float dx = (qx / (float)cam->width * 2.0f - 1.0f) * cam->tan_half_x;
    const float dy = (1.0f - qy / (float)cam->height * 2.0f) * cam->tan_half_y;
    const float dn = nv.x * dx + nv.y * dy - nv.z;
    if (!(fabsf(dn) >= 1e-6f * sqrtf(dx * dx + dy * dy + 1.0f))) continue;
    const float s = k / dn;
    if (!(s > 0.0f) || !isfinite(s)) continue;
    out[i] = s - z;
  }
}

/* Where the first hit was in the previous frame, minus where it is now
 * (both without jitter), both mapped by mm when it is not NULL (a hit seen
 * through mirrors; the previous point through the mirrors' previous
 * places). Off-screen or behind the
 * camera: (-1, -1) pixel. */
static void motion_of(const hush_render_ctx *ctx, const hush_first_hit *f,
                      const hush_mirror_map *mm, float out[2]) {
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
  if (mm) {
    /* a moving mirror moves its virtual world: the previous point through
     * the mirrors where they were then */
    hush_mirror_map was;
    const hush_mirror_map *pm =
        ctx->frame > 0 && hush__mirror_map_at(sc, mm, ctx->frame - 1, &was) ? &was : mm;
    now = w > 0.0f ? hush__mirror_map_point(mm, now) : hush__mirror_map_dir(mm, now);
    prev = w > 0.0f ? hush__mirror_map_point(pm, prev) : hush__mirror_map_dir(pm, prev);
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

static void zero(float *layer, int channels, size_t i) {
  if (layer)
    for (int k = 0; k < channels; k++) layer[(size_t)channels * i + k] = 0.0f;
}

/* Pixel i of every layer set to 0: the layers may be last frame's (see
 * hush__render_frame), so nothing is assumed zero. */
static void clear_pixel(const layers *L, size_t i) {
  zero(L->color, 3, i);
  zero(L->albedo, 3, i);
  zero(L->normal, 3, i);
  zero(L->position, 3, i);
  zero(L->depth, 1, i);
  zero(L->dgrad, 2, i);
  zero(L->motion, 2, i);
  zero(L->id, 1, i);
  zero(L->vis, 3, i);
  zero(L->spp, 1, i);
  zero(L->variance, 1, i);
  zero(L->direct, 3, i);
  zero(L->indirect, 3, i);
  zero(L->diffuse, 3, i);
  zero(L->specular, 3, i);
  zero(L->emission, 3, i);
}

static void write_pixel(const hush_render_ctx *ctx, const layers *L, uint32_t x, uint32_t y,
                        const hush_pixel_result *r) {
  const size_t i = (size_t)y * ctx->params.width + x;
  const hush_first_hit *f = &r->first;
  const hush_scene *sc = ctx->scene;
  /* every value is written (the layers may hold the last frame): the
   * G-buffer entries a sky or sphere pixel does not have are set to 0 */
  memcpy(L->color + 3 * i, r->color, 3 * sizeof(float));
  memcpy(L->emission + 3 * i, r->emission, 3 * sizeof(float));
  if (L->direct)
    for (int k = 0; k < 3; k++) {
      L->direct[3 * i + k] = r->direct[k];
      L->indirect[3 * i + k] = r->color[k] - r->direct[k];
    }
  if (L->diffuse) {
    memcpy(L->diffuse + 3 * i, r->diffuse, 3 * sizeof(float));
    memcpy(L->specular + 3 * i, r->specular, 3 * sizeof(float));
  }
  if (L->spp) L->spp[i] = (float)ctx->params.spp;
  if (L->variance) L->variance[i] = r->variance;
  /* the visibility buffer names the real first hit (A-SVGF re-shades it);
   * the rest describes g, the hit behind the mirrors */
  L->vis[3 * i] = -1.0f;
  L->vis[3 * i + 1] = L->vis[3 * i + 2] = 0.0f;
  if (f->kind == HUSH_FIRST_SPHERE) L->vis[3 * i] = -2.0f - (float)f->sphere;
  if (f->kind == HUSH_FIRST_TRIANGLE) {
    L->vis[3 * i] = (float)f->hit.triangle;
    L->vis[3 * i + 1] = f->hit.u;
    L->vis[3 * i + 2] = f->hit.v;
  }
  hush_first_hit replaced;
  float reflectance[3];
  hush_mirror_map mm;
  const int mirrors = hush__mirror_replace_primary(ctx, f, &replaced, reflectance, &mm);
  const hush_first_hit *g = mirrors ? &replaced : f;
  motion_of(ctx, g, mirrors ? &mm : NULL, L->motion + 2 * i);
  float *alb = L->albedo + 3 * i;
  alb[0] = alb[1] = alb[2] = 1.0f;
  if (g->kind == HUSH_FIRST_SKY) {
    zero(L->normal, 3, i);
    zero(L->position, 3, i);
    zero(L->depth, 1, i);
    zero(L->dgrad, 2, i);
    zero(L->id, 1, i);
    return;
  }
  float px = (float)x + 0.5f + ctx->cam.jitter[0];
  float py = (float)y + 0.5f + ctx->cam.jitter[1];
  /* a gradient sample's point lies elsewhere in the pixel: its depth
   * gradient is taken at its own image point */
  float sx, sy;
  if (r->gradient_sample && hush__camera_project(&ctx->cam, f->p, 1.0f, &sx, &sy)) {
    px = sx;
    py = sy;
  }
  /* behind mirrors, the virtual hit: where the unfolded camera ray meets
   * the reflected surface */
  const hush_vec3 p = mirrors ? hush__mirror_map_point(&mm, g->p) : g->p;
  const hush_vec3 n = mirrors ? hush__mirror_map_dir(&mm, g->n) : g->n;
  const float z = view_depth(&ctx->cam, p);
  L->depth[i] = z;
  memcpy(L->position + 3 * i, &p, 3 * sizeof(float));
  memcpy(L->normal + 3 * i, &n, 3 * sizeof(float));
  if (g->kind == HUSH_FIRST_SPHERE) {
    L->id[i] = (float)(sc->material_count + 1 + g->sphere);
    depth_gradient(ctx, px, py, p, n, z, L->dgrad + 2 * i);
    return;
  }
  const hush_material *m = &sc->materials[g->surface.material];
  hush__bsdf_albedo(m, &g->surface, alb);
  if (mirrors)
    for (int k = 0; k < 3; k++) alb[k] *= reflectance[k];
  L->id[i] = (float)(g->surface.material + 1);
  const hush_vec3 ng = mirrors ? hush__mirror_map_dir(&mm, g->surface.ng) : g->surface.ng;
  depth_gradient(ctx, px, py, p, ng, z, L->dgrad + 2 * i);
}

/* A pixel the progressive pattern skips this frame: every layer 0, spp
 * included, but vis says "no triangle", since 0 would name triangle 0. */
static void write_hole(const hush_render_ctx *ctx, const layers *L, uint32_t x, uint32_t y) {
  const size_t i = (size_t)y * ctx->params.width + x;
  clear_pixel(L, i);
  L->vis[3 * i] = -1.0f;
}

/* The frame's layer `name` if it has one of `channels` channels (a
 * sequence renders every frame into the same hush_frame: reusing its
 * memory saves a fresh ~80 MB allocation, zeroing and page faults per
 * 1280x720 frame, a serial ~5% of the render), else a new one. Every pixel
 * is written, so old contents do not matter. */
static hush_status add_layer(hush_frame out, const char *name, int channels, float **data) {
  const hush_layer *old = hush__frame_find(out, name);
  if (old && old->channels == channels) {
    *data = old->pixels;
    return HUSH_OK;
  }
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
  hush_status st = HUSH_OK;
  if (p->gradients) {
    st = hush__gradients_begin(device, p->gradients, ctx);
    if (st != HUSH_OK) return st;
  }
  layers L;
  memset(&L, 0, sizeof L);
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
      {"diffuse", 3, &L.diffuse, p->split_lobes},
      {"specular", 3, &L.specular, p->split_lobes},
      {"emission", 3, &L.emission, 1},
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
    /* blocks never straddle tiles (TILE is a multiple of BLOCK) */
    for (uint32_t by = y0; by < y1; by += BLOCK)
      for (uint32_t bx = x0; bx < x1; bx += BLOCK) {
        const uint32_t lanes = block_lanes(ctx, bx, by);
        for (uint32_t i = 0; i < HUSH_PACKET; i++) {
          const uint32_t x = bx + i % BLOCK, y = by + i / BLOCK;
          if (x < W && y < H && !((lanes >> i) & 1u)) write_hole(ctx, &L, x, y);
        }
        if (!lanes) continue;
        primary_block b;
        trace_block(ctx, bx, by, &b);
        hush_pixel_result r[HUSH_PACKET];
        uint32_t shade = lanes;
        /* A-SVGF: a forward-projected gradient sample may take a pixel */
        if (p->gradients)
          for (uint32_t i = 0; i < HUSH_PACKET; i++)
            if (((lanes >> i) & 1u) &&
                hush__gradients_shade(p->gradients, ctx, bx + i % BLOCK, by + i / BLOCK, &b.hit[i],
                                      &r[i]))
              shade &= ~(1u << i);
        shade_block(ctx, &b, bx, by, shade, ctx->frame, r);
        for (uint32_t i = 0; i < HUSH_PACKET; i++) {
          if (!((lanes >> i) & 1u)) continue;
          write_pixel(ctx, &L, bx + i % BLOCK, by + i / BLOCK, &r[i]);
          total += r[i].rays;
        }
      }
    uint32_t done;
#pragma omp atomic capture
    done = ++tiles_done;
    /* progress counts rows; a tile stands for its share of them */
    if (progress && omp_get_thread_num() == 0)
      progress(user, (uint32_t)((uint64_t)done * H / tiles), H);
  }
  if (p->gradients) {
    st = hush__gradients_end(device, p->gradients, ctx, out, threads, &total);
    if (st != HUSH_OK) return st;
  }
  if (progress) progress(user, H, H);
  if (rays) *rays = total;
  return HUSH_OK;
}
