/*
 * integrator.c — the 1 spp path tracer (see integrator.h). Follows
 * bmfr-koskela-2019.md §3.1: next-event estimation towards one light point,
 * one importance-sampled secondary ray with its own shadow ray, combined by
 * multiple importance sampling (Veach and Guibas 1995, power heuristic).
 */
#include "render/integrator.h"

#include "core/rng.h"
#include "render/bsdf.h"
#include "render/fminmax.h"

#include <math.h>
#include <string.h>

#define DIM_PATH 4u
#define DIMS_PER_VERTEX 8u
/* offsets inside a vertex's 8 dimensions; 2D pairs start at even numbers */
#define D_LIGHT_PICK 0u
#define D_RR 1u
#define D_LIGHT_UV 2u
#define D_BSDF_UV 4u
#define D_BSDF_LOBE 6u

/* ---- random numbers ------------------------------------------------------- */

uint32_t hush__pixel_seed(uint32_t global_seed, uint32_t frame, uint32_t x, uint32_t y) {
  return hush_rng_u32(global_seed, frame, (y << 16) ^ x);
}

void hush__rand_init(hush_rand *r, hush_sampler kind, uint32_t global_seed, uint32_t frame,
                     uint32_t x, uint32_t y, uint32_t sample, uint32_t spp) {
  r->pixel_seed = hush__pixel_seed(global_seed, frame, x, y);
  r->sample = sample;
  r->kind = kind;
  uint32_t bits = 0;
  while (bits < 31 && (1u << bits) < spp) bits++;
  r->log2_spp = bits;
}

static uint32_t reverse_bits(uint32_t v) {
  v = ((v >> 1) & 0x55555555u) | ((v & 0x55555555u) << 1);
  v = ((v >> 2) & 0x33333333u) | ((v & 0x33333333u) << 2);
  v = ((v >> 4) & 0x0F0F0F0Fu) | ((v & 0x0F0F0F0Fu) << 4);
  v = ((v >> 8) & 0x00FF00FFu) | ((v & 0x00FF00FFu) << 8);
  return (v >> 16) | (v << 16);
}

/* Second dimension of the Sobol sequence (the first is the van der Corput
 * sequence, reverse_bits). */
static uint32_t sobol_dim2(uint32_t n) {
  uint32_t r = 0;
  for (uint32_t v = 1u << 31; n; n >>= 1, v ^= v >> 1)
    if (n & 1u) r ^= v;
  return r;
}

/* A bijection of [0, 2^bits), keyed: shuffles which sample of the pixel uses
 * which point of a pair's (0,2)-sequence, so pairs do not correlate. */
static uint32_t shuffle_index(uint32_t n, uint32_t key, uint32_t bits) {
  if (bits == 0) return n;
  const uint32_t mask = bits >= 32 ? 0xffffffffu : (1u << bits) - 1u;
  uint32_t x = n & mask;
  for (int round = 0; round < 3; round++) {
    x ^= (key >> (8 * round)) & mask;
    x = (x * ((key | 1u) + 2u * (uint32_t)round)) & mask;
    x ^= x >> ((bits + 1) / 2);
  }
  return x | (n & ~mask);
}

float hush__rand_ld(const hush_rand *r, uint32_t dim) {
  const uint32_t pair = dim >> 1;
  const uint32_t key = hush_rng_u32(r->pixel_seed, pair, 0x9e3779b9u);
  const uint32_t n = shuffle_index(r->sample, key, r->log2_spp);
  const uint32_t scramble = hush_rng_u32(r->pixel_seed, pair, 0x85ebca6bu + (dim & 1u));
  const uint32_t bits = ((dim & 1u) ? sobol_dim2(n) : reverse_bits(n)) ^ scramble;
  return (float)(bits >> 8) * (1.0f / 16777216.0f);
}

/* ---- helpers ---------------------------------------------------------------- */

