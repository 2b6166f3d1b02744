/*
 * gradients.c — A-SVGF gradient samples in the renderer (see gradients.h):
 * choosing one sample per 3 x 3 stratum, forward-projecting it into the next
 * frame, the visibility test, re-shading with the previous frame's numbers
 * (realtime-denoising-comparison-higginson-2023.md §2.3.1, "Gradient
 * Estimation" and "Seed Reprojection").
 */
#include "render/gradients.h"

#include "core/device.h"
#include "core/rng.h"
#include "io/frame.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define S HUSH_GRADIENT_STRATUM

/* Visibility test: a landing pixel whose primary ray hit another triangle
 * of the same object still sees the sample's surface if the sample lies on
 * that triangle's plane within this fraction of its distance to the eye
 * (neighbouring triangles of one mesh, either side of an edge). */
#define PLANE_TOLERANCE 1e-2f

hush_status hush__gradients_init(hush_device device, hush_gradients *g, uint32_t width,
                                 uint32_t height) {
  memset(g, 0, sizeof *g);
  if (width == 0 || height == 0 || width > 65536 || height > 65536)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "gradients: bad frame size %ux%u",
                      width, height);
  g->width = width;
  g->height = height;
  g->strata_x = (width + S - 1) / S;
  g->strata_y = (height + S - 1) / S;
  const size_t n = (size_t)g->strata_x * g->strata_y;
  g->sources = calloc(n, sizeof *g->sources);
  g->next = calloc(n, sizeof *g->next);
  g->claim = calloc(n, sizeof *g->claim);
  g->landing = calloc(n, sizeof *g->landing);
  g->accepted = calloc(n, sizeof *g->accepted);
  g->current = calloc(n, sizeof *g->current);
  g->previous = calloc(n, sizeof *g->previous);
  g->reshade_rays = calloc(n, sizeof *g->reshade_rays);
  g->select = HUSH_GRADIENT_SELECT_BRIGHTEST;
  g->landing_mode = HUSH_GRADIENT_LANDING_FRESH;
  g->lobe = HUSH_GRADIENT_LOBE_DIFFUSE;
  if (!g->sources || !g->next || !g->claim || !g->landing || !g->accepted || !g->current ||
      !g->previous || !g->reshade_rays) {
    hush__gradients_free(g);
    return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "gradients: out of memory");
  }
  return HUSH_OK;
}

void hush__gradients_free(hush_gradients *g) {
  free(g->sources);
  free(g->next);
  free(g->claim);
  free(g->landing);
  free(g->accepted);
  free(g->current);
  free(g->previous);
  free(g->reshade_rays);
  memset(g, 0, sizeof *g);
}

void hush__gradients_reset(hush_gradients *g) {
  g->have_sources = 0;
}

static uint32_t stratum_of(const hush_gradients *g, uint32_t x, uint32_t y) {
  return (y / S) * g->strata_x + x / S;
}

/* ---- before the frame: forward projection ------------------------------------------ */

