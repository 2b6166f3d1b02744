/*
 * integrator.h — the path tracer of the documents' 1 spp configuration
 * (bmfr-koskela-2019.md §3.1; realtime-denoising-comparison-higginson-2023.md
 * §1.1.3): a primary ray, a next-event-estimation shadow ray at the first
 * hit, one BSDF-sampled secondary ray with its own shadow ray, and multiple
 * importance sampling (power heuristic) between the BSDF and light sampling.
 *
 * Bounces: `bounces` counts the BSDF-sampled secondary rays of a path.
 * bounces = 1 is the papers' configuration (primary ray, 2 shadow rays, 1
 * secondary ray); bounces = 0 is direct lighting only. At the last vertex the
 * shadow ray takes the whole light-sampling weight, since no BSDF ray
 * competes with it there. Russian roulette starts after 3 secondary rays.
 *
 * Random numbers: every number of a camera sample is a pure function of
 * (global seed, frame, pixel, sample index, dimension), see hush_rand, so a
 * pixel can be re-rendered alone, and a visibility-buffer sample can be
 * re-shaded with another frame's numbers (A-SVGF, schied-2018 §4): see
 * hush__integrator_shade.
 *
 * Path-vertex hook: when vertex_fn is not NULL it is called at every
 * surface vertex of every path (from the worker threads, concurrently; it
 * must be thread-safe) with the vertex position and normal, the path
 * throughput up to it and the radiance the vertex adds to the pixel
 * (emission and next-event estimation, throughput applied). Path-space
 * filtering hooks in here (src/psf/psf_render.h). path_end_fn, when not
 * NULL, is called once at the end of every path with its total radiance
 * (what the vertices added plus the emission a terminating ray saw).
 */
#ifndef HUSH_RENDER_INTEGRATOR_H
#define HUSH_RENDER_INTEGRATOR_H

#include "core/hmath.h"
#include "core/rng.h"
#include "render/lights.h"
#include "render/scene.h"

#include <stdint.h>

typedef enum hush_sampler {
  HUSH_SAMPLER_RANDOM = 0, /* independent numbers from the counter-based hash */
  HUSH_SAMPLER_LD = 1      /* per-pixel scrambled Sobol (0,2) pairs, shuffled per pair */
} hush_sampler;

/* The random numbers of one camera sample. */
typedef struct hush_rand {
  uint32_t pixel_seed;     /* hush__pixel_seed(global, frame, x, y) */
  uint32_t sample;         /* index of the sample in the pixel */
  uint32_t log2_spp;       /* LD: the sample indices are shuffled on this many bits */
  hush_sampler kind;
} hush_rand;

uint32_t hush__pixel_seed(uint32_t global_seed, uint32_t frame, uint32_t x, uint32_t y);
void hush__rand_init(hush_rand *r, hush_sampler kind, uint32_t global_seed, uint32_t frame,
                     uint32_t x, uint32_t y, uint32_t sample, uint32_t spp);
/* The LD sampler's number `dim` (hush__rand). */
float hush__rand_ld(const hush_rand *r, uint32_t dim);
/* Number `dim` of the sample, in [0, 1). Dimensions 0 and 1 place the
 * sample in the pixel; the path uses 4 + 8 * depth + i. Inline: a path
 * asks for a dozen, and the default sampler is a few integer operations. */
static inline float hush__rand(const hush_rand *r, uint32_t dim) {
  if (r->kind != HUSH_SAMPLER_LD) return hush_rng_float(r->pixel_seed, dim, r->sample);
  return hush__rand_ld(r, dim);
}

typedef struct hush_path_vertex {
  uint32_t x, y, sample;
  int depth;               /* 0: the first hit */
  hush_vec3 p, n;          /* position and shading normal */
  uint32_t triangle, material;
  float throughput[3];     /* camera to this vertex */
  float contribution[3];   /* radiance this vertex adds to the pixel */
  const hush_surface *surface; /* the hit, valid during the call */
} hush_path_vertex;

typedef void (*hush_path_vertex_fn)(void *user, const hush_path_vertex *vertex);
typedef void (*hush_path_end_fn)(void *user, uint32_t x, uint32_t y, uint32_t sample,
                                 const float radiance[3]);

typedef struct hush_integrator {
  const hush_scene *scene; /* set to `frame` (hush__scene_set_frame) */
  const hush_lights *lights;
  int bounces;             /* secondary rays per path, >= 0 */
  int rr_depth;            /* Russian roulette before secondary ray rr_depth + 1 (3) */
  float clamp;             /* > 0: clamp each indirect contribution to this (max channel) */
  hush_path_vertex_fn vertex_fn;
  hush_path_end_fn path_end_fn; /* called with vertex_user */
  void *vertex_user;
  int split_lobes;         /* also fill hush_path_result's diffuse and specular */
  /* Primary surface replacement (render.h): a path whose first vertices
   * are planar mirrors (hush__integrator_planar_mirror), up to this many
   * (0: off), reports the emission it meets behind them in
   * hush_path_result's emission, as if seen directly. */
  int mirror_depth;
} hush_integrator;

void hush__integrator_defaults(hush_integrator *it, const hush_scene *scene,
                               const hush_lights *lights);

/* What a camera sample saw first: a triangle (the visibility buffer), a
 * sphere light, or nothing. */
