/*
 * test_render.c — the path tracer (src/render: camera, bsdf, lights,
 * integrator, render): BSDF energy, reciprocity and sampling consistency;
 * environment-map importance sampling; the furnace test; motion vectors
 * against reprojected positions; determinism and per-pixel re-rendering;
 * pixel blocks shaded together equal single paths;
 * G-buffer sanity on the built-in Cornell box; primary surface replacement
 * through its mirrored variant.
 */
#include "check.h"

#include "core/hmath.h"
#include "core/rng.h"
#include "io/frame.h"
#include "render/bsdf.h"
#include "render/camera.h"
#include "render/integrator.h"
#include "render/lights.h"
#include "render/render.h"
#include "render/scene.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#define T_PI 3.14159265358979

static float rnd(uint32_t stream, uint32_t i) {
  return hush_rng_float(12345u, stream, i);
}

static hush_vec3 uniform_sphere(float u1, float u2) {
  const float z = 1.0f - 2.0f * u1, r = sqrtf(fmaxf(0.0f, 1.0f - z * z));
  return hush_v3(r * cosf(2.0f * (float)T_PI * u2), r * sinf(2.0f * (float)T_PI * u2), z);
}

/* ---- BSDFs ------------------------------------------------------------------ */

typedef struct bsdf_case {
  const char *name;
  hush_material_type type;
  float diffuse, specular, roughness;
  int has_delta;
} bsdf_case;

/* The case's material and a surface of it facing +z. */
static void case_material(const bsdf_case *c, hush_material *m, hush_surface *s) {
  memset(m, 0, sizeof *m);
  m->type = c->type;
  m->diffuse[0] = m->diffuse[1] = m->diffuse[2] = c->diffuse;
  m->specular[0] = m->specular[1] = m->specular[2] = c->specular;
  m->roughness = c->roughness;
  m->ior = 1.5f;
  m->diffuse_texture = m->alpha_texture = -1;
  memset(s, 0, sizeof *s);
  s->ng = s->ns = hush_v3(0.0f, 0.0f, 1.0f);
  s->albedo[0] = s->albedo[1] = s->albedo[2] = c->diffuse;
}

static void make_bsdf(const bsdf_case *c, hush_vec3 wo, hush_bsdf *b) {
  hush_material m;
  hush_surface s;
  case_material(c, &m, &s);
  hush__bsdf_setup(b, &m, &s, wo);
}

/* The demodulation albedo stands for what the surface reflects: the filters
 * divide the radiance by it, so where it is far below the reflectance a
 * highlight becomes a huge demodulated value (a plastic's black base under
 * its coat), and where it is far above, the light is lost in the division.
 * Against the directional albedo sampled at near-normal incidence. */
static void test_demodulation_albedo(void) {
  const bsdf_case cases[] = {
      {"lambert-0.5", HUSH_MAT_DIFFUSE, 0.5f, 0.0f, 0.0f, 0},
      {"plastic-black-base", HUSH_MAT_PLASTIC, 0.0f, 0.04f, 0.3f, 0},
      {"plastic-grey-base", HUSH_MAT_PLASTIC, 0.5f, 0.04f, 0.3f, 0},
      {"plastic-white-base", HUSH_MAT_PLASTIC, 1.0f, 0.04f, 0.3f, 0},
      {"plastic-shiny-black", HUSH_MAT_PLASTIC, 0.0f, 0.3f, 0.2f, 0},
  };
  const hush_vec3 wo = hush_v3(sqrtf(1.0f - 0.95f * 0.95f), 0.0f, 0.95f);
  for (size_t ci = 0; ci < sizeof cases / sizeof cases[0]; ci++) {
    const bsdf_case *c = &cases[ci];
    hush_material m;
    hush_surface surf;
    case_material(c, &m, &surf);
    float alb[3];
    hush__bsdf_albedo(&m, &surf, alb);
    hush_bsdf b;
    hush__bsdf_setup(&b, &m, &surf, wo);
    double reflected = 0.0;
    const int n = 40000;
    for (int i = 0; i < n; i++) {
      const float u[3] = {rnd(4, i), rnd(5, i), rnd(6, i)};
      hush_bsdf_sample smp;
      if (hush__bsdf_sample(&b, wo, u, &smp)) reflected += smp.weight[0];
    }
    reflected /= n;
    CHECK_MSG(alb[0] <= 1.0f && alb[0] == alb[1] && alb[1] == alb[2], "%s: albedo %g %g %g", c->name,
              alb[0], alb[1], alb[2]);
    CHECK_MSG(reflected > 0.5 * alb[0] && reflected < 2.0 * alb[0],
              "%s: demodulation albedo %.4f, reflectance %.4f", c->name, alb[0], reflected);
  }
}

static void test_bsdfs(void) {
  const bsdf_case cases[] = {
      {"lambert", HUSH_MAT_DIFFUSE, 1.0f, 0.0f, 0.0f, 0},
      {"plastic-smooth", HUSH_MAT_PLASTIC, 1.0f, 0.04f, 0.0f, 1},
      {"plastic-rough", HUSH_MAT_PLASTIC, 1.0f, 0.04f, 0.3f, 0},
      {"conductor-rough", HUSH_MAT_CONDUCTOR, 0.0f, 1.0f, 0.3f, 0},
      {"conductor-glossy", HUSH_MAT_CONDUCTOR, 0.0f, 1.0f, 0.05f, 0},
      {"mirror", HUSH_MAT_CONDUCTOR, 0.0f, 1.0f, 0.0f, 1},
  };
  const float cos_o[] = {0.9f, 0.4f};
  const int n = 40000;
  for (size_t ci = 0; ci < sizeof cases / sizeof cases[0]; ci++) {
    const bsdf_case *c = &cases[ci];
    for (size_t oi = 0; oi < 2; oi++) {
      const hush_vec3 wo = hush_v3(sqrtf(1.0f - cos_o[oi] * cos_o[oi]), 0.0f, cos_o[oi]);
      hush_bsdf b;
      make_bsdf(c, wo, &b);
      /* energy: the mean sample weight is the directional albedo */
      double energy = 0.0;
      int bad_ratio = 0, bad_pdf = 0;
      for (int i = 0; i < n; i++) {
        const float u[3] = {rnd(1, i), rnd(2, i), rnd(3, i)};
        hush_bsdf_sample s;
        if (!hush__bsdf_sample(&b, wo, u, &s)) continue;
        energy += s.weight[0];
        if (s.delta) continue;
        float f[3], pdf;
        hush__bsdf_eval(&b, wo, s.wi, f, &pdf);
        if (fabsf(pdf - s.pdf) > 1e-3f * fmaxf(1.0f, pdf)) bad_pdf++;
        if (fabsf(f[0] / pdf - s.weight[0]) > 1e-3f * fmaxf(1.0f, s.weight[0])) bad_ratio++;
      }
      energy /= n;
      CHECK_MSG(bad_pdf == 0, "%s: %d samples whose pdf differs from eval's", c->name, bad_pdf);
      CHECK_MSG(bad_ratio == 0, "%s: %d samples with eval / pdf != weight", c->name, bad_ratio);
      CHECK_MSG(energy <= 1.02, "%s cos %.1f: albedo %.4f > 1", c->name, cos_o[oi], energy);
      if (c->type == HUSH_MAT_DIFFUSE || strcmp(c->name, "mirror") == 0)
        CHECK_NEAR(energy, 1.0, 1e-4);
      /* single-scattering GGX loses energy: 0.817 at alpha 0.3, cos 0.4 (checked
       * by direct integration) */
      if (c->type == HUSH_MAT_CONDUCTOR) CHECK_MSG(energy > 0.78, "%s: %.4f", c->name, energy);
      if (c->type == HUSH_MAT_PLASTIC) CHECK_MSG(energy > 0.85, "%s: %.4f", c->name, energy);

      /* the integral of the pdf over the sphere (uniform directions) */
      double ipdf = 0.0, ieval = 0.0;
      for (int i = 0; i < 4 * n; i++) {
        const hush_vec3 wi = uniform_sphere(rnd(4, i), rnd(5, i));
        float f[3], pdf;
        hush__bsdf_eval(&b, wo, wi, f, &pdf);
        ipdf += pdf * 4.0 * T_PI;
        ieval += f[0] * 4.0 * T_PI;
      }
      ipdf /= 4 * n;
      ieval /= 4 * n;
      if (!c->has_delta && c->roughness >= 0.1f) {
        CHECK_MSG(ipdf > 0.9 && ipdf < 1.03, "%s cos %.1f: integral of pdf %.4f", c->name,
                  cos_o[oi], ipdf);
        /* the two estimators of the albedo agree */
        CHECK_MSG(fabs(ieval - energy) < 0.03 + 0.03 * energy, "%s cos %.1f: %.4f vs %.4f",
                  c->name, cos_o[oi], ieval, energy);
      }

      /* reciprocity: f(wo, wi) = f(wi, wo) */
      int bad_recip = 0;
      for (int i = 0; i < 200; i++) {
        hush_vec3 wi = uniform_sphere(rnd(6, i), rnd(7, i));
        wi.z = fabsf(wi.z) + 0.05f;
        wi = hush_v3_normalize(wi);
        float f1[3], f2[3], p1, p2;
        hush__bsdf_eval(&b, wo, wi, f1, &p1);
        hush_bsdf b2;
        make_bsdf(c, wi, &b2);
        hush__bsdf_eval(&b2, wi, wo, f2, &p2);
        const float a = f1[0] / wi.z, bb = f2[0] / wo.z;
        if (fabsf(a - bb) > 1e-3f * fmaxf(1.0f, fabsf(a))) bad_recip++;
      }
      CHECK_MSG(bad_recip == 0, "%s: %d non-reciprocal pairs", c->name, bad_recip);
    }
  }

  /* glass: reflect with probability F, refract otherwise, weights 1 and 1/eta^2 */
  const bsdf_case glass = {"glass", HUSH_MAT_DIELECTRIC, 0.0f, 1.0f, 0.0f, 1};
  const hush_vec3 wo = hush_v3_normalize(hush_v3(0.6f, 0.0f, 0.8f));
  hush_bsdf b;
  make_bsdf(&glass, wo, &b);
  const float fr = hush__fresnel_dielectric(0.8f, 1.5f);
  int refl = 0, total = 0;
  for (int i = 0; i < 20000; i++) {
    const float u[3] = {rnd(8, i), rnd(9, i), rnd(10, i)};
    hush_bsdf_sample s;
    if (!hush__bsdf_sample(&b, wo, u, &s)) continue;
    total++;
    if (s.wi.z > 0.0f) {
      refl++;
      CHECK(fabsf(s.weight[0] - 1.0f) < 1e-6f);
    } else {
      CHECK(fabsf(s.weight[0] - 1.0f / 2.25f) < 1e-5f);
      /* Snell: sin_t = sin_i / 1.5 */
      CHECK(fabsf(sqrtf(s.wi.x * s.wi.x + s.wi.y * s.wi.y) - 0.6f / 1.5f) < 1e-4f);
    }
  }
  CHECK_NEAR((double)refl / total, fr, 0.01);
  CHECK_NEAR(hush__fresnel_dielectric(1.0f, 1.5f), 0.04, 1e-4);
}