hush_status hush__gradients_begin(hush_device device, hush_gradients *g,
                                  const hush_render_ctx *ctx) {
  const hush_render_params *p = &ctx->params;
  if (p->width != g->width || p->height != g->height)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                      "render: gradients were set up for %ux%u, the frame is %ux%u", g->width,
                      g->height, p->width, p->height);
  if (p->spp != 1 || p->progressive)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                      "render: gradients need exactly 1 sample on every pixel (spp 1, no "
                      "spp fraction)");
  const uint32_t n = g->strata_x * g->strata_y;
  for (uint32_t t = 0; t < n; t++) {
    g->claim[t] = -1;
    g->accepted[t] = -1;
    g->current[t] = g->previous[t] = 0.0f;
    g->reshade_rays[t] = 0;
  }
  if (!g->have_sources) return HUSH_OK;
  const hush_scene *sc = ctx->scene;
  /* serial, in source order: which sample a stratum gets does not depend
   * on the thread count */
  for (uint32_t s = 0; s < n; s++) {
    const hush_gradient_source *src = &g->sources[s];
    if (src->triangle >= sc->triangle_count) continue;
    /* behind planar mirrors: the hit they lead to, in their virtual world
     * (where the mirrors are now, if they move) */
    hush_mirror_map now;
    const hush_mirror_map *map =
        src->mirrors && hush__mirror_map_at(sc, &src->map, sc->frame, &now) ? &now : &src->map;
    const hush_vec3 pt =
        src->mirrors ? hush__mirror_map_point(map, hush__scene_point(sc, src->behind_triangle,
                                                                     src->behind_u, src->behind_v,
                                                                     sc->frame))
                     : hush__scene_point(sc, src->triangle, src->u, src->v, sc->frame);
    float cx, cy;
    if (!hush__camera_project(&ctx->cam, pt, 1.0f, &cx, &cy)) continue;
    if (!(cx >= 0.0f && cx < (float)g->width && cy >= 0.0f && cy < (float)g->height)) continue;
    const uint32_t x = (uint32_t)cx, y = (uint32_t)cy;
    const uint32_t t = stratum_of(g, x, y);
    if (g->claim[t] >= 0 && !(src->luminance > g->sources[g->claim[t]].luminance)) continue;
    g->claim[t] = (int32_t)s;
    g->landing[t] = y * g->width + x;
  }
  return HUSH_OK;
}

/* ---- during the frame: visibility test and re-shading -------------------------------- */

/* Whether `seen` is the sample's triangle, or a triangle of the same object
 * whose plane holds the sample's point p (dist away from the eye along the
 * camera ray, unfolded through mirrors). */
static int same_surface(const hush_scene *sc, uint32_t seen, uint32_t triangle, hush_vec3 p,
                        float dist) {
  if (seen >= sc->triangle_count) return 0;
  if (seen == triangle) return 1;
  if (sc->triangle_object[seen] != sc->triangle_object[triangle]) return 0;
  const hush_vec3 a = hush__scene_point(sc, seen, 0.0f, 0.0f, sc->frame);
  const hush_vec3 b = hush__scene_point(sc, seen, 1.0f, 0.0f, sc->frame);
  const hush_vec3 c = hush__scene_point(sc, seen, 0.0f, 1.0f, sc->frame);
  const hush_vec3 n = hush_v3_cross(hush_v3_sub(b, a), hush_v3_sub(c, a));
  const float len = hush_v3_length(n);
  if (!(len > 0.0f)) return 0;
  return fabsf(hush_v3_dot(n, hush_v3_sub(p, a))) / len <= PLANE_TOLERANCE * dist;
}

/* Whether the pixel whose primary ray hit `traced` sees the sample's first
 * hit f: nothing (a sphere light) in front of it, and the same triangle or
 * a triangle of the same object whose plane holds the sample. */
static int sees_sample(const hush_render_ctx *ctx, const hush_hit *traced, const hush_first_hit *f) {
  float ts;
  if (hush__lights_intersect_sphere(ctx->lights, ctx->cam.eye, f->dir, 0.0f, f->t, &ts)) return 0;
  return same_surface(ctx->scene, traced->triangle, f->hit.triangle, f->p, f->t);
}

/* The first hit of a sample behind planar mirrors (src->mirrors > 0) for
 * this frame's eye: where the camera ray towards the sample's point in the
 * mirrors' virtual world meets the first mirror. 0 unless the same number
 * of mirrors leads from there to the sample's surface (it is not hidden in
 * the mirror, nor the mirror moved or gone). */
