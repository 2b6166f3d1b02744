/*
 * lights.c — light sampling and densities (see lights.h): emissive
 * triangles by power, sphere lights by their visible cone, environment maps
 * by a 2D piecewise-constant distribution (Pharr, Jakob, Humphreys, PBRT 3
 * §13.6.7 and §14.2.4), and the sun and sky of Mitsuba 0.5's "sunsky"
 * approximated by a Preetham sky plus a sun disc (docs/renderer.md).
 * These serve next-event estimation with multiple importance sampling
 * (bmfr-koskela-2019.md §3.1).
 */
#include "render/lights.h"

#include "core/device.h"
#include "render/fminmax.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define L_PI 3.14159265358979f
#define SKY_WIDTH 128u
#define SKY_HEIGHT 64u
/* Mitsuba's SUN_APP_RADIUS is the apparent diameter, 0.5358 degrees */
#define SUN_HALF_ANGLE_DEG 0.2679f

static float lum3(const float c[3]) {
  return hush_luminance(c[0], c[1], c[2]);
}

/* Index i with cdf[i] <= u < cdf[i + 1], for a cdf of n + 1 entries from 0
 * to 1. guide[k] (see build_guide) is an index at or near the answer for
 * u in [k/n, (k+1)/n): one or two cache lines are read instead of the
 * dependent loads of a binary search, and the answer is the same. */
static uint32_t cdf_find(const float *cdf, const uint32_t *guide, uint32_t n, float u) {
  uint32_t k = (uint32_t)(u * (float)n);
  if (k >= n) k = n - 1;
  uint32_t lo = guide[k];
  while (lo > 0 && cdf[lo] > u) lo--; /* in case u * n rounded up */
  while (lo + 1 < n && cdf[lo + 1] <= u) lo++;
  /* skip empty bins at the start of a run of equal values */
  while (lo > 0 && cdf[lo + 1] == cdf[lo]) lo--;
  return lo;
}

/* The same by binary search, for tables without a guide (triangle lights). */
static uint32_t cdf_search(const float *cdf, uint32_t n, float u) {
  uint32_t lo = 0, hi = n;
  while (hi - lo > 1) {
    const uint32_t mid = (lo + hi) / 2;
    if (cdf[mid] <= u)
      lo = mid;
    else
      hi = mid;
  }
  while (lo + 1 < n && cdf[lo + 1] <= u) lo++;
  while (lo > 0 && cdf[lo + 1] == cdf[lo]) lo--;
  return lo;
}

/* guide[k] = the last i with cdf[i] <= k / n. */
static void build_guide(const float *cdf, uint32_t n, uint32_t *guide) {
  uint32_t i = 0;
  for (uint32_t k = 0; k < n; k++) {
    const float t = (float)k / (float)n;
    while (i + 1 < n && cdf[i + 1] <= t) i++;
    guide[k] = i;
  }
}

/* Fills cdf[0..n] from weights; returns the total (0: cdf is uniform). */
static double build_cdf(const double *w, uint32_t n, float *cdf) {
  double sum = 0.0;
  for (uint32_t i = 0; i < n; i++) sum += w[i];
  cdf[0] = 0.0f;
  double acc = 0.0;
  for (uint32_t i = 0; i < n; i++) {
    acc += w[i];
    cdf[i + 1] = sum > 0.0 ? (float)(acc / sum) : (float)(i + 1) / (float)n;
  }
  cdf[n] = 1.0f;
  return sum;
}

/* Tangents t, b completing the unit vector axis to an orthonormal frame
 * (Duff et al. 2017). */
static void axis_frame(hush_vec3 axis, hush_vec3 *t, hush_vec3 *b) {
  const float sign = copysignf(1.0f, axis.z);
  const float a = -1.0f / (sign + axis.z);
  const float c = axis.x * axis.y * a;
  *t = hush_v3(1.0f + sign * axis.x * axis.x * a, sign * c, -sign * axis.x);
  *b = hush_v3(c, sign + axis.y * axis.y * a, -axis.y);
}

/* A direction in the cone around axis (frame t, b, axis) whose half-angle
 * has cosine 1 - one_minus_cos. The sun's frame and 1 - cos are computed
 * once per scene; the result is the same as computing them here. */
static hush_vec3 sample_cone_frame(hush_vec3 t, hush_vec3 b, hush_vec3 axis, float one_minus_cos,
                                   float u1, float u2) {
  const float cos_t = 1.0f - u1 * one_minus_cos;
  const float sin_t = sqrtf(hush_fmaxf(0.0f, 1.0f - cos_t * cos_t));
  const float phi = 2.0f * L_PI * u2;
  const float lx = sin_t * cosf(phi), ly = sin_t * sinf(phi);
  return hush_v3_normalize(hush_v3_add(hush_v3_add(hush_v3_scale(t, lx), hush_v3_scale(b, ly)),
                                       hush_v3_scale(axis, cos_t)));
}

/* A direction in the cone of half-angle acos(cos_max) around axis. */
static hush_vec3 sample_cone(hush_vec3 axis, float cos_max, float u1, float u2) {
  hush_vec3 t, b;
  axis_frame(axis, &t, &b);
  return sample_cone_frame(t, b, axis, 1.0f - cos_max, u1, u2);
}

/* 1 - cos_max without cancellation, for tiny cones. */
static float cone_solid_angle(float cos_max, float sin2_max) {
  return 2.0f * L_PI * sin2_max / (1.0f + cos_max);
}

/* ---- environment maps ------------------------------------------------------- */

/* acos and atan2 to within a few 1e-8 rad (Abramowitz and Stegun 4.4.46
 * and 4.4.49), about float precision: libm's acosf and atanf were ~5% of
 * the render (every escaped ray and env sample finds its texel). A
 * direction within ~1e-7 rad of a texel edge may land in the neighbour, as
 * it already could by rounding. */
static float acos_poly(float x) {
  const float a = fabsf(x);
  const float p =
      1.5707963050f +
      a * (-0.2145988016f +
           a * (0.0889789874f +
                a * (-0.0501743046f +
                     a * (0.0308918810f +
                          a * (-0.0170881256f + a * (0.0066700901f + a * -0.0012624911f))))));
  const float r = sqrtf(hush_fmaxf(0.0f, 1.0f - a)) * p;
  return x < 0.0f ? L_PI - r : r;
}