/* ---- environment maps ---------------------------------------------------------------- */

static void test_envmap(void) {
  /* orientation, Mitsuba's convention */
  float u, v;
  hush__envmap_dir_to_uv(hush_v3(0.0f, 1.0f, 0.0f), &u, &v);
  CHECK_NEAR(v, 0.0, 1e-6);
  /* Mitsuba 0.5: u = atan2(d.x, -d.z) / (2 pi) mod 1 */
  hush__envmap_dir_to_uv(hush_v3(0.0f, 0.0f, -1.0f), &u, &v);
  CHECK_NEAR(u, 0.0, 1e-6);
  CHECK_NEAR(v, 0.5, 1e-6);
  hush__envmap_dir_to_uv(hush_v3(1.0f, 0.0f, 0.0f), &u, &v);
  CHECK_NEAR(u, 0.25, 1e-6);
  hush__envmap_dir_to_uv(hush_v3(-1.0f, 0.0f, 0.0f), &u, &v);
  CHECK_NEAR(u, 0.75, 1e-6);
  for (int i = 0; i < 100; i++) {
    const hush_vec3 d = uniform_sphere(rnd(20, i), rnd(21, i));
    hush__envmap_dir_to_uv(d, &u, &v);
    const hush_vec3 e = hush__envmap_uv_to_dir(u, v);
    CHECK(hush_v3_length(hush_v3_sub(d, e)) < 1e-4f);
  }

  /* a small map with a bright spot; rotated 90 degrees about y */
  enum { W = 16, H = 8 };
  float rgb[W * H * 3];
  for (int i = 0; i < W * H; i++) {
    const float val = 0.1f + (float)(i % 7) * 0.05f;
    rgb[3 * i] = val;
    rgb[3 * i + 1] = val * 0.5f;
    rgb[3 * i + 2] = val * 0.25f;
  }
  for (int k = 0; k < 3; k++) rgb[3 * (2 * W + 5) + k] = 40.0f;
  float rot[16];
  hush_m4_identity(rot);
  rot[0] = 0.0f, rot[8] = 1.0f, rot[2] = -1.0f, rot[10] = 0.0f; /* column-major rotate_y(90) */
  hush_envmap m;
  REQUIRE(hush__envmap_build(NULL, &m, rgb, W, H, 3, 1.0f, rot) == HUSH_OK);
  /* the pdf integrates to 1, and sampled directions report the pdf of eval */
  const int n = 400000;
  double ipdf = 0.0, il = 0.0, il_is = 0.0;
  int mismatch = 0;
  for (int i = 0; i < n; i++) {
    const hush_vec3 d = uniform_sphere(rnd(22, i), rnd(23, i));
    float c[3];
    hush__envmap_eval(&m, d, c);
    ipdf += hush__envmap_pdf(&m, d) * 4.0 * T_PI;
    il += c[0] * 4.0 * T_PI;
    float pdf;
    const hush_vec3 s = hush__envmap_sample(&m, rnd(24, i), rnd(25, i), &pdf);
    hush__envmap_eval(&m, s, c);
    if (fabsf(pdf - hush__envmap_pdf(&m, s)) > 1e-4f * pdf) mismatch++;
    if (pdf > 0.0f) il_is += c[0] / pdf;
  }
  ipdf /= n;
  il /= n;
  il_is /= n;
  CHECK_NEAR(ipdf, 1.0, 0.02);
  CHECK_MSG(fabs(il_is - il) < 0.02 * il, "importance-sampled %.4f vs uniform %.4f", il_is, il);
  CHECK(mismatch == 0);
  /* the bright texel (5, 2) in the local frame, rotated into the world */
  const hush_vec3 local = hush__envmap_uv_to_dir(5.5f / W, 2.5f / H);
  const hush_vec3 world = hush_v3(rot[0] * local.x + rot[4] * local.y + rot[8] * local.z,
                                  rot[1] * local.x + rot[5] * local.y + rot[9] * local.z,
                                  rot[2] * local.x + rot[6] * local.y + rot[10] * local.z);
  float c[3];
  hush__envmap_eval(&m, world, c);
  CHECK_NEAR(c[0], 40.0, 1e-4);
  hush__envmap_free(&m);
}

/* The map's shortcuts are exact: the density stored with each texel is the
 * product of its CDF steps (0 for a black map), and a map without rotation
 * (the sky) that skips the 3x3 products evaluates, weighs and samples
 * exactly as with them. */
static void test_envmap_shortcuts(void) {
  enum { W = 24, H = 12 };
  float rgb[W * H * 3];
  for (int i = 0; i < W * H * 3; i++) rgb[i] = 0.05f + (float)((i * 7) % 11) * 0.1f;
  float rot[16];
  hush_m4_identity(rot);
  rot[0] = 0.0f, rot[8] = 1.0f, rot[2] = -1.0f, rot[10] = 0.0f;
  hush_envmap m, r;
  REQUIRE(hush__envmap_build(NULL, &m, rgb, W, H, 3, 1.0f, NULL) == HUSH_OK);
  REQUIRE(hush__envmap_build(NULL, &r, rgb, W, H, 3, 1.0f, rot) == HUSH_OK);
  CHECK(m.identity == 1);
  CHECK(r.identity == 0);
  int bad = 0;
  for (uint32_t y = 0; y < H; y++)
    for (uint32_t x = 0; x < W; x++) {
      const float p_row = m.row_cdf[y + 1] - m.row_cdf[y];
      const float p_col = m.col_cdf[y * (W + 1) + x + 1] - m.col_cdf[y * (W + 1) + x];
      if (m.texels[4 * (y * W + x) + 3] != p_row * p_col * (float)W * (float)H) bad++;
    }
  CHECK_MSG(bad == 0, "%d texels whose stored density is not their CDF steps' product", bad);
  hush_envmap slow = m; /* the same tables, through the 3x3 products */
  slow.identity = 0;
  int differ = 0;
  for (int i = 0; i < 20000; i++) {
    const hush_vec3 d = uniform_sphere(rnd(26, i), rnd(27, i));
    float a[3], b[3];
    hush__envmap_eval(&m, d, a);
    hush__envmap_eval(&slow, d, b);
    if (a[0] != b[0] || a[1] != b[1] || a[2] != b[2]) differ++;
    if (hush__envmap_pdf(&m, d) != hush__envmap_pdf(&slow, d)) differ++;
    float pa, pb;
    const hush_vec3 sa = hush__envmap_sample(&m, rnd(28, i), rnd(29, i), &pa);
    const hush_vec3 sb = hush__envmap_sample(&slow, rnd(28, i), rnd(29, i), &pb);
    if (pa != pb || sa.x != sb.x || sa.y != sb.y || sa.z != sb.z) differ++;
  }
  CHECK_MSG(differ == 0, "%d lookups differ with and without the identity shortcut", differ);
  hush__envmap_free(&m);
  hush__envmap_free(&r);
  /* a black map: every stored density 0, so every pdf 0 */
  float black[W * H * 3] = {0};
  REQUIRE(hush__envmap_build(NULL, &m, black, W, H, 3, 1.0f, NULL) == HUSH_OK);
  bad = 0;
  for (int i = 0; i < W * H; i++) bad += m.texels[4 * i + 3] != 0.0f;
  for (int i = 0; i < 1000; i++) bad += hush__envmap_pdf(&m, uniform_sphere(rnd(30, i), rnd(31, i))) != 0.0f;
  CHECK(bad == 0);
  hush__envmap_free(&m);
}

/* A sun-and-sky light sample drawn with its radiance deferred
 * (hush__lights_sample_deferred, then hush__lights_sample_finish) is the
 * eager sample bit for bit, and is never drawn where the eager one has
 * no light (sun, sky, emissive triangles). */
