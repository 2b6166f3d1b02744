/*
 * lag.c — the event lag and the shift lag of lag.h (issue 7; definitions in
 * lag.h and docs/eval.md "Lag"). Sums in double, in pixel order.
 */
#include "eval/lag.h"

#include <math.h>

void hush__lag_luminance(const float *rgb, size_t count, float *y) {
  for (size_t i = 0; i < count; i++) {
    const float l = 0.2126f * rgb[3 * i] + 0.7152f * rgb[3 * i + 1] + 0.0722f * rgb[3 * i + 2];
    y[i] = l > 0.0f ? (l < 1.0f ? l : 1.0f) : 0.0f; /* NaN fails l > 0: 0 */
  }
}

/* One pass of the box along rows: out[y][x] = mean of in[y][x - r .. x + r]
 * that is inside, by a running sum in double. */
static void box_rows(const float *in, uint32_t width, uint32_t height, int r, float *out) {
  for (uint32_t y = 0; y < height; y++) {
    const float *row = in + (size_t)y * width;
    float *dst = out + (size_t)y * width;
    double sum = 0.0;
    int lo = 0, hi = -1; /* the window [lo, hi] summed */
    for (int x = 0; x < (int)width; x++) {
      const int want_hi = x + r < (int)width - 1 ? x + r : (int)width - 1;
      const int want_lo = x - r > 0 ? x - r : 0;
      while (hi < want_hi) sum += row[++hi];
      while (lo < want_lo) sum -= row[lo++];
      dst[x] = (float)(sum / (double)(hi - lo + 1));
    }
  }
}

/* The same along columns. */
static void box_columns(const float *in, uint32_t width, uint32_t height, int r, float *out) {
  for (uint32_t x = 0; x < width; x++) {
    double sum = 0.0;
    int lo = 0, hi = -1;
    for (int y = 0; y < (int)height; y++) {
      const int want_hi = y + r < (int)height - 1 ? y + r : (int)height - 1;
      const int want_lo = y - r > 0 ? y - r : 0;
      while (hi < want_hi) sum += in[(size_t)(++hi) * width + x];
      while (lo < want_lo) sum -= in[(size_t)(lo++) * width + x];
      out[(size_t)y * width + x] = (float)(sum / (double)(hi - lo + 1));
    }
  }
}

void hush__lag_box(const float *in, uint32_t width, uint32_t height, int radius, float *tmp,
                   float *out) {
  box_rows(in, width, height, radius, tmp);
  box_columns(tmp, width, height, radius, out);
}

void hush__lag_mark_saturated(const float *y, uint32_t width, uint32_t height, int radius,
                              float *tmp, float *ind, float *boxed) {
  const size_t n = (size_t)width * height;
  for (size_t i = 0; i < n; i++) ind[i] = y[i] >= 1.0f ? 1.0f : 0.0f;
  hush__lag_box(ind, width, height, radius, tmp, ind);
  for (size_t i = 0; i < n; i++)
    if (ind[i] > 0.0f) boxed[i] = NAN;
}

size_t hush__lag_region(const float *prev, const float *cur, size_t n, float threshold,
                        float *mask) {
  size_t count = 0;
  for (size_t i = 0; i < n; i++) {
    const float d = fabsf(cur[i] - prev[i]);
    mask[i] = d > threshold ? 1.0f : 0.0f;
    count += d > threshold;
  }
  return count;
}

size_t hush__lag_region_signed(const float *prev, const float *cur, size_t n, float threshold,
                               float *mask, size_t count[2]) {
  size_t up = 0, down = 0;
  for (size_t i = 0; i < n; i++) {
    const float d = cur[i] - prev[i]; /* NaN fails both tests: 0 */
    const int u = d > threshold, w = d < -threshold;
    mask[i] = (float)(u - w);
    up += (size_t)u;
    down += (size_t)w;
  }
  count[0] = up;
  count[1] = down;
  return up + down;
}

