/*
 * test_gradients.c — A-SVGF gradient samples in the renderer
 * (src/render/gradients.c, realtime-denoising-comparison-higginson-2023.md
 * §2.3.1): a static scene and camera give a gradient of exactly 0 and leave
 * every other pixel as it was; a light switched off gives a large relative
 * gradient where it lit; forward projection lands on the pixel that sees the
 * sample's surface point under camera motion and object motion, checked
 * against the renderer's own motion vectors; a sample on a planar mirror is
 * the surface behind it, found again from a moved eye; the result does not depend on
 * the thread count; and `hush render --gradients`
 * writes the layer (half EXRs too) and rejects --spp > 1.
 */
#include "check.h"

#include "core/hmath.h"
#include "io/frame.h"
#include "render/camera.h"
#include "render/gradients.h"
#include "render/lights.h"
#include "render/render.h"
#include "render/scene.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>

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

/* Sets the scene to frame sf and renders frame f of the camera move into
 * out (reused over a sequence, as hush render does); ctx receives the
 * set-up. */
static void render_scene_frame(rig *r, const hush_render_params *p, hush_camera_move move,
                               uint32_t sf, uint32_t f, hush_render_ctx *ctx, hush_frame out) {
  REQUIRE(hush__scene_set_frame(r->device, &r->scene, sf) == HUSH_OK);
  hush__lights_set_frame(&r->lights, sf);
  hush_camera_pose pose;
  int ax;
  float zn, zf;
  hush__camera_pose(&r->scene, move, NULL, 0, &pose, &ax);
  hush__camera_clip_range(&r->scene, hush_v3(pose.position[0], pose.position[1], pose.position[2]),
                          &zn, &zf);
  hush__camera_pose(&r->scene, move, NULL, f, &pose, &ax);
  hush_render_camera cam, prev;
  REQUIRE(hush__camera_setup(&cam, &pose, ax, p->width, p->height, zn, zf, f, p->jitter));
  if (f > 0) {
    hush__camera_pose(&r->scene, move, NULL, f - 1, &pose, &ax);
    REQUIRE(hush__camera_setup(&prev, &pose, ax, p->width, p->height, zn, zf, f - 1, p->jitter));
  }
  hush__render_ctx_init(ctx, &r->scene, &r->lights, p, &cam, f > 0 ? &prev : NULL, f);
  REQUIRE(hush__render_frame(r->device, ctx, out, NULL, NULL, NULL) == HUSH_OK);
}

/* The same with the scene at frame f too. */
static void render_into(rig *r, const hush_render_params *p, hush_camera_move move, uint32_t f,
                        hush_render_ctx *ctx, hush_frame out) {
  render_scene_frame(r, p, move, f, f, ctx, out);
}

static float *layer(hush_frame f, const char *name) {
  hush_layer *l = hush__frame_find(f, name);
  REQUIRE(l);
  return l->pixels;
}

static float lum(const float *c) {
  return hush_luminance(c[0], c[1], c[2]);
}

static void params_for(hush_render_params *p, uint32_t w, uint32_t h) {
  hush__render_defaults(p);
  p->width = w;
  p->height = h;
  p->threads = 2;
}

/* Opens built-in scene `name` into r, render parameters for w x h with the
 * gradients g (initialised here, defaults) and a frame to render into
 * (the caller releases it and frees g). */
static hush_frame open_with_gradients(rig *r, const char *name, uint32_t w, uint32_t h,
                                      hush_render_params *p, hush_gradients *g) {
  rig_open(r, name);
  params_for(p, w, h);
  REQUIRE(hush__gradients_init(r->device, g, p->width, p->height) == HUSH_OK);
  p->gradients = g;
  hush_frame out = hush_frame_new(r->device, p->width, p->height);
  REQUIRE(out);
  return out;
}

/* The layer "gradient" holds, at every pixel of a stratum, what g says
 * about that stratum. Returns the number of accepted samples. */