static void test_deferred_light_samples(void) {
  hush_device device = hush_device_new("threads=1");
  REQUIRE(device);
  hush_scene sc;
  REQUIRE(hush__scene_builtin(device, "cornell", &sc) == HUSH_OK);
  sc.env.type = HUSH_ENV_SUNSKY;
  const hush_vec3 sun = hush_v3_normalize(hush_v3(-0.8f, 0.35f, -0.3f));
  sc.env.sun_direction[0] = sun.x;
  sc.env.sun_direction[1] = sun.y;
  sc.env.sun_direction[2] = sun.z;
  sc.env.turbidity = 3.0f;
  sc.env.sky_scale = 2.0f;
  sc.env.sun_scale = 1.0f;
  sc.env.sun_radius_scale = 10.0f;
  REQUIRE(hush__scene_commit(device, &sc) == HUSH_OK);
  hush_lights L;
  REQUIRE(hush__lights_init(device, &L, &sc) == HUSH_OK);
  int bad = 0, deferred = 0, eager = 0, refused = 0, below = 0;
  for (uint32_t i = 0; i < 20000; i++) {
    const hush_vec3 p = hush_v3(rnd(40, i) - 0.5f, rnd(41, i), rnd(42, i) - 0.5f);
    const float u[3] = {rnd(43, i), rnd(44, i), rnd(45, i)};
    hush_light_sample a, b;
    const int lit = hush__lights_sample(&L, p, u, &a) &&
                    fmaxf(a.radiance[0], fmaxf(a.radiance[1], a.radiance[2])) > 0.0f;
    const int drawn = hush__lights_sample_deferred(&L, p, u, &b);
    if (!lit) {
      refused++;
      below += a.wi.y <= 0.0f;
      bad += drawn && b.deferred;
      continue;
    }
    if (!drawn) {
      bad++;
      continue;
    }
    deferred += b.deferred;
    eager += !b.deferred;
    hush__lights_sample_finish(&L, &b);
    if (b.deferred || memcmp(a.radiance, b.radiance, sizeof a.radiance) || a.pdf != b.pdf ||
        a.dist != b.dist || a.wi.x != b.wi.x || a.wi.y != b.wi.y || a.wi.z != b.wi.z)
      bad++;
  }
  CHECK_MSG(bad == 0, "%d deferred light samples differ from eager ones", bad);
  CHECK_MSG(deferred > 5000 && eager > 1000, "deferred %d, eager %d", deferred, eager);
  printf("deferred light samples: %d deferred, %d eager, %d without light (%d below the "
         "horizon)\n",
         deferred, eager, refused, below);
  hush__lights_free(&L);
  hush__scene_free(&sc);
  hush_device_release(device);
}

/* ---- rendering helpers -------------------------------------------------------------- */

typedef struct rig {
  hush_device device;
  hush_scene scene;
  hush_lights lights;
} rig;

static void rig_open(rig *r, const char *name) {
  memset(r, 0, sizeof *r);
  r->device = hush_device_new("threads=2");
  REQUIRE(r->device);
  REQUIRE(hush__scene_builtin(r->device, name, &r->scene) == HUSH_OK);
  REQUIRE(hush__scene_commit(r->device, &r->scene) == HUSH_OK);
  REQUIRE(hush__lights_init(r->device, &r->lights, &r->scene) == HUSH_OK);
}

static void rig_close(rig *r) {
  hush__lights_free(&r->lights);
  hush__scene_free(&r->scene);
  hush_device_release(r->device);
}

/* Sets the scene to frame f and renders it; ctx receives the set-up. */
static hush_frame render_at(rig *r, const hush_render_params *p, hush_camera_move move, uint32_t f,
                            hush_render_ctx *ctx) {
  REQUIRE(hush__scene_set_frame(r->device, &r->scene, f) == HUSH_OK);
  hush__lights_set_frame(&r->lights, f);
  hush_camera_pose pose;
  int ax;
  float zn, zf;
  hush__camera_pose(&r->scene, move, NULL, f, &pose, &ax);
  hush__camera_clip_range(&r->scene, hush_v3(pose.position[0], pose.position[1], pose.position[2]),
                          &zn, &zf);
  hush_render_camera cam, prev;
  REQUIRE(hush__camera_setup(&cam, &pose, ax, p->width, p->height, zn, zf, f, p->jitter));
  if (f > 0) {
    hush__camera_pose(&r->scene, move, NULL, f - 1, &pose, &ax);
    REQUIRE(hush__camera_setup(&prev, &pose, ax, p->width, p->height, zn, zf, f - 1, p->jitter));
  }
  hush__render_ctx_init(ctx, &r->scene, &r->lights, p, &cam, f > 0 ? &prev : NULL, f);
  hush_frame out = hush_frame_new(r->device, p->width, p->height);
  REQUIRE(out);
  REQUIRE(hush__render_frame(r->device, ctx, out, NULL, NULL, NULL) == HUSH_OK);
  return out;
}

static const float *layer(hush_frame f, const char *name) {
  hush_layer *l = hush__frame_find(f, name);
  REQUIRE(l);
  return l->pixels;
}

/* ---- furnace --------------------------------------------------------------------------- */

static void test_furnace(void) {
  rig r;
  rig_open(&r, "furnace");
  hush_render_params p;
  hush__render_defaults(&p);
  p.width = p.height = 48;
  p.spp = 16;
  p.jitter = 0; /* every sample through the centre: no pixel mixes sphere and sky */
  const int bounces[] = {1, 2, 8};
  for (int pass = 0; pass < 2; pass++) {
    /* pass 0: the scene's albedo 0.8; pass 1: albedo 1 (white furnace) */
    if (pass == 1)
      for (uint32_t i = 0; i < r.scene.material_count; i++)
        for (int k = 0; k < 3; k++) r.scene.materials[i].diffuse[k] = 1.0f;
    const double expect = pass == 0 ? 0.8 : 1.0;
    for (size_t bi = 0; bi < 3; bi++) {
      p.bounces = bounces[bi];
      hush_render_ctx ctx;
      hush_frame f = render_at(&r, &p, HUSH_MOVE_STATIC, 0, &ctx);
      const float *color = layer(f, "color"), *vis = layer(f, "vis");
      double sphere = 0.0, sky = 0.0;
      int ns = 0, nk = 0;
      for (uint32_t i = 0; i < p.width * p.height; i++) {
        const double l = (color[3 * i] + color[3 * i + 1] + color[3 * i + 2]) / 3.0;
        if (vis[3 * i] >= 0.0f) {
          sphere += l;
          ns++;
        } else {
          sky += l;
          nk++;
        }
      }
      REQUIRE(ns > 100 && nk > 100);
      CHECK_MSG(fabs(sphere / ns - expect) < 0.01 * expect + 0.005,
                "furnace albedo %.1f, bounces %d: sphere %.4f", expect, bounces[bi], sphere / ns);
      CHECK_NEAR(sky / nk, 1.0, 1e-5);
      hush_frame_release(f);
    }
  }
  rig_close(&r);
}

/* ---- motion vectors ----------------------------------------------------------------------- */

static void test_motion(const char *scene, hush_camera_move move, int expect_moving) {
  rig r;
  rig_open(&r, scene);
  hush_render_params p;
  hush__render_defaults(&p);
  p.width = 160;
  p.height = 90;
  const uint32_t t = 5;
  hush_render_ctx ctx;
  hush_frame f = render_at(&r, &p, move, t, &ctx);
  const float *pos = layer(f, "position"), *mot = layer(f, "motion"), *vis = layer(f, "vis");
  int checked = 0, bad = 0, moving = 0, bad_center = 0;
  for (uint32_t y = 0; y < p.height; y++)
    for (uint32_t x = 0; x < p.width; x++) {
      const size_t i = (size_t)y * p.width + x;
      if (vis[3 * i] < 0.0f) continue;
      const uint32_t tri = (uint32_t)vis[3 * i];
      const hush_vec3 pt = hush_v3(pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]);
      /* the hit point projects back onto the jittered sample position */
      float cx, cy;
      REQUIRE(hush__camera_project(&ctx.cam, pt, 1.0f, &cx, &cy));
      if (fabsf(cx - ((float)x + 0.5f + ctx.cam.jitter[0])) > 0.01f ||
          fabsf(cy - ((float)y + 0.5f + ctx.cam.jitter[1])) > 0.01f)
        bad_center++;
      /* where it was: the object's previous transform, the previous camera */
      const uint32_t o = r.scene.triangle_object[tri];
      hush_vec3 prev = pt;
      if (r.scene.objects[o].motion.animated) {
        prev = hush__scene_point(&r.scene, tri, vis[3 * i + 1], vis[3 * i + 2], t - 1);
        moving++;
      }
      float px, py;
      if (!hush__camera_project(&ctx.prev_cam, prev, 1.0f, &px, &py)) continue;
      checked++;
      if (fabsf(px - cx - mot[2 * i]) > 0.01f || fabsf(py - cy - mot[2 * i + 1]) > 0.01f) bad++;
    }
  CHECK(checked > 1000);
  CHECK_MSG(bad == 0, "%s: %d of %d motion vectors off by more than 0.01 px", scene, bad, checked);
  CHECK_MSG(bad_center == 0, "%s: %d hit points do not project to their sample", scene, bad_center);
  if (expect_moving) CHECK_MSG(moving > 10, "%s: only %d pixels on moving objects", scene, moving);
  hush_frame_release(f);
  rig_close(&r);
}

/* ---- determinism --------------------------------------------------------------------------- */

static int same_layers(hush_frame a, hush_frame b) {
  if (a->layer_count != b->layer_count) return 0;
  for (uint32_t i = 0; i < a->layer_count; i++) {
    const hush_layer *la = &a->layers[i];
    const hush_layer *lb = hush__frame_find(b, la->name);
    if (!lb || lb->channels != la->channels) return 0;
    if (memcmp(la->pixels, lb->pixels, sizeof(float) * la->channels * a->width * a->height))
      return 0;
  }
  return 1;
}