static float atan2_poly(float y, float x) {
  const float ax = fabsf(x), ay = fabsf(y);
  const float hi = hush_fmaxf(ax, ay), lo = hush_fminf(ax, ay);
  if (!(hi > 0.0f)) return 0.0f;
  const float t = lo / hi, t2 = t * t;
  float r = t * (1.0f +
                 t2 * (-0.3333314528f +
                       t2 * (0.1999355085f +
                             t2 * (-0.1420889944f +
                                   t2 * (0.1065626393f +
                                         t2 * (-0.0752896400f +
                                               t2 * (0.0429096138f +
                                                     t2 * (-0.0161657367f +
                                                           t2 * 0.0028662257f))))))));
  if (ay > ax) r = 0.5f * L_PI - r;
  if (x < 0.0f) r = L_PI - r;
  return y < 0.0f ? -r : r;
}

void hush__envmap_dir_to_uv(hush_vec3 d, float *u, float *v) {
  /* Mitsuba 0.5's envmap.cpp: u = atan2(d.x, -d.z) / (2 pi) wrapped into
   * [0, 1), v = acos(d.y) / pi. (Not (1 + atan2 / pi) / 2, which turns the
   * map by 180 degrees: checked against living-room/TungstenRender.exr.) */
  float a = atan2_poly(d.x, -d.z) / (2.0f * L_PI);
  if (a < 0.0f) a += 1.0f;
  *u = a < 1.0f ? a : 0.0f;
  *v = acos_poly(hush_fminf(1.0f, hush_fmaxf(-1.0f, d.y))) / L_PI;
}

hush_vec3 hush__envmap_uv_to_dir(float u, float v) {
  const float theta = v * L_PI, phi = 2.0f * L_PI * u;
  const float s = sinf(theta);
  return hush_v3(s * sinf(phi), cosf(theta), -s * cosf(phi));
}

/* The sky's map has no rotation: its directions pass through unchanged
 * (the 3x3 product would only turn a -0 into +0). */
static hush_vec3 map_to_local(const hush_envmap *m, hush_vec3 d) {
  if (m->identity) return d;
  const float *r = m->to_world; /* local -> world; its transpose goes back */
  return hush_v3(r[0] * d.x + r[3] * d.y + r[6] * d.z, r[1] * d.x + r[4] * d.y + r[7] * d.z,
                 r[2] * d.x + r[5] * d.y + r[8] * d.z);
}

static hush_vec3 map_to_world(const hush_envmap *m, hush_vec3 d) {
  if (m->identity) return d;
  const float *r = m->to_world;
  return hush_v3(r[0] * d.x + r[1] * d.y + r[2] * d.z, r[3] * d.x + r[4] * d.y + r[5] * d.z,
                 r[6] * d.x + r[7] * d.y + r[8] * d.z);
}

static void texel_of(const hush_envmap *m, float u, float v, uint32_t *x, uint32_t *y) {
  float fx = floorf(u * (float)m->width), fy = floorf(v * (float)m->height);
  fx = hush_fminf(hush_fmaxf(fx, 0.0f), (float)(m->width - 1));
  fy = hush_fminf(hush_fmaxf(fy, 0.0f), (float)(m->height - 1));
  *x = (uint32_t)fx;
  *y = (uint32_t)fy;
}

void hush__envmap_free(hush_envmap *m) {
  free(m->texels);
  free(m->row_cdf);
  free(m->col_cdf);
  free(m->row_guide);
  free(m->col_guide);
  memset(m, 0, sizeof *m);
}

/* Sampling tables from per-texel weights (w is width * height). */
static hush_status envmap_tables(hush_device device, hush_envmap *m, const double *w) {
  const uint32_t W = m->width, H = m->height;
  m->row_cdf = malloc((H + 1) * sizeof(float));
  m->col_cdf = malloc((size_t)H * (W + 1) * sizeof(float));
  m->row_guide = malloc(H * sizeof(uint32_t));
  m->col_guide = malloc((size_t)H * W * sizeof(uint32_t));
  double *rows = malloc(H * sizeof(double));
  if (!m->row_cdf || !m->col_cdf || !m->row_guide || !m->col_guide || !rows) {
    free(rows);
    return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory for the environment map");
  }
  for (uint32_t y = 0; y < H; y++) {
    float *cdf = m->col_cdf + (size_t)y * (W + 1);
    rows[y] = build_cdf(w + (size_t)y * W, W, cdf);
    build_guide(cdf, W, m->col_guide + (size_t)y * W);
  }
  m->total = (float)build_cdf(rows, H, m->row_cdf);
  build_guide(m->row_cdf, H, m->row_guide);
  free(rows);
  /* each texel's density in (u, v), next to its radiance (texel_pdf) */
  for (uint32_t y = 0; y < H; y++) {
    const float p_row = m->row_cdf[y + 1] - m->row_cdf[y];
    const float *cc = m->col_cdf + (size_t)y * (W + 1);
    for (uint32_t x = 0; x < W; x++) {
      const float p_col = cc[x + 1] - cc[x];
      m->texels[4 * ((size_t)y * W + x) + 3] =
          m->total > 0.0f ? p_row * p_col * (float)W * (float)H : 0.0f;
    }
  }
  return HUSH_OK;
}