static int check_layer(const hush_gradients *g, hush_frame out) {
  const float *gl = layer(out, "gradient");
  int bad = 0, accepted = 0;
  for (uint32_t y = 0; y < g->height; y++)
    for (uint32_t x = 0; x < g->width; x++) {
      const uint32_t t = (y / 3) * g->strata_x + x / 3;
      const float *o = gl + 3 * ((size_t)y * g->width + x);
      const int a = g->accepted[t];
      if (o[2] != (float)a) bad++;
      if (a >= 0 && (o[0] != g->current[t] || o[1] != g->previous[t])) bad++;
      if (a < 0 && (o[0] != 0.0f || o[1] != 0.0f)) bad++;
      if (x % 3 == 0 && y % 3 == 0 && a >= 0) accepted++;
    }
  CHECK_MSG(bad == 0, "%d pixels of the gradient layer disagree with the strata", bad);
  return accepted;
}

/* The landing pixel of accepted stratum t. */
static void landing_xy(const hush_gradients *g, uint32_t t, uint32_t *x, uint32_t *y) {
  const int32_t a = g->accepted[t];
  *x = (t % g->strata_x) * 3 + (uint32_t)a % 3;
  *y = (t / g->strata_x) * 3 + (uint32_t)a / 3;
}

/* ---- static scene and camera: exactly zero ------------------------------------------ */