static void test_determinism(void) {
  rig r;
  rig_open(&r, "cornell-moving");
  hush_render_params p;
  hush__render_defaults(&p);
  /* not multiples of the 4 x 4 packets nor of the 16 x 16 tiles */
  p.width = 67;
  p.height = 45;
  p.bounces = 3;
  for (int sampler = 0; sampler < 2; sampler++) {
    p.sampler = sampler ? HUSH_SAMPLER_LD : HUSH_SAMPLER_RANDOM;
    p.spp = sampler ? 4 : 1;
    hush_render_ctx c1, c2, c3;
    p.threads = 2;
    hush_frame a = render_at(&r, &p, HUSH_MOVE_ORBIT, 3, &c1);
    hush_frame b = render_at(&r, &p, HUSH_MOVE_ORBIT, 3, &c2);
    p.threads = 1;
    hush_frame c = render_at(&r, &p, HUSH_MOVE_ORBIT, 3, &c3);
    CHECK(same_layers(a, b));
    CHECK(same_layers(a, c));
    /* another frame uses other numbers */
    hush_frame d = render_at(&r, &p, HUSH_MOVE_ORBIT, 4, &c3);
    CHECK(!same_layers(a, d));
    /* a frame rendered into the last one's layers (as hush render does)
     * is the same as one rendered into a new frame */
    hush_frame e = render_at(&r, &p, HUSH_MOVE_ORBIT, 3, &c2);
    REQUIRE(hush__scene_set_frame(r.device, &r.scene, 4) == HUSH_OK);
    hush__lights_set_frame(&r.lights, 4);
    REQUIRE(hush__render_frame(r.device, &c3, e, NULL, NULL, NULL) == HUSH_OK);
    CHECK(same_layers(e, d));
    hush_frame_release(e);
    REQUIRE(hush__scene_set_frame(r.device, &r.scene, 3) == HUSH_OK);
    hush__lights_set_frame(&r.lights, 3);

    /* single pixels re-rendered alone reproduce the frame bit for bit,
     * every pixel: edge blocks of the primary-ray packets included */
    const float *color = layer(a, "color"), *vis = layer(a, "vis");
    int bad = 0, bad_vis = 0, close = 0, total = 0;
    for (uint32_t y = 0; y < p.height; y++)
      for (uint32_t x = 0; x < p.width; x++) {
        hush_pixel_result px;
        hush__render_pixel(&c1, x, y, 3, &px);
        const size_t i = (size_t)y * p.width + x;
        if (memcmp(px.color, color + 3 * i, sizeof px.color)) bad++;
        if (px.first.kind == HUSH_FIRST_TRIANGLE &&
            ((float)px.first.hit.triangle != vis[3 * i] || px.first.hit.u != vis[3 * i + 1] ||
             px.first.hit.v != vis[3 * i + 2]))
          bad_vis++;
      }
    CHECK_MSG(bad_vis == 0, "%d re-rendered pixels have another first hit", bad_vis);
    for (uint32_t k = 0; k < 50; k++) {
      const uint32_t x = (k * 37u) % p.width, y = (k * 11u) % p.height;
      /* re-shading the visibility sample with the same numbers gives the
       * same radiance up to the rounding of the recomputed hit point */
      const size_t i = (size_t)y * p.width + x;
      if (p.spp != 1 || vis[3 * i] < 0.0f) continue;
      hush_first_hit fh;
      REQUIRE(hush__integrator_first_hit(&c1.it, c1.cam.eye, (uint32_t)vis[3 * i], vis[3 * i + 1],
                                         vis[3 * i + 2], &fh));
      hush_rand rng;
      hush__rand_init(&rng, p.sampler, p.seed, 3, x, y, 0, 1);
      hush_path_result pr;
      hush__integrator_shade(&c1.it, c1.cam.eye, &fh, &rng, x, y, &pr);
      total++;
      const float *c0 = color + 3 * i;
      if (fabsf(pr.radiance[0] - c0[0]) <= 1e-3f * fmaxf(1.0f, c0[0]) &&
          fabsf(pr.radiance[1] - c0[1]) <= 1e-3f * fmaxf(1.0f, c0[1]))
        close++;
    }
    CHECK_MSG(bad == 0, "%d re-rendered pixels differ", bad);
    if (total) CHECK_MSG(close >= total * 9 / 10, "re-shaded %d of %d alike", close, total);
    hush_frame_release(a);
    hush_frame_release(b);
    hush_frame_release(c);
    hush_frame_release(d);
  }
  rig_close(&r);
}

/* ---- pixel blocks ----------------------------------------------------------------------- */

/* Counts the path-vertex hook's calls and hashes what they report, in any
 * order (the lanes of a block interleave their vertices). */
typedef struct hook_tally {
  uint32_t calls;
  uint32_t hash;
} hook_tally;

static void tally_vertex(void *user, const hush_path_vertex *v) {
  hook_tally *t = user;
  uint32_t c[3];
  memcpy(c, v->contribution, sizeof c);
  t->calls++;
  t->hash += hush_rng_u32(c[0] ^ (c[1] * 3u) ^ (c[2] * 7u), v->y * 4096u + v->x,
                          (uint32_t)v->depth * 31u + v->triangle);
}

/* hush__integrator_trace_block shades each lane exactly as
 * hush__integrator_trace_hit shades it alone (bit for bit: radiance,
 * layers, first hit, ray count, hook calls), whatever the other lanes are:
 * every 4 x 4 block of a frame, with full, partial and single-lane masks,
 * on scenes with glass, sphere lights, sun and sky, alpha masks; several
 * bounces, lobe split and both samplers. */
static void test_block_paths(void) {
  static const char *const scenes[] = {"cornell", "courtyard", "mask"};
  static const uint32_t masks[] = {0xffffu, 0x6b5du, 0x8001u, 0x0020u};
  for (int si = 0; si < 3; si++) {
    rig r;
    rig_open(&r, scenes[si]);
    hush_render_params p;
    hush__render_defaults(&p);
    p.width = 40;
    p.height = 28;
    p.bounces = si == 1 ? 3 : 1;
    p.split_lobes = si == 0;
    p.sampler = si == 2 ? HUSH_SAMPLER_LD : HUSH_SAMPLER_RANDOM;
    hush_render_ctx ctx;
    hush_frame f = render_at(&r, &p, HUSH_MOVE_ORBIT, 2, &ctx);
    hook_tally tb = {0, 0}, ts = {0, 0};
    int lanes_checked = 0, bad = 0, hits = 0;
    for (uint32_t y0 = 0; y0 < p.height; y0 += 4)
      for (uint32_t x0 = 0; x0 < p.width; x0 += 4) {
        float d[HUSH_PACKET][3];
        uint32_t xs[HUSH_PACKET], ys[HUSH_PACKET], inside = 0;
        hush_rand rng[HUSH_PACKET];
        for (uint32_t i = 0; i < HUSH_PACKET; i++) {
          xs[i] = x0 + i % 4;
          ys[i] = y0 + i / 4;
          const hush_vec3 v =
              hush__camera_ray(&ctx.cam, (float)xs[i] + 0.5f + ctx.cam.jitter[0],
                               (float)ys[i] + 0.5f + ctx.cam.jitter[1]);
          d[i][0] = v.x;
          d[i][1] = v.y;
          d[i][2] = v.z;
          hush__rand_init(&rng[i], p.sampler, p.seed, 2, xs[i], ys[i], 0, 1);
          if (xs[i] < p.width && ys[i] < p.height) inside |= 1u << i;
        }
        const float eye[3] = {ctx.cam.eye.x, ctx.cam.eye.y, ctx.cam.eye.z};
        hush_hit hit[HUSH_PACKET];
        hush__scene_intersect_packet(&r.scene, eye, (const float(*)[3])d, inside, hit);
        const uint32_t lanes = inside & masks[(x0 / 4 + y0 / 4) % 4];
        hush_first_hit fb[HUSH_PACKET];
        hush_path_result ob[HUSH_PACKET];
        ctx.it.vertex_fn = tally_vertex;
        ctx.it.vertex_user = &tb;
        hush__integrator_trace_block(&ctx.it, ctx.cam.eye, (const float(*)[3])d, hit, rng, xs, ys,
                                     lanes, fb, ob);
        ctx.it.vertex_user = &ts;
        for (uint32_t i = 0; i < HUSH_PACKET; i++) {
          if (!((lanes >> i) & 1u)) continue;
          hush_first_hit fs;
          hush_path_result os;
          hush__integrator_trace_hit(&ctx.it, ctx.cam.eye, hush_v3(d[i][0], d[i][1], d[i][2]),
                                     &hit[i], &rng[i], xs[i], ys[i], &fs, &os);
          lanes_checked++;
          hits += fs.kind == HUSH_FIRST_TRIANGLE;
          if (memcmp(&os, &ob[i], sizeof os) || fs.kind != fb[i].kind ||
              fs.hit.triangle != fb[i].hit.triangle ||
              memcmp(&fs.surface, &fb[i].surface, sizeof fs.surface) ||
              memcmp(&fs.p, &fb[i].p, sizeof fs.p))
            bad++;
        }
        ctx.it.vertex_fn = NULL;
      }
    CHECK_MSG(bad == 0, "%s: %d of %d block lanes differ from single paths", scenes[si], bad,
              lanes_checked);
    CHECK(lanes_checked > 400 && hits > 100);
    CHECK_MSG(tb.calls == ts.calls && tb.hash == ts.hash && tb.calls > 0,
              "%s: hook called %u times in blocks, %u alone", scenes[si], tb.calls, ts.calls);
    hush_frame_release(f);
    rig_close(&r);
  }
}

/* With a progressive pattern the frame shades only some lanes of a block;
 * every traced pixel still re-renders alone bit for bit. */
static void test_progressive_pixels(void) {
  rig r;
  rig_open(&r, "courtyard");
  hush_progressive prog;
  REQUIRE(hush__progressive_init(&prog, 0.25));
  hush_render_params p;
  hush__render_defaults(&p);
  p.width = 37;
  p.height = 21;
  p.progressive = &prog;
  hush_render_ctx ctx;
  hush_frame f = render_at(&r, &p, HUSH_MOVE_ORBIT, 5, &ctx);
  const float *color = layer(f, "color"), *spp = layer(f, "spp");
  int traced = 0, expected = 0, bad = 0;
  for (uint32_t y = 0; y < p.height; y++)
    for (uint32_t x = 0; x < p.width; x++) {
      const size_t i = (size_t)y * p.width + x;
      expected += hush__progressive_traced(&prog, x, y, 5);
      if (spp[i] == 0.0f) continue;
      traced++;
      hush_pixel_result px;
      hush__render_pixel(&ctx, x, y, 5, &px);
      if (memcmp(px.color, color + 3 * i, sizeof px.color)) bad++;
    }
  CHECK(traced == expected && traced > 150);
  CHECK_MSG(bad == 0, "%d of %d progressive pixels re-render differently", bad, traced);
  hush_frame_release(f);
  rig_close(&r);
}

/* Frames rendered one after the other into the same hush_frame, as
 * hush render does: every value is rewritten (the layers start out full of
 * 7s here), sky, sphere-light and progressive holes included, so each
 * frame equals one rendered into a new hush_frame. */
