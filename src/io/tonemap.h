/*
 * tonemap.h — the display transform of pictures: exposure, a tone curve
 * (hush_tonemap) and the sRGB transfer function, and its inverse for reading
 * 8-bit pictures back as linear radiance.
 */
#ifndef HUSH_IO_TONEMAP_H
#define HUSH_IO_TONEMAP_H

#include "hush.h"

#include <stdint.h>

/* 1 if op is one of the hush_tonemap values. */
int hush__tonemap_valid(hush_tonemap op);

/* The tone curve: scene-referred x (after exposure) to [0, 1]. Negative x
 * maps to 0. x must be finite. */
float hush__tonemap(float x, hush_tonemap op);

/* sRGB transfer function (IEC 61966-2-1), exact piecewise form, on [0, 1]
 * (inputs are clamped to it). */
float hush__srgb_encode(float linear);
float hush__srgb_decode(float encoded);

/* A display value in [0, 1] rounded to 8 bits. */
static inline uint8_t hush__quantize8(float v) {
  if (!(v > 0.0f)) return 0;
  if (v >= 1.0f) return 255;
  return (uint8_t)(v * 255.0f + 0.5f);
}

/* The whole transform of one channel: radiance * scale (scale = 2^exposure),
 * tone curve, sRGB, 8 bits. */
static inline uint8_t hush__display8(float radiance, float scale, hush_tonemap op) {
  return hush__quantize8(hush__srgb_encode(hush__tonemap(radiance * scale, op)));
}

#endif
