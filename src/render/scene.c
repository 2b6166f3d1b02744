/*
 * scene.c — the Embree side of a hush_scene: building the acceleration
 * structure, animating rigid objects frame by frame, ray queries, and the
 * surface at a hit (world-space position, normals, uvs, textured albedo).
 *
 * Layout in Embree: one top-level scene in which object o is attached with
 * geometry ID o — a triangle geometry for a static object, or an instance of
 * the object's own sub-scene for an animated one. So a hit's object is its
 * instID (or geomID when not instanced), and its global triangle is the
 * object's first_triangle + primID.
 *
 * Alpha masks: an intersection and occlusion filter on the geometries whose
 * triangles use a material with an opacity map rejects hits on texels with
 * alpha < 0.5. The filter's data holds the arrays it reads (not the
 * hush_scene), so a scene struct may be copied by value after commit.
 */
#include "render/scene.h"

#include "core/device.h"

#include <embree3/rtcore.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* What an alpha filter needs to find a triangle's material and uvs. */
typedef struct mask_data {
  uint32_t first_triangle;
  const uint32_t *indices;
  const float *uvs;
  const uint32_t *triangle_material;
  const hush_material *materials;
  const hush_texture *textures;
} mask_data;

/* Everything hush__scene_surface reads of one triangle, side by side: a hit
 * then touches two cache lines instead of the ~10 scattered ones of the
 * index, position, normal, uv, material and object arrays. Copies of the
 * same floats, so the results are bit-identical. */
typedef struct tri_record {
  float p[3][3];
  float n[3][3];           /* zero when the scene has no normals */
  float uv[3][2];          /* zero when the scene has no uvs */
  uint32_t material, object;
  uint32_t pad[6];         /* 128 bytes: two whole cache lines */
} tri_record;
_Static_assert(sizeof(tri_record) == 128, "tri_record is two cache lines");

typedef struct rtc_state {
  RTCDevice device;
  RTCScene top;
  RTCScene *sub;         /* per object: its sub-scene if animated, else NULL */
  float *vertices;       /* padded copies of the positions and indices: Embree */
  uint32_t *indices;     /* may read 16 bytes at the last element of a buffer  */
  mask_data *masks;      /* per object */
  tri_record *records;   /* per triangle, 128-byte aligned: a record is one pair of
                            lines that the adjacent-line prefetcher fetches together */
  char error[512];       /* the first Embree error, for messages */
} rtc_state;

static void on_embree_error(void *user, enum RTCError code, const char *str) {
  rtc_state *rs = user;
  if (rs->error[0]) return; /* keep the first: later ones are usually consequences */
  snprintf(rs->error, sizeof rs->error, "Embree error %d: %s", (int)code, str ? str : "");
}

static void rtc_state_free(rtc_state *rs, uint32_t object_count) {
  if (!rs) return;
  if (rs->top) rtcReleaseScene(rs->top);
  if (rs->sub) {
    for (uint32_t o = 0; o < object_count; o++)
      if (rs->sub[o]) rtcReleaseScene(rs->sub[o]);
  }
  if (rs->device) rtcReleaseDevice(rs->device);
  free(rs->sub);
  free(rs->vertices);
  free(rs->indices);
  free(rs->masks);
  free(rs->records);
  free(rs);
}

/* ------------------------------------------------------------------------ */
/* Freeing                                                                  */
/* ------------------------------------------------------------------------ */

void hush__scene_free(hush_scene *scene) {
  if (!scene) return;
  rtc_state_free(scene->rtc_data, scene->object_count);
  free(scene->positions);
  free(scene->normals);
  free(scene->uvs);
  free(scene->indices);
  free(scene->triangle_material);
  free(scene->triangle_object);
  free(scene->objects);
  free(scene->materials);
  for (uint32_t i = 0; i < scene->texture_count && scene->textures; i++)
    hush__texture_free(&scene->textures[i]);
  free(scene->textures);
  free(scene->spheres);
  free(scene->path.frames);
  free(scene->object_to_world);
  memset(scene, 0, sizeof *scene);
}

/* ------------------------------------------------------------------------ */
/* Animation                                                                */
/* ------------------------------------------------------------------------ */

/* How far along its path something is at frame f, in frames: f itself, or a
 * triangle wave 0 -> period/2 -> 0 for back-and-forth motion. */