static void test_reuse_frame(void) {
  static const char *const scenes[] = {"courtyard", "moving-light"};
  for (int si = 0; si < 2; si++) {
    rig r;
    rig_open(&r, scenes[si]);
    hush_progressive prog;
    REQUIRE(hush__progressive_init(&prog, 0.25));
    hush_render_params p;
    hush__render_defaults(&p);
    p.width = 40;
    p.height = 30;
    p.split = p.split_lobes = 1;
    hush_render_ctx c;
    hush_frame reused = render_at(&r, &p, HUSH_MOVE_DOLLY, 0, &c);
    for (uint32_t l = 0; l < reused->layer_count; l++)
      for (size_t k = 0; k < (size_t)reused->layers[l].channels * p.width * p.height; k++)
        reused->layers[l].pixels[k] = 7.0f;
    for (uint32_t f = 1; f < 5; f++) {
      p.progressive = f > 1 ? &prog : NULL;
      hush_frame fresh = render_at(&r, &p, HUSH_MOVE_DOLLY, f, &c);
      REQUIRE(hush__render_frame(r.device, &c, reused, NULL, NULL, NULL) == HUSH_OK);
      CHECK_MSG(same_layers(reused, fresh), "%s: frame %u differs when rendered into used layers",
                scenes[si], f);
      hush_frame_release(fresh);
    }
    hush_frame_release(reused);
    rig_close(&r);
  }
}

/* ---- G-buffer --------------------------------------------------------------------------------- */

static void test_cornell_gbuffer(void) {
  rig r;
  rig_open(&r, "cornell");
  CHECK(hush__lights_any(&r.lights));
  hush_render_params p;
  hush__render_defaults(&p);
  p.width = p.height = 64;
  p.jitter = 0;
  hush_render_ctx ctx;
  hush_frame f = render_at(&r, &p, HUSH_MOVE_STATIC, 0, &ctx);
  const float *n = layer(f, "normal"), *alb = layer(f, "albedo"), *z = layer(f, "depth");
  const float *id = layer(f, "id"), *color = layer(f, "color");
  const uint32_t W = p.width, H = p.height;
  /* left wall (+x normal, red), right wall (-x, green), floor (+y), ceiling (-y), back (+z) */
  const struct {
    uint32_t x, y;
    float nx, ny, nz;
    int dominant; /* channel with the largest albedo, -1: grey */
  } probes[] = {{1, H / 2, 1, 0, 0, 0},  {W - 2, H / 2, -1, 0, 0, 1}, {W / 4, H - 2, 0, 1, 0, -1},
                {W / 4, 1, 0, -1, 0, -1}, {W / 2, H / 4, 0, 0, 1, -1}};
  for (size_t k = 0; k < sizeof probes / sizeof probes[0]; k++) {
    const size_t i = (size_t)probes[k].y * W + probes[k].x;
    CHECK_MSG(n[3 * i] * probes[k].nx + n[3 * i + 1] * probes[k].ny + n[3 * i + 2] * probes[k].nz >
                  0.999f,
              "probe %zu: normal (%g, %g, %g)", k, n[3 * i], n[3 * i + 1], n[3 * i + 2]);
    const float *a = alb + 3 * i;
    if (probes[k].dominant == 0) CHECK(a[0] > 2.0f * a[1] && a[0] > 2.0f * a[2]);
    if (probes[k].dominant == 1) CHECK(a[1] > 2.0f * a[0] && a[1] > 2.0f * a[2]);
    if (probes[k].dominant < 0) CHECK(fabsf(a[0] - a[1]) < 0.1f && a[0] > 0.3f);
    CHECK(id[i] >= 1.0f);
  }
  /* the camera at z = 3.4 sees only the inside of the box (z in [-1, 1]) */
  int outside = 0, dark = 0;
  for (uint32_t i = 0; i < W * H; i++) {
    if (!(z[i] >= 2.4f - 1e-3f && z[i] <= 4.4f + 1e-3f)) outside++;
    if (!(color[3 * i] >= 0.0f) || !isfinite(color[3 * i])) dark++;
  }
  CHECK_MSG(outside == 0, "%d depths outside the box", outside);
  CHECK(dark == 0);
  /* depth_gradient is the depth of the tangent plane at the next pixel:
   * where that pixel lies on the same plane, its depth is the prediction */
  const float *g = layer(f, "depth_gradient"), *pos = layer(f, "position");
  int pairs = 0, off = 0;
  for (uint32_t y = 0; y + 1 < H; y++)
    for (uint32_t x = 0; x + 1 < W; x++) {
      const size_t i = (size_t)y * W + x;
      for (int k = 0; k < 2; k++) {
        const size_t j = k == 0 ? i + 1 : i + W;
        const float *a = pos + 3 * i, *b = pos + 3 * j, *na = n + 3 * i;
        const float dist = (b[0] - a[0]) * na[0] + (b[1] - a[1]) * na[1] + (b[2] - a[2]) * na[2];
        if (!(fabsf(dist) < 1e-5f) || z[i] <= 0.0f || z[j] <= 0.0f) continue;
        pairs++;
        if (!(fabsf(z[i] + g[2 * i + k] - z[j]) <= 1e-4f * z[j])) off++;
      }
    }
  CHECK_MSG(pairs > (int)(W * H), "only %d coplanar neighbours", pairs);
  CHECK_MSG(off == 0, "%d of %d depth gradients miss the neighbour's depth", off, pairs);
  hush_frame_release(f);
  rig_close(&r);
}

/* ---- one-sided emitters ----------------------------------------------------------------- */

/* The Cornell lamp (builtin:cornell, y = 1.98, facing down, 2 cm below the
 * ceiling) lights what is below it and nothing above it: no light sample
 * is drawn from the gap above it, a camera ray meeting its back sees no
 * emission, and `two_sided_emitters` restores both (twice the power).
 * Without this the gap glowed and lit a rim of ceiling that no other
 * renderer's Cornell box has. */
static void test_one_sided_emitters(void) {
  rig r;
  rig_open(&r, "cornell");
  for (int two = 0; two <= 1; two++) {
    hush__lights_free(&r.lights);
    r.scene.two_sided_emitters = two;
    REQUIRE(hush__lights_init(r.device, &r.lights, &r.scene) == HUSH_OK);
    int below = 0, above = 0, wrong = 0;
    for (uint32_t i = 0; i < 4000; i++) {
      const float u[3] = {rnd(50, i), rnd(51, i), rnd(52, i)};
      hush_light_sample a;
      /* under the lamp, and in the gap above it */
      if (hush__lights_sample(&r.lights, hush_v3(0.1f, 1.0f, 0.05f), u, &a) && a.pdf > 0.0f) {
        below++;
        wrong += !(a.wi.y > 0.0f) || !(a.radiance[0] > 0.0f);
      }
      if (hush__lights_sample(&r.lights, hush_v3(0.1f, 1.99f, 0.05f), u, &a) && a.pdf > 0.0f) {
        above++;
        wrong += !(a.wi.y < 0.0f);
      }
    }
    CHECK_MSG(below == 4000 && wrong == 0, "two-sided %d: %d of 4000 samples below, %d wrong",
              two, below, wrong);
    CHECK_MSG(two ? above == 4000 : above == 0, "two-sided %d: %d samples from above the lamp", two,
              above);

    hush_integrator it;
    hush__integrator_defaults(&it, &r.scene, &r.lights);
    hush_rand rng;
    hush__rand_init(&rng, HUSH_SAMPLER_RANDOM, 1, 0, 0, 0, 0, 1);
    hush_path_result back, front;
    hush__integrator_trace(&it, hush_v3(0.1f, 1.99f, 0.05f), hush_v3(0.0f, -1.0f, 0.0f), &rng, 0,
                           0, NULL, &back);
    hush__integrator_trace(&it, hush_v3(0.1f, 1.5f, 0.05f), hush_v3(0.0f, 1.0f, 0.0f), &rng, 0, 0,
                           NULL, &front);
    CHECK_MSG(front.emission[0] == 17.0f, "the lamp's front: emission %g", front.emission[0]);
    CHECK_MSG(back.emission[0] == (two ? 17.0f : 0.0f), "two-sided %d: the lamp's back emits %g",
              two, back.emission[0]);
  }
  rig_close(&r);
}

/* ---- emission layer ----------------------------------------------------------------------- */

/* The emission layer holds what the camera ray sees directly at its first
 * hit: 0 on a non-emissive surface, the material's emission on an
 * emissive triangle (the Cornell lamp), the sphere's radiance on a sphere
 * light, and the whole colour on the sky (nothing else reaches a sky
 * pixel). Each sample's primary ray goes through the pixel centre (jitter
 * 0), so all of a pixel's samples see the same first hit. */
static void test_emission_layer(void) {
  static const char *const scenes[] = {"cornell", "courtyard", "moving-light"};
  for (size_t si = 0; si < sizeof scenes / sizeof scenes[0]; si++) {
    rig r;
    rig_open(&r, scenes[si]);
    hush_render_params p;
    hush__render_defaults(&p);
    p.width = p.height = 48;
    p.spp = 2;
    p.jitter = 0;
    hush_render_ctx ctx;
    hush_frame f = render_at(&r, &p, HUSH_MOVE_STATIC, 0, &ctx);
    const float *e = layer(f, "emission"), *color = layer(f, "color"), *vis = layer(f, "vis");
    int lamp = 0, sky = 0, sphere = 0, plain = 0, bad = 0;
    for (uint32_t i = 0; i < p.width * p.height; i++) {
      float expect[3] = {0.0f, 0.0f, 0.0f};
      const float v = vis[3 * i];
      if (v >= 0.0f) {
        const hush_material *m = &r.scene.materials[r.scene.triangle_material[(uint32_t)v]];
        const int emits = m->emission[0] + m->emission[1] + m->emission[2] > 0.0f;
        lamp += emits;
        plain += !emits;
        if (emits) memcpy(expect, m->emission, sizeof expect);
      } else if (v == -1.0f) {
        sky++;
        memcpy(expect, color + 3 * i, sizeof expect);
      } else {
        sphere++;
        memcpy(expect, r.scene.spheres[(uint32_t)(-2.0f - v)].radiance, sizeof expect);
      }
      for (int k = 0; k < 3; k++) {
        if (e[3 * i + k] != expect[k]) bad++;
        /* the rest of the radiance (reflected light) is never negative */
        if (!(color[3 * i + k] - e[3 * i + k] >= -1e-5f * (1.0f + e[3 * i + k]))) bad++;
      }
    }
    printf("emission %s: %d lamp, %d sphere, %d sky, %d other pixels\n", scenes[si], lamp, sphere,
           sky, plain);
    CHECK_MSG(bad == 0, "%s: %d emission values differ from the first hit's", scenes[si], bad);
    CHECK(plain > 100);
    if (si == 0) CHECK_MSG(lamp > 4, "cornell: only %d lamp pixels", lamp);
    if (si == 1) CHECK_MSG(sky > 20, "courtyard: only %d sky pixels", sky);
    hush_frame_release(f);
    rig_close(&r);
  }
}

