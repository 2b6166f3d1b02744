/*
 * synthetic.c — the synthetic sequence generator (see synthetic.h): an
 * analytic ray caster over a ground plane and four spheres, lit by a sun
 * with soft shadows (an analytic visibility, not shadow rays) and a constant
 * sky ambient, producing a noisy "color" whose expectation is exactly "ref",
 * plus the guide layers, motion vectors and cameras.
 */
#include "eval/synthetic.h"

#include "core/device.h"
#include "core/hmath.h"
#include "core/image.h"
#include "core/rng.h"
#include "io/atomic_file.h"
#include "io/sequence.h"

#include <math.h>
#include <string.h>
#include <sys/types.h>

#define SYNTH_SPHERES 4
#define SYNTH_MOVING 3 /* index of the moving sphere */
#define SYNTH_FOV_Y 45.0f
#define SYNTH_NEAR 0.05f
#define SYNTH_FAR 200.0f
#define SYNTH_PI 3.14159265358979f

typedef struct synth_sphere {
  hush_vec3 center;
  float radius;
  hush_vec3 albedo;
  hush_vec3 albedo2; /* second stripe colour; equal to albedo for plain spheres */
  int id;
} synth_sphere;

/* Everything a pixel needs: the scene at this frame, this and the previous
 * camera. Built once per frame, then only read by the worker threads. */
typedef struct synth_setup {
  synth_sphere spheres[SYNTH_SPHERES];
  hush_vec3 move_delta; /* moving sphere: centre now minus centre at the previous frame */
  hush_vec3 sun_dir;    /* unit, towards the sun */
  hush_vec3 sun;        /* irradiance of the sun at normal incidence */
  hush_vec3 ambient;    /* constant sky irradiance */
  float sun_radius;
  float noise;
  uint32_t seed, frame;
  uint32_t width, height;
  hush_camera cam, prev_cam;
  float view_to_world[16];
  hush_vec3 eye;
  int have_prev; /* frame 0 has no previous frame: motion is 0 */
} synth_setup;

typedef struct synth_hit {
  float t;
  hush_vec3 p, n, albedo;
  int id;     /* 0: sky */
  int sphere; /* index into spheres, -1 for the ground and the sky */
} synth_hit;

/* Views of the output layers, filled per pixel. */
typedef struct synth_layers {
  hush_image_view color, ref, albedo, normal, position, depth, motion, id;
} synth_layers;

void hush__synth_defaults(hush_synth_params *p) {
  memset(p, 0, sizeof *p);
  p->width = 320;
  p->height = 180;
  p->frames = 16;
  p->seed = 1;
  p->noise = 1.0f;
  p->camera_move = HUSH_SYNTH_ORBIT;
  p->moving_object = 1;
  p->sun_radius = 0.03f;
  p->exr_type = HUSH_EXR_FLOAT;
}

hush_status hush__synth_validate(hush_device device, const hush_synth_params *p) {
  if (!p) return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "synth: params is NULL");
  if (p->width == 0 || p->height == 0 || p->width > 16384 || p->height > 16384)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                      "synth: size %ux%u is outside 1x1 .. 16384x16384", p->width, p->height);
  if (p->frames == 0 || p->frames > 100000)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                      "synth: frames = %u is outside [1, 100000]", p->frames);
  if (!(p->noise >= 0.0f && p->noise <= 1.0f))
    return hush__fail(device, HUSH_ERROR_OUT_OF_RANGE, "synth: noise = %g is outside [0, 1]",
                      (double)p->noise);
  if (p->camera_move < HUSH_SYNTH_STATIC || p->camera_move > HUSH_SYNTH_DOLLY)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                      "synth: camera_move = %d is not 0 (static), 1 (orbit) or 2 (dolly)",
                      p->camera_move);
  if (!(p->sun_radius >= 0.0f && p->sun_radius <= 0.5f))
    return hush__fail(device, HUSH_ERROR_OUT_OF_RANGE,
                      "synth: sun_radius = %g is outside [0, 0.5] radians", (double)p->sun_radius);
  if (p->exr_type != HUSH_EXR_HALF && p->exr_type != HUSH_EXR_FLOAT)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "synth: exr_type = %d",
                      (int)p->exr_type);
  return HUSH_OK;
}

/* ---- scene -------------------------------------------------------------- */

/* The moving sphere swings left and right along x; a sine keeps it in view
 * however many frames are made. */
