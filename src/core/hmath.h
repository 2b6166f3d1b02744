/*
 * hmath.h — small vector and 4x4 matrix helpers. Matrices are column-major,
 * as in hush.h: element (row r, column c) is m[c * 4 + r].
 */
#ifndef HUSH_CORE_HMATH_H
#define HUSH_CORE_HMATH_H

#include <math.h>

typedef struct hush_vec3 {
  float x, y, z;
} hush_vec3;

typedef struct hush_vec4 {
  float x, y, z, w;
} hush_vec4;

static inline hush_vec3 hush_v3(float x, float y, float z) {
  hush_vec3 v = {x, y, z};
  return v;
}
static inline hush_vec3 hush_v3_add(hush_vec3 a, hush_vec3 b) {
  return hush_v3(a.x + b.x, a.y + b.y, a.z + b.z);
}
static inline hush_vec3 hush_v3_sub(hush_vec3 a, hush_vec3 b) {
  return hush_v3(a.x - b.x, a.y - b.y, a.z - b.z);
}
static inline hush_vec3 hush_v3_scale(hush_vec3 a, float s) {
  return hush_v3(a.x * s, a.y * s, a.z * s);
}
static inline float hush_v3_dot(hush_vec3 a, hush_vec3 b) {
  return a.x * b.x + a.y * b.y + a.z * b.z;
}
static inline hush_vec3 hush_v3_cross(hush_vec3 a, hush_vec3 b) {
  return hush_v3(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}
static inline float hush_v3_length(hush_vec3 a) {
  return sqrtf(hush_v3_dot(a, a));
}
static inline hush_vec3 hush_v3_normalize(hush_vec3 a) {
  const float l = hush_v3_length(a);
  return l > 0.0f ? hush_v3_scale(a, 1.0f / l) : a;
}

/* out = m * (x, y, z, w) */
static inline hush_vec4 hush_m4_mul_v4(const float m[16], float x, float y, float z, float w) {
  hush_vec4 r;
  r.x = m[0] * x + m[4] * y + m[8] * z + m[12] * w;
  r.y = m[1] * x + m[5] * y + m[9] * z + m[13] * w;
  r.z = m[2] * x + m[6] * y + m[10] * z + m[14] * w;
  r.w = m[3] * x + m[7] * y + m[11] * z + m[15] * w;
  return r;
}

/* out = a * b (out may alias neither input). */
void hush_m4_mul(float out[16], const float a[16], const float b[16]);
void hush_m4_identity(float out[16]);
/* General inverse; returns 0 (and leaves out untouched) if m is singular. */
int hush_m4_invert(float out[16], const float m[16]);
/* Right-handed look-at (OpenGL gluLookAt): world-to-view. */
void hush_m4_look_at(float out[16], hush_vec3 eye, hush_vec3 target, hush_vec3 up);
/* OpenGL perspective: vertical field of view in degrees, NDC z in [-1, 1]. */
void hush_m4_perspective(float out[16], float fov_y_deg, float aspect, float z_near, float z_far);

/* Rec. 709 luminance of linear RGB. */
static inline float hush_luminance(float r, float g, float b) {
  return 0.2126f * r + 0.7152f * g + 0.0722f * b;
}

#endif