static int mirror_first_hit(const hush_render_ctx *ctx, const hush_gradient_source *src,
                            hush_first_hit *f) {
  const hush_scene *sc = ctx->scene;
  const hush_vec3 eye = ctx->cam.eye;
  const hush_vec3 behind =
      hush__scene_point(sc, src->behind_triangle, src->behind_u, src->behind_v, sc->frame);
  hush_mirror_map now;
  const hush_mirror_map *map =
      hush__mirror_map_at(sc, &src->map, sc->frame, &now) ? &now : &src->map;
  const hush_vec3 to = hush_v3_sub(hush__mirror_map_point(map, behind), eye);
  const float dist = hush_v3_length(to);
  if (!(dist > 0.0f)) return 0;
  const hush_vec3 d = hush_v3_scale(to, 1.0f / dist);
  const float o[3] = {eye.x, eye.y, eye.z}, dd[3] = {d.x, d.y, d.z};
  hush_hit hit;
  if (!hush__scene_intersect(sc, o, dd, 0.0f, INFINITY, &hit)) return 0;
  if (!hush__integrator_first_hit(&ctx->it, eye, hit.triangle, hit.u, hit.v, f)) return 0;
  hush_first_hit g;
  float reflectance[3];
  hush_mirror_map mm;
  if (hush__mirror_replace_primary(ctx, f, &g, reflectance, &mm) != (int)src->mirrors) return 0;
  return g.kind == HUSH_FIRST_TRIANGLE &&
         same_surface(sc, g.hit.triangle, src->behind_triangle, behind, dist);
}

/* The pixel colour of one shaded sample, as render.c's shade_pixel makes it
 * at 1 spp (with split_lobes the colour is diffuse + specular). */
static void sample_color(int split_lobes, const hush_path_result *r, float c[3]) {
  for (int k = 0; k < 3; k++) c[k] = split_lobes ? r->diffuse[k] + r->specular[k] : r->radiance[k];
}

/* The luminance a gradient compares, of a sample shaded by gradient_integrator's. */
static float gradient_luminance(const hush_gradients *g, int split_lobes,
                                const hush_path_result *r) {
  if (g->lobe == HUSH_GRADIENT_LOBE_DIFFUSE)
    return hush_luminance(r->diffuse[0], r->diffuse[1], r->diffuse[2]);
  float c[3];
  sample_color(split_lobes, r, c);
  return hush_luminance(c[0], c[1], c[2]);
}

/* The integrator of the re-shading: the frame's, with the lobes split when the
 * gradient compares the diffuse one (same paths: the split only adds sums). */
static hush_integrator gradient_integrator(const hush_gradients *g, const hush_integrator *it) {
  hush_integrator copy = *it;
  if (g->lobe == HUSH_GRADIENT_LOBE_DIFFUSE) copy.split_lobes = 1;
  return copy;
}

int hush__gradients_shade(hush_gradients *g, const hush_render_ctx *ctx, uint32_t x, uint32_t y,
                          const hush_hit *traced, hush_pixel_result *out) {
  const uint32_t t = stratum_of(g, x, y);
  const int32_t c = g->claim[t];
  if (c < 0 || g->landing[t] != y * g->width + x) return 0;
  const hush_gradient_source *src = &g->sources[c];
  hush_first_hit f;
  /* + the primary ray traced for the visibility test; behind mirrors + the
   * ray to the mirror and one per mirror */
  const uint32_t test_rays = src->mirrors ? 2u + src->mirrors : 1u;
  if (src->mirrors ? !mirror_first_hit(ctx, src, &f)
                   : !hush__integrator_first_hit(&ctx->it, ctx->cam.eye, src->triangle, src->u,
                                                 src->v, &f))
    return 0;
  if (!sees_sample(ctx, traced, &f)) return 0;
  const hush_render_params *p = &ctx->params;
  hush_rand rng;
  hush__rand_init(&rng, p->sampler, p->seed, src->seed_frame, src->seed_x, src->seed_y, 0, 1);
  hush_path_result r;
  const hush_integrator it = gradient_integrator(g, &ctx->it);
  hush__integrator_shade(&it, ctx->cam.eye, &f, &rng, x, y, &r);
  if (g->landing_mode == HUSH_GRADIENT_LANDING_FRESH) {
    g->current[t] = gradient_luminance(g, p->split_lobes, &r);
    g->previous[t] = src->luminance;
    g->accepted[t] = (int32_t)((y % S) * S + x % S);
    g->reshade_rays[t] = r.rays + test_rays;
    return 0; /* the pixel takes its own fresh sample */
  }
  memset(out, 0, sizeof *out);
  sample_color(p->split_lobes, &r, out->color);
  memcpy(out->direct, r.direct, sizeof out->direct);
  memcpy(out->emission, r.emission, sizeof out->emission);
  if (p->split_lobes) {
    memcpy(out->diffuse, r.diffuse, sizeof out->diffuse);
    memcpy(out->specular, r.specular, sizeof out->specular);
  }
  out->first = f;
  out->gradient_sample = 1;
  out->rays = (uint64_t)r.rays + test_rays;
  g->current[t] = gradient_luminance(g, p->split_lobes, &r);
  g->previous[t] = src->luminance;
  g->accepted[t] = (int32_t)((y % S) * S + x % S);
  return 1;
}

