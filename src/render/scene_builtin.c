/*
 * scene_builtin.c — procedural scenes that need no files, for tests, demos
 * and the temporal-filter experiments ("builtin:NAME" on the command line).
 * World units are metres, +Y up. Every face is built with its normal facing
 * the side meant to be seen, with per-vertex normals and uvs.
 */
#include "render/scene.h"

#include "core/device.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

const char *const hush__scene_builtin_names[] = {
    "cornell",    "cornell-moving", "cornell-mirror", "courtyard", "moving-light",
    "light-off",  "mirror-light-off", "light-jump",   "furnace",   "mask",
    NULL};

const char *const hush__scene_builtin_docs[] = {
    "the Cornell box: white floor, ceiling and back wall, red left and green right wall, two "
    "boxes, a small emissive quad under the ceiling",
    "the Cornell box with the short box sliding back and forth along x (0.025 m per frame, "
    "period 40 frames)",
    "cornell-moving with a mirror on the back wall (x -0.2 to 0.9, y 0.15 to 1.85): the "
    "G-buffer's primary surface replacement sees the room and the lamp in it",
    "a courtyard: checkered ground texture, pillars, glossy plastic, a rough metal sphere, a glass "
    "sphere, a moving box, a small sphere light moving back and forth and a dim sky",
    "the courtyard with nothing moving but the sphere light",
    "the courtyard with everything still and the sphere light switched off from frame 8",
    "light-off with a mirror standing behind the last pillars (x -2.6 to 2.6, y 0 to 2.9, z "
    "-6.6, facing the camera): the light going off, seen in a mirror",
    "the courtyard with everything still and the sphere light jumping at frame 8 from the "
    "left of the roof's middle to its front right (2.2 m right, 2.5 m forward)",
    "a Lambert sphere of albedo 0.8 inside a uniform environment of radiance 1 (the furnace "
    "test: the sphere converges to 0.8, the background to 1)",
    "an alpha-masked quad (opaque right half, a hole in the left half) in front of a white wall",
    NULL};

#define DEG2RAD 0.017453292519943295f

/* ------------------------------------------------------------------------ */
/* A growing scene                                                          */
/* ------------------------------------------------------------------------ */

typedef struct builder {
  hush_scene *s;
  uint32_t vcap, tcap, ocap, mcap, xcap;
  uint32_t object;  /* the object triangles go to */
  int failed;       /* out of memory: every later call does nothing */
} builder;

static int grow(void **p, uint32_t need, uint32_t *cap, size_t elem, int commit) {
  if (need <= *cap) return 1;
  uint32_t n = *cap ? *cap : 16;
  while (n < need) n *= 2;
  void *q = realloc(*p, (size_t)n * elem);
  if (!q) return 0;
  *p = q;
  if (commit) *cap = n;
  return 1;
}

static int reserve_vertices(builder *b, uint32_t extra) {
  hush_scene *s = b->s;
  const uint32_t need = s->vertex_count + extra;
  uint32_t cap = b->vcap;
  if (!grow((void **)&s->positions, need, &cap, 3 * sizeof(float), 0) ||
      !grow((void **)&s->normals, need, &cap, 3 * sizeof(float), 0) ||
      !grow((void **)&s->uvs, need, &cap, 2 * sizeof(float), 1))
    return 0;
  b->vcap = cap;
  return 1;
}

static int reserve_triangles(builder *b, uint32_t extra) {
  hush_scene *s = b->s;
  const uint32_t need = s->triangle_count + extra;
  uint32_t cap = b->tcap;
  if (!grow((void **)&s->indices, need, &cap, 3 * sizeof(uint32_t), 0) ||
      !grow((void **)&s->triangle_material, need, &cap, sizeof(uint32_t), 0) ||
      !grow((void **)&s->triangle_object, need, &cap, sizeof(uint32_t), 1))
    return 0;
  b->tcap = cap;
  return 1;
}