hush_status hush__envmap_build(hush_device device, hush_envmap *m, const float *src, uint32_t width,
                               uint32_t height, int channels, float scale, const float tw[16]) {
  memset(m, 0, sizeof *m);
  if (!src || width == 0 || height == 0 || channels < 1 || channels > 4)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "environment map: bad texture");
  m->width = width;
  m->height = height;
  for (int r = 0; r < 3; r++)
    for (int c = 0; c < 3; c++) m->to_world[r * 3 + c] = tw ? tw[c * 4 + r] : (r == c ? 1.0f : 0.0f);
  m->identity = 1;
  for (int k = 0; k < 9; k++) m->identity &= m->to_world[k] == ((k % 4 == 0) ? 1.0f : 0.0f);
  const size_t n = (size_t)width * height;
  m->texels = malloc(n * 4 * sizeof(float));
  double *w = malloc(n * sizeof(double));
  if (!m->texels || !w) {
    free(w);
    hush__envmap_free(m);
    return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory for the environment map");
  }
  for (uint32_t y = 0; y < height; y++) {
    const double sin_t = sin(((double)y + 0.5) / height * 3.14159265358979);
    for (uint32_t x = 0; x < width; x++) {
      const size_t i = (size_t)y * width + x;
      float *o = m->texels + 4 * i;
      const float *s = src + i * (size_t)channels;
      for (int k = 0; k < 3; k++) {
        const float v = s[channels >= 3 ? k : 0] * scale;
        o[k] = isfinite(v) && v > 0.0f ? v : 0.0f;
      }
      w[i] = (double)lum3(o) * sin_t;
    }
  }
  const hush_status st = envmap_tables(device, m, w);
  free(w);
  if (st != HUSH_OK) hush__envmap_free(m);
  return st;
}

/* The density (solid angle) with which envmap_sample draws a direction in
 * the texel whose 4 floats start at t, at local polar cosine cos_t. Its
 * density in (u, v) was stored with its radiance (envmap_tables): no read
 * of the CDF tables here. */
static float texel_pdf(const float *t, float cos_t) {
  const float sin_t = sqrtf(hush_fmaxf(0.0f, 1.0f - cos_t * cos_t));
  if (sin_t <= 0.0f) return 0.0f;
  return t[3] / (2.0f * L_PI * L_PI * sin_t);
}

/* The texel along world direction d, and the density (solid angle) with
 * which envmap_sample draws d: one direction-to-texel conversion for both. */
static float envmap_lookup(const hush_envmap *m, hush_vec3 d, const float **texel) {
  float u, v;
  uint32_t x, y;
  const hush_vec3 l = map_to_local(m, d);
  hush__envmap_dir_to_uv(l, &u, &v);
  texel_of(m, u, v, &x, &y);
  *texel = m->texels + 4 * ((size_t)y * m->width + x);
  return texel_pdf(*texel, l.y);
}

void hush__envmap_eval(const hush_envmap *m, hush_vec3 d, float out[3]) {
  const float *texel;
  envmap_lookup(m, d, &texel);
  memcpy(out, texel, 3 * sizeof(float));
}

float hush__envmap_pdf(const hush_envmap *m, hush_vec3 d) {
  const float *texel;
  return envmap_lookup(m, d, &texel);
}

/* A direction drawn from the map, with the density and texel of the texel
 * it was drawn in: no conversion of the direction back to a texel (that
 * could only differ within rounding of a texel's edge). */
static hush_vec3 envmap_sample_texel(const hush_envmap *m, float u1, float u2, float *pdf,
                                     const float **texel) {
  const uint32_t y = cdf_find(m->row_cdf, m->row_guide, m->height, u2);
  const float *cc = m->col_cdf + (size_t)y * (m->width + 1);
  const uint32_t x = cdf_find(cc, m->col_guide + (size_t)y * m->width, m->width, u1);
  /* where inside the bins the numbers fell, reused as the position in the texel */
  const float pr = m->row_cdf[y + 1] - m->row_cdf[y], pc = cc[x + 1] - cc[x];
  const float fy = pr > 0.0f ? hush_fminf(0.999999f, hush_fmaxf(0.0f, (u2 - m->row_cdf[y]) / pr)) : 0.5f;
  const float fx = pc > 0.0f ? hush_fminf(0.999999f, hush_fmaxf(0.0f, (u1 - cc[x]) / pc)) : 0.5f;
  const float u = ((float)x + fx) / (float)m->width, v = ((float)y + fy) / (float)m->height;
  const hush_vec3 l = hush__envmap_uv_to_dir(u, v);
  *texel = m->texels + 4 * ((size_t)y * m->width + x);
  *pdf = texel_pdf(*texel, l.y);
  return map_to_world(m, l);
}

hush_vec3 hush__envmap_sample(const hush_envmap *m, float u1, float u2, float *pdf) {
  const float *texel;
  return envmap_sample_texel(m, u1, u2, pdf, &texel);
}

/* ---- sun and sky --------------------------------------------------------------------- */

static float perez(const float c[5], float cos_theta, float gamma, float cos_gamma) {
  return (1.0f + c[0] * expf(c[1] / hush_fmaxf(cos_theta, 1e-3f))) *
         (1.0f + c[2] * expf(c[3] * gamma) + c[4] * cos_gamma * cos_gamma);
}

void hush__sky_model_init(hush_sky_model *sky, hush_vec3 sun_dir, float T) {
  sky->sun_dir = sun_dir;
  const float ts = acosf(hush_fminf(1.0f, hush_fmaxf(-1.0f, sun_dir.y)));
  const float c[3][5] = {
      {0.1787f * T - 1.4630f, -0.3554f * T + 0.4275f, -0.0227f * T + 5.3251f,
       0.1206f * T - 2.5771f, -0.0670f * T + 0.3703f},
      {-0.0193f * T - 0.2592f, -0.0665f * T + 0.0008f, -0.0004f * T + 0.2125f,
       -0.0641f * T - 0.8989f, -0.0033f * T + 0.0452f},
      {-0.0167f * T - 0.2608f, -0.0950f * T + 0.0092f, -0.0079f * T + 0.2102f,
       -0.0441f * T - 1.6537f, -0.0109f * T + 0.0529f}};
  memcpy(sky->coef, c, sizeof sky->coef);
  const float chi = (4.0f / 9.0f - T / 120.0f) * (L_PI - 2.0f * ts);
  const float Yz = hush_fmaxf(0.0f, (4.0453f * T - 4.9710f) * tanf(chi) - 0.2155f * T + 2.4192f);
  const float t2 = ts * ts, t3 = t2 * ts;
  const float xz = T * T * (0.00166f * t3 - 0.00375f * t2 + 0.00209f * ts) +
                   T * (-0.02903f * t3 + 0.06377f * t2 - 0.03202f * ts + 0.00394f) +
                   (0.11693f * t3 - 0.21196f * t2 + 0.06052f * ts + 0.25886f);
  const float yz = T * T * (0.00275f * t3 - 0.00610f * t2 + 0.00317f * ts) +
                   T * (-0.04214f * t3 + 0.08970f * t2 - 0.04153f * ts + 0.00516f) +
                   (0.15346f * t3 - 0.26756f * t2 + 0.06670f * ts + 0.26688f);
  const float z[3] = {Yz, xz, yz};
  const float cos_ts = cosf(ts);
  for (int k = 0; k < 3; k++) sky->zenith[k] = z[k] / perez(sky->coef[k], 1.0f, ts, cos_ts);
}