static float travel(uint32_t frame, uint32_t period) {
  if (period == 0) return (float)frame;
  const float m = (float)(frame % period);
  const float half = 0.5f * (float)period;
  return m <= half ? m : (float)period - m;
}

void hush__scene_object_transform(const hush_scene *scene, uint32_t object, uint32_t frame,
                                  float out[16]) {
  hush_m4_identity(out);
  if (!scene || object >= scene->object_count) return;
  const hush_motion *m = &scene->objects[object].motion;
  if (!m->animated) return;
  const float s = travel(frame, m->period);
  /* spin turns forever; only the translation goes back and forth */
  const float a = (float)frame * m->spin_deg_per_frame * 0.017453292519943295f;
  const float c = cosf(a), sn = sinf(a);
  /* rotate_y about the pivot: R (x - p) + p, then translate */
  out[0] = c;
  out[2] = -sn;
  out[8] = sn;
  out[10] = c;
  const float px = m->pivot[0], pz = m->pivot[2];
  const float rx = c * px + sn * pz, rz = -sn * px + c * pz;
  out[12] = px - rx + m->translation[0] + s * m->velocity[0];
  out[13] = m->translation[1] + s * m->velocity[1];
  out[14] = pz - rz + m->translation[2] + s * m->velocity[2];
}

int hush__scene_sphere_at(const hush_scene *scene, uint32_t light, uint32_t frame,
                          float center[3]) {
  if (!scene || light >= scene->sphere_count) return 0;
  const hush_sphere_light *l = &scene->spheres[light];
  const float s = travel(frame, l->period);
  const float jumped = frame >= l->jump_from_frame ? 1.0f : 0.0f;
  for (int k = 0; k < 3; k++) center[k] = l->center[k] + s * l->velocity[k] + jumped * l->jump[k];
  return l->off_from_frame < 0 || frame < (uint32_t)l->off_from_frame;
}

/* ------------------------------------------------------------------------ */
/* Alpha masks                                                              */
/* ------------------------------------------------------------------------ */

/* 1 if the point (u, v) of global triangle tri is a hole of its mask. */
static int is_hole(const mask_data *md, uint32_t tri, float u, float v) {
  const hush_material *mat = &md->materials[md->triangle_material[tri]];
  if (mat->alpha_texture < 0 || !md->uvs) return 0;
  const uint32_t *ix = md->indices + 3 * (size_t)tri;
  const float w = 1.0f - u - v;
  const float tu = w * md->uvs[2 * ix[0]] + u * md->uvs[2 * ix[1]] + v * md->uvs[2 * ix[2]];
  const float tv =
      w * md->uvs[2 * ix[0] + 1] + u * md->uvs[2 * ix[1] + 1] + v * md->uvs[2 * ix[2] + 1];
  float a[4] = {1.0f, 1.0f, 1.0f, 1.0f};
  hush__texture_sample(&md->textures[mat->alpha_texture], tu, tv, a);
  return a[0] < 0.5f;
}

/* Embree's hit layout for N rays (rtcore_ray.h's RTCHitN accessors are C++):
 * Ng x, y, z, u, v, primID, geomID, instID, each N wide. */
static void mask_filter(const struct RTCFilterFunctionNArguments *args) {
  const mask_data *md = args->geometryUserPtr;
  const unsigned n = args->N;
  const float *hf = (const float *)args->hit;
  const unsigned *hu = (const unsigned *)args->hit;
  for (unsigned i = 0; i < n; i++) {
    if (args->valid[i] == 0) continue;
    const uint32_t tri = md->first_triangle + hu[5 * n + i];
    if (is_hole(md, tri, hf[3 * n + i], hf[4 * n + i])) args->valid[i] = 0;
  }
}

static int object_has_mask(const hush_scene *scene, const hush_object *obj) {
  for (uint32_t t = obj->first_triangle; t < obj->first_triangle + obj->triangle_count; t++)
    if (scene->materials[scene->triangle_material[t]].alpha_texture >= 0) return 1;
  return 0;
}

/* ------------------------------------------------------------------------ */
/* Building                                                                 */
/* ------------------------------------------------------------------------ */