static uint32_t add_vertex(builder *b, hush_vec3 p, hush_vec3 n, float u, float v) {
  if (b->failed || !reserve_vertices(b, 1)) {
    b->failed = 1;
    return 0;
  }
  hush_scene *s = b->s;
  const uint32_t i = s->vertex_count++;
  float *pp = s->positions + 3 * (size_t)i, *nn = s->normals + 3 * (size_t)i;
  pp[0] = p.x, pp[1] = p.y, pp[2] = p.z;
  nn[0] = n.x, nn[1] = n.y, nn[2] = n.z;
  s->uvs[2 * (size_t)i] = u;
  s->uvs[2 * (size_t)i + 1] = v;
  return i;
}

static void add_triangle(builder *b, uint32_t i0, uint32_t i1, uint32_t i2, uint32_t material) {
  if (b->failed || !reserve_triangles(b, 1)) {
    b->failed = 1;
    return;
  }
  hush_scene *s = b->s;
  const uint32_t t = s->triangle_count++;
  s->indices[3 * (size_t)t] = i0;
  s->indices[3 * (size_t)t + 1] = i1;
  s->indices[3 * (size_t)t + 2] = i2;
  s->triangle_material[t] = material;
  s->triangle_object[t] = b->object;
  if (s->materials[material].emission[0] > 0.0f || s->materials[material].emission[1] > 0.0f ||
      s->materials[material].emission[2] > 0.0f)
    s->emissive_triangles++;
  s->objects[b->object].triangle_count++;
}

static void begin_object(builder *b, const char *name, const hush_motion *motion) {
  hush_scene *s = b->s;
  if (b->failed || !grow((void **)&s->objects, s->object_count + 1, &b->ocap,
                         sizeof *s->objects, 1)) {
    b->failed = 1;
    return;
  }
  hush_object *o = &s->objects[s->object_count];
  memset(o, 0, sizeof *o);
  snprintf(o->name, sizeof o->name, "%s", name);
  o->first_triangle = s->triangle_count;
  if (motion) o->motion = *motion;
  b->object = s->object_count++;
}

static hush_material base_material(const char *name, hush_material_type type, float r, float g,
                                   float bl) {
  hush_material m;
  memset(&m, 0, sizeof m);
  snprintf(m.name, sizeof m.name, "%s", name);
  m.type = type;
  m.diffuse[0] = r, m.diffuse[1] = g, m.diffuse[2] = bl;
  m.diffuse_texture = -1;
  m.alpha_texture = -1;
  m.ior = 1.5f;
  m.opacity = 1.0f;
  m.two_sided = type != HUSH_MAT_DIELECTRIC;
  return m;
}

static uint32_t add_material(builder *b, const hush_material *m) {
  hush_scene *s = b->s;
  if (b->failed || !grow((void **)&s->materials, s->material_count + 1, &b->mcap,
                         sizeof *s->materials, 1)) {
    b->failed = 1;
    return 0;
  }
  s->materials[s->material_count] = *m;
  return s->material_count++;
}

static hush_texture *add_texture(builder *b, int *index) {
  hush_scene *s = b->s;
  *index = -1;
  if (b->failed || !grow((void **)&s->textures, s->texture_count + 1, &b->xcap,
                         sizeof *s->textures, 1)) {
    b->failed = 1;
    return NULL;
  }
  hush_texture *t = &s->textures[s->texture_count];
  memset(t, 0, sizeof *t);
  *index = (int)s->texture_count++;
  return t;
}

/* ------------------------------------------------------------------------ */
/* Shapes                                                                   */
/* ------------------------------------------------------------------------ */

/* A planar quad p0 p1 p2 p3, counter-clockwise seen from its front; uvs run
 * 0..us along p0->p1 and 0..vs along p0->p3. */