void hush__integrator_defaults(hush_integrator *it, const hush_scene *scene,
                               const hush_lights *lights) {
  memset(it, 0, sizeof *it);
  it->scene = scene;
  it->lights = lights;
  it->bounces = 1;
  it->rr_depth = 3;
}

static float power_heuristic(float a, float b) {
  const float a2 = a * a, b2 = b * b;
  return a2 + b2 > 0.0f ? a2 / (a2 + b2) : 0.0f;
}

static float max3(const float c[3]) {
  return hush_fmaxf(c[0], hush_fmaxf(c[1], c[2]));
}

/* A ray origin just off the surface on the side of direction w: the offset
 * scales with the magnitude of the position so large scenes stay clean. */
static hush_vec3 offset_origin(hush_vec3 p, hush_vec3 ng, hush_vec3 w) {
  const float mag = hush_fmaxf(fabsf(p.x), hush_fmaxf(fabsf(p.y), fabsf(p.z)));
  const float eps = 1e-4f * hush_fmaxf(1.0f, mag);
  const float side = hush_v3_dot(w, ng) >= 0.0f ? eps : -eps;
  return hush_v3_add(p, hush_v3_scale(ng, side));
}

static float ray_eps(hush_vec3 p) {
  const float mag = hush_fmaxf(fabsf(p.x), hush_fmaxf(fabsf(p.y), fabsf(p.z)));
  return 1e-4f * hush_fmaxf(1.0f, mag);
}

/* Adds beta * c * w to the result; contributions beyond the first hit are
 * clamped when asked. With split_lobes, the share `share` of it (per
 * channel) goes to the diffuse layer and the rest to the specular one.
 * `direct`: also to the direct light, and, for emission (`emission` 1), to
 * the emission seen directly (hush_path_result). */
static void add(const hush_integrator *it, hush_path_result *out, float vertex_sum[3],
                const float beta[3], const float c[3], float w, int depth, int direct,
                int emission, const float share[3]) {
  float v[3];
  for (int k = 0; k < 3; k++) v[k] = beta[k] * c[k] * w;
  if (!(isfinite(v[0]) && isfinite(v[1]) && isfinite(v[2]))) return;
  if (it->clamp > 0.0f && depth > 0) {
    const float m = max3(v);
    if (m > it->clamp)
      for (int k = 0; k < 3; k++) v[k] *= it->clamp / m;
  }
  for (int k = 0; k < 3; k++) {
    out->radiance[k] += v[k];
    vertex_sum[k] += v[k];
    if (direct) out->direct[k] += v[k];
    if (direct && emission) out->emission[k] += v[k];
  }
  if (it->split_lobes)
    for (int k = 0; k < 3; k++) {
      const float d = v[k] * share[k];
      out->diffuse[k] += d;
      out->specular[k] += v[k] - d;
    }
}

/* The diffuse share of f = fd + fs, per channel: 1 where f is 0 (nothing
 * to split; it only multiplies zeros). fd / f is exactly 1 when fs is 0 and
 * exactly 0 when fd is 0, so pure Lambert or pure glossy surfaces put
 * nothing in the other layer. */
static void diffuse_share(const float fd[3], const float fs[3], float share[3]) {
  for (int k = 0; k < 3; k++) {
    const float f = fd[k] + fs[k];
    share[k] = f > 0.0f ? fd[k] / f : 1.0f;
  }
}

/* A next-event shadow ray whose query is deferred (see path_rays): if
 * nothing blocks o + t d for t in (0, tfar), the vertex receives
 * f L w / pdf, L the light sample's radiance (and a sun sample's pdf, hence
 * the MIS weight w) evaluated only then. */
typedef struct shadow_ray {
  int traced;              /* 0: no ray (no light sample, or it cannot contribute) */
  float o[3], d[3], tfar;
  hush_light_sample ls;    /* its radiance may be deferred (hush__lights_sample_deferred) */
  float f[3], pdf_b;       /* BSDF value and density towards the light */
  int last;                /* no MIS at the last vertex */
} shadow_ray;