static RTCGeometry triangle_geometry(rtc_state *rs, const hush_scene *scene, uint32_t o) {
  const hush_object *obj = &scene->objects[o];
  RTCGeometry g = rtcNewGeometry(rs->device, RTC_GEOMETRY_TYPE_TRIANGLE);
  if (!g) return NULL;
  rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, rs->vertices, 0,
                             3 * sizeof(float), scene->vertex_count);
  rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, rs->indices,
                             (size_t)obj->first_triangle * 3 * sizeof(uint32_t),
                             3 * sizeof(uint32_t), obj->triangle_count);
  mask_data *md = &rs->masks[o];
  md->first_triangle = obj->first_triangle;
  md->indices = scene->indices;
  md->uvs = scene->uvs;
  md->triangle_material = scene->triangle_material;
  md->materials = scene->materials;
  md->textures = scene->textures;
  rtcSetGeometryUserData(g, md);
  if (object_has_mask(scene, obj)) {
    rtcSetGeometryIntersectFilterFunction(g, mask_filter);
    rtcSetGeometryOccludedFilterFunction(g, mask_filter);
  }
  rtcCommitGeometry(g);
  return g;
}

/* Checks the pieces commit relies on, so a malformed scene fails with a
 * message rather than a crash inside Embree. */
static hush_status check_scene(hush_device device, const hush_scene *scene) {
  if (scene->triangle_count && (!scene->positions || !scene->indices ||
                                !scene->triangle_material || !scene->triangle_object))
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "scene '%s': geometry arrays missing",
                      scene->name);
  for (uint32_t i = 0; i < 3 * (size_t)scene->triangle_count; i++)
    if (scene->indices[i] >= scene->vertex_count)
      return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                        "scene '%s': triangle %u uses vertex %u of %u", scene->name, i / 3,
                        scene->indices[i], scene->vertex_count);
  for (uint32_t t = 0; t < scene->triangle_count; t++)
    if (scene->triangle_material[t] >= scene->material_count ||
        scene->triangle_object[t] >= scene->object_count)
      return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                        "scene '%s': triangle %u has a bad material or object", scene->name, t);
  for (uint32_t o = 0; o < scene->object_count; o++) {
    const hush_object *obj = &scene->objects[o];
    if ((uint64_t)obj->first_triangle + obj->triangle_count > scene->triangle_count)
      return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                        "scene '%s': object '%s' reaches past the last triangle", scene->name,
                        obj->name);
  }
  for (uint32_t m = 0; m < scene->material_count; m++) {
    const hush_material *mat = &scene->materials[m];
    if (mat->diffuse_texture >= (int)scene->texture_count ||
        mat->alpha_texture >= (int)scene->texture_count)
      return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                        "scene '%s': material '%s' names a missing texture", scene->name,
                        mat->name);
  }
  return HUSH_OK;
}

static hush_status embree_failed(hush_device device, const hush_scene *scene,
                                 const rtc_state *rs, const char *step) {
  return hush__fail(device, HUSH_ERROR_UNKNOWN, "scene '%s': %s failed%s%s", scene->name, step,
                    rs->error[0] ? ": " : "", rs->error);
}

static hush_status attach_object(hush_device device, rtc_state *rs, hush_scene *scene,
                                 uint32_t o) {
  RTCGeometry tris = triangle_geometry(rs, scene, o);
  if (!tris) return embree_failed(device, scene, rs, "creating a triangle geometry");
  if (!scene->objects[o].motion.animated) {
    rtcAttachGeometryByID(rs->top, tris, o);
    rtcReleaseGeometry(tris);
    return HUSH_OK;
  }
  rs->sub[o] = rtcNewScene(rs->device);
  if (!rs->sub[o]) {
    rtcReleaseGeometry(tris);
    return embree_failed(device, scene, rs, "creating an object's scene");
  }
  rtcAttachGeometryByID(rs->sub[o], tris, 0);
  rtcReleaseGeometry(tris);
  rtcCommitScene(rs->sub[o]);
  RTCGeometry inst = rtcNewGeometry(rs->device, RTC_GEOMETRY_TYPE_INSTANCE);
  if (!inst) return embree_failed(device, scene, rs, "creating an instance");
  rtcSetGeometryInstancedScene(inst, rs->sub[o]);
  rtcSetGeometryTimeStepCount(inst, 1);
  rtcSetGeometryTransform(inst, 0, RTC_FORMAT_FLOAT4X4_COLUMN_MAJOR,
                          scene->object_to_world + 16 * (size_t)o);
  rtcCommitGeometry(inst);
  rtcAttachGeometryByID(rs->top, inst, o);
  rtcReleaseGeometry(inst);
  return HUSH_OK;
}