/* ---- after the frame: the layer, and the samples for the next frame ------------------ */

static hush_status write_layer(const hush_gradients *g, hush_frame out) {
  float *d;
  const hush_layer *old = hush__frame_find(out, "gradient");
  if (old && old->channels == 3) {
    d = old->pixels; /* a frame reused over a sequence, as render.c does */
  } else {
    hush_image_view v;
    const hush_status st = hush_frame_add_layer(out, "gradient", 3, &v);
    if (st != HUSH_OK) return st;
    d = (float *)v.data;
  }
  for (uint32_t y = 0; y < g->height; y++)
    for (uint32_t x = 0; x < g->width; x++) {
      const uint32_t t = stratum_of(g, x, y);
      const int ok = g->accepted[t] >= 0;
      float *o = d + 3 * ((size_t)y * g->width + x);
      o[0] = ok ? g->current[t] : 0.0f;
      o[1] = ok ? g->previous[t] : 0.0f;
      o[2] = (float)g->accepted[t];
    }
  return HUSH_OK;
}

/* Stratum t's sample for the next frame: one of its pixels that see a
 * triangle (the brightest, or one at random), re-shaded from the visibility
 * buffer with the numbers the pixel was shaded with. A landing pixel whose
 * colour is a re-shaded sample (landing SAMPLE) is never chosen: its
 * numbers are an older frame's, and a bright sample would chain from frame
 * to frame and stay (a lasting bias, measured in docs/asvgf.md). Returns the
 * rays traced. */
