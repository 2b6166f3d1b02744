/*
 * synthetic.h — a deterministic synthetic frame-sequence generator: a small
 * analytic scene (checkered ground plane, four spheres, one of them moving,
 * a sun with soft analytic shadows and a constant sky ambient) ray cast at
 * one sample per pixel centre, with the noisy radiance, its exact
 * expectation and every guide layer a real renderer would write. It stands
 * in for the path tracer in tests, `make demo` and benchmarks.
 *
 * Layers of each frame (conventions in hush.h):
 *   color     noisy radiance: ref times a mean-1 random factor, plus a
 *             randomised shadow term (sky pixels are noise-free)
 *   ref       the clean radiance, the exact expectation of "color"
 *   albedo, normal (world, unit), position (world), depth (-z_view),
 *   motion    (pixels, previous minus current; 0 at frame 0),
 *   id        0 sky, 1 ground, 2.. spheres (the moving one is 5)
 * Sky pixels: depth 0, normal 0, position 0, id 0, albedo 1, color = ref =
 * the sky colour. Every random number is a pure function of (seed, frame,
 * pixel), so frames are reproducible, in any order, with any thread count.
 */
#ifndef HUSH_EVAL_SYNTHETIC_H
#define HUSH_EVAL_SYNTHETIC_H

#include "hush.h"
#include "io/sequence.h"

#include <stdint.h>

typedef enum hush_synth_camera {
  HUSH_SYNTH_STATIC = 0,
  HUSH_SYNTH_ORBIT = 1, /* circles the scene centre, about 1.1 degrees a frame */
  HUSH_SYNTH_DOLLY = 2  /* moves straight towards the scene centre */
} hush_synth_camera;

typedef struct hush_synth_params {
  uint32_t width, height; /* pixels, >= 1 */
  uint32_t frames;        /* frames of a written sequence, >= 1 */
  uint32_t seed;
  float noise;            /* 0 (color == ref) .. 1 (full 1-spp-like noise) */
  int camera_move;        /* a hush_synth_camera */
  int moving_object;      /* 1: sphere 5 translates from frame to frame */
  float sun_radius;       /* angular radius of the sun in radians; 0: hard shadows */
  hush_exr_type exr_type; /* what hush__synth_write_sequence writes */
} hush_synth_params;

/* 320x180, 16 frames, seed 1, noise 1, orbit, moving object, sun radius
 * 0.03 rad, float EXR. */
void hush__synth_defaults(hush_synth_params *p);

/* Checks p; reports an error naming the bad field on device. */
hush_status hush__synth_validate(hush_device device, const hush_synth_params *p);

/* The camera of frame `frame` (jitter is always 0). */
void hush__synth_camera(const hush_synth_params *p, uint32_t frame, hush_camera *camera);

/*
 * Renders frame `frame` (any index; frames need not be made in order) into a
 * new hush_frame with the layers above, and its camera into *camera (may be
 * NULL). The caller owns *out.
 */
hush_status hush__synth_frame(hush_device device, const hush_synth_params *p, uint32_t frame,
                              hush_frame *out, hush_camera *camera);

/*
 * Writes p->frames frames into dir (created if missing, parents included) as
 * a hush sequence: one EXR per frame of type p->exr_type, then cameras.json.
 * cameras.json is written last, so an interrupted run leaves no readable
 * sequence behind.
 */
hush_status hush__synth_write_sequence(hush_device device, const hush_synth_params *p,
                                       const char *dir);

#endif
