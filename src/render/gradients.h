/*
 * gradients.h — the renderer side of A-SVGF's temporal gradients
 * (realtime-denoising-comparison-higginson-2023.md §2.3.1 "Gradient
 * Estimation" and "Seed Reprojection"; ../shared/papers/NOTES.md, A-SVGF):
 * `hush render --gradients`.
 *
 * The screen is cut into strata of 3 x 3 pixels. After a frame is rendered,
 * each stratum picks its pixel of largest luminance among those that see a
 * triangle, remembers that pixel's visibility sample (triangle, u, v) and the
 * random numbers it was shaded with, and re-shades the sample from the
 * visibility buffer to get its "previous" luminance (see below why).
 *
 * In the next frame each such sample is forward-projected: the same surface
 * point (triangle, u, v) at the new frame's object transforms, so moving
 * objects carry their samples, through the new camera. It lands on pixel
 * (floor x, floor y), in some stratum of the new grid; a stratum takes at
 * most one sample (the landing sample of largest previous luminance, then
 * the lowest source stratum). If that pixel's own primary ray sees the same
 * surface (the visibility test, see gradients.c), the forward-projected
 * sample is re-shaded with the previous frame's random numbers. By default
 * (landing FRESH) that only measures the gradient and the pixel keeps its
 * fresh sample, so the image is the render without gradients bit for bit;
 * with landing SAMPLE (A-SVGF as published) the pixel's "color" is the
 * re-shaded sample and its G-buffer (vis, normal, position, depth ...) the
 * sample's first hit, which biases the image upwards with the brightest
 * selection (docs/renderer.md). The other pixels are rendered as usual.
 *
 * Both luminances of a gradient sample come from the same code path
 * (hush__integrator_first_hit + hush__integrator_shade from the visibility
 * sample): the previous frame's traced primary ray hits the point with
 * other rounding than the one rebuilt from (triangle, u, v), and that would
 * leave a small non-zero gradient where nothing changed. With the re-shade on
 * both sides, a static scene and camera give a gradient of exactly 0. The
 * price is one extra path per stratum (1/9 of a frame's paths).
 *
 * Output, the layer "gradient" (3 channels, docs/sequence-format.md): every
 * pixel of stratum (sx, sy) holds that stratum's sample: current luminance,
 * previous luminance, and where it landed as the pixel's index inside the
 * stratum, (y - 3 sy) * 3 + (x - 3 sx) in 0..8, or -1 (and luminances 0)
 * where no sample landed or the visibility test failed. The index is small so
 * that it stays exact in half-float EXRs.
 *
 * Behind planar mirrors (primary surface replacement, mirror.h) the sample
 * is the hit the mirrors lead to: forward-projected as a point of their
 * virtual world, it must be seen again behind the same mirrors, and the
 * re-shading starts on the mirror where the camera ray to that virtual
 * point meets it (hush_gradient_source).
 *
 * Needs 1 sample per pixel on every pixel (no --spp > 1, no --spp-fraction):
 * the sample replaces the pixel's only sample.
 */
#ifndef HUSH_RENDER_GRADIENTS_H
#define HUSH_RENDER_GRADIENTS_H

#include "hush.h"
#include "render/mirror.h"
#include "render/render.h"

#include <stdint.h>

#define HUSH_GRADIENT_STRATUM 3u

/* A visibility sample chosen in one frame, to be re-shaded in the next. */
typedef struct hush_gradient_source {
  uint32_t triangle;       /* UINT32_MAX: the stratum has none */
  float u, v;
  uint32_t x, y;           /* the pixel it was chosen at */
  uint32_t seed_frame, seed_x, seed_y; /* the numbers it was shaded with (hush__rand_init) */
  float luminance;         /* re-shaded in its own frame */
  /* A sample on a planar mirror (primary surface replacement, mirror.h):
   * the hit behind the mirrors, which the pixel describes, and the map
   * into their virtual world. It is that hit that is forward-projected
   * (through the mirrors where they are in the new frame) and must be seen
   * again behind the same mirrors: re-shading the mirror point itself
   * from a moved eye would reflect elsewhere, a change of view read as a
   * gradient. mirrors 0: none (triangle, u, v is the sample). */
  uint32_t mirrors;
  uint32_t behind_triangle;
  float behind_u, behind_v;
  hush_mirror_map map;
} hush_gradient_source;

/* State carried from frame to frame. All arrays have one entry per stratum
 * (strata_x * strata_y, row-major) and are owned. */
