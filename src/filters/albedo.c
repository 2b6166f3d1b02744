/*
 * albedo.c — albedo demodulation and remodulation (see albedo.h), also
 * fused into the import of the radiance and the export of the result.
 */
#include "filters/albedo.h"

#include "core/device.h"

#include <string.h>

static inline float albedo_clamped(float a) { return a > HUSH_ALBEDO_EPS ? a : HUSH_ALBEDO_EPS; }

/* col[x] /= max(alb[x], eps) over one row of one channel. */
static inline void demodulate_row(float *restrict col, const float *restrict alb, size_t n) {
  for (size_t x = 0; x < n; x++) col[x] = col[x] / albedo_clamped(alb[x]);
}

void hush__demodulate(hush_planar *color, const hush_planar *albedo, int threads) {
  const int H = (int)color->height;
  const size_t W = color->width;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < H; y++)
    for (int c = 0; c < 3; c++)
      demodulate_row(color->plane[c] + (size_t)y * W, albedo->plane[c] + (size_t)y * W, W);
}

void hush__remodulate(hush_planar *albedo, const hush_planar *filtered, int threads) {
  const int H = (int)albedo->height;
  const size_t W = albedo->width;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < H; y++)
    for (int c = 0; c < 3; c++) {
      float *alb = albedo->plane[c] + (size_t)y * W;
      const float *flt = filtered->plane[c] + (size_t)y * W;
      for (size_t x = 0; x < W; x++) alb[x] = flt[x] * albedo_clamped(alb[x]);
    }
}

/* Row y of view into dst divided by the albedo's row, while it is in L1
 * (left undivided when it has NaN/Inf: the caller redoes the frame);
 * returns the count of those. */
static size_t import_row_demodulated(const hush_image_view *view, uint32_t y, hush_planar *dst,
                                     const hush_planar *albedo) {
  size_t bad = 0;
  if (hush__view_import_row_divided(view, y, dst, albedo, HUSH_ALBEDO_EPS, &bad)) return bad;
  bad = hush__view_import_row_cached(view, y, dst);
  const size_t W = view->width;
  if (!bad)
    for (int c = 0; c < 3; c++)
      demodulate_row(dst->plane[c] + (size_t)y * W, albedo->plane[c] + (size_t)y * W, W);
  return bad;
}

hush_status hush__import_demodulated(hush_device device, const hush_image_view *view,
                                     const char *what, hush_planar *dst,
                                     const hush_planar *albedo, hush_nonfinite_policy policy,
                                     size_t *replaced, int threads) {
  const int H = (int)view->height;
  size_t bad = 0;
#pragma omp parallel for schedule(static) num_threads(threads) reduction(+ : bad)
  for (int y = 0; y < H; y++) bad += import_row_demodulated(view, (uint32_t)y, dst, albedo);
  if (replaced) *replaced = bad;
  if (!bad) return HUSH_OK;
  /* rare: as the separate passes (the values replaced first, then all
   * divided), so the result does not depend on which rows were divided */
  hush_status s = hush__view_import(device, view, what, dst, policy, NULL);
  if (s) return s;
  hush__demodulate(dst, albedo, threads);
  return HUSH_OK;
}

/* Row y of the albedo into albedo and of the radiance into dst divided by
 * it: the pair from the registers where it can (stream as
 * hush__view_import_row_pair_divided), else the albedo's row kept in the
 * cache for the division. Adds the NaN/Inf counts to *bad and *bad_albedo. */
static void import_pair_row(const hush_image_view *view, hush_planar *dst,
                            const hush_image_view *albedo_view, hush_planar *albedo, int y,
                            int stream, size_t *bad, size_t *bad_albedo) {
  size_t row_bad = 0, row_bad_albedo = 0;
  if (!hush__view_import_row_pair_divided(view, albedo_view, (uint32_t)y, dst, albedo,
                                          HUSH_ALBEDO_EPS, stream, &row_bad, &row_bad_albedo)) {
    row_bad_albedo = hush__view_import_row_cached(albedo_view, (uint32_t)y, albedo);
    row_bad = import_row_demodulated(view, (uint32_t)y, dst, albedo);
  }
  *bad += row_bad;
  *bad_albedo += row_bad_albedo;
}