static void add_quad(builder *b, hush_vec3 p0, hush_vec3 p1, hush_vec3 p2, hush_vec3 p3,
                     uint32_t material, float us, float vs) {
  const hush_vec3 n =
      hush_v3_normalize(hush_v3_cross(hush_v3_sub(p1, p0), hush_v3_sub(p3, p0)));
  const uint32_t a = add_vertex(b, p0, n, 0.0f, 0.0f);
  const uint32_t c = add_vertex(b, p1, n, us, 0.0f);
  const uint32_t d = add_vertex(b, p2, n, us, vs);
  const uint32_t e = add_vertex(b, p3, n, 0.0f, vs);
  add_triangle(b, a, c, d, material);
  add_triangle(b, a, d, e, material);
}

/* An axis-aligned box of half extents h, turned by rot_deg about +Y, with
 * its bottom at center.y - h.y; faces point outwards. */
static void add_box(builder *b, hush_vec3 center, hush_vec3 h, float rot_deg, uint32_t material) {
  const float c = cosf(rot_deg * DEG2RAD), s = sinf(rot_deg * DEG2RAD);
  hush_vec3 p[8];
  for (int i = 0; i < 8; i++) {
    const float x = (i & 1) ? h.x : -h.x, y = (i & 2) ? h.y : -h.y, z = (i & 4) ? h.z : -h.z;
    p[i] = hush_v3(center.x + c * x + s * z, center.y + y, center.z - s * x + c * z);
  }
  add_quad(b, p[4], p[5], p[7], p[6], material, 1, 1); /* +z */
  add_quad(b, p[1], p[0], p[2], p[3], material, 1, 1); /* -z */
  add_quad(b, p[5], p[1], p[3], p[7], material, 1, 1); /* +x */
  add_quad(b, p[0], p[4], p[6], p[2], material, 1, 1); /* -x */
  add_quad(b, p[6], p[7], p[3], p[2], material, 1, 1); /* +y */
  add_quad(b, p[0], p[1], p[5], p[4], material, 1, 1); /* -y */
}

/* A UV sphere with smooth normals; the pole rows are single triangles so
 * none is degenerate. */
static void add_sphere(builder *b, hush_vec3 center, float radius, uint32_t material) {
  const int rings = 24, segs = 48;
  const uint32_t first = b->s->vertex_count;
  for (int r = 0; r <= rings; r++) {
    const float th = (float)r / (float)rings * 3.14159265f;
    for (int k = 0; k <= segs; k++) {
      const float ph = (float)k / (float)segs * 6.2831853f;
      const hush_vec3 n = hush_v3(sinf(th) * cosf(ph), cosf(th), -sinf(th) * sinf(ph));
      add_vertex(b, hush_v3_add(center, hush_v3_scale(n, radius)), n, (float)k / (float)segs,
                 1.0f - (float)r / (float)rings);
    }
  }
  for (int r = 0; r < rings; r++) {
    for (int k = 0; k < segs; k++) {
      const uint32_t a = first + (uint32_t)(r * (segs + 1) + k), c = a + (uint32_t)segs + 1;
      if (r > 0) add_triangle(b, a, c, a + 1, material);
      if (r < rings - 1) add_triangle(b, a + 1, c, c + 1, material);
    }
  }
}

static void set_camera(hush_scene *s, hush_vec3 pos, hush_vec3 target, float fov_y,
                       uint32_t width, uint32_t height) {
  s->camera.position[0] = pos.x, s->camera.position[1] = pos.y, s->camera.position[2] = pos.z;
  s->camera.target[0] = target.x, s->camera.target[1] = target.y, s->camera.target[2] = target.z;
  s->camera.up[0] = 0.0f, s->camera.up[1] = 1.0f, s->camera.up[2] = 0.0f;
  s->camera.fov_deg = fov_y;
  s->camera_fov_axis_x = 0;
  s->width = width;
  s->height = height;
}

/* ------------------------------------------------------------------------ */
/* The scenes                                                               */
/* ------------------------------------------------------------------------ */

