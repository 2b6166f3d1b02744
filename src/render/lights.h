/*
 * lights.h — light sampling for next-event estimation and the light-side
 * densities for multiple importance sampling (bmfr-koskela-2019.md §3.1:
 * "one shadow ray towards a random point in one random light source",
 * combined with the BSDF-sampled ray by MIS).
 *
 * Light groups, one of which is picked per shadow ray with probability
 * 0.5 * (its share of the estimated power) + 0.5 / (number of groups):
 *   - emissive triangles (one group; inside it a triangle by area * luminance(Ke),
 *     then a uniform point on it, at the current frame's transform);
 *   - each sphere light (uniform direction in the cone of its visible cap);
 *   - the environment: CONSTANT (cosine-free uniform sphere), MAP (2D
 *     piecewise-constant distribution over the lat-long texels, weighted by
 *     luminance * sin(theta)), or the sky of SUNSKY (a tabulated Preetham
 *     sky, sampled the same way);
 *   - the sun disc of SUNSKY (uniform in its cone).
 * docs/renderer.md documents the sun-and-sky model.
 */
#ifndef HUSH_RENDER_LIGHTS_H
#define HUSH_RENDER_LIGHTS_H

#include "hush.h"
#include "core/hmath.h"
#include "render/scene.h"

#include <stdint.h>

/* A lat-long map with its sampling tables (the MAP environment, or the
 * tabulated sky). Texel (x, y), row 0 at the top (theta = 0: local +Y). */
typedef struct hush_envmap {
  uint32_t width, height;
  /* width * height * 4: radiance r, g, b (scale applied) and the texel's
   * sampling density in (u, v) (p_row * p_col * width * height; 0 for a
   * black map), side by side so that a lookup reads one cache line */
  float *texels;
  float *row_cdf;          /* height + 1 */
  float *col_cdf;          /* height * (width + 1) */
  uint32_t *row_guide;     /* height: where to start looking in row_cdf for u in [k/h, (k+1)/h) */
  uint32_t *col_guide;     /* height * width: the same for each row's col_cdf */
  float total;             /* sum of the weights (0: a black map) */
  float to_world[9];       /* local -> world rotation, row-major 3x3 */
  int identity;            /* to_world is the identity (the sky): no rotation */
} hush_envmap;

/* Preetham sky for one sun position and turbidity: everything of the model
 * that does not depend on the view direction, computed once, so that an
 * evaluation costs one acosf and six expf. */
typedef struct hush_sky_model {
  hush_vec3 sun_dir;       /* towards the sun (world) */
  float coef[3][5];        /* Perez coefficients of Y, x and y */
  float zenith[3];         /* Y, x, y at the zenith over the Perez value there */
} hush_sky_model;

/* The sky model as two 1D tables, for escaped rays and light samples: the
 * Perez function is a product of a factor of cos(theta) (zenith scale
 * included) and a factor of the angle gamma to the sun, each tabulated with
 * HUSH_SKY_TABLE steps and interpolated linearly (no acos, no exp per
 * lookup). The gamma factor is tabulated over t = sqrt((1 - cos gamma) / 2)
 * = sin(gamma / 2), in which it is smooth near the sun. Max relative error
 * against hush__sky_model_eval: see docs/renderer.md. */
#define HUSH_SKY_TABLE 1024
typedef struct hush_sky_table {
  float theta[HUSH_SKY_TABLE + 1][3]; /* zenith[k] (1 + c0 exp(c1 / cos theta)), cos theta in [0, 1] */
  float gamma[HUSH_SKY_TABLE + 1][3]; /* 1 + c2 exp(c3 gamma) + c4 cos^2 gamma, t in [0, 1] */
  hush_vec3 sun_dir;
} hush_sky_table;

typedef struct hush_lights {
  /* emissive triangles */
  uint32_t tri_count;
  uint32_t *tris;          /* global triangle indices */
  float *tri_cdf;          /* tri_count + 1 */
  float *tri_pmf;          /* per GLOBAL triangle: probability within the group (0: not a light) */
  float tri_power;
  float *tri_front;        /* tri_count (tris' order): +1 or -1, the sign that turns the
                            * winding normal to the emitting side; 0: both sides emit */
  /* the environment (NONE, CONSTANT, MAP, SUNSKY) */
  hush_env_type env_type;
  float env_color[3];      /* CONSTANT */
  hush_envmap map;         /* MAP, or the sky of SUNSKY */
  hush_vec3 sun_dir;       /* SUNSKY: towards the sun (world) */
  hush_vec3 sun_t, sun_b;  /* SUNSKY: tangent frame around sun_dir (cone samples) */
  float sun_one_minus_cos; /* SUNSKY: 1 - sun_cos_max */
  hush_sky_model sky;      /* SUNSKY: the sky (sky_scale not applied) */
  hush_sky_table *sky_table; /* SUNSKY: the same, tabulated (owned) */
  float sky_scale;
  float sun_cos_max;       /* cosine of the (scaled) sun's angular radius */
  float sun_radiance[3];   /* radiance of the disc */
  float scene_radius;      /* for the power estimate of distant lights */
  hush_vec3 scene_center;
  /* group selection, set per frame (spheres switch off) */
  uint32_t group_count;    /* 0: no light */
  float p_tris, p_env, p_sun;
  float *p_sphere;         /* per sphere light */
  uint32_t sphere_count;   /* the scene's, kept here: the hot path reads no scene field */
  const hush_scene *scene;
  uint32_t frame;
} hush_lights;