double hush__lag_region_mean_of(const float *y, const float *mask, float value, size_t n) {
  double sum = 0.0, count = 0.0;
  for (size_t i = 0; i < n; i++) {
    const double in = mask[i] == value ? 1.0 : 0.0;
    sum += in * y[i];
    count += in;
  }
  return count > 0.0 ? sum / count : NAN;
}

double hush__lag_region_mean(const float *y, const float *mask, size_t n) {
  double sum = 0.0, count = 0.0;
  for (size_t i = 0; i < n; i++) {
    sum += (double)mask[i] * y[i];
    count += mask[i];
  }
  return count > 0.0 ? sum / count : NAN;
}

int hush__lag_event(const double *out_mean, const double *ref_mean, uint32_t count,
                    double tolerance) {
  for (uint32_t k = 0; k < count; k++)
    if (fabs(out_mean[k] - ref_mean[k]) <= tolerance * fabs(ref_mean[k])) return (int)k;
  return -1;
}

int hush__lag_event_signed(const double *const out_mean[2], const double *const ref_mean[2],
                           const int use[2], uint32_t count, double tolerance) {
  int lag = -2;
  for (int s = 0; s < 2; s++) {
    if (!use[s]) continue;
    const int k = hush__lag_event(out_mean[s], ref_mean[s], count, tolerance);
    if (k < 0) return -1; /* one part never follows: neither does the event */
    if (k > lag) lag = k;
  }
  return lag;
}

void hush__lag_shift_add(const float *out, const float *const *ref, const float *mask,
                         uint32_t shifts, size_t n, double *sse) {
  for (uint32_t k = 0; k < shifts; k++) {
    const float *r = ref[k];
    double s = 0.0;
    for (size_t i = 0; i < n; i++) {
      const double d = (double)out[i] - r[i];
      s += (mask ? (double)mask[i] : 1.0) * d * d;
    }
    sse[k] += s;
  }
}

void hush__lag_shift_add_pixels(const float *out, const float *const *ref, uint32_t shifts,
                                size_t n, float *sse) {
  for (size_t i = 0; i < n; i++)
    for (uint32_t k = 0; k < shifts; k++) {
      const float d = out[i] - ref[k][i];
      sse[i * shifts + k] += d * d;
    }
}

void hush__lag_range_add(const float *boxed, size_t n, float *lo, float *hi) {
  for (size_t i = 0; i < n; i++) {
    const float v = boxed[i];
    if (v != v || lo[i] != lo[i]) { /* NaN now or before: out for good */
      lo[i] = hi[i] = NAN;
      continue;
    }
    lo[i] = v < lo[i] ? v : lo[i];
    hi[i] = v > hi[i] ? v : hi[i];
  }
}

size_t hush__lag_range_region(const float *lo, const float *hi, size_t n, float threshold,
                              float *mask) {
  size_t count = 0;
  for (size_t i = 0; i < n; i++) {
    const int in = hi[i] - lo[i] > threshold; /* NaN: 0 */
    mask[i] = in ? 1.0f : 0.0f;
    count += (size_t)in;
  }
  return count;
}

void hush__lag_shift_sum(const float *pixels, const float *mask, uint32_t shifts, size_t n,
                         double *sse) {
  for (uint32_t k = 0; k < shifts; k++) sse[k] = 0.0;
  for (size_t i = 0; i < n; i++)
    if (mask[i] != 0.0f)
      for (uint32_t k = 0; k < shifts; k++) sse[k] += (double)mask[i] * pixels[i * shifts + k];
}

double hush__lag_shift(const double *sse, uint32_t shifts) {
  if (shifts == 0) return NAN;
  uint32_t best = 0;
  for (uint32_t k = 1; k < shifts; k++)
    if (sse[k] < sse[best]) best = k;
  if (best == 0 || best + 1 >= shifts) return (double)best;
  /* vertex of the parabola through (best - 1, best, best + 1) */
  const double a = sse[best - 1], b = sse[best], c = sse[best + 1];
  const double curve = a - 2.0 * b + c;
  return curve > 0.0 ? (double)best + 0.5 * (a - c) / curve : (double)best;
}