size_t hush__import_albedo_demodulated_rows(const hush_image_view *view, hush_planar *dst,
                                            const hush_image_view *albedo_view,
                                            hush_planar *albedo, int y0, int y1, int stream) {
  size_t bad = 0, bad_albedo = 0;
  for (int y = y0; y < y1; y++)
    import_pair_row(view, dst, albedo_view, albedo, y, stream, &bad, &bad_albedo);
  return bad + bad_albedo;
}

hush_status hush__import_albedo_demodulated(hush_device device, const hush_image_view *view,
                                            const char *what, hush_planar *dst,
                                            const hush_image_view *albedo_view,
                                            const char *albedo_what, hush_planar *albedo,
                                            hush_nonfinite_policy policy, size_t *replaced,
                                            size_t *replaced_albedo, int threads) {
  const int H = (int)view->height;
  size_t bad = 0, bad_albedo = 0;
#pragma omp parallel for schedule(static) num_threads(threads) reduction(+ : bad, bad_albedo)
  for (int y = 0; y < H; y++)
    import_pair_row(view, dst, albedo_view, albedo, y, 1, &bad, &bad_albedo);
  if (replaced) *replaced = bad;
  if (replaced_albedo) *replaced_albedo = bad_albedo;
  hush_status s =
      hush__view_import_nonfinite(device, albedo_view, albedo_what, albedo, policy, bad_albedo);
  if (s || (!bad && !bad_albedo)) return s;
  /* rare: as the separate passes (the albedo's values replaced, the
   * radiance's replaced, then all divided) */
  if ((s = hush__view_import(device, view, what, dst, policy, NULL))) return s;
  hush__demodulate(dst, albedo, threads);
  return HUSH_OK;
}

/* Pixels per span of the remodulating export: 3 stack rows of this many
 * floats (L1-resident) between the multiply and the interleave. */
#define EXPORT_SPAN 512

void hush__export_remodulated_span(const float *const filtered[3], const float *const albedo[3],
                                   const float *const add[3], int add_zero,
                                   const hush_image_view *view, uint32_t y, uint32_t x0,
                                   uint32_t n) {
  float buf[3][EXPORT_SPAN];
  const float *const in[3] = {buf[0], buf[1], buf[2]};
  for (uint32_t s0 = 0; s0 < n; s0 += EXPORT_SPAN) {
    const uint32_t m = n - s0 < EXPORT_SPAN ? n - s0 : EXPORT_SPAN;
    for (int c = 0; c < 3; c++) {
      const float *restrict flt = filtered[c] + s0;
      float *restrict o = buf[c];
      if (albedo) {
        const float *restrict alb = albedo[c] + s0;
        for (uint32_t x = 0; x < m; x++) o[x] = flt[x] * albedo_clamped(alb[x]);
      } else {
        memcpy(o, flt, m * sizeof(float));
      }
      if (add && add_zero) {
        /* + 0 as the row holds (a -0 becomes +0, as with the load) */
        for (uint32_t x = 0; x < m; x++) o[x] = o[x] + 0.0f;
      } else if (add) {
        const float *restrict a = add[c] + s0;
        for (uint32_t x = 0; x < m; x++) o[x] = o[x] + a[x];
      }
    }
    hush__view_export_span(in, 3, view, y, x0 + s0, m);
  }
}

void hush__export_remodulated(const hush_planar *filtered, const hush_planar *albedo,
                              const hush_planar *add, const float *add_rows,
                              const hush_image_view *view, int threads) {
  const int H = (int)filtered->height;
  const size_t W = filtered->width;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < H; y++) {
    const size_t at = (size_t)y * W;
    const float *flt[3], *alb[3], *a[3];
    hush__export_remodulated_span(hush__planar_at3(filtered, at, flt),
                                  hush__planar_at3(albedo, at, alb), hush__planar_at3(add, at, a),
                                  add_rows && add_rows[y] == 0.0f, view, (uint32_t)y, 0,
                                  (uint32_t)W);
  }
}