static void test_static_zero(hush_gradient_landing mode, hush_gradient_lobe lobe) {
  rig r;
  rig_open(&r, "cornell");
  hush_render_params p;
  params_for(&p, 97, 70); /* not multiples of 3 */
  hush_gradients g;
  REQUIRE(hush__gradients_init(r.device, &g, p.width, p.height) == HUSH_OK);
  CHECK(g.landing_mode == HUSH_GRADIENT_LANDING_FRESH); /* the default: an unbiased image */
  CHECK(g.lobe == HUSH_GRADIENT_LOBE_DIFFUSE); /* the default */
  g.landing_mode = mode;
  g.lobe = lobe;
  const int sample = mode == HUSH_GRADIENT_LANDING_SAMPLE;
  p.gradients = &g;
  hush_render_params plain = p;
  plain.gradients = NULL;
  hush_frame out = hush_frame_new(r.device, p.width, p.height);
  hush_frame ref = hush_frame_new(r.device, p.width, p.height);
  float *prev_color = malloc(sizeof(float) * 3 * p.width * p.height);
  REQUIRE(out && ref && prev_color);
  const uint32_t strata = g.strata_x * g.strata_y;
  for (uint32_t f = 2; f < 6; f++) {
    hush_render_ctx ctx, cref;
    render_into(&r, &p, HUSH_MOVE_STATIC, f, &ctx, out);
    const int accepted = check_layer(&g, out);
    if (f == 2) {
      CHECK_MSG(accepted == 0, "the first frame has %d gradient samples", accepted);
    } else {
      /* every sample of the last frame (in g.next after the frame) lands
       * in its own stratum, and nearly all pass the visibility test */
      int claims = 0, sources = 0;
      for (uint32_t t = 0; t < strata; t++) {
        claims += g.claim[t] >= 0;
        sources += g.next[t].triangle != UINT32_MAX;
      }
      CHECK_MSG(claims == sources && sources >= (int)strata / 2, "frame %u: %d of %d samples landed",
                f, claims, sources);
      CHECK_MSG(accepted >= claims * 9 / 10, "frame %u: %d of %d samples accepted", f, accepted,
                claims);
      const float *color = layer(out, "color");
      int nonzero = 0, far = 0, moved = 0, bad_color = 0, chained = 0;
      float max_prev = 0.0f;
      for (uint32_t t = 0; t < strata; t++) {
        if (g.accepted[t] < 0) continue;
        if (memcmp(&g.current[t], &g.previous[t], sizeof(float)) != 0) nonzero++;
        max_prev = fmaxf(max_prev, g.previous[t]);
        uint32_t x, y;
        landing_xy(&g, t, &x, &y);
        const size_t i = (size_t)y * p.width + x;
        /* the re-shaded sample is the pixel's colour, or (fresh) its
         * gradient only */
        if (sample && lum(color + 3 * i) != g.current[t]) bad_color++;
        /* no chains: a pixel showing a re-shaded sample is never the next
         * source of its stratum (its bright sample would stay for good) */
        /* (after the frame, g.sources holds the samples chosen for the next) */
        if (sample && g.sources[t].triangle != UINT32_MAX && g.sources[t].x == x &&
            g.sources[t].y == y)
          chained++;
        /* the used samples are in g.next after the frame; with a still
         * camera each lands on the pixel it was chosen at */
        const hush_gradient_source *s = &g.next[g.claim[t]];
        if (s->x != x || s->y != y) moved++;
        /* its previous luminance is the pixel's last colour, up to the
         * rounding of the hit point rebuilt from the visibility buffer */
        const float l0 = lum(prev_color + 3 * i);
        if (fabsf(l0 - g.previous[t]) > 1e-3f * fmaxf(1.0f, l0)) far++;
      }
      CHECK_MSG(nonzero == 0, "frame %u: %d gradients are not exactly 0", f, nonzero);
      CHECK_MSG(bad_color == 0, "frame %u: %d landing pixels do not show the sample", f,
                bad_color);
      CHECK_MSG(chained == 0, "frame %u: %d landing pixels chosen again", f, chained);
      CHECK_MSG(moved == 0, "frame %u: %d samples moved under a still camera", f, moved);
      CHECK_MSG(far <= accepted / 20, "frame %u: %d previous luminances far from the pixel", f,
                far);
      CHECK(max_prev > 0.1f);
      /* every other pixel is rendered with fresh numbers, as without
       * gradients, bit for bit; the landing pixels mostly differ */
      render_into(&r, &plain, HUSH_MOVE_STATIC, f, &cref, ref);
      const float *rc = layer(ref, "color");
      /* a landing pixel's depth gradient is its sample's: on the same
       * triangle it matches the plain render's to second order (taken at
       * the pixel's jittered point instead, it would be off by up to the
       * whole gradient) */
      const float *dg = layer(out, "depth_gradient"), *rdg = layer(ref, "depth_gradient");
      const float *vis = layer(out, "vis"), *rvis = layer(ref, "vis");
      int dg_checked = 0, dg_bad = 0;
      for (uint32_t t = 0; t < strata; t++) {
        if (g.accepted[t] < 0) continue;
        uint32_t x, y;
        landing_xy(&g, t, &x, &y);
        const size_t i = (size_t)y * p.width + x;
        if (vis[3 * i] != rvis[3 * i]) continue;
        dg_checked++;
        for (int k = 0; k < 2; k++)
          if (fabsf(dg[2 * i + k] - rdg[2 * i + k]) > 0.05f * fabsf(rdg[2 * i + k]) + 1e-5f) dg_bad++;
      }
      CHECK_MSG(dg_checked > accepted / 2 && dg_bad <= dg_checked / 10,
                "frame %u: %d of %d landing depth gradients off", f, dg_bad, dg_checked);
      int other_bad = 0, landing_same = 0;
      for (uint32_t y = 0; y < p.height; y++)
        for (uint32_t x = 0; x < p.width; x++) {
          const uint32_t t = (y / 3) * g.strata_x + x / 3;
          const size_t i = (size_t)y * p.width + x;
          const int landing = g.accepted[t] == (int32_t)((y % 3) * 3 + x % 3);
          const int same = memcmp(color + 3 * i, rc + 3 * i, 3 * sizeof(float)) == 0;
          if (!landing && !same) other_bad++;
          if (landing && same) landing_same++;
        }
      CHECK_MSG(other_bad == 0, "frame %u: %d pixels without a sample changed", f, other_bad);
      if (sample)
        CHECK_MSG(landing_same <= accepted / 4, "frame %u: %d of %d landing pixels kept a fresh "
                  "sample's colour", f, landing_same, accepted);
      else
        CHECK_MSG(landing_same == accepted, "frame %u: %d of %d landing pixels kept their fresh "
                  "sample (landing fresh)", f, landing_same, accepted);
    }
    memcpy(prev_color, layer(out, "color"), sizeof(float) * 3 * p.width * p.height);
  }
  free(prev_color);
  hush_frame_release(out);
  hush_frame_release(ref);
  hush__gradients_free(&g);
  rig_close(&r);
}

/* ---- a light switched off ---------------------------------------------------------- */