static hush_vec3 moving_center(const hush_synth_params *p, uint32_t frame) {
  const float dx = p->moving_object ? 1.8f * sinf(0.25f * (float)frame) : 0.0f;
  return hush_v3(dx, 0.45f, 2.0f);
}

static void scene_objects(const hush_synth_params *p, uint32_t frame, synth_setup *s) {
  static const struct {
    float c[3], r, a[3], a2[3];
  } table[SYNTH_SPHERES] = {
      {{-1.7f, 0.8f, -0.5f}, 0.8f, {0.75f, 0.18f, 0.14f}, {0.75f, 0.18f, 0.14f}},
      {{1.5f, 0.6f, 0.8f}, 0.6f, {0.2f, 0.62f, 0.28f}, {0.2f, 0.62f, 0.28f}},
      {{0.4f, 1.1f, -2.4f}, 1.1f, {0.24f, 0.34f, 0.8f}, {0.24f, 0.34f, 0.8f}},
      {{0.0f, 0.45f, 2.0f}, 0.45f, {0.9f, 0.72f, 0.2f}, {0.45f, 0.3f, 0.08f}},
  };
  for (int i = 0; i < SYNTH_SPHERES; i++) {
    synth_sphere *sp = &s->spheres[i];
    sp->center = hush_v3(table[i].c[0], table[i].c[1], table[i].c[2]);
    sp->radius = table[i].r;
    sp->albedo = hush_v3(table[i].a[0], table[i].a[1], table[i].a[2]);
    sp->albedo2 = hush_v3(table[i].a2[0], table[i].a2[1], table[i].a2[2]);
    sp->id = 2 + i;
  }
  s->spheres[SYNTH_MOVING].center = moving_center(p, frame);
  s->move_delta = frame > 0 ? hush_v3_sub(moving_center(p, frame), moving_center(p, frame - 1))
                            : hush_v3(0.0f, 0.0f, 0.0f);
  s->sun_dir = hush_v3_normalize(hush_v3(0.55f, 0.8f, 0.3f));
  s->sun = hush_v3(2.6f, 2.45f, 2.2f);
  s->ambient = hush_v3(0.22f, 0.27f, 0.36f);
}

void hush__synth_camera(const hush_synth_params *p, uint32_t frame, hush_camera *camera) {
  const hush_vec3 target = hush_v3(0.0f, 0.6f, 0.0f);
  float angle = 0.35f, dist = 7.0f;
  if (p->camera_move == HUSH_SYNTH_ORBIT) angle += 0.02f * (float)frame;
  if (p->camera_move == HUSH_SYNTH_DOLLY) dist = fmaxf(3.0f, 9.0f - 0.06f * (float)frame);
  /* height proportional to distance: the same downward look in a dolly */
  const hush_vec3 eye =
      hush_v3(target.x + dist * sinf(angle), target.y + 0.33f * dist, target.z + dist * cosf(angle));
  hush_m4_look_at(camera->world_to_view, eye, target, hush_v3(0.0f, 1.0f, 0.0f));
  hush_m4_perspective(camera->view_to_clip, SYNTH_FOV_Y, (float)p->width / (float)p->height,
                      SYNTH_NEAR, SYNTH_FAR);
  camera->jitter[0] = camera->jitter[1] = 0.0f;
}

static hush_status setup_frame(hush_device device, const hush_synth_params *p, uint32_t frame,
                               synth_setup *s) {
  memset(s, 0, sizeof *s);
  scene_objects(p, frame, s);
  s->sun_radius = p->sun_radius;
  s->noise = p->noise;
  s->seed = p->seed;
  s->frame = frame;
  s->width = p->width;
  s->height = p->height;
  hush__synth_camera(p, frame, &s->cam);
  hush__synth_camera(p, frame > 0 ? frame - 1 : 0, &s->prev_cam);
  s->have_prev = frame > 0;
  if (!hush_m4_invert(s->view_to_world, s->cam.world_to_view))
    return hush__fail(device, HUSH_ERROR_UNKNOWN, "synth: singular camera at frame %u", frame);
  s->eye = hush_v3(s->view_to_world[12], s->view_to_world[13], s->view_to_world[14]);
  return HUSH_OK;
}

/* ---- ray casting ------------------------------------------------------- */