/* Builds the sampling tables (once per scene, after loading). */
hush_status hush__lights_init(hush_device device, hush_lights *lights, const hush_scene *scene);
void hush__lights_free(hush_lights *lights);
/* Sets the group probabilities for frame f (sphere lights move and switch off). */
void hush__lights_set_frame(hush_lights *lights, uint32_t frame);
/* Whether the scene has any light at this frame. */
int hush__lights_any(const hush_lights *lights);

typedef struct hush_light_sample {
  hush_vec3 wi;            /* unit, from the shading point towards the light */
  float dist;              /* distance to the light point; INFINITY for distant lights */
  float radiance[3];       /* emitted radiance towards the point */
  float pdf;               /* solid angle, including the group choice */
  int delta;               /* never set now: every light has area */
  int deferred;            /* hush__lights_sample_deferred: 1 radiance not set yet,
                            * 2 nor pdf (a sun sample: pdf > 0 for sure) */
} hush_light_sample;

/* Draws a light and a point on it for the shading point p, from u in [0,1)^3.
 * Returns 0 if nothing was drawn (no light, or the point faces away). */
int hush__lights_sample(const hush_lights *lights, hush_vec3 p, const float u[3],
                        hush_light_sample *s);
/* The same draw, but the radiance of a sun or sky sample (the sky model:
 * the costly part, wasted on a blocked shadow ray) is left for
 * hush__lights_sample_finish: s->deferred is 1 and s->radiance not set. It
 * returns 0 where hush__lights_sample's radiance would be exactly 0 for
 * want of light (a sky direction below the horizon outside the sun), so
 * a caller that skips zero radiance skips the same samples. A sun sample's
 * density (a map lookup for the sky's share) is deferred too. Finishing
 * gives hush__lights_sample's radiance and pdf bit for bit. */
int hush__lights_sample_deferred(const hush_lights *lights, hush_vec3 p, const float u[3],
                                 hush_light_sample *s);
void hush__lights_sample_finish(const hush_lights *lights, hush_light_sample *s);

/* Radiance of the environment (sky, map or constant, and the sun disc) along d. */
void hush__lights_env_radiance(const hush_lights *lights, hush_vec3 d, float out[3]);
/* Both at once: the radiance along d into out, and returns the density of
 * hush__lights_env_pdf (one map lookup instead of two). */
float hush__lights_env_eval(const hush_lights *lights, hush_vec3 d, float out[3]);
/* The solid-angle density with which hush__lights_sample picks direction d
 * on the environment (sky and sun together). */
float hush__lights_env_pdf(const hush_lights *lights, hush_vec3 d);
/* Density for a hit on emissive triangle `tri` at distance dist, with
 * |cos| between the ray and the light's normal cos_l, of area `area`. */
float hush__lights_triangle_pdf(const hush_lights *lights, uint32_t tri, float area, float dist,
                                float cos_l);
/* Density of sphere light i for a ray from p in direction d (0 if p lies inside). */
float hush__lights_sphere_pdf(const hush_lights *lights, uint32_t i, hush_vec3 p);

/* Area of triangle tri (object space: rigid motion keeps it). */
float hush__lights_triangle_area(const hush_scene *scene, uint32_t tri);

/* Closest sphere light (on at this frame) hit by o + t d, t in (tnear, tfar):
 * returns its index + 1 and sets *t, or 0. Inline so that the common case,
 * a scene without sphere lights, costs one compare instead of a call (it is
 * asked after every ray). */
uint32_t hush__lights_intersect_sphere_any(const hush_lights *lights, hush_vec3 o, hush_vec3 d,
                                           float tnear, float tfar, float *t);
static inline uint32_t hush__lights_intersect_sphere(const hush_lights *lights, hush_vec3 o,
                                                     hush_vec3 d, float tnear, float tfar,
                                                     float *t) {
  if (lights->sphere_count == 0) return 0;
  return hush__lights_intersect_sphere_any(lights, o, d, tnear, tfar, t);
}

/* Envmap pieces, exposed for tests: direction <-> (u, v) in the map's local
 * frame (Mitsuba's convention), texel lookup, sampling and density (solid
 * angle, world directions). */
void hush__envmap_dir_to_uv(hush_vec3 local, float *u, float *v);
hush_vec3 hush__envmap_uv_to_dir(float u, float v);
hush_status hush__envmap_build(hush_device device, hush_envmap *map, const float *rgb,
                               uint32_t width, uint32_t height, int channels, float scale,
                               const float to_world_4x4_col_major[16]);
void hush__envmap_free(hush_envmap *map);
void hush__envmap_eval(const hush_envmap *map, hush_vec3 d, float out[3]);
float hush__envmap_pdf(const hush_envmap *map, hush_vec3 d);
hush_vec3 hush__envmap_sample(const hush_envmap *map, float u1, float u2, float *pdf);

/* Preetham sky radiance (linear sRGB, Mitsuba's spectral units, sky_scale
 * not applied) for a world direction d with the sun towards sun_dir. */
void hush__preetham_sky(hush_vec3 d, hush_vec3 sun_dir, float turbidity, float out[3]);
void hush__sky_model_init(hush_sky_model *sky, hush_vec3 sun_dir, float turbidity);
void hush__sky_model_eval(const hush_sky_model *sky, hush_vec3 d, float out[3]);
/* The table of a model, and a lookup in it (what rendering uses). */
void hush__sky_table_init(hush_sky_table *t, const hush_sky_model *sky);
void hush__sky_table_eval(const hush_sky_table *t, hush_vec3 d, float out[3]);

#endif