static void test_light_off(void) {
  rig r;
  hush_render_params p;
  hush_gradients g;
  hush_frame out = open_with_gradients(&r, "light-off", 120, 68, &p, &g);
  const uint32_t strata = g.strata_x * g.strata_y;
  for (uint32_t f = 6; f <= 8; f++) {
    hush_render_ctx ctx;
    render_into(&r, &p, HUSH_MOVE_STATIC, f, &ctx, out);
    const int accepted = check_layer(&g, out);
    if (f == 7) {
      /* the light is still on: nothing changed */
      int nonzero = 0;
      for (uint32_t t = 0; t < strata; t++)
        if (g.accepted[t] >= 0 && g.current[t] != g.previous[t]) nonzero++;
      CHECK_MSG(nonzero == 0, "light on: %d of %d gradients not 0", nonzero, accepted);
    }
    if (f != 8) continue;
    /* lit region: strata whose sample saw the sphere light's glow (the
     * sky alone gives luminance below 0.1) */
    int lit = 0, large = 0;
    for (uint32_t t = 0; t < strata; t++) {
      if (g.accepted[t] < 0 || !(g.previous[t] > 0.5f)) continue;
      lit++;
      const float lambda =
          fabsf(g.current[t] - g.previous[t]) / fmaxf(g.current[t], g.previous[t]);
      if (lambda > 0.8f) large++;
    }
    printf("light off: %d lit strata of %d accepted, %d with lambda > 0.8\n", lit, accepted,
           large);
    CHECK_MSG(lit >= 20, "only %d lit strata", lit);
    CHECK_MSG(large >= lit * 9 / 10, "%d of %d lit strata have lambda > 0.8", large, lit);
  }
  hush_frame_release(out);
  hush__gradients_free(&g);
  rig_close(&r);
}

/* ---- forward projection under motion --------------------------------------------------- */

/* Renders frames f - 1 and f with gradients, and f without: each accepted
 * sample's surface point projects into its landing pixel, and that pixel's
 * own motion vector (plain render) leads back to within ~1 pixel of where
 * the sample was chosen, on the same object. Returns how many samples
 * moved to another pixel (on animated objects only, if animated_only). */
static int check_projection(const char *scene, hush_camera_move move, uint32_t f,
                            int animated_only) {
  rig r;
  rig_open(&r, scene);
  hush_render_params p;
  params_for(&p, 160, 120);
  hush_gradients g;
  REQUIRE(hush__gradients_init(r.device, &g, p.width, p.height) == HUSH_OK);
  g.landing_mode = HUSH_GRADIENT_LANDING_SAMPLE; /* the landing pixel's G-buffer is the sample's */
  p.gradients = &g;
  hush_render_params plain = p;
  plain.gradients = NULL;
  hush_frame out = hush_frame_new(r.device, p.width, p.height);
  hush_frame ref = hush_frame_new(r.device, p.width, p.height);
  REQUIRE(out && ref);
  hush_render_ctx ctx, cprev, cref;
  render_into(&r, &p, move, f - 1, &cprev, out);
  render_into(&r, &p, move, f, &ctx, out);
  const int accepted = check_layer(&g, out);
  render_into(&r, &plain, move, f, &cref, ref);
  const float *vis = layer(out, "vis"), *rvis = layer(ref, "vis"), *rmot = layer(ref, "motion");
  int bad_pixel = 0, bad_motion = 0, bad_object = 0, bad_vis = 0, moved = 0;
  const uint32_t strata = g.strata_x * g.strata_y;
  for (uint32_t t = 0; t < strata; t++) {
    if (g.accepted[t] < 0) continue;
    uint32_t x, y;
    landing_xy(&g, t, &x, &y);
    const size_t i = (size_t)y * p.width + x;
    const hush_gradient_source *s = &g.next[g.claim[t]];
    /* the landing pixel's visibility buffer is the sample */
    if (vis[3 * i] != (float)s->triangle || vis[3 * i + 1] != s->u || vis[3 * i + 2] != s->v)
      bad_vis++;
    /* the point at this frame's transforms projects into the pixel */
    const hush_vec3 pt = hush__scene_point(&r.scene, s->triangle, s->u, s->v, f);
    float cx, cy;
    if (!hush__camera_project(&ctx.cam, pt, 1.0f, &cx, &cy) || (uint32_t)floorf(cx) != x ||
        (uint32_t)floorf(cy) != y)
      bad_pixel++;
    /* independent: the plain render's motion vector at the landing pixel */
    const uint32_t o = r.scene.triangle_object[s->triangle];
    if (rvis[3 * i] < 0.0f || r.scene.triangle_object[(uint32_t)rvis[3 * i]] != o) {
      bad_object++;
      continue;
    }
    const float was_x = (float)x + 0.5f + ctx.cam.jitter[0] + rmot[2 * i];
    const float was_y = (float)y + 0.5f + ctx.cam.jitter[1] + rmot[2 * i + 1];
    const float src_x = (float)s->x + 0.5f + cprev.cam.jitter[0];
    const float src_y = (float)s->y + 0.5f + cprev.cam.jitter[1];
    if (fabsf(was_x - src_x) > 1.5f || fabsf(was_y - src_y) > 1.5f) bad_motion++;
    if ((s->x != x || s->y != y) && (!animated_only || r.scene.objects[o].motion.animated)) moved++;
  }
  printf("%s: %d accepted, %d moved; off: pixel %d, vis %d, object %d, motion %d\n", scene,
         accepted, moved, bad_pixel, bad_vis, bad_object, bad_motion);
  CHECK_MSG(accepted >= (int)strata / 2, "%s: %d of %u strata accepted", scene, accepted, strata);
  CHECK_MSG(bad_pixel == 0, "%s: %d samples outside their landing pixel", scene, bad_pixel);
  CHECK_MSG(bad_vis == 0, "%s: %d landing pixels do not hold the sample's vis", scene, bad_vis);
  CHECK_MSG(bad_object <= accepted / 50, "%s: %d landing pixels see another object", scene,
            bad_object);
  CHECK_MSG(bad_motion <= accepted / 50, "%s: %d landings disagree with the motion vectors", scene,
            bad_motion);
  hush_frame_release(out);
  hush_frame_release(ref);
  hush__gradients_free(&g);
  rig_close(&r);
  return moved;
}