/* Y, x, y (Perez times zenith values) to Mitsuba's RGB radiance. */
static void sky_xyy_to_rgb(float Y, float x, float y, float out[3]) {
  out[0] = out[1] = out[2] = 0.0f;
  if (!(y > 0.0f)) return;
  /* kcd/m^2 -> Mitsuba's W / (m^2 sr nm) as RGB: 1000 / (683 lm/W * 106.857 nm) */
  const float Yu = Y * (1000.0f / (683.0f * 106.857f));
  const float X = x / y * Yu, Z = (1.0f - x - y) / y * Yu;
  out[0] = hush_fmaxf(0.0f, 3.2404542f * X - 1.5371385f * Yu - 0.4985314f * Z);
  out[1] = hush_fmaxf(0.0f, -0.9692660f * X + 1.8760108f * Yu + 0.0415560f * Z);
  out[2] = hush_fmaxf(0.0f, 0.0556434f * X - 0.2040259f * Yu + 1.0572252f * Z);
}

void hush__sky_model_eval(const hush_sky_model *sky, hush_vec3 d, float out[3]) {
  out[0] = out[1] = out[2] = 0.0f;
  if (d.y <= 0.0f) return; /* Mitsuba's sky is black below the horizon */
  const float cos_gamma = hush_fminf(1.0f, hush_fmaxf(-1.0f, hush_v3_dot(d, sky->sun_dir)));
  const float gamma = acosf(cos_gamma);
  const float Y = sky->zenith[0] * perez(sky->coef[0], d.y, gamma, cos_gamma);
  const float x = sky->zenith[1] * perez(sky->coef[1], d.y, gamma, cos_gamma);
  const float y = sky->zenith[2] * perez(sky->coef[2], d.y, gamma, cos_gamma);
  sky_xyy_to_rgb(Y, x, y, out);
}

void hush__sky_table_init(hush_sky_table *t, const hush_sky_model *sky) {
  const uint32_t n = HUSH_SKY_TABLE;
  t->sun_dir = sky->sun_dir;
  for (uint32_t i = 0; i <= n; i++) {
    const double c = (double)i / n;                  /* cos theta */
    const double s = (double)i / n;                  /* sin(gamma / 2) */
    const double gamma = 2.0 * asin(s), cg = cos(gamma);
    for (int k = 0; k < 3; k++) {
      const float *cf = sky->coef[k];
      t->theta[i][k] = (float)(sky->zenith[k] * (1.0 + cf[0] * exp(cf[1] / fmax(c, 1e-3))));
      t->gamma[i][k] = (float)(1.0 + cf[2] * exp(cf[3] * gamma) + cf[4] * cg * cg);
    }
  }
}

/* Row a of a table at x in [0, 1], linearly interpolated. */
static void table_lerp(const float (*tab)[3], float x, float out[3]) {
  const float f = hush_fminf(hush_fmaxf(x, 0.0f), 1.0f) * (float)HUSH_SKY_TABLE;
  uint32_t i = (uint32_t)f;
  if (i >= HUSH_SKY_TABLE) i = HUSH_SKY_TABLE - 1;
  const float w = f - (float)i;
  for (int k = 0; k < 3; k++) out[k] = tab[i][k] + w * (tab[i + 1][k] - tab[i][k]);
}

void hush__sky_table_eval(const hush_sky_table *t, hush_vec3 d, float out[3]) {
  out[0] = out[1] = out[2] = 0.0f;
  if (d.y <= 0.0f) return;
  const float cos_gamma = hush_v3_dot(d, t->sun_dir);
  const float s = sqrtf(hush_fmaxf(0.0f, 0.5f - 0.5f * cos_gamma));
  float a[3], b[3];
  table_lerp(t->theta, d.y, a);
  table_lerp(t->gamma, s, b);
  sky_xyy_to_rgb(a[0] * b[0], a[1] * b[1], a[2] * b[2], out);
}

void hush__preetham_sky(hush_vec3 d, hush_vec3 sun_dir, float T, float out[3]) {
  hush_sky_model sky;
  hush__sky_model_init(&sky, sun_dir, T);
  hush__sky_model_eval(&sky, d, out);
}

/* Sun radiance after the atmosphere, as in Mitsuba's computeSunRadiance
 * (Preetham 1999, appendix) but only Rayleigh and aerosol extinction, at one
 * wavelength per sRGB primary. W / (m^2 sr nm). */
static void sun_radiance(float theta_s, float T, float out[3]) {
  static const float lambda[3] = {610.0f, 550.0f, 465.0f};
  static const float solar[3] = {24173.2f, 25503.8f, 30360.0f}; /* Mitsuba's table */
  const float beta = 0.04608365822050f * T - 0.04586025928522f;
  const float deg = theta_s * 180.0f / L_PI;
  const float m = 1.0f / (cosf(theta_s) + 0.15f * powf(hush_fmaxf(93.885f - deg, 1e-3f), -1.253f));
  for (int k = 0; k < 3; k++) {
    const float l = lambda[k] / 1000.0f;
    const float tau_r = expf(-m * 0.008735f * powf(l, -4.08f));
    const float tau_a = expf(-m * beta * powf(l, -1.3f));
    out[k] = solar[k] * tau_r * tau_a;
  }
}