/* ---- primary surface replacement ------------------------------------------------------- */

static uint32_t material_named(const hush_scene *sc, const char *name) {
  for (uint32_t i = 0; i < sc->material_count; i++)
    if (strcmp(sc->materials[i].name, name) == 0) return i;
  REQUIRE(0);
  return 0;
}

/* Bilinear sample of a 3-channel layer at continuous pixel coordinates
 * (pixel centres at +0.5); -1 when a tap falls outside. */
static float bilinear(const float *img, uint32_t W, uint32_t H, float fx, float fy, int c) {
  const float x = fx - 0.5f, y = fy - 0.5f;
  const int x0 = (int)floorf(x), y0 = (int)floorf(y);
  if (x0 < 0 || y0 < 0 || x0 + 1 >= (int)W || y0 + 1 >= (int)H) return -1.0f;
  const float ax = x - (float)x0, ay = y - (float)y0;
  const float *r0 = img + 3 * ((size_t)y0 * W + (size_t)x0), *r1 = r0 + 3 * (size_t)W;
  return (1 - ay) * ((1 - ax) * r0[c] + ax * r0[3 + c]) + ay * ((1 - ax) * r1[c] + ax * r1[3 + c]);
}

/* builtin:cornell-mirror (a mirror on the back wall, z = -0.995): with
 * mirror_depth, a mirror pixel's G-buffer is the virtual surface behind
 * the mirror (on the camera ray, the room reflected through the plane),
 * its albedo the mirror's reflectance times the reflected surface's, its
 * emission the lamp seen in it; the colour is the same bits as without;
 * and its motion vectors follow the reflection, which the mirror's own
 * do not: the previous frame's colour where they point matches the pixel's
 * far better. Curved (smooth-normal) triangles are not planar mirrors. */
/* |prev - cur| summed over the 3 channels of pixel (x, y), prev read
 * bilinearly where motion (mx, my) points; -1 when that is off the image. */
static float history_error(const float *prev, const float *cur, uint32_t W, uint32_t H,
                           uint32_t x, uint32_t y, float mx, float my) {
  const size_t i = (size_t)y * W + x;
  float e = 0.0f;
  for (int c = 0; c < 3; c++) {
    const float h = bilinear(prev, W, H, (float)x + 0.5f + mx, (float)y + 0.5f + my, c);
    if (h < 0.0f) return -1.0f;
    e += fabsf(h - cur[3 * i + c]);
  }
  return e;
}

/* Whether pixel (x, y) (2 or more from the border) and its 5x5
 * neighbourhood all see material `mirror` first, and, with depth z not
 * NULL, a surface behind it (not the sky). */
static int mirror_interior(const hush_scene *sc, uint32_t mirror, const float *vis,
                           const float *z, uint32_t W, uint32_t x, uint32_t y) {
  for (int dy = -2; dy <= 2; dy++)
    for (int dx = -2; dx <= 2; dx++) {
      const size_t j = (size_t)((int)y + dy) * W + (size_t)((int)x + dx);
      if (!(vis[3 * j] >= 0.0f) || sc->triangle_material[(uint32_t)vis[3 * j]] != mirror) return 0;
      if (z && !(z[j] > 0.0f)) return 0;
    }
  return 1;
}

static void test_mirror_gbuffer(void) {
  rig r;
  rig_open(&r, "cornell-mirror");
  const uint32_t mirror = material_named(&r.scene, "mirror");
  const uint32_t green = material_named(&r.scene, "green");
  const uint32_t light = material_named(&r.scene, "light");
  for (uint32_t t = 0; t < r.scene.triangle_count; t++)
    CHECK(hush__scene_triangle_flat(&r.scene, t));
  hush_render_params p;
  hush__render_defaults(&p);
  p.width = p.height = 96;
  p.spp = 4;
  p.jitter = 0;
  const uint32_t W = p.width, H = p.height, t1 = 6;
  hush_frame f[2][2]; /* [mirror_depth on][frame t1 - 1, t1] */
  hush_render_ctx ctx[2][2];
  for (int on = 0; on < 2; on++) {
    p.mirror_depth = on ? HUSH_RENDER_MIRROR_DEPTH_MAX : 0;
    for (int k = 0; k < 2; k++) f[on][k] = render_at(&r, &p, HUSH_MOVE_ORBIT, t1 - 1 + (uint32_t)k,
                                                     &ctx[on][k]);
  }
  /* only the G-buffer and the emission layer change */
  for (int k = 0; k < 2; k++)
    CHECK(memcmp(layer(f[0][k], "color"), layer(f[1][k], "color"), 3 * sizeof(float) * W * H) ==
          0);
  const float *vis = layer(f[1][1], "vis"), *pos = layer(f[1][1], "position");
  const float *pos0 = layer(f[0][1], "position"), *alb = layer(f[1][1], "albedo");
  const float *id = layer(f[1][1], "id"), *em = layer(f[1][1], "emission");
  const float *em0 = layer(f[0][1], "emission"), *color = layer(f[1][1], "color");
  const float *z = layer(f[1][1], "depth");
  const hush_material *mg = &r.scene.materials[green], *ml = &r.scene.materials[light];
  int mirrors = 0, behind = 0, off_plane = 0, off_ray = 0, outside = 0, greens = 0, bad_green = 0;
  int lamps = 0, bad_lamp = 0, lit0 = 0;
  for (uint32_t y = 0; y < H; y++)
    for (uint32_t x = 0; x < W; x++) {
      const size_t i = (size_t)y * W + x;
      if (vis[3 * i] < 0.0f ||
          r.scene.triangle_material[(uint32_t)vis[3 * i]] != mirror)
        continue;
      mirrors++;
      if (fabsf(pos0[3 * i + 2] + 0.995f) > 1e-3f) off_plane++;
      lit0 += em0[3 * i] != 0.0f;
      if (z[i] == 0.0f) continue; /* the open front of the box, seen in the mirror */
      behind++;
      const hush_vec3 v = hush_v3(pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]);
      float cx, cy;
      if (!hush__camera_project(&ctx[1][1].cam, v, 1.0f, &cx, &cy) ||
          fabsf(cx - ((float)x + 0.5f)) > 0.01f || fabsf(cy - ((float)y + 0.5f)) > 0.01f)
        off_ray++;
      /* reflected back through the plane, the point lies in the room */
      const float rz = -1.99f - v.z;
      if (!(v.z < -0.995f + 1e-3f) || fabsf(v.x) > 1.001f || v.y < -1e-3f || v.y > 2.001f ||
          rz < -1.001f || rz > 1.001f)
        outside++;
      const uint32_t m = (uint32_t)id[i] - 1u;
      if (m == green) {
        greens++;
        const float f0 = alb[3 * i] / mg->diffuse[0];
        for (int k = 0; k < 3; k++)
          if (!(fabsf(alb[3 * i + k] / mg->diffuse[k] - f0) < 1e-4f) || f0 < 0.89f || f0 > 1.0f)
            bad_green++;
      }
      if (m == light) {
        lamps++;
        const float f0 = em[3 * i] / ml->emission[0];
        for (int k = 0; k < 3; k++)
          if (!(fabsf(em[3 * i + k] / ml->emission[k] - f0) < 1e-4f) || f0 < 0.89f ||
              f0 > 1.0f || color[3 * i + k] < em[3 * i + k] * (1.0f - 1e-5f))
            bad_lamp++;
      }
    }
  printf("mirror: %d pixels, %d with a surface behind (%d green wall, %d lamp)\n", mirrors,
         behind, greens, lamps);
  CHECK_MSG(mirrors > 1000 && behind > 500, "%d mirror pixels, %d behind", mirrors, behind);
  CHECK_MSG(off_plane == 0, "mirror_depth 0: %d mirror positions off the mirror", off_plane);
  CHECK_MSG(lit0 == 0, "mirror_depth 0: %d mirror pixels with emission", lit0);
  CHECK_MSG(off_ray == 0 && outside == 0, "%d virtual points off the camera ray, %d not the room's",
            off_ray, outside);
  CHECK_MSG(greens > 20 && bad_green == 0, "%d of %d green-wall albedos not reflectance x Kd",
            bad_green, greens);
  CHECK_MSG(lamps > 3 && bad_lamp == 0, "%d of %d lamp emissions not reflectance x Le", bad_lamp,
            lamps);

  /* motion: what the mirror shows (the replaced albedo, noise-free; the
   * open front of the box is white) in the previous frame where the vector
   * points, against the pixel's own, over the mirror's interior (a pixel
   * whose 5x5 neighbourhood is all mirror) */
  const float *alb_prev = layer(f[1][0], "albedo");
  double err[2] = {0.0, 0.0};
  int n = 0;
  for (uint32_t y = 2; y + 2 < H; y++)
    for (uint32_t x = 2; x + 2 < W; x++) {
      if (!mirror_interior(&r.scene, mirror, vis, NULL, W, x, y)) continue;
      const size_t i = (size_t)y * W + x;
      float e[2];
      for (int on = 0; on < 2; on++) {
        const float *mot = layer(f[on][1], "motion");
        e[on] = history_error(alb_prev, alb, W, H, x, y, mot[2 * i], mot[2 * i + 1]);
      }
      if (e[0] < 0.0f || e[1] < 0.0f) continue;
      err[0] += e[0];
      err[1] += e[1];
      n++;
    }
  printf("mirror: motion over %d pixels: |history - albedo| %.4f along the mirror's own motion, "
         "%.4f along the reflection's\n",
         n, err[0] / n, err[1] / n);
  CHECK(n > 200);
  CHECK_MSG(err[1] < 0.5 * err[0], "motion through the mirror: %.4f vs %.4f", err[1] / n,
            err[0] / n);
  /* with the split, the lamp seen in the mirror is direct light: svgf
   * takes the emission off 'direct' */
  p.split = 1;
  hush_render_ctx sctx;
  hush_frame fs = render_at(&r, &p, HUSH_MOVE_ORBIT, t1, &sctx);
  const float *dir = layer(fs, "direct"), *ems = layer(fs, "emission");
  int lit = 0, short_direct = 0;
  for (size_t i = 0; i < (size_t)W * H; i++) {
    if (!(ems[3 * i] > 0.0f)) continue;
    lit++;
    for (int c = 0; c < 3; c++)
      if (!(dir[3 * i + c] >= ems[3 * i + c] * (1.0f - 1e-5f))) short_direct++;
  }
  CHECK_MSG(lit > 3 && short_direct == 0, "%d of %d lit pixels with less direct than emission",
            short_direct, lit);
  /* and a mirror pixel splits its light as the surface behind it would,
   * seen directly: every surface behind this mirror is Lambert, so all of
   * it is diffuse (the mirror's own delta lobe would make it specular), and
   * the light sample of the wall seen in it is direct light */
  p.split_lobes = 1;
  hush_frame fl = render_at(&r, &p, HUSH_MOVE_ORBIT, t1, &sctx);
  const float *dif = layer(fl, "diffuse"), *spec = layer(fl, "specular");
  const float *dirl = layer(fl, "direct"), *visl = layer(fl, "vis"), *idl = layer(fl, "id");
  int seen = 0, specular = 0, walls = 0, wall_direct = 0;
  for (size_t i = 0; i < (size_t)W * H; i++) {
    if (visl[3 * i] < 0.0f || r.scene.triangle_material[(uint32_t)visl[3 * i]] != mirror) continue;
    if (dif[3 * i] + dif[3 * i + 1] + dif[3 * i + 2] > 0.0f) seen++;
    if (spec[3 * i] != 0.0f || spec[3 * i + 1] != 0.0f || spec[3 * i + 2] != 0.0f) specular++;
    if ((uint32_t)idl[i] - 1u != green) continue;
    walls++;
    wall_direct += dirl[3 * i + 1] > 0.0f;
  }
  printf("mirror: split: %d pixels with diffuse light, %d with specular; %d of %d green-wall "
         "pixels with direct light\n", seen, specular, wall_direct, walls);
  CHECK_MSG(seen > 300 && specular == 0, "%d mirror pixels with specular light", specular);
  CHECK_MSG(walls > 20 && wall_direct > walls * 3 / 4, "%d of %d green-wall pixels in the mirror "
            "with direct light", wall_direct, walls);
  hush_frame_release(fl);
  hush_frame_release(fs);
  for (int on = 0; on < 2; on++)
    for (int k = 0; k < 2; k++) hush_frame_release(f[on][k]);
  rig_close(&r);

  /* the courtyard's spheres have smooth normals: not planar */
  rig_open(&r, "courtyard");
  uint32_t curved = 0;
  for (uint32_t t = 0; t < r.scene.triangle_count; t++)
    curved += !hush__scene_triangle_flat(&r.scene, t);
  CHECK_MSG(curved > 1000, "courtyard: %u curved triangles", curved);
  rig_close(&r);
}