static void test_projection(void) {
  const int cam = check_projection("cornell", HUSH_MOVE_ORBIT, 5, 0);
  CHECK_MSG(cam >= 30, "orbit: only %d samples moved", cam);
  const int obj = check_projection("cornell-moving", HUSH_MOVE_STATIC, 5, 1);
  CHECK_MSG(obj >= 10, "moving box: only %d samples moved", obj);
}

/* ---- behind a planar mirror ----------------------------------------------------------- */

/* A still scene (cornell-mirror held at frame 0) under an orbiting camera:
 * a sample on the mirror is the wall behind it (primary surface
 * replacement), so its point in the mirror's virtual world lands where the
 * new camera sees it in the mirror, its luminance is that wall's diffuse
 * light (the mirror has no diffuse lobe of its own), and as nothing
 * changed, its gradient is about 0, as on the surfaces seen directly.
 * Re-shading the mirror point itself from the moved eye would reflect
 * elsewhere: a gradient of the view. */
static void test_mirror(void) {
  rig r;
  hush_render_params p;
  hush_gradients g;
  hush_frame out = open_with_gradients(&r, "cornell-mirror", 160, 120, &p, &g);
  hush_render_ctx ctx;
  int mirrored = 0, lit = 0, still = 0, landed = 0, near = 0, direct_still = 0, direct = 0;
  for (uint32_t f = 4; f <= 6; f++) {
    render_scene_frame(&r, &p, HUSH_MOVE_ORBIT, 0, f, &ctx, out);
    check_layer(&g, out);
    if (f == 4) continue;
    const float *pos = layer(out, "position");
    for (uint32_t t = 0; t < g.strata_x * g.strata_y; t++) {
      if (g.accepted[t] < 0) continue;
      const hush_gradient_source *s = &g.next[g.claim[t]];
      const float lambda = fabsf(g.current[t] - g.previous[t]) /
                           fmaxf(1e-6f, fmaxf(g.current[t], g.previous[t]));
      if (!s->mirrors) {
        direct++;
        direct_still += lambda < 1e-2f;
        continue;
      }
      mirrored++;
      lit += g.previous[t] > 0.0f;
      still += lambda < 1e-2f;
      /* the virtual point projects into the landing pixel; the pixel's
       * own virtual point (the position layer, from its jittered ray) is
       * mostly near it (not across an edge of what the mirror shows) */
      uint32_t x, y;
      landing_xy(&g, t, &x, &y);
      const hush_vec3 v = hush__mirror_map_point(
          &s->map, hush__scene_point(&r.scene, s->behind_triangle, s->behind_u, s->behind_v, 0));
      float cx, cy;
      if (hush__camera_project(&ctx.cam, v, 1.0f, &cx, &cy) && (uint32_t)floorf(cx) == x &&
          (uint32_t)floorf(cy) == y)
        landed++;
      const size_t i = (size_t)y * p.width + x;
      const hush_vec3 q = hush_v3(pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]);
      near += hush_v3_length(hush_v3_sub(q, v)) < 0.03f * hush_v3_length(hush_v3_sub(v, ctx.cam.eye));
    }
  }
  printf("mirror: %d samples behind the mirror (%d lit, %d with gradient < 0.01, %d landed, "
         "%d near the pixel's point); %d elsewhere (%d with gradient < 0.01)\n",
         mirrored, lit, still, landed, near, direct, direct_still);
  CHECK_MSG(mirrored >= 100, "only %d samples behind the mirror", mirrored);
  CHECK_MSG(lit >= mirrored / 2, "%d of %d samples behind the mirror lit", lit, mirrored);
  CHECK_MSG(landed == mirrored && near >= mirrored * 3 / 4,
            "of %d samples behind the mirror %d landed on their point, %d near the pixel's",
            mirrored, landed, near);
  CHECK_MSG(still >= mirrored * 9 / 10, "%d of %d samples behind the mirror with a gradient",
            mirrored - still, mirrored);
  CHECK(direct_still >= direct * 9 / 10);
  hush_frame_release(out);
  hush__gradients_free(&g);
  rig_close(&r);
}