/* Gathers triangle tri's data from the scene's arrays. */
static void fill_record(const hush_scene *scene, uint32_t tri, tri_record *r) {
  memset(r, 0, sizeof *r);
  const uint32_t *ix = scene->indices + 3 * (size_t)tri;
  for (int c = 0; c < 3; c++) {
    memcpy(r->p[c], scene->positions + 3 * (size_t)ix[c], 3 * sizeof(float));
    if (scene->normals) memcpy(r->n[c], scene->normals + 3 * (size_t)ix[c], 3 * sizeof(float));
    if (scene->uvs) memcpy(r->uv[c], scene->uvs + 2 * (size_t)ix[c], 2 * sizeof(float));
  }
  r->material = scene->triangle_material[tri];
  r->object = scene->triangle_object[tri];
}

static hush_status build(hush_device device, rtc_state *rs, hush_scene *scene) {
  char config[64];
  snprintf(config, sizeof config, "threads=%d", device ? device->threads : 0);
  rs->device = rtcNewDevice(config);
  if (!rs->device)
    return hush__fail(device, HUSH_ERROR_UNKNOWN, "scene '%s': cannot create an Embree device "
                      "(error %d)", scene->name, (int)rtcGetDeviceError(NULL));
  rtcSetDeviceErrorFunction(rs->device, on_embree_error, rs);

  const size_t nv = (size_t)scene->vertex_count * 3;
  const size_t ni = (size_t)scene->triangle_count * 3;
  rs->vertices = malloc((nv + 4) * sizeof *rs->vertices);
  rs->indices = malloc((ni + 4) * sizeof *rs->indices);
  rs->sub = calloc(scene->object_count ? scene->object_count : 1, sizeof *rs->sub);
  rs->masks = calloc(scene->object_count ? scene->object_count : 1, sizeof *rs->masks);
  scene->object_to_world =
      malloc((scene->object_count ? scene->object_count : 1) * 16 * sizeof(float));
  rs->records = aligned_alloc(128, ((size_t)scene->triangle_count + 1) * sizeof *rs->records);
  if (!rs->vertices || !rs->indices || !rs->sub || !rs->masks || !scene->object_to_world ||
      !rs->records)
    return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "scene '%s': out of memory for Embree",
                      scene->name);
  if (nv) memcpy(rs->vertices, scene->positions, nv * sizeof *rs->vertices);
  memset(rs->vertices + nv, 0, 4 * sizeof *rs->vertices);
  if (ni) memcpy(rs->indices, scene->indices, ni * sizeof *rs->indices);
  memset(rs->indices + ni, 0, 4 * sizeof *rs->indices);
  for (uint32_t t = 0; t < scene->triangle_count; t++) fill_record(scene, t, &rs->records[t]);
  scene->frame = 0;
  for (uint32_t o = 0; o < scene->object_count; o++)
    hush__scene_object_transform(scene, o, 0, scene->object_to_world + 16 * (size_t)o);

  rs->top = rtcNewScene(rs->device);
  if (!rs->top) return embree_failed(device, scene, rs, "creating the scene");
  rtcSetSceneBuildQuality(rs->top, RTC_BUILD_QUALITY_MEDIUM);
  for (uint32_t o = 0; o < scene->object_count; o++) {
    if (scene->objects[o].triangle_count == 0) continue;
    const hush_status st = attach_object(device, rs, scene, o);
    if (st != HUSH_OK) return st;
  }
  rtcCommitScene(rs->top);
  if (rs->error[0]) return embree_failed(device, scene, rs, "building the scene");
  return HUSH_OK;
}

hush_status hush__scene_commit(hush_device device, hush_scene *scene) {
  if (!scene) return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "scene is NULL");
  if (scene->rtc_data)
    return hush__fail(device, HUSH_ERROR_INVALID_OPERATION, "scene '%s' is already committed",
                      scene->name);
  hush_status st = check_scene(device, scene);
  if (st != HUSH_OK) return st;
  rtc_state *rs = calloc(1, sizeof *rs);
  if (!rs) return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory");
  st = build(device, rs, scene);
  if (st != HUSH_OK) {
    rtc_state_free(rs, scene->object_count);
    free(scene->object_to_world);
    scene->object_to_world = NULL;
    return st;
  }
  scene->rtc_data = rs;
  scene->rtc_device = rs->device;
  scene->rtc_scene = rs->top;
  return HUSH_OK;
}

