/*
 * mirror.h — primary surface replacement through planar mirrors (NRD's
 * "PSR"; docs/renderer.md): where a camera ray meets a planar mirror, the
 * G-buffer describes the hit behind it, in the mirrors' virtual world. The
 * renderer's G-buffer (render.c) and A-SVGF's gradient samples
 * (gradients.c) both see a mirror pixel through this.
 */
#ifndef HUSH_RENDER_MIRROR_H
#define HUSH_RENDER_MIRROR_H

#include "core/vecmath.h"
#include "render/render.h"

/* The map from the world to the virtual world seen through planar mirrors:
 * x -> a x + b, the composition of the mirrors' reflections in the order
 * the camera ray meets them. */
typedef struct hush_mirror_map {
  hush_vec3 a[3]; /* rows */
  hush_vec3 b;
  /* the mirrors' triangles, in the order the camera ray met them */
  uint32_t triangle[HUSH_RENDER_MIRROR_DEPTH_MAX];
  int count;
} hush_mirror_map;

static inline hush_vec3 hush__mirror_map_dir(const hush_mirror_map *m, hush_vec3 v) {
  return hush_v3(hush_v3_dot(m->a[0], v), hush_v3_dot(m->a[1], v), hush_v3_dot(m->a[2], v));
}

static inline hush_vec3 hush__mirror_map_point(const hush_mirror_map *m, hush_vec3 p) {
  return hush_v3_add(hush__mirror_map_dir(m, p), m->b);
}

/* The hit g the G-buffer describes behind the planar mirrors that the
 * first hit f leads to (at most ctx's mirror_depth and bounces of them),
 * the mirrors' reflectance and the map into their virtual world at ctx's
 * frame. Returns the number of mirrors; 0 (f is no planar mirror, or
 * replacement is off): g, reflectance and mm are not set. */
int hush__mirror_replace_primary(const hush_render_ctx *ctx, const hush_first_hit *f,
                                 hush_first_hit *g, float reflectance[3], hush_mirror_map *mm);

/* The map of the same mirrors (mm's triangles) at scene frame `frame`,
 * their planes taken from their triangles there, into *out. Returns 0 and
 * leaves *out alone when none of them is on an animated object: the map is
 * then mm at every frame. */
int hush__mirror_map_at(const hush_scene *scene, const hush_mirror_map *mm, uint32_t frame,
                        hush_mirror_map *out);

#endif