/* Next event, up to its shadow ray: one light sample, MIS-weighted unless
 * it is the last vertex. share (may be NULL) receives the diffuse lobe's
 * share of it. */
static void next_event(const hush_integrator *it, const hush_rand *rng, uint32_t base,
                       const hush_bsdf *b, hush_vec3 p, hush_vec3 wo, int last, shadow_ray *sr,
                       float share[3]) {
  sr->traced = 0;
  const float u[3] = {hush__rand(rng, base + D_LIGHT_PICK), hush__rand(rng, base + D_LIGHT_UV),
                      hush__rand(rng, base + D_LIGHT_UV + 1)};
  hush_light_sample *ls = &sr->ls;
  if (!hush__lights_sample_deferred(it->lights, p, u, ls)) return;
  if (!ls->deferred && !(max3(ls->radiance) > 0.0f)) return;
  float *f = sr->f;
  if (share) {
    float fs[3];
    hush__bsdf_eval_lobes(b, wo, ls->wi, f, fs, &sr->pdf_b);
    diffuse_share(f, fs, share);
    for (int k = 0; k < 3; k++) f[k] += fs[k]; /* hush__bsdf_eval's f, bit for bit */
  } else {
    hush__bsdf_eval(b, wo, ls->wi, f, &sr->pdf_b);
  }
  if (!(max3(f) > 0.0f)) return;
  const hush_vec3 o = offset_origin(p, b->ng, ls->wi);
  const float tfar = isfinite(ls->dist) ? ls->dist * (1.0f - 1e-4f) - ray_eps(p) : INFINITY;
  if (!(tfar > 0.0f)) return;
  sr->traced = 1;
  sr->o[0] = o.x;
  sr->o[1] = o.y;
  sr->o[2] = o.z;
  sr->d[0] = ls->wi.x;
  sr->d[1] = ls->wi.y;
  sr->d[2] = ls->wi.z;
  sr->tfar = tfar;
  sr->last = last;
}

/* What an unblocked shadow ray brings. A deferred sun-and-sky radiance is
 * evaluated here; where it is 0 the contribution is 0, as if the ray had
 * not been traced (the sky model is positive above the horizon, so that
 * does not happen in practice). */
static void shadow_light(const hush_integrator *it, shadow_ray *sr, float c[3]) {
  hush_light_sample *ls = &sr->ls;
  c[0] = c[1] = c[2] = 0.0f;
  hush__lights_sample_finish(it->lights, ls);
  if (!(max3(ls->radiance) > 0.0f)) return;
  const float w = sr->last ? 1.0f : power_heuristic(ls->pdf, sr->pdf_b);
  for (int k = 0; k < 3; k++) c[k] = sr->f[k] * ls->radiance[k] * w / ls->pdf;
}

static void call_hook(const hush_integrator *it, uint32_t x, uint32_t y, const hush_rand *rng,
                      int depth, const hush_surface *s, uint32_t tri, const float beta[3],
                      const float sum[3]) {
  if (!it->vertex_fn) return;
  hush_path_vertex v;
  v.x = x;
  v.y = y;
  v.sample = rng->sample;
  v.depth = depth;
  v.p = s->p;
  v.n = s->ns;
  v.triangle = tri;
  v.material = s->material;
  memcpy(v.throughput, beta, sizeof v.throughput);
  memcpy(v.contribution, sum, sizeof v.contribution);
  v.surface = s;
  it->vertex_fn(it->vertex_user, &v);
}

/* What a ray from o along d hits next: a triangle, a sphere light, or nothing. */
typedef struct next_hit {
  hush_first_kind kind;
  hush_hit hit;
  uint32_t sphere;
  float t;
} next_hit;

/* What a ray whose closest triangle is `tri` (triangle UINT32_MAX: none)
 * hits: that triangle, or a sphere light in front of it, or nothing. */
