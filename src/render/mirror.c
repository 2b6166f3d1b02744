/*
 * mirror.c — primary surface replacement through planar mirrors (see
 * mirror.h): the camera ray followed through the mirrors it meets first,
 * the reflections composed into one affine map.
 */
#include "render/mirror.h"

static void map_identity(hush_mirror_map *m) {
  m->a[0] = hush_v3(1.0f, 0.0f, 0.0f);
  m->a[1] = hush_v3(0.0f, 1.0f, 0.0f);
  m->a[2] = hush_v3(0.0f, 0.0f, 1.0f);
  m->b = hush_v3(0.0f, 0.0f, 0.0f);
}

/* m after the reflection about the plane through q with unit normal n:
 * x -> m(x - 2 ((x - q) . n) n). */
static void map_reflect(hush_mirror_map *m, hush_vec3 q, hush_vec3 n) {
  const hush_vec3 an = hush__mirror_map_dir(m, n);
  for (int r = 0; r < 3; r++) {
    const float c = 2.0f * (r == 0 ? an.x : r == 1 ? an.y : an.z);
    m->a[r] = hush_v3_sub(m->a[r], hush_v3_scale(n, c));
  }
  m->b = hush_v3_add(m->b, hush_v3_scale(an, 2.0f * hush_v3_dot(q, n)));
}

int hush__mirror_replace_primary(const hush_render_ctx *ctx, const hush_first_hit *f,
                                 hush_first_hit *g, float reflectance[3], hush_mirror_map *mm) {
  const int limit = ctx->params.mirror_depth < ctx->it.bounces ? ctx->params.mirror_depth
                                                                : ctx->it.bounces;
  /* the usual pixel returns here, before the copy */
  if (limit <= 0 || f->kind != HUSH_FIRST_TRIANGLE ||
      !hush__integrator_planar_mirror(&ctx->it, &f->surface, f->hit.triangle))
    return 0;
  *g = *f;
  reflectance[0] = reflectance[1] = reflectance[2] = 1.0f;
  map_identity(mm);
  mm->count = 0;
  hush_vec3 q, n;
  for (uint32_t tri = g->hit.triangle;
       mm->count < limit && hush__integrator_mirror_step(&ctx->it, g, reflectance, &q, &n);
       tri = g->hit.triangle) {
    map_reflect(mm, q, n);
    mm->triangle[mm->count++] = tri;
  }
  return mm->count;
}

int hush__mirror_map_at(const hush_scene *scene, const hush_mirror_map *mm, uint32_t frame,
                        hush_mirror_map *out) {
  int animated = 0;
  for (int k = 0; k < mm->count; k++)
    animated |= scene->objects[scene->triangle_object[mm->triangle[k]]].motion.animated;
  if (!animated) return 0;
  map_identity(out);
  for (int k = 0; k < mm->count; k++) {
    const uint32_t t = mm->triangle[k];
    const hush_vec3 a = hush__scene_point(scene, t, 0.0f, 0.0f, frame);
    const hush_vec3 b = hush__scene_point(scene, t, 1.0f, 0.0f, frame);
    const hush_vec3 c = hush__scene_point(scene, t, 0.0f, 1.0f, frame);
    const hush_vec3 n = hush_v3_cross(hush_v3_sub(b, a), hush_v3_sub(c, a));
    const float len = hush_v3_length(n);
    if (!(len > 0.0f)) return 0;
    map_reflect(out, a, hush_v3_scale(n, 1.0f / len));
    out->triangle[k] = t;
  }
  out->count = mm->count;
  return 1;
}