/* A mirror that turns (cornell-mirror's mirror set spinning about the
 * vertical, 2 degrees a frame, before the scene is committed; a still
 * camera): what it shows moves with it, so the motion vectors over it must
 * follow the reflection through the mirror where it was in the previous
 * frame. Over the room seen in it (the open front, sky, left out: its
 * edges are parallax, not motion), the previous frame's noise-free albedo
 * where they point matches the pixel's own far better than with no motion
 * (what a still-mirror assumption gives for the still room). */
static void test_moving_mirror(void) {
  rig r;
  memset(&r, 0, sizeof r);
  r.device = hush_device_new("threads=2");
  REQUIRE(r.device);
  REQUIRE(hush__scene_builtin(r.device, "cornell-mirror", &r.scene) == HUSH_OK);
  hush_object *mo = NULL;
  for (uint32_t o = 0; o < r.scene.object_count; o++)
    if (strcmp(r.scene.objects[o].name, "mirror") == 0) mo = &r.scene.objects[o];
  REQUIRE(mo);
  mo->motion.animated = 1;
  mo->motion.spin_deg_per_frame = 2.0f;
  mo->motion.pivot[0] = 0.35f, mo->motion.pivot[1] = 1.0f, mo->motion.pivot[2] = -0.995f;
  mo->motion.translation[2] = 0.1f; /* clear of the back wall as it turns */
  REQUIRE(hush__scene_commit(r.device, &r.scene) == HUSH_OK);
  REQUIRE(hush__lights_init(r.device, &r.lights, &r.scene) == HUSH_OK);
  const uint32_t mirror = material_named(&r.scene, "mirror");
  hush_render_params p;
  hush__render_defaults(&p);
  p.spp = 4;
  p.jitter = 0;
  p.width = p.height = 128;
  const uint32_t W = p.width, H = p.height, t1 = 4;
  hush_render_ctx c0, c1;
  hush_frame f0 = render_at(&r, &p, HUSH_MOVE_STATIC, t1 - 1, &c0);
  hush_frame f1 = render_at(&r, &p, HUSH_MOVE_STATIC, t1, &c1);
  const float *vis = layer(f1, "vis"), *alb = layer(f1, "albedo"), *mot = layer(f1, "motion");
  const float *alb_prev = layer(f0, "albedo"), *z = layer(f1, "depth");
  double err_motion = 0.0, err_still = 0.0, moved = 0.0;
  int n = 0;
  for (uint32_t y = 2; y + 2 < H; y++)
    for (uint32_t x = 2; x + 2 < W; x++) {
      if (!mirror_interior(&r.scene, mirror, vis, z, W, x, y)) continue;
      const size_t i = (size_t)y * W + x;
      const float e[2] = {history_error(alb_prev, alb, W, H, x, y, mot[2 * i], mot[2 * i + 1]),
                          history_error(alb_prev, alb, W, H, x, y, 0.0f, 0.0f)};
      if (e[0] < 0.0f || e[1] < 0.0f) continue;
      err_motion += e[0];
      err_still += e[1];
      moved += hypotf(mot[2 * i], mot[2 * i + 1]);
      n++;
    }
  printf("moving mirror: %d pixels, mean motion %.2f px; |history - albedo| %.4f along the "
         "vectors, %.4f without motion\n", n, moved / n, err_motion / n, err_still / n);
  CHECK(n > 200);
  CHECK_MSG(moved / n > 0.5, "the reflection moved %.2f px a frame", moved / n);
  CHECK_MSG(err_motion < 0.5 * err_still, "motion behind a turning mirror: %.4f vs %.4f",
            err_motion / n, err_still / n);
  hush_frame_release(f0);
  hush_frame_release(f1);
  rig_close(&r);
}

/* ---- diffuse / specular split ----------------------------------------------------------------- */

/* hush__bsdf_eval_lobes: the lobes add up to hush__bsdf_eval bit for bit,
 * Lambert has no glossy lobe, a conductor no diffuse one, a rough plastic
 * both. */
static void test_bsdf_lobes(void) {
  const bsdf_case cases[] = {
      {"lambert", HUSH_MAT_DIFFUSE, 0.7f, 0.0f, 0.0f, 0},
      {"plastic-smooth", HUSH_MAT_PLASTIC, 0.7f, 0.04f, 0.0f, 1},
      {"plastic-rough", HUSH_MAT_PLASTIC, 0.7f, 0.04f, 0.3f, 0},
      {"conductor-rough", HUSH_MAT_CONDUCTOR, 0.0f, 0.9f, 0.3f, 0},
  };
  for (size_t ci = 0; ci < sizeof cases / sizeof cases[0]; ci++) {
    const hush_vec3 wo = hush_v3(0.6f, 0.0f, 0.8f);
    hush_bsdf b;
    make_bsdf(&cases[ci], wo, &b);
    int differ = 0, diffuse = 0, glossy = 0;
    for (int k = 0; k < 2000; k++) {
      const hush_vec3 wi = uniform_sphere(rnd(40, k), rnd(41, k));
      float f[3], fd[3], fs[3], pdf, pdf_l;
      hush__bsdf_eval(&b, wo, wi, f, &pdf);
      hush__bsdf_eval_lobes(&b, wo, wi, fd, fs, &pdf_l);
      for (int c = 0; c < 3; c++) {
        const float sum = fd[c] + fs[c];
        if (memcmp(&sum, &f[c], sizeof sum) || pdf != pdf_l) differ++;
        diffuse += fd[c] > 0.0f;
        glossy += fs[c] > 0.0f;
      }
    }
    CHECK_MSG(differ == 0, "%s: %d lobe sums differ from eval", cases[ci].name, differ);
    const int lambert = cases[ci].type == HUSH_MAT_DIFFUSE;
    const int conductor = cases[ci].type == HUSH_MAT_CONDUCTOR;
    const int rough = cases[ci].roughness > 0.0f;
    CHECK_MSG((diffuse > 0) == !conductor, "%s: diffuse lobe %d", cases[ci].name, diffuse);
    CHECK_MSG((glossy > 0) == (!lambert && rough), "%s: glossy lobe %d", cases[ci].name, glossy);
  }
}

/* The diffuse and specular layers: color is exactly their sum and within
 * rounding of the unsplit colour (the paths are the same); a pure Lambert
 * scene has no specular, a surface of conductors and glass no diffuse
 * (where the camera does not see a light), a mix has both. */