static void complete_hit(const hush_integrator *it, hush_vec3 o, hush_vec3 d, const hush_hit *tri,
                         next_hit *h) {
  h->kind = HUSH_FIRST_SKY;
  h->t = INFINITY;
  h->hit = *tri;
  if (tri->triangle != UINT32_MAX) {
    h->kind = HUSH_FIRST_TRIANGLE;
    h->t = tri->t;
  }
  float ts;
  const uint32_t s = hush__lights_intersect_sphere(it->lights, o, d, 0.0f, h->t, &ts);
  if (s) {
    h->kind = HUSH_FIRST_SPHERE;
    h->sphere = s - 1;
    h->t = ts;
  }
}

/* ---- the path ------------------------------------------------------------------ */

/* One path in flight, between its vertices. A path is shaded as a loop of
 * path_vertex (the vertex's shading, up to its two rays), path_rays (the
 * path's next ray, then the shadow ray) and path_resolve (the shadow ray's
 * light added, then on to the next hit) — one path alone (shade_path), or
 * the paths of a pixel block stage by stage (hush__integrator_trace_block).
 * Each path's numbers and rays are the same either way. */
typedef struct path_state {
  const hush_first_hit *first;
  const hush_rand *rng;
  hush_path_result *out;
  uint32_t x, y;
  float beta[3];           /* throughput from the camera to the vertex */
  hush_vec3 d, origin;     /* the ray that found the vertex */
  next_hit h;
  float prev_pdf;
  int prev_delta;          /* the camera ray sees emission with full weight */
  /* split_lobes: the diffuse share of what the path adds; light seen
   * directly counts as diffuse, then the first hit's BSDF sample sets it */
  float share[3];
  int depth;
  int done;
  /* the path has met only planar mirrors so far (mirror_depth): the
   * emission it meets counts as seen directly (hush_path_result) */
  int chain, chain_next;
  /* the vertex in progress */
  hush_surface later;      /* its surface beyond the first hit */
  const hush_surface *sp;  /* &first->surface or &later */
  float vsum[3];           /* what the vertex adds (the hook's contribution) */
  int nee;                 /* a light sample was taken */
  shadow_ray sr;
  float nee_share[3];
  int go;                  /* the path continues along bs from next_origin */
  hush_bsdf_sample bs;
  float nbeta[3];
  hush_vec3 next_origin;
  hush_hit next_tri;       /* the next ray's closest triangle, already traced */
} path_state;

static void path_begin(path_state *st, hush_vec3 eye, const hush_first_hit *first,
                       const hush_rand *rng, uint32_t x, uint32_t y, hush_path_result *out) {
  memset(out, 0, sizeof *out);
  st->first = first;
  st->rng = rng;
  st->out = out;
  st->x = x;
  st->y = y;
  st->beta[0] = st->beta[1] = st->beta[2] = 1.0f;
  st->d = first->dir;
  st->origin = eye;
  st->h.kind = first->kind;
  st->h.hit = first->hit;
  st->h.sphere = first->sphere;
  st->h.t = first->t;
  st->prev_pdf = 0.0f;
  st->prev_delta = 1;
  st->share[0] = st->share[1] = st->share[2] = 1.0f;
  st->depth = 0;
  st->done = 0;
  st->chain = 1;
  st->chain_next = 0;
}

/* The vertex st->h: emission, the light sample up to its shadow ray
 * (st->sr, not asked yet), and the BSDF sample up to the path's next ray
 * (st->go, st->bs, st->next_origin, not traced yet). The contributions
 * are added in the estimator's order (emission here, the light sample in
 * path_resolve), so splitting the vertex changes no result. A path that
 * escapes or meets a sphere light ends here (st->done). */