static uint64_t choose_source(const hush_gradients *g, const hush_render_ctx *ctx,
                              const hush_integrator *it, const float *color, const float *vis,
                              uint32_t t, hush_gradient_source *src) {
  memset(src, 0, sizeof *src);
  src->triangle = UINT32_MAX;
  const uint32_t x0 = (t % g->strata_x) * S, y0 = (t / g->strata_x) * S;
  const uint32_t x1 = x0 + S < g->width ? x0 + S : g->width;
  const uint32_t y1 = y0 + S < g->height ? y0 + S : g->height;
  const int32_t reused = g->landing_mode == HUSH_GRADIENT_LANDING_SAMPLE ? g->accepted[t] : -1;
  size_t candidates[S * S];
  float lum[S * S];
  uint32_t count = 0;
  for (uint32_t y = y0; y < y1; y++)
    for (uint32_t x = x0; x < x1; x++) {
      const size_t i = (size_t)y * g->width + x;
      if (!(vis[3 * i] >= 0.0f)) continue; /* sky, sphere light, hole */
      if (reused >= 0 && (uint32_t)reused == (y - y0) * S + (x - x0)) continue;
      const float l = hush_luminance(color[3 * i], color[3 * i + 1], color[3 * i + 2]);
      if (!(l >= 0.0f)) continue; /* NaN */
      lum[count] = l;
      candidates[count++] = i;
    }
  if (!count) return 0;
  uint32_t pick = 0;
  if (g->select == HUSH_GRADIENT_SELECT_RANDOM) {
    /* a function of (seed, frame, stratum): not of the thread count */
    pick = hush_hash32(hush_hash32(ctx->params.seed ^ hush_hash32(ctx->frame)) ^ t) % count;
  } else {
    for (uint32_t k = 1; k < count; k++)
      if (lum[k] > lum[pick]) pick = k;
  }
  const size_t best_i = candidates[pick];
  const uint32_t bx = (uint32_t)(best_i % g->width), by = (uint32_t)(best_i / g->width);
  src->x = bx;
  src->y = by;
  src->seed_frame = ctx->frame;
  src->seed_x = bx;
  src->seed_y = by;
  const uint32_t tri = (uint32_t)vis[3 * best_i];
  const float u = vis[3 * best_i + 1], v = vis[3 * best_i + 2];
  hush_first_hit f;
  if (!hush__integrator_first_hit(it, ctx->cam.eye, tri, u, v, &f)) return 0;
  /* on a planar mirror: the hit behind, which the pixel describes */
  hush_first_hit behind;
  float reflectance[3];
  const int mirrors = hush__mirror_replace_primary(ctx, &f, &behind, reflectance, &src->map);
  if (mirrors && behind.kind != HUSH_FIRST_TRIANGLE) return (uint64_t)mirrors;
  const hush_render_params *p = &ctx->params;
  hush_rand rng;
  hush__rand_init(&rng, p->sampler, p->seed, src->seed_frame, src->seed_x, src->seed_y, 0, 1);
  hush_path_result r;
  hush__integrator_shade(it, ctx->cam.eye, &f, &rng, bx, by, &r);
  const float l = gradient_luminance(g, p->split_lobes, &r);
  if (!isfinite(l)) return r.rays + (uint64_t)mirrors;
  src->mirrors = (uint32_t)mirrors;
  if (mirrors) {
    src->behind_triangle = behind.hit.triangle;
    src->behind_u = behind.hit.u;
    src->behind_v = behind.hit.v;
  }
  src->triangle = tri;
  src->u = u;
  src->v = v;
  src->luminance = l;
  return r.rays + (uint64_t)mirrors;
}

hush_status hush__gradients_end(hush_device device, hush_gradients *g, const hush_render_ctx *ctx,
                                hush_frame out, int threads, uint64_t *rays) {
  const hush_layer *lc = hush__frame_find(out, "color"), *lv = hush__frame_find(out, "vis");
  if (!lc || !lv || lc->channels != 3 || lv->channels != 3)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                      "render: gradients need the frame's color and vis layers");
  const hush_status st = write_layer(g, out);
  if (st != HUSH_OK) return hush__fail(device, st, "render: cannot add the layer 'gradient'");
  /* the extra shading must not reach the path hooks (psf): it is no
   * pixel's sample */
  hush_integrator it = gradient_integrator(g, &ctx->it);
  it.vertex_fn = NULL;
  it.path_end_fn = NULL;
  const int n = (int)(g->strata_x * g->strata_y);
  uint64_t total = 0;
  for (int t = 0; t < n; t++) total += g->reshade_rays[t];
#pragma omp parallel for schedule(dynamic, 64) num_threads(threads) reduction(+ : total)
  for (int t = 0; t < n; t++)
    total += choose_source(g, ctx, &it, lc->pixels, lv->pixels, (uint32_t)t, &g->next[t]);
  hush_gradient_source *tmp = g->sources;
  g->sources = g->next;
  g->next = tmp;
  g->have_sources = 1;
  *rays += total;
  return HUSH_OK;
}