/* Nearest positive root of |o + t d - c| = r, or -1. d is unit. */
static float ray_sphere(hush_vec3 o, hush_vec3 d, const synth_sphere *sp) {
  const hush_vec3 oc = hush_v3_sub(o, sp->center);
  const float b = hush_v3_dot(oc, d);
  const float c = hush_v3_dot(oc, oc) - sp->radius * sp->radius;
  const float disc = b * b - c;
  if (disc < 0.0f) return -1.0f;
  const float q = sqrtf(disc);
  if (-b - q > 1e-4f) return -b - q;
  if (-b + q > 1e-4f) return -b + q;
  return -1.0f;
}

static hush_vec3 ground_albedo(hush_vec3 p) {
  const int parity = ((int)floorf(p.x) + (int)floorf(p.z)) & 1;
  return parity ? hush_v3(0.72f, 0.7f, 0.64f) : hush_v3(0.22f, 0.24f, 0.27f);
}

/* Horizontal bands, so the moving sphere has texture that moves with it. */
static hush_vec3 sphere_albedo(const synth_sphere *sp, hush_vec3 p) {
  const float band = sinf(9.0f * (p.y - sp->center.y) / sp->radius);
  return band > 0.0f ? sp->albedo : sp->albedo2;
}

static synth_hit cast(const synth_setup *s, hush_vec3 o, hush_vec3 d) {
  synth_hit h;
  memset(&h, 0, sizeof h);
  h.t = INFINITY;
  h.sphere = -1;
  if (d.y < -1e-6f && o.y > 0.0f) {
    h.t = -o.y / d.y;
    h.id = 1;
  }
  for (int i = 0; i < SYNTH_SPHERES; i++) {
    const float t = ray_sphere(o, d, &s->spheres[i]);
    if (t > 0.0f && t < h.t) {
      h.t = t;
      h.id = s->spheres[i].id;
      h.sphere = i;
    }
  }
  if (h.id == 0) return h;
  h.p = hush_v3_add(o, hush_v3_scale(d, h.t));
  if (h.sphere < 0) {
    h.p.y = 0.0f; /* exactly on the plane, whatever the rounding */
    h.n = hush_v3(0.0f, 1.0f, 0.0f);
    h.albedo = ground_albedo(h.p);
  } else {
    const synth_sphere *sp = &s->spheres[h.sphere];
    h.n = hush_v3_normalize(hush_v3_sub(h.p, sp->center));
    h.albedo = sphere_albedo(sp, h.p);
  }
  return h;
}

static float smoothstep01(float x) {
  x = x < 0.0f ? 0.0f : (x > 1.0f ? 1.0f : x);
  return x * x * (3.0f - 2.0f * x);
}

/*
 * Fraction of the sun disc visible from p: for each sphere, compare the
 * angle between the sun and the sphere's centre with the sphere's angular
 * radius; the penumbra is a smoothstep across the sun's angular diameter.
 * Occluders are combined as independent, which is not exact where two
 * penumbrae overlap, but it defines the expectation "color" is drawn from.
 */
static float sun_visibility(const synth_setup *s, hush_vec3 p, int self) {
  float v = 1.0f;
  for (int i = 0; i < SYNTH_SPHERES; i++) {
    if (i == self) continue; /* a sphere's own shadow is its cosine term */
    const synth_sphere *sp = &s->spheres[i];
    const hush_vec3 dc = hush_v3_sub(sp->center, p);
    const float dist = hush_v3_length(dc);
    if (dist <= sp->radius) return 0.0f;
    const float cos_theta = hush_v3_dot(dc, s->sun_dir) / dist;
    const float theta = acosf(fmaxf(-1.0f, fminf(1.0f, cos_theta)));
    const float alpha = asinf(sp->radius / dist);
    const float gap = theta - alpha; /* > 0: the sun centre is outside the sphere's disc */
    if (s->sun_radius > 0.0f)
      v *= smoothstep01((gap + s->sun_radius) / (2.0f * s->sun_radius));
    else if (gap <= 0.0f)
      v = 0.0f;
  }
  return v;
}

static hush_vec3 sky_color(hush_vec3 d) {
  const float t = fmaxf(0.0f, fminf(1.0f, d.y));
  const hush_vec3 horizon = hush_v3(0.72f, 0.8f, 0.92f), zenith = hush_v3(0.28f, 0.44f, 0.8f);
  return hush_v3_add(hush_v3_scale(horizon, 1.0f - t), hush_v3_scale(zenith, t));
}