/* A planar mirror (a smooth conductor of reflectance 0.9, which primary
 * surface replacement sees through) facing +z: x in [x0, x1], y in [y0, y1]
 * at z; its own object "mirror" (static; a test may animate it), so the
 * caller begins a new object after it. */
static void add_mirror(builder *b, float x0, float x1, float y0, float y1, float z) {
  begin_object(b, "mirror", NULL);
  hush_material m = base_material("mirror", HUSH_MAT_CONDUCTOR, 0.0f, 0.0f, 0.0f);
  m.specular[0] = m.specular[1] = m.specular[2] = 0.9f;
  const uint32_t silver = add_material(b, &m);
  add_quad(b, hush_v3(x0, y0, z), hush_v3(x1, y0, z), hush_v3(x1, y1, z), hush_v3(x0, y1, z),
           silver, 1, 1);
}

/* The box spans x, z in [-1, 1] and y in [0, 2], open towards +z; the camera
 * looks down -z along x = 0, y = 1, which no box blocks. */
static void build_cornell(builder *b, int moving, int mirror) {
  hush_scene *s = b->s;
  hush_material m = base_material("white", HUSH_MAT_DIFFUSE, 0.725f, 0.71f, 0.68f);
  const uint32_t white = add_material(b, &m);
  m = base_material("red", HUSH_MAT_DIFFUSE, 0.63f, 0.065f, 0.05f);
  const uint32_t red = add_material(b, &m);
  m = base_material("green", HUSH_MAT_DIFFUSE, 0.14f, 0.45f, 0.091f);
  const uint32_t green = add_material(b, &m);
  m = base_material("light", HUSH_MAT_DIFFUSE, 0.78f, 0.78f, 0.78f);
  m.emission[0] = 17.0f, m.emission[1] = 12.0f, m.emission[2] = 4.0f;
  const uint32_t light = add_material(b, &m);

  begin_object(b, "room", NULL);
  add_quad(b, hush_v3(-1, 0, 1), hush_v3(1, 0, 1), hush_v3(1, 0, -1), hush_v3(-1, 0, -1), white, 1,
           1); /* floor, +y */
  add_quad(b, hush_v3(-1, 2, -1), hush_v3(1, 2, -1), hush_v3(1, 2, 1), hush_v3(-1, 2, 1), white, 1,
           1); /* ceiling, -y */
  add_quad(b, hush_v3(-1, 0, -1), hush_v3(1, 0, -1), hush_v3(1, 2, -1), hush_v3(-1, 2, -1), white,
           1, 1); /* back wall, +z */
  add_quad(b, hush_v3(-1, 0, 1), hush_v3(-1, 0, -1), hush_v3(-1, 2, -1), hush_v3(-1, 2, 1), red, 1,
           1); /* left wall, +x */
  add_quad(b, hush_v3(1, 0, -1), hush_v3(1, 0, 1), hush_v3(1, 2, 1), hush_v3(1, 2, -1), green, 1,
           1); /* right wall, -x */
  add_box(b, hush_v3(-0.45f, 0.6f, -0.35f), hush_v3(0.28f, 0.6f, 0.28f), 17.0f, white);
  if (!moving) add_box(b, hush_v3(0.4f, 0.3f, 0.4f), hush_v3(0.3f, 0.3f, 0.3f), -18.0f, white);
  if (mirror) add_mirror(b, -0.2f, 0.9f, 0.15f, 1.85f, -0.995f);
  begin_object(b, "light", NULL);
  add_quad(b, hush_v3(-0.235f, 1.98f, -0.19f), hush_v3(0.235f, 1.98f, -0.19f),
           hush_v3(0.235f, 1.98f, 0.19f), hush_v3(-0.235f, 1.98f, 0.19f), light, 1, 1);
  if (moving) {
    hush_motion mo;
    memset(&mo, 0, sizeof mo);
    mo.animated = 1;
    mo.velocity[0] = -0.025f;
    mo.period = 40;
    begin_object(b, "short box", &mo);
    add_box(b, hush_v3(0.4f, 0.3f, 0.4f), hush_v3(0.3f, 0.3f, 0.3f), -18.0f, white);
  }
  set_camera(s, hush_v3(0, 1, 3.4f), hush_v3(0, 1, 0), 40.0f, 512, 512);
}