/* ---- thread count ------------------------------------------------------------------------ */

/* Which sample a stratum takes and how the pixels are shaded do not depend
 * on the thread count: three frames with 1 and with 2 threads are equal bit
 * for bit (colour, vis and the gradient layer). */
static void test_threads(hush_gradient_select select) {
  rig r;
  rig_open(&r, "cornell-moving");
  hush_frame out[2];
  for (int k = 0; k < 2; k++) {
    hush_render_params p;
    params_for(&p, 83, 61);
    p.threads = k + 1;
    hush_gradients g;
    REQUIRE(hush__gradients_init(r.device, &g, p.width, p.height) == HUSH_OK);
    g.select = select;
    p.gradients = &g;
    out[k] = hush_frame_new(r.device, p.width, p.height);
    REQUIRE(out[k]);
    for (uint32_t f = 3; f < 6; f++) {
      hush_render_ctx ctx;
      render_into(&r, &p, HUSH_MOVE_ORBIT, f, &ctx, out[k]);
    }
    CHECK(check_layer(&g, out[k]) > 100);
    hush__gradients_free(&g);
  }
  static const char *const names[] = {"color", "vis", "gradient"};
  const size_t n = (size_t)83 * 61 * 3;
  for (int i = 0; i < 3; i++)
    CHECK_MSG(memcmp(layer(out[0], names[i]), layer(out[1], names[i]), n * sizeof(float)) == 0,
              "layer %s differs between 1 and 2 threads", names[i]);
  hush_frame_release(out[0]);
  hush_frame_release(out[1]);
  rig_close(&r);
}

/* ---- bad parameters ---------------------------------------------------------------------- */