/* Which pixel of a stratum gives the next frame's sample. */
typedef enum hush_gradient_select {
  HUSH_GRADIENT_SELECT_BRIGHTEST, /* largest luminance (Q2RTX; catches a light going off) */
  HUSH_GRADIENT_SELECT_RANDOM     /* uniform among the stratum's surface pixels (Schied 2018) */
} hush_gradient_select;

/* What the landing pixel's colour is. */
typedef enum hush_gradient_landing {
  /* a fresh sample, as every other pixel; the re-shaded sample only
   * measures the gradient (one extra path per stratum). Unbiased. */
  HUSH_GRADIENT_LANDING_FRESH,
  /* the re-shaded sample itself (A-SVGF as published). With the brightest
   * selection a ninth of the pixels then repeat their stratum's brightest
   * sample of the frame before: the image is biased upwards (docs/asvgf.md). */
  HUSH_GRADIENT_LANDING_SAMPLE
} hush_gradient_landing;

/* Which radiance the gradient compares. */
typedef enum hush_gradient_lobe {
  /* the first hit's diffuse lobe only (hush_path_result.diffuse; the
   * default): a moved eye turns a glossy lobe's paths elsewhere with the same
   * numbers, a change of view that at 1 spp reads as a large gradient and
   * cut the history of every glossy surface on a camera path (classroom
   * RMSE +10% over svgf); the diffuse lobe's share of the same paths
   * changes only with the lighting. Surfaces without a diffuse lobe
   * (curved mirror, glass) give no gradient; behind a planar mirror the
   * lobes are those of the hit it leads to (integrator.h). */
  HUSH_GRADIENT_LOBE_DIFFUSE,
  HUSH_GRADIENT_LOBE_ALL /* the sample's whole colour (the papers) */
} hush_gradient_lobe;

typedef struct hush_gradients {
  uint32_t width, height;
  hush_gradient_lobe lobe;       /* set by hush__gradients_init to DIFFUSE */
  hush_gradient_select select;   /* set by hush__gradients_init to BRIGHTEST */
  hush_gradient_landing landing_mode; /* set by hush__gradients_init to FRESH */
  uint32_t strata_x, strata_y; /* ceil(width / 3), ceil(height / 3) */
  int have_sources;        /* sources hold the last rendered frame's samples */
  hush_gradient_source *sources; /* by the stratum of the last frame they were chosen in */
  hush_gradient_source *next;    /* being chosen for the next frame */
  /* this frame, by the stratum of the landing pixel: */
  int32_t *claim;          /* index into sources of the sample landing here, or -1 */
  uint32_t *landing;       /* its landing pixel, y * width + x */
  int32_t *accepted;       /* after the visibility test: index in the stratum 0..8, or -1 */
  float *current, *previous; /* luminances of accepted samples */
  uint32_t *reshade_rays;  /* rays of re-shades not taken as the pixel's sample (landing FRESH) */
} hush_gradients;

hush_status hush__gradients_init(hush_device device, hush_gradients *g, uint32_t width,
                                 uint32_t height);
void hush__gradients_free(hush_gradients *g);
/* Forgets the last frame's samples (a cut: the next frame has no gradients). */
void hush__gradients_reset(hush_gradients *g);

/* The three hooks of hush__render_frame (render.c), in order: */

/* Before the frame: forward-projects the last frame's samples into ctx's
 * frame and assigns them to landing strata. Checks ctx's parameters. */
hush_status hush__gradients_begin(hush_device device, hush_gradients *g,
                                  const hush_render_ctx *ctx);

/* For pixel (x, y), whose sample 0 primary ray hit `traced`: if a sample
 * landed here and passes the visibility test, shades the pixel with it into
 * *out and returns 1; else returns 0 (shade the pixel as usual). Called from
 * the worker threads: each writes only the entries of (x, y)'s stratum. */
int hush__gradients_shade(hush_gradients *g, const hush_render_ctx *ctx, uint32_t x, uint32_t y,
                          const hush_hit *traced, hush_pixel_result *out);

/* After the frame: writes the layer "gradient" into out, then chooses and
 * re-shades this frame's samples for the next frame (the scene must still be
 * at ctx's frame). *rays (not NULL) is increased by the rays traced. */
hush_status hush__gradients_end(hush_device device, hush_gradients *g, const hush_render_ctx *ctx,
                                hush_frame out, int threads, uint64_t *rays);

#endif