static void path_vertex(const hush_integrator *it, path_state *st) {
  const hush_scene *sc = it->scene;
  const hush_lights *L = it->lights;
  hush_path_result *out = st->out;
  /* emission seen directly: at the first hit (throughput and MIS weight
   * 1, so the emitted radiance itself), or behind planar mirrors (times
   * their reflectance; st->chain is 1 at depth 0) */
  const int depth = st->depth, direct = st->chain;
  const hush_vec3 d = st->d;
  float *vsum = st->vsum;
  vsum[0] = vsum[1] = vsum[2] = 0.0f;
  st->nee = 0;
  st->go = 0;
  st->chain_next = 0;
  if (st->h.kind == HUSH_FIRST_SKY) {
    float le[3];
    const float pdf_env = hush__lights_env_eval(L, d, le);
    const float w = st->prev_delta ? 1.0f : power_heuristic(st->prev_pdf, pdf_env);
    add(it, out, vsum, st->beta, le, w, depth, direct, 1, st->share);
    st->done = 1;
    return;
  }
  if (st->h.kind == HUSH_FIRST_SPHERE) {
    const float w = st->prev_delta ? 1.0f
                                   : power_heuristic(st->prev_pdf,
                                                     hush__lights_sphere_pdf(L, st->h.sphere,
                                                                             st->origin));
    add(it, out, vsum, st->beta, sc->spheres[st->h.sphere].radiance, w, depth, direct, 1,
        st->share);
    st->done = 1;
    return;
  }
  /* the first hit's surface is read in place (copying it and reading a
   * field back stalls on store forwarding) */
  st->sp = &st->first->surface;
  if (depth > 0) {
    const float dd[3] = {d.x, d.y, d.z};
    hush__scene_surface(sc, &st->h.hit, dd, &st->later);
    st->sp = &st->later;
  }
  const hush_surface *sp = st->sp;
  const hush_material *m = &sc->materials[sp->material];
  /* a one-sided emitter seen from behind emits nothing (as its light
   * samples: lights.c), but still reflects */
  if (max3(m->emission) > 0.0f && (!sp->back_face || sc->two_sided_emitters)) {
    float w = 1.0f;
    if (!st->prev_delta) {
      const float cos_l = fabsf(hush_v3_dot(d, sp->ng));
      const float area = hush__lights_triangle_area(sc, st->h.hit.triangle);
      w = power_heuristic(st->prev_pdf,
                          hush__lights_triangle_pdf(L, st->h.hit.triangle, area, st->h.t, cos_l));
    }
    add(it, out, vsum, st->beta, m->emission, w, depth, direct, 1, st->share);
  }
  const hush_vec3 wo = hush_v3_scale(d, -1.0f);
  hush_bsdf b;
  hush__bsdf_setup(&b, m, sp, wo);
  const int last = depth >= it->bounces;
  const uint32_t base = DIM_PATH + DIMS_PER_VERTEX * (uint32_t)depth;
  st->nee = hush__bsdf_has_smooth(&b) && hush__lights_any(L);
  st->sr.traced = 0;
  st->nee_share[0] = st->nee_share[1] = st->nee_share[2] = 1.0f;
  if (st->nee)
    /* at the first hit (behind planar mirrors: the first hit beyond
     * them, st->chain) the light sample is split by lobe; later ones
     * follow that hit's split of the path */
    next_event(it, st->rng, base, &b, sp->p, wo, last, &st->sr,
               it->split_lobes && st->chain ? st->nee_share : NULL);
  if (last) return;

  const float u[3] = {hush__rand(st->rng, base + D_BSDF_LOBE),
                      hush__rand(st->rng, base + D_BSDF_UV),
                      hush__rand(st->rng, base + D_BSDF_UV + 1)};
  hush_bsdf_sample *bs = &st->bs;
  if (!hush__bsdf_sample(&b, wo, u, bs)) return;
  /* the path goes on through a planar mirror of the chain (primary
   * surface replacement): the hit behind it counts as the first */
  const int mirror = st->chain && depth < it->mirror_depth && bs->delta &&
                     hush__integrator_planar_mirror(it, sp, st->h.hit.triangle);
  if (it->split_lobes && st->chain && !mirror) {
    /* the rest of the path is split as the first hit's lobes reflect
     * the sampled direction: delta lobes are specular, a smooth
     * direction by the lobes' values there (this vertex's light sample
     * uses nee_share, not share). Behind planar mirrors the hit they
     * lead to decides, as if the camera saw it directly: the pixel
     * describes that hit, and the light seen in the mirror is diffuse
     * as light seen directly. */
    if (bs->delta) {
      st->share[0] = st->share[1] = st->share[2] = 0.0f;
    } else {
      float fd[3], fs[3], pdf_l;
      hush__bsdf_eval_lobes(&b, wo, bs->wi, fd, fs, &pdf_l);
      diffuse_share(fd, fs, st->share);
    }
  }
  for (int k = 0; k < 3; k++) st->nbeta[k] = st->beta[k] * bs->weight[k];
  if (!(max3(st->nbeta) > 0.0f)) return;
  if (depth + 1 > it->rr_depth) {
    const float q = hush_fminf(0.95f, max3(st->nbeta));
    if (hush__rand(st->rng, base + D_RR) >= q) return;
    for (int k = 0; k < 3; k++) st->nbeta[k] /= q;
  }
  st->go = 1;
  st->next_origin = offset_origin(sp->p, b.ng, bs->wi);
  st->chain_next = mirror;
}