hush_status hush__scene_set_frame(hush_device device, hush_scene *scene, uint32_t frame) {
  if (!scene || !scene->rtc_data)
    return hush__fail(device, HUSH_ERROR_INVALID_OPERATION, "scene is not committed");
  rtc_state *rs = scene->rtc_data;
  scene->frame = frame;
  int moved = 0;
  for (uint32_t o = 0; o < scene->object_count; o++) {
    if (!rs->sub[o]) continue;
    float *m = scene->object_to_world + 16 * (size_t)o;
    hush__scene_object_transform(scene, o, frame, m);
    RTCGeometry inst = rtcGetGeometry(rs->top, o);
    rtcSetGeometryTransform(inst, 0, RTC_FORMAT_FLOAT4X4_COLUMN_MAJOR, m);
    rtcCommitGeometry(inst);
    moved = 1;
  }
  if (moved) rtcCommitScene(rs->top);
  if (rs->error[0]) return embree_failed(device, scene, rs, "updating the scene");
  return HUSH_OK;
}

/* ------------------------------------------------------------------------ */
/* Ray queries                                                              */
/* ------------------------------------------------------------------------ */

static void set_ray(struct RTCRay *ray, const float o[3], const float d[3], float tnear,
                    float tfar) {
  ray->org_x = o[0];
  ray->org_y = o[1];
  ray->org_z = o[2];
  ray->dir_x = d[0];
  ray->dir_y = d[1];
  ray->dir_z = d[2];
  ray->tnear = tnear;
  ray->tfar = tfar;
  ray->time = 0.0f;
  ray->mask = 0xffffffffu;
  ray->id = 0;
  ray->flags = 0;
}

int hush__scene_intersect(const hush_scene *scene, const float o[3], const float d[3], float tnear,
                          float tfar, hush_hit *hit) {
  hit->triangle = UINT32_MAX;
  hit->u = hit->v = 0.0f;
  hit->t = INFINITY;
  if (!scene || !scene->rtc_scene) return 0;
  struct RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  struct RTCRayHit rh;
  set_ray(&rh.ray, o, d, tnear, tfar);
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1((RTCScene)scene->rtc_scene, &ctx, &rh);
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return 0;
  const uint32_t object =
      rh.hit.instID[0] != RTC_INVALID_GEOMETRY_ID ? rh.hit.instID[0] : rh.hit.geomID;
  if (object >= scene->object_count) return 0;
  hit->triangle = scene->objects[object].first_triangle + rh.hit.primID;
  hit->u = rh.hit.u;
  hit->v = rh.hit.v;
  hit->t = rh.ray.tfar;
  return 1;
}

void hush__scene_intersect_packet(const hush_scene *scene, const float o[3],
                                  const float d[HUSH_PACKET][3], uint32_t lanes,
                                  hush_hit hits[HUSH_PACKET]) {
  for (int i = 0; i < HUSH_PACKET; i++) {
    hits[i].triangle = UINT32_MAX;
    hits[i].u = hits[i].v = 0.0f;
    hits[i].t = INFINITY;
  }
  if (!scene || !scene->rtc_scene || !lanes) return;
  /* Embree reads packets with aligned vector loads */
  _Alignas(64) struct RTCRayHit16 rh;
  _Alignas(64) int valid[HUSH_PACKET];
  for (int i = 0; i < HUSH_PACKET; i++) {
    const int on = (lanes >> i) & 1u;
    valid[i] = on ? -1 : 0;
    rh.ray.org_x[i] = o[0];
    rh.ray.org_y[i] = o[1];
    rh.ray.org_z[i] = o[2];
    rh.ray.dir_x[i] = on ? d[i][0] : 0.0f;
    rh.ray.dir_y[i] = on ? d[i][1] : 0.0f;
    rh.ray.dir_z[i] = on ? d[i][2] : 1.0f;
    rh.ray.tnear[i] = 0.0f;
    rh.ray.tfar[i] = INFINITY;
    rh.ray.time[i] = 0.0f;
    rh.ray.mask[i] = 0xffffffffu;
    rh.ray.id[i] = (unsigned)i;
    rh.ray.flags[i] = 0;
    rh.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
    rh.hit.primID[i] = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0][i] = RTC_INVALID_GEOMETRY_ID;
  }
  struct RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  rtcIntersect16(valid, (RTCScene)scene->rtc_scene, &ctx, &rh);
  for (int i = 0; i < HUSH_PACKET; i++) {
    if (!valid[i] || rh.hit.geomID[i] == RTC_INVALID_GEOMETRY_ID) continue;
    const uint32_t object =
        rh.hit.instID[0][i] != RTC_INVALID_GEOMETRY_ID ? rh.hit.instID[0][i] : rh.hit.geomID[i];
    if (object >= scene->object_count) continue;
    hits[i].triangle = scene->objects[object].first_triangle + rh.hit.primID[i];
    hits[i].u = rh.hit.u[i];
    hits[i].v = rh.hit.v[i];
    hits[i].t = rh.ray.tfar[i];
  }
}