static void test_lobe_layers(void) {
  static const char *const scenes[] = {"cornell", "courtyard", "cornell-metal"};
  for (int si = 0; si < 3; si++) {
    rig r;
    rig_open(&r, si == 2 ? "cornell" : scenes[si]);
    if (si == 2)
      for (uint32_t m = 0; m < r.scene.material_count; m++) {
        hush_material *mat = &r.scene.materials[m];
        if (mat->emission[0] + mat->emission[1] + mat->emission[2] > 0.0f) continue;
        /* rough and glossy metal, a mirror and glass: no diffuse lobe */
        mat->type = m % 4 == 3 ? HUSH_MAT_DIELECTRIC : HUSH_MAT_CONDUCTOR;
        mat->roughness = m % 4 == 2 ? 0.0f : m % 4 == 1 ? 0.05f : 0.3f;
        for (int c = 0; c < 3; c++) mat->specular[c] = 0.9f - 0.1f * (float)c;
      }
    hush_render_params p;
    hush__render_defaults(&p);
    p.width = 48;
    p.height = 36;
    p.bounces = 2;
    /* more samples may land on another material than the G-buffer's
     * sample 0: 1 spp where materials are checked pixel by pixel */
    p.spp = si == 0 ? 3 : 1;
    hush_render_ctx c1, c2;
    hush_frame plain = render_at(&r, &p, HUSH_MOVE_STATIC, 0, &c1);
    p.split_lobes = 1;
    hush_frame split = render_at(&r, &p, HUSH_MOVE_STATIC, 0, &c2);
    const float *color = layer(split, "color"), *d = layer(split, "diffuse");
    const float *sp = layer(split, "specular"), *color0 = layer(plain, "color");
    const float *id = layer(split, "id");
    int inexact = 0, far = 0, spec_in_lambert = 0, diff_in_metal = 0, seen = 0;
    double dsum = 0.0, ssum = 0.0;
    for (uint32_t i = 0; i < 3 * p.width * p.height; i++) {
      const float sum = d[i] + sp[i];
      if (memcmp(&sum, &color[i], sizeof sum)) inexact++;
      if (!(fabsf(color[i] - color0[i]) <= 1e-5f * fmaxf(1.0f, color0[i]))) far++;
      dsum += d[i];
      ssum += sp[i];
      const uint32_t m = (uint32_t)id[i / 3];
      if (m == 0 || m > r.scene.material_count) continue; /* sky, sphere lights */
      const hush_material *mat = &r.scene.materials[m - 1];
      if (mat->emission[0] + mat->emission[1] + mat->emission[2] > 0.0f) continue;
      seen++;
      if (mat->type == HUSH_MAT_DIFFUSE && sp[i] != 0.0f) spec_in_lambert++;
      if ((mat->type == HUSH_MAT_CONDUCTOR || mat->type == HUSH_MAT_DIELECTRIC) && d[i] != 0.0f)
        diff_in_metal++;
    }
    CHECK_MSG(inexact == 0, "%s: %d colours are not diffuse + specular", scenes[si], inexact);
    CHECK_MSG(far == 0, "%s: %d split colours differ from the unsplit ones", scenes[si], far);
    CHECK_MSG(spec_in_lambert == 0, "%s: %d Lambert pixels with specular", scenes[si],
              spec_in_lambert);
    CHECK_MSG(diff_in_metal == 0, "%s: %d conductor/glass pixels with diffuse", scenes[si],
              diff_in_metal);
    CHECK(seen > 0);
    if (si == 0) CHECK_MSG(ssum == 0.0, "cornell (all Lambert): specular sum %g", ssum);
    if (si >= 1) CHECK_MSG(ssum > 0.01 * (dsum + ssum), "%s: specular %g of %g", scenes[si], ssum,
                           dsum + ssum);
    if (si == 1) CHECK_MSG(dsum > 0.01 * (dsum + ssum), "courtyard: diffuse %g", dsum);
    /* the G-buffer does not change */
    CHECK(!memcmp(layer(split, "vis"), layer(plain, "vis"), 3 * sizeof(float) * p.width * p.height));
    hush_frame_release(plain);
    hush_frame_release(split);
    rig_close(&r);
  }
}

/* ---- camera -------------------------------------------------------------------------------------- */

static void test_camera(void) {
  hush_camera_pose pose = {{1, 2, 3}, {0, 1, 0}, {0, 1, 0}, 50.0f};
  for (int axis = 0; axis < 2; axis++) {
    hush_render_camera cam;
    REQUIRE(hush__camera_setup(&cam, &pose, axis, 160, 90, 0.01f, 100.0f, 7, 1));
    CHECK(cam.jitter[0] >= -0.5f && cam.jitter[0] < 0.5f);
    CHECK(cam.jitter[1] >= -0.5f && cam.jitter[1] < 0.5f);
    for (int k = 0; k < 20; k++) {
      const float px = rnd(30, k) * 160.0f, py = rnd(31, k) * 90.0f;
      const hush_vec3 d = hush__camera_ray(&cam, px, py);
      float qx, qy;
      REQUIRE(hush__camera_project(&cam, hush_v3_add(cam.eye, hush_v3_scale(d, 3.0f)), 1.0f, &qx,
                                   &qy));
      CHECK(fabsf(qx - px) < 1e-3f && fabsf(qy - py) < 1e-3f);
    }
    /* the fov is measured along the requested axis */
    const hush_vec3 l = hush__camera_ray(&cam, 0.0f, 45.0f), rr = hush__camera_ray(&cam, 160.0f, 45.0f);
    const hush_vec3 t = hush__camera_ray(&cam, 80.0f, 0.0f), b = hush__camera_ray(&cam, 80.0f, 90.0f);
    const float fov = acosf(axis ? hush_v3_dot(l, rr) : hush_v3_dot(t, b)) * 180.0f / (float)T_PI;
    CHECK_NEAR(fov, 50.0, 0.01);
  }
  /* Halton jitter: 16 distinct offsets */
  float j0[2], j1[2];
  hush__camera_jitter(0, j0);
  hush__camera_jitter(16, j1);
  CHECK(j0[0] == j1[0] && j0[1] == j1[1]);
  CHECK_NEAR(j0[0], 0.0, 1e-6);  /* halton(1, 2) = 0.5 */
}

/* The tabulated sky against the exact Preetham model over the upper
 * hemisphere, for a high and a low sun and three turbidities: the largest
 * relative error of the luminance and of each channel stays small. */
static void test_sky_table(void) {
  static hush_sky_table table;
  const float suns[2][3] = {{-0.865804f, 0.416766f, -0.276929f}, {0.3f, 0.08f, 0.95f}};
  const float turbidity[3] = {2.0f, 3.0f, 6.0f};
  double worst_lum = 0.0, worst_rgb = 0.0;
  for (int si = 0; si < 2; si++)
    for (int ti = 0; ti < 3; ti++) {
      hush_sky_model sky;
      const hush_vec3 sun = hush_v3_normalize(hush_v3(suns[si][0], suns[si][1], suns[si][2]));
      hush__sky_model_init(&sky, sun, turbidity[ti]);
      hush__sky_table_init(&table, &sky);
      for (uint32_t i = 0; i < 200000; i++) {
        hush_vec3 d = uniform_sphere(rnd(40, i), rnd(41, i));
        if (d.y < 0.0f) d.y = -d.y;
        if (d.y <= 0.0f) continue;
        float a[3], b[3];
        hush__sky_model_eval(&sky, d, a);
        hush__sky_table_eval(&table, d, b);
        const double la = hush_luminance(a[0], a[1], a[2]), lb = hush_luminance(b[0], b[1], b[2]);
        if (la > 0.0) worst_lum = fmax(worst_lum, fabs(lb / la - 1.0));
        for (int k = 0; k < 3; k++)
          if (a[k] > 1e-3f * (float)la) worst_rgb = fmax(worst_rgb, fabs(b[k] / a[k] - 1.0));
      }
    }
  printf("sky table: max relative error %.2e (luminance), %.2e (channels)\n", worst_lum, worst_rgb);
  CHECK_MSG(worst_lum < 1e-3, "sky table luminance error %g", worst_lum);
  CHECK_MSG(worst_rgb < 1e-3, "sky table channel error %g", worst_rgb);
}

/* hush__envmap_dir_to_uv's polynomial acos and atan2 against libm. */
static void test_dir_to_uv(void) {
  double worst = 0.0;
  for (uint32_t i = 0; i < 400000; i++) {
    const hush_vec3 d = uniform_sphere(rnd(42, i), rnd(43, i));
    float u, v;
    hush__envmap_dir_to_uv(d, &u, &v);
    double eu = atan2((double)d.x, -(double)d.z) / (2.0 * T_PI);
    if (eu < 0.0) eu += 1.0;
    const double ev = acos(fmin(1.0, fmax(-1.0, (double)d.y))) / T_PI;
    double du = fabs(u - eu);
    if (du > 0.5) du = 1.0 - du; /* wrap-around at u = 0 */
    worst = fmax(worst, fmax(du, fabs(v - ev)));
  }
  printf("dir_to_uv: max error %.2e\n", worst);
  CHECK_MSG(worst < 1e-6, "dir_to_uv error %g", worst);
}

int main(void) {
  test_camera();
  test_dir_to_uv();
  test_sky_table();
  test_bsdfs();
  test_demodulation_albedo();
  test_envmap();
  test_envmap_shortcuts();
  test_deferred_light_samples();
  test_furnace();
  test_motion("cornell-moving", HUSH_MOVE_ORBIT, 1);
  test_motion("courtyard", HUSH_MOVE_DOLLY, 1);
  test_determinism();
  test_block_paths();
  test_progressive_pixels();
  test_reuse_frame();
  test_cornell_gbuffer();
  test_emission_layer();
  test_one_sided_emitters();
  test_mirror_gbuffer();
  test_moving_mirror();
  test_bsdf_lobes();
  test_lobe_layers();
  return check_summary();
}