/* Pixel coordinates of a homogeneous world point (w = 1 for points, 0 for
 * directions) seen by a camera; 0 if it is behind the camera. */
static int project(const hush_camera *cam, uint32_t width, uint32_t height, hush_vec3 p, float w,
                   float *px, float *py) {
  const hush_vec4 v = hush_m4_mul_v4(cam->world_to_view, p.x, p.y, p.z, w);
  const hush_vec4 c = hush_m4_mul_v4(cam->view_to_clip, v.x, v.y, v.z, v.w);
  if (c.w <= 1e-6f) return 0;
  *px = (c.x / c.w + 1.0f) * 0.5f * (float)width;
  *py = (1.0f - c.y / c.w) * 0.5f * (float)height;
  return 1;
}

static float *at(const hush_image_view *v, uint32_t x, uint32_t y) {
  return (float *)((char *)v->data + v->byte_offset + y * hush__view_row_stride(v) +
                   x * hush__view_pixel_stride(v));
}

static void put3(const hush_image_view *v, uint32_t x, uint32_t y, hush_vec3 a) {
  float *o = at(v, x, y);
  o[0] = a.x;
  o[1] = a.y;
  o[2] = a.z;
}

static hush_vec3 mul3(hush_vec3 a, hush_vec3 b) { return hush_v3(a.x * b.x, a.y * b.y, a.z * b.z); }

/*
 * Motion of the point seen at pixel centre (cx, cy): where the previous
 * camera saw the same surface point (for the moving sphere, where the point
 * was before it moved), minus the centre. A point the previous camera could
 * not see lands at (-1, -1), off screen, so filters treat it as new.
 */
static void pixel_motion(const synth_setup *s, const synth_hit *h, hush_vec3 dir, float cx,
                         float cy, float m[2]) {
  m[0] = m[1] = 0.0f;
  if (!s->have_prev) return;
  hush_vec3 prev = h->id ? h->p : dir;
  if (h->sphere == SYNTH_MOVING) prev = hush_v3_sub(prev, s->move_delta);
  float px, py;
  if (!project(&s->prev_cam, s->width, s->height, prev, h->id ? 1.0f : 0.0f, &px, &py)) {
    px = -1.0f;
    py = -1.0f;
  }
  m[0] = px - cx;
  m[1] = py - cy;
}

static void render_pixel(const synth_setup *s, const synth_layers *L, uint32_t x, uint32_t y) {
  const float cx = (float)x + 0.5f, cy = (float)y + 0.5f;
  const float ndc_x = cx / (float)s->width * 2.0f - 1.0f;
  const float ndc_y = 1.0f - cy / (float)s->height * 2.0f;
  /* The inverse projection of the pixel centre, so projecting the hit point
   * with the frame's own matrices gives back the centre. */
  const hush_vec3 dv = hush_v3(ndc_x / s->cam.view_to_clip[0], ndc_y / s->cam.view_to_clip[5], -1.0f);
  const hush_vec4 dw = hush_m4_mul_v4(s->view_to_world, dv.x, dv.y, dv.z, 0.0f);
  const hush_vec3 dir = hush_v3_normalize(hush_v3(dw.x, dw.y, dw.z));
  const synth_hit h = cast(s, s->eye, dir);
  float *m = at(&L->motion, x, y);
  pixel_motion(s, &h, dir, cx, cy, m);

  if (h.id == 0) {
    const hush_vec3 sky = sky_color(dir);
    put3(&L->color, x, y, sky);
    put3(&L->ref, x, y, sky);
    put3(&L->albedo, x, y, hush_v3(1.0f, 1.0f, 1.0f));
    /* normal, position, depth and id stay 0 from hush_frame_add_layer */
    return;
  }

  const float cos_sun = fmaxf(0.0f, hush_v3_dot(h.n, s->sun_dir));
  const float vis = cos_sun > 0.0f ? sun_visibility(s, h.p, h.sphere) : 0.0f;
  const hush_vec3 direct = hush_v3_scale(s->sun, cos_sun);
  const hush_vec3 ref = mul3(h.albedo, hush_v3_add(hush_v3_scale(direct, vis), s->ambient));

  /* The noise: the shadow is a Bernoulli draw with probability vis (a
   * one-sample shadow ray), and the whole pixel is scaled by an exponential
   * variate of mean 1 (-log u), a heavy tail like 1-spp path tracing. Both
   * are blended with their means by `noise`, so E[color] = ref exactly. */
  const uint32_t pixel = y * s->width + x;
  const float u_shadow = hush_rng_float(s->seed, s->frame, 2u * pixel);
  const float u_scale = hush_rng_float(s->seed, s->frame, 2u * pixel + 1u);
  const float shadow = (1.0f - s->noise) * vis + s->noise * (u_shadow < vis ? 1.0f : 0.0f);
  const float scale = (1.0f - s->noise) + s->noise * -logf(1.0f - u_scale);
  const hush_vec3 color = hush_v3_scale(
      mul3(h.albedo, hush_v3_add(hush_v3_scale(direct, shadow), s->ambient)), scale);

  put3(&L->color, x, y, color);
  put3(&L->ref, x, y, ref);
  put3(&L->albedo, x, y, h.albedo);
  put3(&L->normal, x, y, h.n);
  put3(&L->position, x, y, h.p);
  const hush_vec4 pv = hush_m4_mul_v4(s->cam.world_to_view, h.p.x, h.p.y, h.p.z, 1.0f);
  at(&L->depth, x, y)[0] = -pv.z;
  at(&L->id, x, y)[0] = (float)h.id;
}