int hush__scene_occluded(const hush_scene *scene, const float o[3], const float d[3], float tnear,
                         float tfar) {
  if (!scene || !scene->rtc_scene) return 0;
  struct RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  struct RTCRay ray;
  set_ray(&ray, o, d, tnear, tfar);
  rtcOccluded1((RTCScene)scene->rtc_scene, &ctx, &ray);
  /* Embree sets tfar to -inf when something blocks the ray */
  return ray.tfar < 0.0f;
}

/* ------------------------------------------------------------------------ */
/* Surfaces                                                                 */
/* ------------------------------------------------------------------------ */

static hush_vec3 vertex(const hush_scene *scene, uint32_t i) {
  const float *p = scene->positions + 3 * (size_t)i;
  return hush_v3(p[0], p[1], p[2]);
}

static hush_vec3 xform_point(const float m[16], hush_vec3 p) {
  const hush_vec4 r = hush_m4_mul_v4(m, p.x, p.y, p.z, 1.0f);
  return hush_v3(r.x, r.y, r.z);
}

/* Rigid transforms only: the normal matrix is the rotation itself. */
static hush_vec3 xform_dir(const float m[16], hush_vec3 d) {
  const hush_vec4 r = hush_m4_mul_v4(m, d.x, d.y, d.z, 0.0f);
  return hush_v3(r.x, r.y, r.z);
}

static int finite3(hush_vec3 v) {
  return isfinite(v.x) && isfinite(v.y) && isfinite(v.z);
}

static const float *current_transform(const hush_scene *scene, uint32_t object, float tmp[16]) {
  if (scene->object_to_world && object < scene->object_count)
    return scene->object_to_world + 16 * (size_t)object;
  hush__scene_object_transform(scene, object, scene->frame, tmp);
  return tmp;
}

