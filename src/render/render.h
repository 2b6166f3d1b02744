/*
 * render.h — renders one frame of a sequence into a hush_frame: the noisy
 * radiance of the 1 spp configuration (bmfr-koskela-2019.md §3.1) and the
 * noise-free feature buffers the filters read
 * (realtime-denoising-comparison-higginson-2023.md §1.2.1-1.2.2), with the
 * layer names of docs/sequence-format.md:
 *
 *   color (3)          mean radiance of the pixel's samples
 *   albedo (3)         first-hit demodulation albedo (docs/renderer.md)
 *   normal (3)         world shading normal of the first hit (0 for sky)
 *   position (3)       world position of the first hit (0 for sky)
 *   depth (1)          linear view depth, 0 for sky
 *   depth_gradient (2) d depth / d pixel in x and y, from the first hit's
 *                      tangent plane (0 for sky)
 *   motion (2)         pixels, previous minus current, camera and object motion
 *   id (1)             material index + 1; sphere light i: material_count + 1 + i; sky 0
 *   vis (3)            visibility buffer: triangle index (exact float),
 *                      barycentrics u, v; -1 for sky, -2 - i for sphere light i
 *   spp (1)            when spp > 1 or progressive: the samples of the pixel,
 *                      0 for a hole (a pixel this frame did not trace)
 *   variance (1)       when spp > 1: the sample variance of the luminance
 *                      of one sample
 *   emission (3)       the radiance the camera rays see directly at their
 *                      first hit (emissive triangle, sphere light, sky),
 *                      averaged as color is: color - emission is what the
 *                      first hits reflect, the part filters should filter
 *   direct, indirect (3) with split: emission (as above) + the first hit's shadow ray,
 *                      and the rest
 *   diffuse, specular (3) with split_lobes: the radiance by the first hit's
 *                      BSDF lobe (integrator.h, hush_path_result); light seen
 *                      directly is diffuse. color is then diffuse + specular,
 *                      exactly (without the split it can differ in the last bit)
 *
 *   gradient (3)       with params.gradients: A-SVGF gradient samples per 3 x 3
 *                      stratum (render/gradients.h)
 *
 * With params.progressive (fewer than one sample per pixel, progressive.h)
 * only the pattern's pixels are traced; the others are holes: spp 0, every
 * other layer 0 except vis, which is -1 (no triangle) as for the sky.
 *
 * The G-buffer comes from the first sample's primary ray, which goes through
 * (x + 0.5 + jitter).
 *
 * Primary surface replacement (params.mirror_depth, on by default): where
 * that ray meets a planar mirror (a smooth conductor on flat-shaded
 * triangles), the pixel shows what lies behind it, and the G-buffer
 * describes that instead, as the virtual surface the unfolded ray meets:
 * position and normal reflected through the mirrors' planes (depth and its
 * gradient follow), albedo times the mirrors' reflectance, the reflected
 * surface's id, and motion that follows the reflection (mirrors are taken
 * to be still); vis keeps the real first hit, emission includes the light
 * seen in the mirror. Without it a mirror's features are its own flat
 * plane, and a filter smears the reflection across it. Curved mirrors and
 * glass keep their own G-buffer (their reflection is not a rigid image). Pixels are independent, so the frame is the same for
 * any thread count; rows are spread over OpenMP threads.
 */
#ifndef HUSH_RENDER_RENDER_H
#define HUSH_RENDER_RENDER_H

#include "hush.h"
#include "render/camera.h"
#include "render/integrator.h"
#include "render/lights.h"
#include "render/progressive.h"
#include "render/scene.h"

#include <stdint.h>

struct hush_gradients;

typedef struct hush_render_params {
  uint32_t width, height;
  uint32_t spp;            /* >= 1 */
  int bounces;             /* BSDF-sampled secondary rays per path (integrator.h) */
  uint32_t seed;
  hush_sampler sampler;
  int jitter;              /* Halton frame jitter; samples 1.. of a pixel spread over it */
  float clamp;             /* > 0: firefly clamp of indirect contributions */
  int split;               /* also write "direct" and "indirect" */
  int split_lobes;         /* also write "diffuse" and "specular" (color = their sum) */
  /* primary surface replacement through up to this many planar mirrors (0:
   * off; at most HUSH_RENDER_MIRROR_DEPTH_MAX, the default; also at most
   * bounces, since the path's rays are what the G-buffer describes) */
  int mirror_depth;
  int threads;             /* 0: the device's */
  const hush_progressive *progressive; /* not NULL: trace only its pixels (progressive.h) */
  hush_path_vertex_fn vertex_fn;
  hush_path_end_fn path_end_fn; /* integrator.h; both get vertex_user */
  void *vertex_user;
  /* not NULL: A-SVGF gradient samples (render/gradients.h); the caller owns
   * it and keeps it from frame to frame; needs spp 1 and no progressive */
  struct hush_gradients *gradients;
} hush_render_params;

/* Russian roulette starts after 3 secondary rays (integrator.h): a mirror
 * chain deeper than that would not be deterministic. */
#define HUSH_RENDER_MIRROR_DEPTH_MAX 3

void hush__render_defaults(hush_render_params *p);

typedef struct hush_render_ctx {
  const hush_scene *scene; /* set to `frame` */
  const hush_lights *lights; /* set to `frame` */
  hush_render_params params;
  hush_render_camera cam;
  hush_render_camera prev_cam;
  int have_prev;           /* 0: motion is 0 */
  uint32_t frame;
  hush_integrator it;
} hush_render_ctx;

/* prev_cam may be NULL (no previous frame). */
void hush__render_ctx_init(hush_render_ctx *ctx, const hush_scene *scene, const hush_lights *lights,
                           const hush_render_params *params, const hush_render_camera *cam,
                           const hush_render_camera *prev_cam, uint32_t frame);

typedef struct hush_pixel_result {
  float color[3];
  float direct[3];
  float emission[3];       /* mean over the samples of hush_path_result's emission */
  float diffuse[3], specular[3]; /* split_lobes; color = diffuse + specular */
  float variance;          /* of one sample's luminance (spp > 1) */
  hush_first_hit first;    /* of sample 0 */
  int gradient_sample;     /* 1: a forward-projected A-SVGF sample (gradients.h), whose first hit
                            * is not on the pixel's jittered ray */
  uint64_t rays;
} hush_pixel_result;

/* Renders pixel (x, y) of ctx's frame with the random numbers of frame
 * seed_frame (normally ctx->frame): the same arguments always give the same
 * result, bit for bit. It ignores params.gradients. */
void hush__render_pixel(const hush_render_ctx *ctx, uint32_t x, uint32_t y, uint32_t seed_frame,
                        hush_pixel_result *out);

typedef void (*hush_render_progress_fn)(void *user, uint32_t rows_done, uint32_t rows);

/* Renders the frame into out (size params.width x params.height; layers
 * added or replaced). progress, if not NULL, is called from one thread as
 * rows complete. *rays (may be NULL) receives the number of rays traced. */
hush_status hush__render_frame(hush_device device, const hush_render_ctx *ctx, hush_frame out,
                               hush_render_progress_fn progress, void *user, uint64_t *rays);

#endif