typedef enum hush_first_kind {
  HUSH_FIRST_SKY = 0,
  HUSH_FIRST_TRIANGLE = 1,
  HUSH_FIRST_SPHERE = 2
} hush_first_kind;

typedef struct hush_first_hit {
  hush_first_kind kind;
  hush_vec3 dir;           /* unit camera ray direction */
  float t;                 /* distance along it */
  hush_hit hit;            /* TRIANGLE */
  hush_surface surface;    /* TRIANGLE */
  uint32_t sphere;         /* SPHERE */
  hush_vec3 p, n;          /* position and normal of the hit (TRIANGLE, SPHERE) */
} hush_first_hit;

typedef struct hush_path_result {
  float radiance[3];
  float direct[3];         /* emission seen directly (as `emission`) + the first hit's shadow
                            * ray (with mirror_depth, behind planar mirrors: the shadow ray
                            * of the first hit beyond them) */
  float emission[3];       /* emission seen directly: what the camera ray's first hit
                            * emits towards it (emissive triangle, sphere light, sky),
                            * or, with mirror_depth, the first hit behind the planar
                            * mirrors it meets first, times their reflectance;
                            * radiance - emission is what the surfaces reflect */
  /* With split_lobes (else 0): radiance by the first hit's lobe. Light seen
   * directly is diffuse. The first hit's shadow ray is split by the BSDF's
   * lobes evaluated towards the light (hush__bsdf_eval_lobes); everything
   * after the first hit by the lobes' values in the sampled direction, all
   * specular for a delta lobe (mirror, smooth coat, glass). So each layer's
   * expectation is its lobe's integral, and diffuse + specular = radiance
   * up to rounding. With mirror_depth, "the first hit" of a path through
   * planar mirrors is the first hit beyond them (primary surface
   * replacement: the pixel describes it). */
  float diffuse[3], specular[3];
  uint32_t rays;           /* rays traced, primary and shadow included */
} hush_path_result;

/* Whether the path sees through surface s of `triangle` deterministically
 * as through a plane: a smooth conductor (a single delta lobe) on a
 * flat-shaded triangle (hush__scene_triangle_flat). */
int hush__integrator_planar_mirror(const hush_integrator *it, const hush_surface *s,
                                   uint32_t triangle);

/* One step of primary surface replacement (render.h): when h is a
 * triangle hit on a planar mirror that reflects towards h->dir's origin
 * side, *h becomes the hit of the reflected ray (traced here, from the
 * same origin as the path's own ray), weight is multiplied by the mirror's
 * reflectance and (q, n) receive the mirror's plane. Returns 0 and changes
 * nothing otherwise. */
int hush__integrator_mirror_step(const hush_integrator *it, hush_first_hit *h, float weight[3],
                                 hush_vec3 *q, hush_vec3 *n);

/* Traces the camera ray from eye along unit direction d and shades it.
 * first may be NULL. */
void hush__integrator_trace(const hush_integrator *it, hush_vec3 eye, hush_vec3 d,
                            const hush_rand *rng, uint32_t x, uint32_t y, hush_first_hit *first,
                            hush_path_result *out);

/* The same for a camera ray whose closest triangle was already found (by
 * a packet, hush__scene_intersect_packet; triangle UINT32_MAX: none): the
 * sphere lights are tested, then the path is shaded. */
void hush__integrator_trace_hit(const hush_integrator *it, hush_vec3 eye, hush_vec3 d,
                                const hush_hit *tri, const hush_rand *rng, uint32_t x, uint32_t y,
                                hush_first_hit *first, hush_path_result *out);

/* hush__integrator_trace_hit for the lanes of a block of camera rays from
 * eye (bit i of `lanes`: lane i, direction d[i], closest triangle hits[i],
 * numbers rng[i], pixel (x[i], y[i]); results in first[i] and out[i]),
 * with the same results bit for bit: every ray is the same single ray and
 * every lane's arithmetic its own. The paths advance together one vertex
 * at a time, which lets a vertex's memory traffic (the next hit's shading
 * record) overlap the other lanes' work. */
void hush__integrator_trace_block(const hush_integrator *it, hush_vec3 eye,
                                  const float d[HUSH_PACKET][3], const hush_hit hits[HUSH_PACKET],
                                  const hush_rand rng[HUSH_PACKET], const uint32_t x[HUSH_PACKET],
                                  const uint32_t y[HUSH_PACKET], uint32_t lanes,
                                  hush_first_hit first[HUSH_PACKET],
                                  hush_path_result out[HUSH_PACKET]);

/* The first hit of visibility sample (triangle, u, v) at the scene's
 * current frame, seen from eye: what a forward-projected sample needs to be
 * re-shaded. Returns 0 if the point coincides with the eye. */
int hush__integrator_first_hit(const hush_integrator *it, hush_vec3 eye, uint32_t triangle, float u,
                               float v, hush_first_hit *first);

/* Shades a given first hit from eye with the numbers of rng (which may
 * belong to another frame and pixel). Does not trace the primary ray. */
void hush__integrator_shade(const hush_integrator *it, hush_vec3 eye, const hush_first_hit *first,
                            const hush_rand *rng, uint32_t x, uint32_t y, hush_path_result *out);

#endif