/* A checkerboard with thin stripes, 64x64 texels, sRGB-like values already
 * linear: two checker tiles per texture repeat. */
static int checker_texture(builder *b) {
  int index;
  hush_texture *t = add_texture(b, &index);
  if (!t || hush__texture_init(NULL, t, "checker", 64, 64, 3) != HUSH_OK) {
    b->failed = 1;
    return -1;
  }
  for (uint32_t y = 0; y < 64; y++) {
    for (uint32_t x = 0; x < 64; x++) {
      const int check = ((x / 32) + (y / 32)) & 1;
      const int stripe = (x % 32) < 2 || (y % 32) < 2;
      float *p = t->texels + 3 * ((size_t)y * 64 + x);
      const float v = stripe ? 0.05f : check ? 0.7f : 0.35f;
      p[0] = v;
      p[1] = check && !stripe ? v * 0.9f : v;
      p[2] = check && !stripe ? v * 0.75f : v;
    }
  }
  return index;
}

enum {
  COURTYARD_ALL = 0,
  COURTYARD_LIGHT_MOVES = 1,
  COURTYARD_LIGHT_OFF = 2,
  COURTYARD_LIGHT_JUMPS = 3
};

static void build_courtyard(builder *b, int variant, int mirror) {
  hush_scene *s = b->s;
  const int tex = checker_texture(b);
  hush_material m = base_material("ground", HUSH_MAT_DIFFUSE, 0.5f, 0.5f, 0.5f);
  m.diffuse_texture = tex;
  const uint32_t ground = add_material(b, &m);
  m = base_material("stone", HUSH_MAT_DIFFUSE, 0.6f, 0.55f, 0.5f);
  const uint32_t stone = add_material(b, &m);
  m = base_material("red plastic", HUSH_MAT_PLASTIC, 0.6f, 0.08f, 0.05f);
  m.specular[0] = m.specular[1] = m.specular[2] = 0.04f;
  m.roughness = 0.05f;
  const uint32_t plastic = add_material(b, &m);
  m = base_material("blue plastic", HUSH_MAT_PLASTIC, 0.1f, 0.2f, 0.6f);
  m.specular[0] = m.specular[1] = m.specular[2] = 0.04f;
  const uint32_t smooth_plastic = add_material(b, &m);
  m = base_material("gold", HUSH_MAT_CONDUCTOR, 0.0f, 0.0f, 0.0f);
  m.specular[0] = 1.0f, m.specular[1] = 0.78f, m.specular[2] = 0.34f;
  m.roughness = 0.2f;
  const uint32_t metal = add_material(b, &m);
  m = base_material("glass", HUSH_MAT_DIELECTRIC, 0.0f, 0.0f, 0.0f);
  m.specular[0] = m.specular[1] = m.specular[2] = 1.0f;
  m.opacity = 0.0f;
  const uint32_t glass = add_material(b, &m);

  begin_object(b, "ground", NULL);
  add_quad(b, hush_v3(-20, 0, 20), hush_v3(20, 0, 20), hush_v3(20, 0, -20), hush_v3(-20, 0, -20),
           ground, 20, 20);
  begin_object(b, "pillars", NULL);
  for (int i = 0; i < 5; i++) {
    for (int side = -1; side <= 1; side += 2) {
      add_box(b, hush_v3(3.0f * (float)side, 1.5f, -6.0f + 2.5f * (float)i),
              hush_v3(0.25f, 1.5f, 0.25f), 0.0f, stone);
    }
  }
  /* a roof over the pillars: light comes in from the sides and bounces */
  add_box(b, hush_v3(0, 3.1f, -1.0f), hush_v3(3.3f, 0.1f, 5.3f), 0.0f, stone);
  if (mirror) add_mirror(b, -2.6f, 2.6f, 0.02f, 2.9f, -6.6f);
  begin_object(b, "props", NULL);
  add_box(b, hush_v3(-1.2f, 0.4f, -2.0f), hush_v3(0.4f, 0.4f, 0.4f), 25.0f, plastic);
  add_box(b, hush_v3(1.5f, 0.6f, -4.0f), hush_v3(0.5f, 0.6f, 0.3f), -10.0f, smooth_plastic);
  add_sphere(b, hush_v3(1.2f, 0.6f, -1.0f), 0.6f, metal);
  add_sphere(b, hush_v3(-0.3f, 0.45f, 0.8f), 0.45f, glass);

  hush_motion mo;
  memset(&mo, 0, sizeof mo);
  mo.animated = variant == COURTYARD_ALL;
  mo.velocity[2] = 0.05f;
  mo.period = 60;
  begin_object(b, "moving box", &mo);
  add_box(b, hush_v3(-1.8f, 0.35f, -4.5f), hush_v3(0.35f, 0.35f, 0.35f), 40.0f, plastic);

  s->spheres = calloc(1, sizeof *s->spheres);
  if (!s->spheres) {
    b->failed = 1;
    return;
  }
  s->sphere_count = 1;
  hush_sphere_light *l = &s->spheres[0];
  l->center[0] = -1.0f, l->center[1] = 2.2f, l->center[2] = -2.5f;
  l->radius = 0.15f;
  l->radiance[0] = 120.0f, l->radiance[1] = 100.0f, l->radiance[2] = 80.0f;
  l->off_from_frame = variant == COURTYARD_LIGHT_OFF ? 8 : -1;
  if (variant == COURTYARD_LIGHT_JUMPS) {
    /* a step: the shading it lit darkens and new shading brightens in the
     * same frame (the event lag by sign, docs/eval.md "Lag") */
    l->jump[0] = 2.2f, l->jump[2] = 2.5f;
    l->jump_from_frame = 8;
  } else if (variant != COURTYARD_LIGHT_OFF) {
    l->velocity[0] = 0.08f;
    l->period = 50;
  }
  s->env.type = HUSH_ENV_CONSTANT;
  s->env.color[0] = 0.04f, s->env.color[1] = 0.05f, s->env.color[2] = 0.07f;
  s->env.texture = -1;
  s->env.scale = 1.0f;
  hush_m4_identity(s->env.to_world);
  set_camera(s, hush_v3(0.5f, 2.2f, 5.5f), hush_v3(0, 0.8f, -2.0f), 55.0f, 640, 360);
}