/* The vertex's rays: the path's next ray first, its hit's shading record
 * prefetched, then the shadow ray, so the record arrives while Embree
 * traverses the shadow ray. Neither ray depends on the other. Returns
 * whether the shadow ray is blocked. */
static int path_rays(const hush_integrator *it, path_state *st) {
  if (st->go) {
    const float oo[3] = {st->next_origin.x, st->next_origin.y, st->next_origin.z};
    const float dd[3] = {st->bs.wi.x, st->bs.wi.y, st->bs.wi.z};
    hush__scene_intersect(it->scene, oo, dd, 0.0f, INFINITY, &st->next_tri);
    hush__scene_prefetch_surface(it->scene, st->next_tri.triangle);
  }
  const shadow_ray *sr = &st->sr;
  return sr->traced && hush__scene_occluded(it->scene, sr->o, sr->d, 0.0f, sr->tfar);
}

/* The vertex's shadow ray answered (`occluded`; ignored when none was
 * traced): its light is added, the hook called, and the path moves on to
 * its next hit or ends (st->done). */
static void path_resolve(const hush_integrator *it, path_state *st, int occluded) {
  hush_path_result *out = st->out;
  const int depth = st->depth;
  if (st->nee) {
    float c[3] = {0.0f, 0.0f, 0.0f};
    if (st->sr.traced) {
      out->rays++;
      if (!occluded) shadow_light(it, &st->sr, c);
    }
    const float one[3] = {1.0f, 1.0f, 1.0f};
    float bc[3];
    for (int k = 0; k < 3; k++) bc[k] = st->beta[k] * c[k];
    /* the light sample of the first hit, or of the hit behind the
     * planar mirrors, is direct light, as the emission seen there */
    add(it, out, st->vsum, one, bc, 1.0f, depth, st->chain, 0,
        st->chain ? st->nee_share : st->share);
  }
  call_hook(it, st->x, st->y, st->rng, depth, st->sp, st->h.hit.triangle, st->beta, st->vsum);
  if (!st->go) {
    st->done = 1;
    return;
  }
  for (int k = 0; k < 3; k++) st->beta[k] = st->nbeta[k];
  st->prev_pdf = st->bs.pdf;
  st->prev_delta = st->bs.delta;
  st->chain = st->chain_next;
  st->origin = st->next_origin;
  st->d = st->bs.wi;
  out->rays++;
  complete_hit(it, st->origin, st->d, &st->next_tri, &st->h);
  st->depth = depth + 1;
}