static hush_status add_layers(hush_frame frame, synth_layers *L) {
  const struct {
    const char *name;
    int channels;
    hush_image_view *view;
  } list[] = {
      {"color", 3, &L->color},       {"ref", 3, &L->ref},     {"albedo", 3, &L->albedo},
      {"normal", 3, &L->normal},     {"position", 3, &L->position},
      {"depth", 1, &L->depth},       {"motion", 2, &L->motion}, {"id", 1, &L->id},
  };
  for (size_t i = 0; i < sizeof list / sizeof list[0]; i++) {
    const hush_status st = hush_frame_add_layer(frame, list[i].name, list[i].channels, list[i].view);
    if (st != HUSH_OK) return st;
  }
  return HUSH_OK;
}

hush_status hush__synth_frame(hush_device device, const hush_synth_params *p, uint32_t frame,
                              hush_frame *out, hush_camera *camera) {
  if (!out) return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "synth: out is NULL");
  *out = NULL;
  hush_status st = hush__synth_validate(device, p);
  if (st != HUSH_OK) return st;
  synth_setup s;
  st = setup_frame(device, p, frame, &s);
  if (st != HUSH_OK) return st;

  hush_frame f = hush_frame_new(device, p->width, p->height);
  if (!f) return HUSH_ERROR_OUT_OF_MEMORY; /* reported by hush_frame_new */
  synth_layers L;
  st = add_layers(f, &L);
  if (st != HUSH_OK) {
    hush_frame_release(f);
    return st;
  }
  const int rows = (int)p->height;
#pragma omp parallel for num_threads(hush_device_threads(device)) schedule(static)
  for (int y = 0; y < rows; y++)
    for (uint32_t x = 0; x < p->width; x++) render_pixel(&s, &L, x, (uint32_t)y);

  if (camera) *camera = s.cam;
  *out = f;
  return HUSH_OK;
}

/* ---- sequences ---------------------------------------------------------- */

hush_status hush__synth_write_sequence(hush_device device, const hush_synth_params *p,
                                       const char *dir) {
  hush_status st = hush__synth_validate(device, p);
  if (st != HUSH_OK) return st;
  st = hush__make_dirs(device, dir);
  if (st != HUSH_OK) return st;
  hush_sequence seq;
  st = hush__sequence_init(device, &seq, dir, p->width, p->height, p->frames);
  if (st != HUSH_OK) return st;
  /* The moving sphere needs the motion vectors; camera motion alone would
   * smear it. */
  seq.motion = p->moving_object ? HUSH_MOTION_VECTORS : HUSH_MOTION_CAMERA;
  for (uint32_t i = 0; i < p->frames && st == HUSH_OK; i++) {
    char path[HUSH_PATH_MAX];
    hush_frame frame = NULL;
    st = hush__sequence_frame_path(device, &seq, i, path, sizeof path);
    if (st == HUSH_OK) st = hush__synth_frame(device, p, i, &frame, &seq.cameras[i]);
    if (st == HUSH_OK) st = hush_frame_write_exr(frame, path, p->exr_type);
    hush_frame_release(frame);
  }
  if (st == HUSH_OK) st = hush__sequence_write_cameras(device, &seq);
  hush__sequence_free(&seq);
  return st;
}