static void build_furnace(builder *b) {
  hush_scene *s = b->s;
  hush_material m = base_material("white", HUSH_MAT_DIFFUSE, 0.8f, 0.8f, 0.8f);
  const uint32_t white = add_material(b, &m);
  begin_object(b, "sphere", NULL);
  add_sphere(b, hush_v3(0, 0, 0), 1.0f, white);
  s->env.type = HUSH_ENV_CONSTANT;
  s->env.color[0] = s->env.color[1] = s->env.color[2] = 1.0f;
  s->env.texture = -1;
  s->env.scale = 1.0f;
  hush_m4_identity(s->env.to_world);
  set_camera(s, hush_v3(0, 0, 4), hush_v3(0, 0, 0), 40.0f, 256, 256);
}

/* A quad at z = 0 spanning x, y in [-1, 1] whose left half (x < 0) is a
 * hole, in front of a wall at z = -1. */
static void build_mask(builder *b) {
  hush_scene *s = b->s;
  int index;
  hush_texture *t = add_texture(b, &index);
  if (!t || hush__texture_init(NULL, t, "half mask", 4, 4, 1) != HUSH_OK) {
    b->failed = 1;
    return;
  }
  for (uint32_t i = 0; i < 16; i++) t->texels[i] = (i % 4) >= 2 ? 1.0f : 0.0f;
  hush_material m = base_material("leaf", HUSH_MAT_DIFFUSE, 0.2f, 0.6f, 0.1f);
  m.alpha_texture = index;
  const uint32_t leaf = add_material(b, &m);
  m = base_material("wall", HUSH_MAT_DIFFUSE, 0.8f, 0.8f, 0.8f);
  const uint32_t wall = add_material(b, &m);
  begin_object(b, "masked quad", NULL);
  /* uvs stay inside (0.1, 0.9) of the map so the wrap never blends the
   * two halves at the quad's edges */
  const hush_vec3 n = hush_v3(0, 0, 1);
  const uint32_t a = add_vertex(b, hush_v3(-1, -1, 0), n, 0.1f, 0.1f);
  const uint32_t c = add_vertex(b, hush_v3(1, -1, 0), n, 0.9f, 0.1f);
  const uint32_t d = add_vertex(b, hush_v3(1, 1, 0), n, 0.9f, 0.9f);
  const uint32_t e = add_vertex(b, hush_v3(-1, 1, 0), n, 0.1f, 0.9f);
  add_triangle(b, a, c, d, leaf);
  add_triangle(b, a, d, e, leaf);
  begin_object(b, "wall", NULL);
  add_quad(b, hush_v3(-3, -3, -1), hush_v3(3, -3, -1), hush_v3(3, 3, -1), hush_v3(-3, 3, -1), wall,
           1, 1);
  s->env.type = HUSH_ENV_CONSTANT;
  s->env.color[0] = s->env.color[1] = s->env.color[2] = 1.0f;
  s->env.texture = -1;
  s->env.scale = 1.0f;
  hush_m4_identity(s->env.to_world);
  set_camera(s, hush_v3(0, 0, 3), hush_v3(0, 0, 0), 60.0f, 256, 256);
}