static hush_status sky_build(hush_device device, hush_lights *L, const hush_environment *env) {
  const uint32_t W = SKY_WIDTH, H = SKY_HEIGHT;
  hush_envmap *m = &L->map;
  memset(m, 0, sizeof *m);
  m->width = W;
  m->height = H;
  for (int k = 0; k < 9; k++) m->to_world[k] = (k % 4 == 0) ? 1.0f : 0.0f;
  m->identity = 1;
  m->texels = malloc((size_t)W * H * 4 * sizeof(float));
  double *w = malloc((size_t)W * H * sizeof(double));
  if (!m->texels || !w) {
    free(w);
    hush__envmap_free(m);
    return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory for the sky");
  }
  hush__sky_model_init(&L->sky, L->sun_dir, env->turbidity);
  L->sky_scale = env->sky_scale;
  L->sky_table = malloc(sizeof *L->sky_table);
  if (!L->sky_table) {
    free(w);
    hush__envmap_free(m);
    return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory for the sky");
  }
  hush__sky_table_init(L->sky_table, &L->sky);
  double sum = 0.0;
  for (uint32_t y = 0; y < H; y++)
    for (uint32_t x = 0; x < W; x++) {
      const size_t i = (size_t)y * W + x;
      const hush_vec3 d = hush__envmap_uv_to_dir(((float)x + 0.5f) / W, ((float)y + 0.5f) / H);
      float *o = m->texels + 4 * i;
      hush__sky_model_eval(&L->sky, d, o);
      for (int k = 0; k < 3; k++) o[k] *= env->sky_scale;
      w[i] = (double)lum3(o) * sin(((double)y + 0.5) / H * 3.14159265358979);
      sum += w[i];
    }
  /* the sky is evaluated exactly, not from the table: every texel of the
   * upper hemisphere keeps some probability so the estimator stays unbiased */
  const double floor_w = 0.01 * sum / ((double)W * H);
  for (uint32_t y = 0; y < H / 2 + 1; y++)
    for (uint32_t x = 0; x < W; x++) w[(size_t)y * W + x] += floor_w;
  const hush_status st = envmap_tables(device, m, w);
  free(w);
  if (st != HUSH_OK) hush__envmap_free(m);
  return st;
}

static hush_status env_init(hush_device device, hush_lights *L, const hush_scene *scene) {
  const hush_environment *env = &scene->env;
  L->env_type = env->type;
  switch (env->type) {
  case HUSH_ENV_CONSTANT:
    memcpy(L->env_color, env->color, sizeof L->env_color);
    if (!(lum3(L->env_color) > 0.0f)) L->env_type = HUSH_ENV_NONE;
    return HUSH_OK;
  case HUSH_ENV_MAP: {
    if (env->texture < 0 || (uint32_t)env->texture >= scene->texture_count)
      return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "environment map: no texture");
    const hush_texture *t = &scene->textures[env->texture];
    const float scale = env->scale > 0.0f ? env->scale : 1.0f;
    hush_status st = hush__envmap_build(device, &L->map, t->texels, t->width, t->height,
                                        t->channels, scale, env->to_world);
    if (st == HUSH_OK && !(L->map.total > 0.0f)) {
      hush__envmap_free(&L->map);
      L->env_type = HUSH_ENV_NONE;
    }
    return st;
  }
  case HUSH_ENV_SUNSKY: {
    L->sun_dir = hush_v3_normalize(
        hush_v3(env->sun_direction[0], env->sun_direction[1], env->sun_direction[2]));
    const float theta0 = SUN_HALF_ANGLE_DEG * L_PI / 180.0f;
    const float scale = env->sun_radius_scale > 0.0f ? env->sun_radius_scale : 1.0f;
    const float theta = hush_fminf(theta0 * scale, 0.5f * L_PI);
    L->sun_cos_max = cosf(theta);
    L->sun_one_minus_cos = 1.0f - L->sun_cos_max;
    axis_frame(L->sun_dir, &L->sun_t, &L->sun_b);
    const float theta_s = acosf(hush_fminf(1.0f, hush_fmaxf(-1.0f, L->sun_dir.y)));
    sun_radiance(hush_fminf(theta_s, 0.5f * L_PI), env->turbidity, L->sun_radiance);
    /* Mitsuba keeps the sun's power when its radius is scaled */
    const float ratio = cone_solid_angle(cosf(theta0), sinf(theta0) * sinf(theta0)) /
                        cone_solid_angle(L->sun_cos_max, sinf(theta) * sinf(theta));
    for (int k = 0; k < 3; k++) L->sun_radiance[k] *= env->sun_scale * ratio;
    return sky_build(device, L, env);
  }
  default:
    L->env_type = HUSH_ENV_NONE;
    return HUSH_OK;
  }
}

/* ---- set-up ------------------------------------------------------------------------------- */

/* (b - a) x (c - a) of the triangle's object-space corners: twice its area
 * along its winding normal. */
static hush_vec3 object_cross(const hush_scene *s, uint32_t tri) {
  const uint32_t *ix = s->indices + 3 * (size_t)tri;
  const float *a = s->positions + 3 * (size_t)ix[0];
  const float *b = s->positions + 3 * (size_t)ix[1];
  const float *c = s->positions + 3 * (size_t)ix[2];
  return hush_v3_cross(hush_v3(b[0] - a[0], b[1] - a[1], b[2] - a[2]),
                       hush_v3(c[0] - a[0], c[1] - a[1], c[2] - a[2]));
}

/* +1 when the triangle's winding normal is its front, -1 when its vertex
 * normals point the other way: the rule by which scene.c sets back_face,
 * so a light sample and a ray that meets the triangle agree on which side
 * emits (rigid motion keeps the sign). */
static float front_sign(const hush_scene *s, uint32_t tri) {
  if (!s->normals) return 1.0f;
  const uint32_t *ix = s->indices + 3 * (size_t)tri;
  const hush_vec3 ng = object_cross(s, tri);
  hush_vec3 n = hush_v3(0.0f, 0.0f, 0.0f);
  for (int k = 0; k < 3; k++) {
    const float *v = s->normals + 3 * (size_t)ix[k];
    n = hush_v3_add(n, hush_v3(v[0], v[1], v[2]));
  }
  return hush_v3_dot(ng, n) < 0.0f ? -1.0f : 1.0f;
}

static void triangle_corners(const hush_scene *s, uint32_t tri, uint32_t frame, hush_vec3 p[3]) {
  p[0] = hush__scene_point(s, tri, 0.0f, 0.0f, frame);
  p[1] = hush__scene_point(s, tri, 1.0f, 0.0f, frame);
  p[2] = hush__scene_point(s, tri, 0.0f, 1.0f, frame);
}