static void shade_path(const hush_integrator *it, hush_vec3 eye, const hush_first_hit *first,
                       const hush_rand *rng, uint32_t x, uint32_t y, hush_path_result *out) {
  path_state st;
  path_begin(&st, eye, first, rng, x, y, out);
  for (;;) {
    path_vertex(it, &st);
    if (st.done) return;
    path_resolve(it, &st, path_rays(it, &st));
    if (st.done) return;
  }
}

void hush__integrator_shade(const hush_integrator *it, hush_vec3 eye, const hush_first_hit *first,
                            const hush_rand *rng, uint32_t x, uint32_t y, hush_path_result *out) {
  shade_path(it, eye, first, rng, x, y, out);
  if (it->path_end_fn) it->path_end_fn(it->vertex_user, x, y, rng->sample, out->radiance);
}

int hush__integrator_first_hit(const hush_integrator *it, hush_vec3 eye, uint32_t triangle, float u,
                               float v, hush_first_hit *first) {
  memset(first, 0, sizeof *first);
  const hush_scene *sc = it->scene;
  if (triangle >= sc->triangle_count) return 0;
  const hush_vec3 p = hush__scene_point(sc, triangle, u, v, sc->frame);
  const hush_vec3 to = hush_v3_sub(p, eye);
  const float t = hush_v3_length(to);
  if (!(t > 0.0f)) return 0;
  first->kind = HUSH_FIRST_TRIANGLE;
  first->dir = hush_v3_scale(to, 1.0f / t);
  first->t = t;
  first->hit.triangle = triangle;
  first->hit.u = u;
  first->hit.v = v;
  first->hit.t = t;
  const float dd[3] = {first->dir.x, first->dir.y, first->dir.z};
  hush__scene_surface(sc, &first->hit, dd, &first->surface);
  first->p = first->surface.p;
  first->n = first->surface.ns;
  return 1;
}

void hush__integrator_trace(const hush_integrator *it, hush_vec3 eye, hush_vec3 d,
                            const hush_rand *rng, uint32_t x, uint32_t y, hush_first_hit *first,
                            hush_path_result *out) {
  const float oo[3] = {eye.x, eye.y, eye.z}, dd[3] = {d.x, d.y, d.z};
  hush_hit tri;
  hush__scene_intersect(it->scene, oo, dd, 0.0f, INFINITY, &tri);
  hush__integrator_trace_hit(it, eye, d, &tri, rng, x, y, first, out);
}

/* The first hit of a camera ray from eye along d whose closest triangle
 * is tri: that triangle's surface, or a sphere light in front, or sky. */
static void first_hit_of(const hush_integrator *it, hush_vec3 eye, hush_vec3 d,
                         const hush_hit *tri, hush_first_hit *f) {
  memset(f, 0, sizeof *f);
  f->dir = d;
  next_hit h;
  complete_hit(it, eye, d, tri, &h);
  f->kind = h.kind;
  f->t = h.t;
  if (h.kind == HUSH_FIRST_TRIANGLE) {
    f->hit = h.hit;
    const float dd[3] = {d.x, d.y, d.z};
    hush__scene_surface(it->scene, &h.hit, dd, &f->surface);
    f->p = f->surface.p;
    f->n = f->surface.ns;
  } else if (h.kind == HUSH_FIRST_SPHERE) {
    float c[3];
    f->sphere = h.sphere;
    hush__scene_sphere_at(it->scene, h.sphere, it->scene->frame, c);
    f->p = hush_v3_add(eye, hush_v3_scale(d, h.t));
    f->n = hush_v3_normalize(hush_v3_sub(f->p, hush_v3(c[0], c[1], c[2])));
  }
}

int hush__integrator_planar_mirror(const hush_integrator *it, const hush_surface *s,
                                   uint32_t triangle) {
  const hush_material *m = &it->scene->materials[s->material];
  return m->type == HUSH_MAT_CONDUCTOR && !(m->roughness > 0.0f) &&
         hush__scene_triangle_flat(it->scene, triangle);
}

