/*
 * emission.h — light seen directly kept out of the filtered signal.
 *
 * A pixel whose first hit is a light (the Cornell lamp, a sphere light, the
 * sky) holds radiance its neighbours do not share; a screen-space filter
 * (bmfr-koskela-2019.md §3.3's per-block fit above all) smears it into the
 * surfaces around it. With the renderer's 'emission' layer
 * (docs/sequence-format.md) a filter filters (color - emission), clamped at
 * 0, and adds emission back after remodulation, as NRD and the papers'
 * renderers keep first-hit emission out of the denoised signal. Shared by
 * accumulate, svgf and bmfr.
 */
#ifndef HUSH_FILTERS_EMISSION_H
#define HUSH_FILTERS_EMISSION_H

#include "core/image.h"

/* color[c] = max(color[c] - emission[c], 0), in place (3 channels). */
void hush__emission_subtract(hush_planar *color, const hush_planar *emission, int threads);
/* emission[c] += filtered[c], in place: the emission planes become the
 * output (3 channels), so the filter's own result (often its history) is
 * left untouched. */
void hush__emission_add(hush_planar *emission, const hush_planar *filtered, int threads);

#endif
