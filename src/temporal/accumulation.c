/*
 * accumulation.c — colour and luminance-moment accumulation with a history
 * length, through a reprojection plan. Dundr 2018 §4.1.3, Koskela et al.
 * 2019 §3.2, Higginson 2023 §1.3 (eqs. 1.2, 1.3); see accumulation.h.
 */
#include "temporal/accumulation.h"

#include "core/device.h"

#include <math.h>
#include <string.h>

hush_status hush__accum_init(hush_device device, hush_accum *acc, int channels, uint32_t width,
                             uint32_t height) {
  memset(acc, 0, sizeof *acc);
  if (channels < 1 || channels > 4)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                      "accumulation of %d channels (1..4 supported)", channels);
  acc->width = width;
  acc->height = height;
  acc->channels = channels;
  hush_status s = HUSH_OK;
  for (int k = 0; k < 2 && !s; k++) {
    s = hush__planar_init(device, &acc->color[k], channels, width, height);
    if (!s) s = hush__planar_init(device, &acc->moments[k], 2, width, height);
    if (!s) s = hush__planar_init(device, &acc->age[k], 1, width, height);
  }
  if (s) hush__accum_free(acc);
  return s;
}

void hush__accum_free(hush_accum *acc) {
  for (int k = 0; k < 2; k++) {
    hush__planar_free(&acc->color[k]);
    hush__planar_free(&acc->moments[k]);
    hush__planar_free(&acc->age[k]);
  }
  memset(acc, 0, sizeof *acc);
}

void hush__accum_reset(hush_accum *acc) { acc->has_history = 0; }

void hush__accum_blend(hush_accum *acc, const hush_reproject_plan *plan,
                       const float *const *sample, const hush_accum_params *params,
                       float *variance, int threads) {
  if (!acc->has_history) plan = NULL;
  if (threads < 1) threads = 1;
  const int src = acc->latest, dst = 1 - acc->latest;
  const int nc = acc->channels;
  const int H = (int)acc->height;
  const size_t W = acc->width;
  const float alpha_min = params->alpha_min;
  const float alpha_mom_min = params->alpha_moments_min;
  const float max_age = (float)(params->max_age < 1 ? 1 : params->max_age);

  const float *pc[4] = {NULL, NULL, NULL, NULL};
  float *oc[4] = {NULL, NULL, NULL, NULL};
  for (int c = 0; c < nc; c++) {
    pc[c] = acc->color[src].plane[c];
    oc[c] = acc->color[dst].plane[c];
  }
  const float *pm1 = acc->moments[src].plane[0], *pm2 = acc->moments[src].plane[1];
  const float *pa = acc->age[src].plane[0];
  float *om1 = acc->moments[dst].plane[0], *om2 = acc->moments[dst].plane[1];
  float *oa = acc->age[dst].plane[0];

#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < H; y++) {
    for (size_t x = 0; x < W; x++) {
      const size_t i = (size_t)y * W + x;
      const float l = hush__accum_luminance(sample, nc, i);
      /* gathered history: colour (nc), m1, m2, age */
      float h[4], h1, h2, ha;
      int has = 1;
      if (plan && hush__reproject_is_block(plan, i)) {
        float w4[4];
        hush__reproject_weights4(plan, i, w4);
        const size_t o = (size_t)plan->origin[i];
        ha = hush__reproject_apply4(pa, o, W, w4);
        h1 = hush__reproject_apply4(pm1, o, W, w4);
        h2 = hush__reproject_apply4(pm2, o, W, w4);
        for (int c = 0; c < nc; c++) h[c] = hush__reproject_apply4(pc[c], o, W, w4);
      } else {
        int32_t idx[9];
        float w[9];
        const int n = plan ? hush__reproject_taps(plan, i, idx, w) : 0;
        has = n > 0;
        ha = has ? hush__reproject_apply(pa, idx, w, n) : 0.0f;
        h1 = has ? hush__reproject_apply(pm1, idx, w, n) : 0.0f;
        h2 = has ? hush__reproject_apply(pm2, idx, w, n) : 0.0f;
        for (int c = 0; c < nc; c++) h[c] = has ? hush__reproject_apply(pc[c], idx, w, n) : 0.0f;
      }
      float m1, m2;
      if (!has) {
        for (int c = 0; c < nc; c++) oc[c][i] = sample[c][i];
        m1 = l;
        m2 = l * l;
        oa[i] = 1.0f;
      } else {
        float age = floorf(ha + 0.5f) + 1.0f;
        if (age > max_age) age = max_age;
        const float inv_age = 1.0f / age;
        const float a = alpha_min > inv_age ? alpha_min : inv_age;
        const float am = alpha_mom_min > inv_age ? alpha_mom_min : inv_age;
        for (int c = 0; c < nc; c++) oc[c][i] = (1.0f - a) * h[c] + a * sample[c][i];
        m1 = (1.0f - am) * h1 + am * l;
        m2 = (1.0f - am) * h2 + am * (l * l);
        oa[i] = age;
      }
      om1[i] = m1;
      om2[i] = m2;
      if (variance) {
        /* separate statements: no fused multiply-add, so one sample gives
         * exactly 0 with every compiler */
        const float m1sq = m1 * m1;
        const float v = m2 - m1sq;
        variance[i] = v > 0.0f ? v : 0.0f;
      }
    }
  }
  acc->latest = dst;
  acc->has_history = 1;
}

#define BLEND_MAX 8

void hush__temporal_blend(const hush_reproject_plan *plan, const float *const *prev,
                          const float *const *sample, int channels, const float *age,
                          float alpha_min, float *const *out, int threads) {
  if (threads < 1) threads = 1;
  if (channels > BLEND_MAX) channels = BLEND_MAX;
  const int H = (int)plan->height;
  const size_t W = plan->width;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < H; y++) {
    for (size_t x = 0; x < W; x++) {
      const size_t i = (size_t)y * W + x;
      const float inv_age = age[i] > 1.0f ? 1.0f / age[i] : 1.0f;
      const float a = alpha_min > inv_age ? alpha_min : inv_age;
      if (prev && hush__reproject_is_block(plan, i)) {
        float w4[4];
        hush__reproject_weights4(plan, i, w4);
        const size_t o = (size_t)plan->origin[i];
        for (int c = 0; c < channels; c++)
          out[c][i] = (1.0f - a) * hush__reproject_apply4(prev[c], o, W, w4) + a * sample[c][i];
        continue;
      }
      int32_t idx[9];
      float w[9];
      const int n = prev ? hush__reproject_taps(plan, i, idx, w) : 0;
      if (n == 0) {
        for (int c = 0; c < channels; c++) out[c][i] = sample[c][i];
        continue;
      }
      for (int c = 0; c < channels; c++)
        out[c][i] = (1.0f - a) * hush__reproject_apply(prev[c], idx, w, n) + a * sample[c][i];
    }
  }
}
