/*
 * taa.c — temporal anti-aliasing resolve; see taa.h. Karis 2014 (neighbourhood
 * clamp/clip in YCoCg, constant blend), as papers/NOTES.md summarises it.
 */
#include "temporal/taa.h"

#include <string.h>

hush_status hush__taa_init(hush_device device, hush_taa *taa, uint32_t width, uint32_t height) {
  memset(taa, 0, sizeof *taa);
  hush_status s = hush__planar_init(device, &taa->history[0], 3, width, height);
  if (!s) s = hush__planar_init(device, &taa->history[1], 3, width, height);
  if (!s) s = hush__planar_init(device, &taa->gathered, 3, width, height);
  if (!s) s = hush__planar_init(device, &taa->current, 3, width, height);
  if (s) hush__taa_free(taa);
  return s;
}

void hush__taa_free(hush_taa *taa) {
  hush__planar_free(&taa->history[0]);
  hush__planar_free(&taa->history[1]);
  hush__planar_free(&taa->gathered);
  hush__planar_free(&taa->current);
  memset(taa, 0, sizeof *taa);
}

/* Tone mapping c / (1 + l) with l the Rec. 709 luminance, and its inverse
 * c / (1 - l) (l of the mapped colour, below 1). Scaling all channels by one
 * factor keeps the hue. */
static inline float tonemap_scale(float r, float g, float b) {
  const float l = 0.2126f * r + 0.7152f * g + 0.0722f * b;
  return 1.0f / (1.0f + (l > 0.0f ? l : 0.0f));
}
static inline float untonemap_scale(float r, float g, float b) {
  float l = 0.2126f * r + 0.7152f * g + 0.0722f * b;
  l = l > 0.0f ? l : 0.0f;
  l = l < 0.999999f ? l : 0.999999f; /* radiance luminance up to 1e6 */
  return 1.0f / (1.0f - l);
}

/* YCoCg (not normalised: Y = (r + 2g + b) / 4, Co = (r - b) / 2,
 * Cg = (-r + 2g - b) / 4) and back; a linear map, so a blend in either
 * space is the same. */
static inline void to_ycocg(float r, float g, float b, float v[3]) {
  v[0] = 0.25f * r + 0.5f * g + 0.25f * b;
  v[1] = 0.5f * r - 0.5f * b;
  v[2] = -0.25f * r + 0.5f * g - 0.25f * b;
}
static inline void from_ycocg(const float v[3], float *r, float *g, float *b) {
  *r = v[0] + v[1] - v[2];
  *g = v[0] + v[2];
  *b = v[0] - v[1] - v[2];
}

static inline int clampi(int v, int lo, int hi) { return v < lo ? lo : v > hi ? hi : v; }

/* Clips h towards the box centre c (Karis's clip_aabb): the point of the
 * segment c..h closest to h inside the box [lo, hi]. */
static void clip_box(float h[3], const float lo[3], const float hi[3]) {
  float t = 1.0f;
  for (int k = 0; k < 3; k++) {
    const float c = 0.5f * (lo[k] + hi[k]), e = 0.5f * (hi[k] - lo[k]) + 1e-7f;
    const float d = h[k] - c;
    const float a = d > 0.0f ? d : -d;
    if (a > e) {
      const float tk = e / a;
      t = tk < t ? tk : t;
    }
  }
  for (int k = 0; k < 3; k++) {
    const float c = 0.5f * (lo[k] + hi[k]);
    h[k] = c + (h[k] - c) * t;
  }
}

void hush__taa_resolve(hush_taa *taa, const hush_reproject_plan *plan, const float *const *color,
                       const hush_taa_params *params, int threads) {
  hush_planar *cur = &taa->current;
  const int W = (int)cur->width, H = (int)cur->height;
  const int tonemap = params->tonemap;
  const float alpha = params->alpha;

  /* this frame, tone-mapped if asked, into planes the 3x3 box is read from */
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < H; y++)
    for (int x = 0; x < W; x++) {
      const size_t i = (size_t)y * W + x;
      const float r = color[0][i], g = color[1][i], b = color[2][i];
      const float s = tonemap ? tonemap_scale(r, g, b) : 1.0f;
      cur->plane[0][i] = r * s;
      cur->plane[1][i] = g * s;
      cur->plane[2][i] = b * s;
    }

  const int use_history = taa->has_history && plan;
  if (use_history)
    hush__reproject_gather(plan, (const float *const *)taa->history[taa->latest].plane, 3,
                           taa->gathered.plane, 0.0f, threads);
  hush_planar *out = &taa->history[1 - taa->latest];

#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < H; y++)
    for (int x = 0; x < W; x++) {
      const size_t i = (size_t)y * W + x;
      float c[3], lo[3], hi[3];
      to_ycocg(cur->plane[0][i], cur->plane[1][i], cur->plane[2][i], c);
      float r = cur->plane[0][i], g = cur->plane[1][i], b = cur->plane[2][i];
      if (use_history && plan->kind[i] != HUSH_FOOTPRINT_NONE) {
        /* the history is stored linear: map it like the current frame */
        float hr = taa->gathered.plane[0][i], hg = taa->gathered.plane[1][i],
              hb = taa->gathered.plane[2][i];
        const float s = tonemap ? tonemap_scale(hr, hg, hb) : 1.0f;
        float h[3];
        to_ycocg(hr * s, hg * s, hb * s, h);
        for (int k = 0; k < 3; k++) lo[k] = hi[k] = c[k];
        for (int j = -1; j <= 1; j++)
          for (int l = -1; l <= 1; l++) {
            const size_t q = (size_t)clampi(y + j, 0, H - 1) * W + (size_t)clampi(x + l, 0, W - 1);
            float v[3];
            to_ycocg(cur->plane[0][q], cur->plane[1][q], cur->plane[2][q], v);
            for (int k = 0; k < 3; k++) {
              lo[k] = v[k] < lo[k] ? v[k] : lo[k];
              hi[k] = v[k] > hi[k] ? v[k] : hi[k];
            }
          }
        if (params->box == HUSH_TAA_CLIP) {
          clip_box(h, lo, hi);
        } else {
          for (int k = 0; k < 3; k++) h[k] = h[k] < lo[k] ? lo[k] : h[k] > hi[k] ? hi[k] : h[k];
        }
        float m[3];
        for (int k = 0; k < 3; k++) m[k] = h[k] + alpha * (c[k] - h[k]);
        from_ycocg(m, &r, &g, &b);
      }
      const float s = tonemap ? untonemap_scale(r, g, b) : 1.0f;
      out->plane[0][i] = r * s;
      out->plane[1][i] = g * s;
      out->plane[2][i] = b * s;
    }
  taa->latest = 1 - taa->latest;
  taa->has_history = 1;
}