static void test_bad_params(void) {
  rig r;
  rig_open(&r, "cornell");
  hush_render_params p;
  params_for(&p, 30, 20);
  hush_gradients g;
  const char *msg = NULL;
  CHECK(hush__gradients_init(r.device, &g, 0, 20) == HUSH_ERROR_INVALID_ARGUMENT);
  CHECK(hush_device_get_error(r.device, &msg) == HUSH_ERROR_INVALID_ARGUMENT);
  REQUIRE(hush__gradients_init(r.device, &g, 31, 20) == HUSH_OK);
  p.gradients = &g;
  hush_frame out = hush_frame_new(r.device, p.width, p.height);
  REQUIRE(out);
  hush_render_ctx ctx;
  hush__render_ctx_init(&ctx, &r.scene, &r.lights, &p, &(hush_render_camera){0}, NULL, 0);
  /* a size mismatch and spp > 1 are errors with a message, not a crash */
  CHECK(hush__render_frame(r.device, &ctx, out, NULL, NULL, NULL) == HUSH_ERROR_INVALID_ARGUMENT);
  CHECK(hush_device_get_error(r.device, &msg) == HUSH_ERROR_INVALID_ARGUMENT);
  CHECK(msg && strstr(msg, "31x20") != NULL);
  hush__gradients_free(&g);
  REQUIRE(hush__gradients_init(r.device, &g, 30, 20) == HUSH_OK);
  p.spp = 4;
  hush__render_ctx_init(&ctx, &r.scene, &r.lights, &p, &(hush_render_camera){0}, NULL, 0);
  CHECK(hush__render_frame(r.device, &ctx, out, NULL, NULL, NULL) == HUSH_ERROR_INVALID_ARGUMENT);
  CHECK(hush_device_get_error(r.device, &msg) == HUSH_ERROR_INVALID_ARGUMENT);
  CHECK(msg && strstr(msg, "1 sample") != NULL);
  hush_frame_release(out);
  hush__gradients_free(&g);
  rig_close(&r);
}

/* ---- the CLI ---------------------------------------------------------------------------- */

#define WORK HUSH_BINARY_DIR "/test_gradients"

static int run(const char *args) {
  char cmd[2048];
  snprintf(cmd, sizeof cmd, "'%s' render %s > '%s/out.txt' 2>&1", HUSH_CLI, args, WORK);
  const int s = system(cmd);
  return (s != -1 && WIFEXITED(s)) ? WEXITSTATUS(s) : -1;
}

static void test_cli(void) {
  REQUIRE(system("mkdir -p '" WORK "'") == 0);
  CHECK(run("--scene builtin:cornell --out " WORK "/seq --gradients --spp 4") == 2);
  CHECK(run("--scene builtin:cornell --out " WORK "/seq --gradients --spp-fraction 0.25") == 2);
  CHECK(run("--scene builtin:cornell --out " WORK "/seq --gradient-lobe specular") == 2);
  CHECK(run("--scene builtin:cornell --out " WORK "/seq --gradient-landing later") == 2);
  CHECK(run("--scene builtin:cornell --out " WORK "/seq --gradient-select dimmest") == 2);
  REQUIRE(run("--scene builtin:cornell --out " WORK "/seq --gradients --half --quiet --size 40x31 "
              "--frames 2 --path static") == 0);
  hush_device dev = hush_device_new("threads=1");
  REQUIRE(dev);
  hush_frame fr;
  REQUIRE(hush_frame_read_exr(dev, WORK "/seq/frame_0001.exr", &fr) == HUSH_OK);
  const hush_layer *v = hush__frame_find(fr, "gradient");
  REQUIRE(v && v->channels == 3);
  int accepted = 0, bad = 0;
  for (uint32_t y = 0; y < 31; y++)
    for (uint32_t x = 0; x < 40; x++) {
      const float *o = v->pixels + 3 * ((size_t)y * 40 + x);
      if (!(o[2] == -1.0f || (o[2] >= 0.0f && o[2] <= 8.0f && o[2] == floorf(o[2])))) bad++;
      if (o[2] >= 0.0f && x % 3 == 0 && y % 3 == 0) {
        accepted++;
        if (o[0] != o[1]) bad++; /* still: exactly 0, half rounding alike */
      }
    }
  CHECK_MSG(bad == 0, "%d bad gradient entries in the EXR", bad);
  CHECK_MSG(accepted > 100, "only %d gradient samples in the EXR", accepted);
  hush_frame_release(fr);
  hush_device_release(dev);
}

int main(void) {
  /* the published configuration, and the default */
  test_static_zero(HUSH_GRADIENT_LANDING_SAMPLE, HUSH_GRADIENT_LOBE_ALL);
  test_static_zero(HUSH_GRADIENT_LANDING_FRESH, HUSH_GRADIENT_LOBE_DIFFUSE);
  test_light_off();
  test_projection();
  test_mirror();
  test_threads(HUSH_GRADIENT_SELECT_BRIGHTEST);
  test_threads(HUSH_GRADIENT_SELECT_RANDOM);
  test_bad_params();
  test_cli();
  return check_summary();
}
