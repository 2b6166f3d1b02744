/*
 * progressive.h — SVGF with fewer than one sample per pixel (Dundr 2018
 * §4.2): frames where some pixels were not traced (`hush render
 * --spp-fraction`: spp 0, every other layer 0).
 *
 *  - §4.2.1 the G-buffer holes (depth, normal, albedo, position; and the
 *    emission, with emission_bypass, so that lamps have no holes) are filled
 *    from a pyramid of 3x3 averages of the traced pixels, looked up
 *    bilinearly from the finest level without holes;
 *  - §4.2.4 the previous frame's state (each pixel's accumulated colour,
 *    moments and history length, at its world position) is reprojected
 *    forwards by scatter: each state pixel lands on the pixel its position
 *    projects to, the nearest surface winning an atomic depth test; a hole
 *    pixel takes the state that landed on it, else the average of those
 *    that landed in its 3x3 neighbourhood ("a 3x3 neighborhood average in
 *    UV-space");
 *  - §4.2.5 a sample that moved is rejected where it is closer to the far
 *    than to the near side of the traced depths in the 27x27 neighbourhood
 *    (three dilated 3x3 min/max passes): a surface seen through a hole of
 *    the geometry in front of it. (A sample that stayed on its pixel is not
 *    tested: with a static camera nothing can be seen through a hole.)
 *  - §4.2.3 the luminance weight's epsilon grows where a pixel has few
 *    samples: eps_l = 1e-4 + epsilon / max(samples, 1) below 4 samples.
 * Traced pixels use the usual backward reprojection (their G-buffer is
 * real); pixels with no data at all carry no weight in the a-trous.
 */
#ifndef HUSH_FILTERS_SVGF_PROGRESSIVE_H
#define HUSH_FILTERS_SVGF_PROGRESSIVE_H

#include "core/image.h"
#include "hush.h"

#include <stdint.h>

#define SVGF_PYRAMID_MAX_PLANES 13 /* depth, normal, position, albedo, emission */

typedef struct svgf_progressive {
  uint32_t width, height;
  hush_planar pos[2];   /* 4: world position of each pixel's state, valid; [latest] */
  int latest, has_pos;  /* pos[latest] belongs to the history */
  hush_planar depth;    /* 1: this frame's traced depth (0 in holes), for near/far */
  hush_planar near_far; /* 2: 27x27 min and max of the traced depths */
  hush_planar scratch;  /* 2 */
  hush_planar background; /* 1: this frame's holes that are background (svgf_split_background) */
  int32_t *src;         /* per pixel: the previous pixel whose state landed here, or -1 */
  uint64_t *keys;       /* scatter depth test: depth bits << 32 | source */
  float *pyramid;       /* the coarser levels of the hole-filling pyramid */
  size_t pyramid_floats;
} svgf_progressive;

hush_status svgf_progressive_init(hush_device device, svgf_progressive *p, uint32_t width,
                                  uint32_t height);
void svgf_progressive_free(svgf_progressive *p);

/* 1 when some pixel of spp is 0 (a hole). */
int svgf_has_holes(const float *spp, size_t n, int threads);

/* §4.2.1: fills the holes (spp 0) of `count` planes by the pyramid. */
void svgf_fill_holes(svgf_progressive *p, const float *spp, float *const *planes, int count,
                     int threads);

/* After svgf_fill_holes: each hole background or a surface by majority
 * (hush__holes_split_background; geometry: depth first, then normal and
 * position planes), remembered in p->background for the forward state: a
 * background hole takes no scattered surface state (below). */
void svgf_split_background(svgf_progressive *p, const float *spp, float *const *geometry,
                           int count, int threads);

/*
 * §4.2.4-4.2.5: p->src for this frame from the previous state's positions
 * (p->pos[latest], where prev_age > 0) and this frame's camera; the traced
 * depth (p->depth, set by the caller before filling the holes) gives the
 * near/far rejection. Without a history every src is -1.
 */
void svgf_forward_scatter(svgf_progressive *p, const float *spp, const float *prev_age,
                          const hush_frame_info *info, int threads);

/*
 * Hole pixels of a component's state get the forward-reprojected previous
 * state (prev: 3 colour, 2 moment and 1 age planes, or NULL without a
 * history), averaged over the 3x3 neighbourhood where nothing landed on the
 * pixel itself; with nothing around, or for a background hole (the
 * background has no position and never lands: the states around it are
 * an object's, and a lamp moving across the sky left a trail of them), the backward-reprojected history that
 * the blend (accumulation.h, alphas as given) mixed with the hole's 0 sample,
 * unmixed again; without that either, age 0 and zeros.
 */
void svgf_forward_state(const svgf_progressive *p, const float *spp,
                        const float *const prev[6], float *const cur[6], float alpha_min,
                        float alpha_moments_min, int threads);

/* The next state's positions (x, y, z, valid): holes' carried along from
 * the states that landed around them (not a background hole's), else
 * position (traced or filled),
 * valid where depth > 0. Makes them the history's. */
void svgf_carry_positions(svgf_progressive *p, const float *spp, const float *const position[3],
                          const float *depth, int threads);

/* eps[i] = 1e-4 + epsilon / max(samples, 1) where samples < 4, else 1e-4. */
void svgf_progressive_epsilon(const float *samples, float epsilon, float *eps, size_t n,
                              int threads);

#endif
