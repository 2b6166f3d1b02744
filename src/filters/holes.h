/*
 * holes.h — pixels without a sample this frame (`hush render --spp-fraction`
 * F < 1: layer 'spp' 0, every other layer 0; docs/renderer.md "Holes") and
 * their filling from the pixels around them.
 *
 * The fill is Dundr 2018 §4.2.1 (svgf-progressive-dundr-2018.md): a top-down
 * pyramid of 3x3 averages of the valid pixels, built until a level has no
 * hole, then every hole of a level looked up bilinearly from the level
 * above ("a crude and blurry approximation, but good enough in practice").
 * Shared by svgf's progressive mode (G-buffer), the G-buffer import of the
 * other temporal filters (gbuffer.h) and their outputs at pixels that never
 * had a sample (docs/holes.md).
 */
#ifndef HUSH_FILTERS_HOLES_H
#define HUSH_FILTERS_HOLES_H

#include "hush.h"

#include <stddef.h>
#include <stdint.h>

/* Most planes one fill can carry. */
#define HUSH_HOLES_MAX_PLANES 16

/* A pixel is valid (has data) where valid[i] > 0: spp, or a history length. */
static inline int hush__holes_is_hole(float valid) { return !(valid > 0.0f); }

/* 1 when some valid[i] is not > 0 (NaN counts as a hole). */
int hush__holes_any(const float *valid, size_t n, int threads);

/* Floats of scratch hush__holes_fill needs for `planes` planes of W x H. */
size_t hush__holes_pyramid_floats(uint32_t width, uint32_t height, int planes);

/*
 * Fills the holes (valid not > 0) of `count` planes (<= HUSH_HOLES_MAX_PLANES)
 * of W x H in place; valid pixels are left bit for bit. pyramid: at least
 * hush__holes_pyramid_floats(W, H, count) floats of scratch. Without any
 * valid pixel everything becomes 0. Deterministic whatever the threads.
 */
void hush__holes_fill(float *pyramid, uint32_t width, uint32_t height, const float *valid,
                      float *const *planes, int count, int threads);

/*
 * After a fill of the G-buffer: each hole is background (depth <= 0) or a
 * surface by the majority of the valid pixels the fill averages (the same
 * pyramid, on the flag depth > 0, into scratch[0]). A surface hole's
 * geometry planes (planes[0] the depth, then e.g. normal and position, all
 * 0 on the background) are divided by that fraction: the average over the
 * surfaces alone; a background hole's are set to 0. motion (2 planes, or
 * NULL), filled over all pixels (the background's motion is real), becomes
 * the average over the surfaces or over the background alone (by the fill
 * of motion x flag, in scratch[1] and scratch[2]). Without this a hole
 * between an object and the sky got a depth (and motion) between the
 * object's and the sky's, a surface that is nowhere, which reprojects onto
 * whatever lies there (a lamp seen against the sky dragged a trail).
 * pyramid: as hush__holes_fill for 3 planes; scratch: 1 plane, 3 with motion.
 */
/* After a fill of the normals: unit length for the holes' normals (the fill
 * averages unit vectors) and +z on all the background (depth <= 0: one
 * normal for all of it, so that its holes fill from the traced background
 * around them). */
void hush__holes_normalize_normals(const float *valid, const float *depth, float *const n[3],
                                   size_t count, int threads);

void hush__holes_split_background(float *pyramid, uint32_t width, uint32_t height,
                                  const float *valid, float *const *scratch, float *const *planes,
                                  int count, float *const *motion, int threads);

/* The scratch of hush__holes_fill for up to `planes` planes, allocated on
 * first use (hush__holes_reserve) and owned by the struct. */
typedef struct hush_holes {
  float *pyramid;
  size_t floats;
} hush_holes;

hush_status hush__holes_reserve(hush_device device, hush_holes *h, uint32_t width,
                                uint32_t height, int planes);
void hush__holes_free(hush_holes *h);

#endif