float hush__lights_triangle_area(const hush_scene *s, uint32_t tri) {
  return 0.5f * hush_v3_length(object_cross(s, tri));
}

static hush_status tris_init(hush_device device, hush_lights *L, const hush_scene *s) {
  uint32_t n = 0;
  for (uint32_t t = 0; t < s->triangle_count; t++)
    if (lum3(s->materials[s->triangle_material[t]].emission) > 0.0f) n++;
  if (n == 0) return HUSH_OK;
  L->tris = malloc(n * sizeof(uint32_t));
  L->tri_cdf = malloc((n + 1) * sizeof(float));
  L->tri_pmf = calloc(s->triangle_count, sizeof(float));
  L->tri_front = malloc(n * sizeof(float));
  double *w = malloc(n * sizeof(double));
  if (!L->tris || !L->tri_cdf || !L->tri_pmf || !L->tri_front || !w) {
    free(w);
    return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory for the light table");
  }
  n = 0;
  for (uint32_t t = 0; t < s->triangle_count; t++) {
    const float le = lum3(s->materials[s->triangle_material[t]].emission);
    if (!(le > 0.0f)) continue;
    L->tris[n] = t;
    L->tri_front[n] = s->two_sided_emitters ? 0.0f : front_sign(s, t);
    /* rigid motion keeps areas: object space is good enough */
    w[n] = (double)hush__lights_triangle_area(s, t) * le;
    n++;
  }
  const double total = build_cdf(w, n, L->tri_cdf);
  for (uint32_t i = 0; i < n; i++)
    L->tri_pmf[L->tris[i]] = total > 0.0 ? (float)(w[i] / total) : 1.0f / (float)n;
  free(w);
  L->tri_count = n;
  L->tri_power = (float)(total * L_PI * (s->two_sided_emitters ? 2.0 : 1.0));
  return HUSH_OK;
}

hush_status hush__lights_init(hush_device device, hush_lights *L, const hush_scene *scene) {
  memset(L, 0, sizeof *L);
  L->scene = scene;
  float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (uint32_t i = 0; i < scene->vertex_count; i++)
    for (int k = 0; k < 3; k++) {
      lo[k] = hush_fminf(lo[k], scene->positions[3 * i + k]);
      hi[k] = hush_fmaxf(hi[k], scene->positions[3 * i + k]);
    }
  if (scene->vertex_count > 0) {
    L->scene_center = hush_v3(0.5f * (lo[0] + hi[0]), 0.5f * (lo[1] + hi[1]), 0.5f * (lo[2] + hi[2]));
    L->scene_radius = 0.5f * hush_v3_length(hush_v3(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]));
  }
  if (!(L->scene_radius > 0.0f) || !isfinite(L->scene_radius)) L->scene_radius = 1.0f;
  L->sphere_count = scene->sphere_count;
  if (scene->sphere_count) {
    L->p_sphere = calloc(scene->sphere_count, sizeof(float));
    if (!L->p_sphere) return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory");
  }
  hush_status st = tris_init(device, L, scene);
  if (st == HUSH_OK) st = env_init(device, L, scene);
  if (st != HUSH_OK) {
    hush__lights_free(L);
    return st;
  }
  hush__lights_set_frame(L, scene->frame);
  return HUSH_OK;
}

void hush__lights_free(hush_lights *L) {
  free(L->tris);
  free(L->tri_cdf);
  free(L->tri_pmf);
  free(L->tri_front);
  free(L->p_sphere);
  hush__envmap_free(&L->map);
  free(L->sky_table);
  memset(L, 0, sizeof *L);
}

static float env_power(const hush_lights *L) {
  const float area = L_PI * L->scene_radius * L->scene_radius;
  if (L->env_type == HUSH_ENV_CONSTANT) return lum3(L->env_color) * 4.0f * L_PI * area;
  if (L->env_type == HUSH_ENV_MAP || L->env_type == HUSH_ENV_SUNSKY) {
    /* total = sum of lum * sin(theta) over texels ~ integral / (2 pi^2 / (W H)) */
    const float integral = L->map.total * 2.0f * L_PI * L_PI / ((float)L->map.width * L->map.height);
    return integral * area;
  }
  return 0.0f;
}

void hush__lights_set_frame(hush_lights *L, uint32_t frame) {
  const hush_scene *s = L->scene;
  L->frame = frame;
  float power[3] = {L->tri_count ? L->tri_power : 0.0f, 0.0f, 0.0f};
  power[1] = L->env_type != HUSH_ENV_NONE ? env_power(L) : 0.0f;
  if (L->env_type == HUSH_ENV_SUNSKY)
    power[2] = lum3(L->sun_radiance) *
               cone_solid_angle(L->sun_cos_max, 1.0f - L->sun_cos_max * L->sun_cos_max) * L_PI *
               L->scene_radius * L->scene_radius;
  float total = 0.0f;
  uint32_t groups = 0;
  for (int i = 0; i < 3; i++)
    if (power[i] > 0.0f) {
      total += power[i];
      groups++;
    }
  for (uint32_t i = 0; i < s->sphere_count; i++) {
    float c[3];
    const hush_sphere_light *sl = &s->spheres[i];
    const int on = hush__scene_sphere_at(s, i, frame, c);
    const float p = on ? 4.0f * L_PI * L_PI * sl->radius * sl->radius * lum3(sl->radiance) : 0.0f;
    L->p_sphere[i] = p;
    if (p > 0.0f) {
      total += p;
      groups++;
    }
  }
  L->group_count = groups;
  L->p_tris = L->p_env = L->p_sun = 0.0f;
  if (groups == 0) return;
  const float uni = 0.5f / (float)groups;
#define MIX(p) ((p) > 0.0f ? 0.5f * (p) / total + uni : 0.0f)
  L->p_tris = MIX(power[0]);
  L->p_env = MIX(power[1]);
  L->p_sun = MIX(power[2]);
  for (uint32_t i = 0; i < s->sphere_count; i++) L->p_sphere[i] = MIX(L->p_sphere[i]);
#undef MIX
}

int hush__lights_any(const hush_lights *L) {
  return L->group_count > 0;
}

