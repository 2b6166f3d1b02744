/*
 * tonemap.c — tone curves and the sRGB transfer function, shared by the
 * picture writers and readers and by the command-line tools.
 */
#include "io/tonemap.h"

#include <math.h>

int hush__tonemap_valid(hush_tonemap op) {
  return op == HUSH_TONEMAP_CLAMP || op == HUSH_TONEMAP_REINHARD || op == HUSH_TONEMAP_ACES;
}

/* Krzysztof Narkowicz, "ACES Filmic Tone Mapping Curve" (2016): a rational
 * fit of the ACES RRT + ODT, applied per channel. */
static float aces_narkowicz(float x) {
  const float a = 2.51f, b = 0.03f, c = 2.43f, d = 0.59f, e = 0.14f;
  return (x * (a * x + b)) / (x * (c * x + d) + e);
}

float hush__tonemap(float x, hush_tonemap op) {
  if (!(x > 0.0f)) return 0.0f;
  float y;
  switch (op) {
  case HUSH_TONEMAP_REINHARD: y = x / (1.0f + x); break;
  case HUSH_TONEMAP_ACES: y = aces_narkowicz(x); break;
  case HUSH_TONEMAP_CLAMP:
  default: y = x; break;
  }
  return y < 1.0f ? y : 1.0f;
}

float hush__srgb_encode(float linear) {
  if (!(linear > 0.0f)) return 0.0f;
  if (linear >= 1.0f) return 1.0f;
  if (linear <= 0.0031308f) return 12.92f * linear;
  return 1.055f * powf(linear, 1.0f / 2.4f) - 0.055f;
}

float hush__srgb_decode(float encoded) {
  if (!(encoded > 0.0f)) return 0.0f;
  if (encoded >= 1.0f) return 1.0f;
  if (encoded <= 0.04045f) return encoded / 12.92f;
  return powf((encoded + 0.055f) / 1.055f, 2.4f);
}
