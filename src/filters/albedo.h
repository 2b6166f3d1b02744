/*
 * albedo.h — demodulation by the first-hit albedo before filtering and
 * remodulation after (Schied et al. 2017; bmfr-koskela-2019.md §3.1), so
 * texture detail is not blurred. Shared by every filter that demodulates.
 */
#ifndef HUSH_FILTERS_ALBEDO_H
#define HUSH_FILTERS_ALBEDO_H

#include "core/image.h"

/*
 * Albedo below this counts as this. Black texels must not divide by 0, and
 * a channel a renderer reports as nearly 0 where the surface still reflects
 * (the blue of an orange plastic under its white coat: albedo 0.001,
 * radiance 0.1) must not turn that light into a demodulated value 100x
 * its neighbours', which BMFR's fit and the a-trous weights then spread over
 * the block (blue halos around the living room's picture frame: bmfr RMSE
 * 1.83 -> 1.65 at 2e-2, docs/renderer.md "Demodulation albedo"). The same
 * floor as psf's.
 */
#define HUSH_ALBEDO_EPS 2e-2f

/* color[c] /= max(albedo[c], eps), in place (3 channels). */
void hush__demodulate(hush_planar *color, const hush_planar *albedo, int threads);
/* albedo[c] = filtered[c] * max(albedo[c], eps), in place: the albedo planes
 * become the remodulated output (3 channels). */
void hush__remodulate(hush_planar *albedo, const hush_planar *filtered, int threads);

/*
 * The import of a radiance view (3 channels) fused with its demodulation:
 * dst <- view / max(albedo, eps), bit for bit hush__view_import (same
 * policy, message and count of NaN/Inf) followed by hush__demodulate, in
 * one pass over the rows instead of two over the frame. albedo: 3 planes
 * of the view's size, already imported.
 */
hush_status hush__import_demodulated(hush_device device, const hush_image_view *view,
                                     const char *what, hush_planar *dst,
                                     const hush_planar *albedo, hush_nonfinite_policy policy,
                                     size_t *replaced, int threads);

/*
 * hush__view_import of the albedo view (albedo_what names it) into albedo,
 * then hush__import_demodulated of the radiance view by it, bit for bit
 * (the albedo's policy applied, and reported, first), in one pass over
 * the rows: each albedo row divides its radiance row from the registers
 * (hush__view_import_row_pair_divided) instead of being read back from
 * memory. *replaced and *replaced_albedo: the counts of NaN/Inf values.
 */
hush_status hush__import_albedo_demodulated(hush_device device, const hush_image_view *view,
                                            const char *what, hush_planar *dst,
                                            const hush_image_view *albedo_view,
                                            const char *albedo_what, hush_planar *albedo,
                                            hush_nonfinite_policy policy, size_t *replaced,
                                            size_t *replaced_albedo, int threads);

/* hush__import_albedo_demodulated's work on rows y0..y1-1, on the calling
 * thread, for a caller that imports the rows where it uses them: returns
 * the count of NaN/Inf values in both views. Those rows are final only
 * when the whole frame's count is 0; otherwise the caller imports the
 * frame again with hush__import_albedo_demodulated (which applies the
 * policy and replaces them as the separate passes do). stream 0: the rows
 * stay in the caches (where the AVX-512 path takes them) for a caller that
 * reads them soon; 1: they bypass them, as the whole import's. */
size_t hush__import_albedo_demodulated_rows(const hush_image_view *view, hush_planar *dst,
                                            const hush_image_view *albedo_view,
                                            hush_planar *albedo, int y0, int y1, int stream);

/*
 * The remodulation fused with the export: view <- filtered * max(albedo,
 * eps) + add (3 channels), bit for bit hush__remodulate, then
 * hush__emission_add of `add`, then hush__view_export, in one pass and
 * without writing the albedo planes (use it when nothing else needs the
 * remodulated planes). albedo NULL: a factor of 1; add NULL: nothing added.
 * add_rows (NULL: none) marks the rows of `add` that may hold a non-zero
 * bit (0: all +0, as hush__emission_rows_of says): those are not read, +0
 * is added instead (the same bits).
 */
void hush__export_remodulated(const hush_planar *filtered, const hush_planar *albedo,
                              const hush_planar *add, const float *add_rows,
                              const hush_image_view *view, int threads);

/* r[c] = p's plane c at element `at` (3 channels); returns r, or NULL when p
 * is NULL: the arguments of hush__export_remodulated_span. */
static inline const float *const *hush__planar_at3(const hush_planar *p, size_t at,
                                                   const float *r[3]) {
  if (!p) return NULL;
  for (int c = 0; c < 3; c++) r[c] = p->plane[c] + at;
  return r;
}

/* hush__export_remodulated's work for pixels x0..x0+n-1 of row y:
 * filtered[c], albedo[c] and add[c] (albedo, add NULL: none) point at
 * pixel x0 of their rows; add_zero: add's row is all +0 (not read, +0
 * added). The same values, for a caller that exports rows as it finishes
 * them. */
void hush__export_remodulated_span(const float *const filtered[3], const float *const albedo[3],
                                   const float *const add[3], int add_zero,
                                   const hush_image_view *view, uint32_t y, uint32_t x0,
                                   uint32_t n);

#endif