/* ---- evaluation and densities ------------------------------------------------------------------ */

static int in_sun(const hush_lights *L, hush_vec3 d) {
  return L->env_type == HUSH_ENV_SUNSKY && hush_v3_dot(d, L->sun_dir) >= L->sun_cos_max;
}

static float sun_pdf(const hush_lights *L) {
  return L->p_sun / cone_solid_angle(L->sun_cos_max, 1.0f - L->sun_cos_max * L->sun_cos_max);
}

/* Sky plus, inside the disc, the sun. */
static void sunsky_radiance(const hush_lights *L, hush_vec3 d, int sun, float out[3]) {
  hush__sky_table_eval(L->sky_table, d, out);
  for (int k = 0; k < 3; k++) out[k] *= L->sky_scale;
  if (sun)
    for (int k = 0; k < 3; k++) out[k] += L->sun_radiance[k];
}

void hush__lights_env_radiance(const hush_lights *L, hush_vec3 d, float out[3]) {
  out[0] = out[1] = out[2] = 0.0f;
  switch (L->env_type) {
  case HUSH_ENV_CONSTANT:
    memcpy(out, L->env_color, 3 * sizeof(float));
    break;
  case HUSH_ENV_MAP:
    hush__envmap_eval(&L->map, d, out);
    break;
  case HUSH_ENV_SUNSKY:
    sunsky_radiance(L, d, in_sun(L, d), out);
    break;
  default:
    break;
  }
}

float hush__lights_env_pdf(const hush_lights *L, hush_vec3 d) {
  switch (L->env_type) {
  case HUSH_ENV_CONSTANT:
    return L->p_env / (4.0f * L_PI);
  case HUSH_ENV_MAP:
    return L->p_env * hush__envmap_pdf(&L->map, d);
  case HUSH_ENV_SUNSKY:
    return L->p_env * hush__envmap_pdf(&L->map, d) + (in_sun(L, d) ? sun_pdf(L) : 0.0f);
  default:
    return 0.0f;
  }
}

float hush__lights_env_eval(const hush_lights *L, hush_vec3 d, float out[3]) {
  out[0] = out[1] = out[2] = 0.0f;
  const float *texel;
  switch (L->env_type) {
  case HUSH_ENV_CONSTANT:
    memcpy(out, L->env_color, 3 * sizeof(float));
    return L->p_env / (4.0f * L_PI);
  case HUSH_ENV_MAP: {
    const float pdf = envmap_lookup(&L->map, d, &texel);
    memcpy(out, texel, 3 * sizeof(float));
    return L->p_env * pdf;
  }
  case HUSH_ENV_SUNSKY: {
    const int sun = in_sun(L, d);
    sunsky_radiance(L, d, sun, out);
    return L->p_env * envmap_lookup(&L->map, d, &texel) + (sun ? sun_pdf(L) : 0.0f);
  }
  default:
    return 0.0f;
  }
}

float hush__lights_triangle_pdf(const hush_lights *L, uint32_t tri, float area, float dist,
                                float cos_l) {
  if (!L->tri_pmf || tri >= L->scene->triangle_count) return 0.0f;
  const float pmf = L->tri_pmf[tri];
  if (!(pmf > 0.0f) || !(area > 0.0f) || !(cos_l > 0.0f)) return 0.0f;
  return L->p_tris * pmf * dist * dist / (area * cos_l);
}

/* Visible cap of sphere i from p: axis, cos_max and the cap's solid angle. */
static int sphere_cone(const hush_lights *L, uint32_t i, hush_vec3 p, hush_vec3 *axis,
                       float *dist_c, float *cos_max, float *omega) {
  float c[3];
  if (!hush__scene_sphere_at(L->scene, i, L->frame, c)) return 0;
  const float r = L->scene->spheres[i].radius;
  const hush_vec3 to = hush_v3_sub(hush_v3(c[0], c[1], c[2]), p);
  const float d = hush_v3_length(to);
  if (!(d > r * 1.0001f)) return 0;
  const float sin2 = (r * r) / (d * d);
  *cos_max = sqrtf(hush_fmaxf(0.0f, 1.0f - sin2));
  *omega = cone_solid_angle(*cos_max, sin2);
  *axis = hush_v3_scale(to, 1.0f / d);
  *dist_c = d;
  return 1;
}

float hush__lights_sphere_pdf(const hush_lights *L, uint32_t i, hush_vec3 p) {
  if (i >= L->scene->sphere_count || !(L->p_sphere[i] > 0.0f)) return 0.0f;
  hush_vec3 axis;
  float d, cos_max, omega;
  if (!sphere_cone(L, i, p, &axis, &d, &cos_max, &omega)) return 0.0f;
  return L->p_sphere[i] / omega;
}

uint32_t hush__lights_intersect_sphere_any(const hush_lights *L, hush_vec3 o, hush_vec3 d,
                                           float tnear, float tfar, float *t) {
  uint32_t found = 0;
  for (uint32_t i = 0; i < L->scene->sphere_count; i++) {
    float c[3];
    if (!hush__scene_sphere_at(L->scene, i, L->frame, c)) continue;
    const float r = L->scene->spheres[i].radius;
    const hush_vec3 oc = hush_v3_sub(o, hush_v3(c[0], c[1], c[2]));
    const float b = hush_v3_dot(oc, d);
    const float disc = b * b - (hush_v3_dot(oc, oc) - r * r);
    if (disc < 0.0f) continue;
    const float q = sqrtf(disc);
    const float t0 = -b - q > tnear ? -b - q : -b + q;
    if (t0 > tnear && t0 < tfar) {
      tfar = t0;
      found = i + 1;
    }
  }
  if (found) *t = tfar;
  return found;
}

/* ---- sampling -------------------------------------------------------------------------------------- */