void hush__scene_surface(const hush_scene *scene, const hush_hit *hit, const float d[3],
                         hush_surface *s) {
  memset(s, 0, sizeof *s);
  const uint32_t tri = hit->triangle;
  if (!scene || tri >= scene->triangle_count) return;
  /* the committed scene's record, or one gathered now */
  const rtc_state *rs = scene->rtc_data;
  tri_record local;
  const tri_record *r = rs ? &rs->records[tri] : &local;
  if (!rs) fill_record(scene, tri, &local);
  const float u = hit->u, v = hit->v, w = 1.0f - u - v;
  const uint32_t object = r->object;
  float tmp[16];
  const float *m = current_transform(scene, object, tmp);
  s->object = object;
  s->material = r->material;
  const hush_material *mat = &scene->materials[s->material];

  const hush_vec3 p0 = hush_v3(r->p[0][0], r->p[0][1], r->p[0][2]);
  const hush_vec3 p1 = hush_v3(r->p[1][0], r->p[1][1], r->p[1][2]);
  const hush_vec3 p2 = hush_v3(r->p[2][0], r->p[2][1], r->p[2][2]);
  const hush_vec3 p = hush_v3_add(hush_v3_add(hush_v3_scale(p0, w), hush_v3_scale(p1, u)),
                                  hush_v3_scale(p2, v));
  s->p = xform_point(m, p);
  hush_vec3 ng = hush_v3_normalize(xform_dir(m, hush_v3_cross(hush_v3_sub(p1, p0),
                                                              hush_v3_sub(p2, p0))));
  hush_vec3 ns = ng;
  if (scene->normals) {
    const float *n0 = r->n[0], *n1 = r->n[1], *n2 = r->n[2];
    const hush_vec3 n = hush_v3(w * n0[0] + u * n1[0] + v * n2[0],
                                w * n0[1] + u * n1[1] + v * n2[1],
                                w * n0[2] + u * n1[2] + v * n2[2]);
    const float len = hush_v3_length(n);
    if (isfinite(len) && len > 1e-8f) {
      ns = hush_v3_normalize(xform_dir(m, hush_v3_scale(n, 1.0f / len)));
      /* The stored normals say which side is the front: a winding that
       * disagrees with them must not turn the surface inside out. */
      if (hush_v3_dot(ng, ns) < 0.0f) ng = hush_v3_scale(ng, -1.0f);
    }
  }
  if (!finite3(ns) || hush_v3_length(ns) < 0.5f) ns = ng;

  const hush_vec3 dir = hush_v3(d[0], d[1], d[2]);
  s->back_face = hush_v3_dot(ng, dir) > 0.0f;
  if (s->back_face && mat->two_sided && mat->type != HUSH_MAT_DIELECTRIC) {
    ng = hush_v3_scale(ng, -1.0f);
    ns = hush_v3_scale(ns, -1.0f);
  }
  s->ng = ng;
  s->ns = ns;

  if (scene->uvs) {
    const float *t0 = r->uv[0], *t1 = r->uv[1], *t2 = r->uv[2];
    s->uv[0] = w * t0[0] + u * t1[0] + v * t2[0];
    s->uv[1] = w * t0[1] + u * t1[1] + v * t2[1];
  }
  for (int c = 0; c < 3; c++) s->albedo[c] = mat->diffuse[c];
  if (mat->diffuse_texture >= 0 && (uint32_t)mat->diffuse_texture < scene->texture_count) {
    const hush_texture *t = &scene->textures[mat->diffuse_texture];
    float rgba[4] = {0.0f, 0.0f, 0.0f, 1.0f};
    hush__texture_sample(t, s->uv[0], s->uv[1], rgba);
    for (int c = 0; c < 3; c++) s->albedo[c] = rgba[t->channels >= 3 ? c : 0];
  }
}

void hush__scene_prefetch_surface(const hush_scene *scene, uint32_t triangle) {
  const rtc_state *rs = scene ? scene->rtc_data : NULL;
  if (!rs || triangle >= scene->triangle_count) return;
  /* both lines of the record (the adjacent-line prefetcher may not pair
   * software prefetches) */
  const char *r = (const char *)&rs->records[triangle];
  __builtin_prefetch(r, 0, 3);
  __builtin_prefetch(r + 64, 0, 3);
}

int hush__scene_triangle_flat(const hush_scene *scene, uint32_t triangle) {
  if (!scene || triangle >= scene->triangle_count) return 0;
  if (!scene->normals) return 1;
  const uint32_t *ix = scene->indices + 3 * (size_t)triangle;
  const hush_vec3 p0 = vertex(scene, ix[0]);
  const hush_vec3 face = hush_v3_normalize(
      hush_v3_cross(hush_v3_sub(vertex(scene, ix[1]), p0), hush_v3_sub(vertex(scene, ix[2]), p0)));
  for (int k = 0; k < 3; k++) {
    const float *n = scene->normals + 3 * (size_t)ix[k];
    const hush_vec3 v = hush_v3(n[0], n[1], n[2]);
    const float len = hush_v3_length(v);
    /* 0.9999: within 0.8 degrees of the face; either side (the winding
     * may disagree with the stored normals, see hush__scene_surface) */
    if (!(fabsf(hush_v3_dot(face, v)) >= 0.9999f * len)) return 0;
  }
  return 1;
}

hush_vec3 hush__scene_point(const hush_scene *scene, uint32_t triangle, float u, float v,
                            uint32_t frame) {
  if (!scene || triangle >= scene->triangle_count) return hush_v3(0.0f, 0.0f, 0.0f);
  const uint32_t *ix = scene->indices + 3 * (size_t)triangle;
  const float w = 1.0f - u - v;
  const hush_vec3 p = hush_v3_add(
      hush_v3_add(hush_v3_scale(vertex(scene, ix[0]), w), hush_v3_scale(vertex(scene, ix[1]), u)),
      hush_v3_scale(vertex(scene, ix[2]), v));
  float m[16];
  hush__scene_object_transform(scene, scene->triangle_object[triangle], frame, m);
  return xform_point(m, p);
}