int hush__integrator_mirror_step(const hush_integrator *it, hush_first_hit *h, float weight[3],
                                 hush_vec3 *q, hush_vec3 *n) {
  if (h->kind != HUSH_FIRST_TRIANGLE || !hush__integrator_planar_mirror(it, &h->surface,
                                                                         h->hit.triangle))
    return 0;
  const hush_surface *s = &h->surface;
  const hush_vec3 wo = hush_v3_scale(h->dir, -1.0f);
  hush_bsdf b;
  hush__bsdf_setup(&b, &it->scene->materials[s->material], s, wo);
  /* the lobe is a delta: the numbers do not matter */
  const float u[3] = {0.5f, 0.5f, 0.5f};
  hush_bsdf_sample bs;
  if (!hush__bsdf_sample(&b, wo, u, &bs) || !bs.delta) return 0;
  *q = s->p;
  *n = s->ng;
  for (int k = 0; k < 3; k++) weight[k] *= bs.weight[k];
  const hush_vec3 o = offset_origin(s->p, b.ng, bs.wi);
  const float oo[3] = {o.x, o.y, o.z}, dd[3] = {bs.wi.x, bs.wi.y, bs.wi.z};
  hush_hit tri;
  hush__scene_intersect(it->scene, oo, dd, 0.0f, INFINITY, &tri);
  first_hit_of(it, o, bs.wi, &tri, h);
  return 1;
}

void hush__integrator_trace_hit(const hush_integrator *it, hush_vec3 eye, hush_vec3 d,
                                const hush_hit *tri, const hush_rand *rng, uint32_t x, uint32_t y,
                                hush_first_hit *first, hush_path_result *out) {
  hush_first_hit local;
  hush_first_hit *f = first ? first : &local;
  first_hit_of(it, eye, d, tri, f);
  hush__integrator_shade(it, eye, f, rng, x, y, out);
  out->rays++;
}

void hush__integrator_trace_block(const hush_integrator *it, hush_vec3 eye,
                                  const float d[HUSH_PACKET][3], const hush_hit hits[HUSH_PACKET],
                                  const hush_rand rng[HUSH_PACKET], const uint32_t x[HUSH_PACKET],
                                  const uint32_t y[HUSH_PACKET], uint32_t lanes,
                                  hush_first_hit first[HUSH_PACKET],
                                  hush_path_result out[HUSH_PACKET]) {
  path_state st[HUSH_PACKET];
  for (uint32_t i = 0; i < HUSH_PACKET; i++) {
    if (!((lanes >> i) & 1u)) continue;
    first_hit_of(it, eye, hush_v3(d[i][0], d[i][1], d[i][2]), &hits[i], &first[i]);
    path_begin(&st[i], eye, &first[i], &rng[i], x[i], y[i], &out[i]);
  }
  /* One vertex of every path at a time: each path_vertex traces its
   * path's next ray and prefetches the hit's record, which then has the
   * other lanes' work to arrive in; and each stage's code stays in the
   * instruction cache across the lanes. */
  uint32_t active = lanes;
  while (active) {
    for (uint32_t i = 0; i < HUSH_PACKET; i++) {
      if (!((active >> i) & 1u)) continue;
      path_vertex(it, &st[i]);
      if (st[i].done) active &= ~(1u << i);
    }
    uint32_t blocked = 0;
    for (uint32_t i = 0; i < HUSH_PACKET; i++)
      if ((active >> i) & 1u) blocked |= (uint32_t)path_rays(it, &st[i]) << i;
    for (uint32_t i = 0; i < HUSH_PACKET; i++) {
      if (!((active >> i) & 1u)) continue;
      path_resolve(it, &st[i], (int)((blocked >> i) & 1u));
      if (st[i].done) active &= ~(1u << i);
    }
  }
  for (uint32_t i = 0; i < HUSH_PACKET; i++) {
    if (!((lanes >> i) & 1u)) continue;
    if (it->path_end_fn)
      it->path_end_fn(it->vertex_user, x[i], y[i], rng[i].sample, out[i].radiance);
    out[i].rays++;
  }
}