static int sample_triangle(const hush_lights *L, hush_vec3 p, float u0, float u1, float u2,
                           hush_light_sample *s) {
  const hush_scene *sc = L->scene;
  const uint32_t i = cdf_search(L->tri_cdf, L->tri_count, u0);
  const uint32_t tri = L->tris[i];
  hush_vec3 c[3];
  triangle_corners(sc, tri, L->frame, c);
  const hush_vec3 cr = hush_v3_cross(hush_v3_sub(c[1], c[0]), hush_v3_sub(c[2], c[0]));
  const float area = 0.5f * hush_v3_length(cr);
  if (!(area > 0.0f)) return 0;
  const float su = sqrtf(u1);
  const float bu = su * (1.0f - u2), bv = su * u2;
  const hush_vec3 q = hush_v3_add(hush_v3_add(hush_v3_scale(c[0], 1.0f - bu - bv),
                                              hush_v3_scale(c[1], bu)),
                                  hush_v3_scale(c[2], bv));
  const hush_vec3 to = hush_v3_sub(q, p);
  const float dist = hush_v3_length(to);
  if (!(dist > 0.0f)) return 0;
  s->wi = hush_v3_scale(to, 1.0f / dist);
  /* p behind a one-sided light: no light (front 0: both sides emit) */
  if (L->tri_front[i] * hush_v3_dot(s->wi, cr) > 0.0f) return 0;
  const float cos_l = fabsf(hush_v3_dot(s->wi, cr)) / (2.0f * area);
  s->pdf = hush__lights_triangle_pdf(L, tri, area, dist, cos_l);
  if (!(s->pdf > 0.0f)) return 0;
  s->dist = dist;
  memcpy(s->radiance, sc->materials[sc->triangle_material[tri]].emission, 3 * sizeof(float));
  return 1;
}

static int sample_sphere(const hush_lights *L, uint32_t i, hush_vec3 p, float u1, float u2,
                         hush_light_sample *s) {
  hush_vec3 axis;
  float d, cos_max, omega;
  if (!sphere_cone(L, i, p, &axis, &d, &cos_max, &omega)) return 0;
  s->wi = sample_cone(axis, cos_max, u1, u2);
  const float r = L->scene->spheres[i].radius;
  const float b = d * hush_v3_dot(s->wi, axis);
  const float disc = r * r - (d * d - b * b);
  s->dist = b - sqrtf(hush_fmaxf(0.0f, disc));
  s->pdf = L->p_sphere[i] / omega;
  memcpy(s->radiance, L->scene->spheres[i].radiance, 3 * sizeof(float));
  return s->pdf > 0.0f;
}

/* hush__lights_sample, with the sun-and-sky radiance left out when `defer`. */
static int sample_light(const hush_lights *L, hush_vec3 p, const float u[3], int defer,
                        hush_light_sample *s) {
  memset(s, 0, sizeof *s);
  if (L->group_count == 0) return 0;
  /* pick a group with u[0], then reuse what is left of it */
  float x = u[0];
  if (x < L->p_tris) {
    return sample_triangle(L, p, x / L->p_tris, u[1], u[2], s);
  }
  x -= L->p_tris;
  const uint32_t ns = L->scene->sphere_count;
  for (uint32_t i = 0; i < ns; i++) {
    if (x < L->p_sphere[i]) return sample_sphere(L, i, p, u[1], u[2], s);
    x -= L->p_sphere[i];
  }
  const int sun = L->p_sun > 0.0f && (L->p_env <= 0.0f || x >= L->p_env);
  if (L->p_env <= 0.0f && !sun) return 0;
  s->dist = INFINITY;
  defer = defer && L->env_type == HUSH_ENV_SUNSKY;
  if (sun || L->env_type == HUSH_ENV_CONSTANT) {
    if (sun) {
      s->wi = sample_cone_frame(L->sun_t, L->sun_b, L->sun_dir, L->sun_one_minus_cos, u[1], u[2]);
    } else {
      const float z = 1.0f - 2.0f * u[1], r = sqrtf(hush_fmaxf(0.0f, 1.0f - z * z));
      const float phi = 2.0f * L_PI * u[2];
      s->wi = hush_v3(r * cosf(phi), r * sinf(phi), z);
    }
    if (defer) {
      /* hush__lights_env_eval's density, without its radiance; inside the
       * sun it is positive whatever the map's share, which is then left
       * for hush__lights_sample_finish too (a map lookup) */
      const float *texel;
      const int in = in_sun(L, s->wi);
      s->deferred = 1;
      if (in) {
        s->deferred = 2;
        return 1;
      }
      s->pdf = L->p_env * envmap_lookup(&L->map, s->wi, &texel);
      return s->pdf > 0.0f && s->wi.y > 0.0f;
    }
    s->pdf = hush__lights_env_eval(L, s->wi, s->radiance);
    return s->pdf > 0.0f;
  }
  /* the map (or the tabulated sky): its density and texel come with the
   * sample, so the direction is not converted back a second time */
  float pdf_map;
  const float *texel;
  s->wi = envmap_sample_texel(&L->map, u[1], u[2], &pdf_map, &texel);
  s->pdf = L->p_env * pdf_map;
  if (L->env_type == HUSH_ENV_MAP) {
    memcpy(s->radiance, texel, 3 * sizeof(float));
  } else {
    const int in = in_sun(L, s->wi);
    if (defer) {
      s->deferred = 1;
      if (in) s->pdf += sun_pdf(L);
      return s->pdf > 0.0f && (in || s->wi.y > 0.0f);
    }
    sunsky_radiance(L, s->wi, in, s->radiance);
    if (in) s->pdf += sun_pdf(L);
  }
  return s->pdf > 0.0f;
}

int hush__lights_sample(const hush_lights *L, hush_vec3 p, const float u[3], hush_light_sample *s) {
  return sample_light(L, p, u, 0, s);
}

int hush__lights_sample_deferred(const hush_lights *L, hush_vec3 p, const float u[3],
                                 hush_light_sample *s) {
  return sample_light(L, p, u, 1, s);
}

void hush__lights_sample_finish(const hush_lights *L, hush_light_sample *s) {
  if (!s->deferred) return;
  /* the sky is black below the horizon (sky_table_eval), so this is
   * hush__lights_env_eval's radiance, as hush__lights_sample has it */
  sunsky_radiance(L, s->wi, in_sun(L, s->wi), s->radiance);
  if (s->deferred == 2) {
    const float *texel;
    s->pdf = L->p_env * envmap_lookup(&L->map, s->wi, &texel) + sun_pdf(L);
  }
  s->deferred = 0;
}