hush_status hush__scene_builtin(hush_device device, const char *name, hush_scene *scene) {
  if (!scene) return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "scene is NULL");
  memset(scene, 0, sizeof *scene);
  scene->env.texture = -1;
  if (!name) return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "scene name is NULL");
  builder b;
  memset(&b, 0, sizeof b);
  b.s = scene;
  snprintf(scene->name, sizeof scene->name, "%s", name);
  scene->two_sided = 1;
  if (strcmp(name, "cornell") == 0) build_cornell(&b, 0, 0);
  else if (strcmp(name, "cornell-moving") == 0) build_cornell(&b, 1, 0);
  else if (strcmp(name, "cornell-mirror") == 0) build_cornell(&b, 1, 1);
  else if (strcmp(name, "courtyard") == 0) build_courtyard(&b, COURTYARD_ALL, 0);
  else if (strcmp(name, "moving-light") == 0) build_courtyard(&b, COURTYARD_LIGHT_MOVES, 0);
  else if (strcmp(name, "light-off") == 0) build_courtyard(&b, COURTYARD_LIGHT_OFF, 0);
  else if (strcmp(name, "mirror-light-off") == 0) build_courtyard(&b, COURTYARD_LIGHT_OFF, 1);
  else if (strcmp(name, "light-jump") == 0) build_courtyard(&b, COURTYARD_LIGHT_JUMPS, 0);
  else if (strcmp(name, "furnace") == 0) build_furnace(&b);
  else if (strcmp(name, "mask") == 0) build_mask(&b);
  else {
    char list[256] = "";
    for (int i = 0; hush__scene_builtin_names[i]; i++) {
      if (i) strncat(list, ", ", sizeof list - strlen(list) - 1);
      strncat(list, hush__scene_builtin_names[i], sizeof list - strlen(list) - 1);
    }
    return hush__fail(device, HUSH_ERROR_NOT_FOUND, "no built-in scene '%s' (there are: %s)", name,
                      list);
  }
  if (b.failed) {
    hush__scene_free(scene);
    return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory building scene '%s'", name);
  }
  return HUSH_OK;
}
