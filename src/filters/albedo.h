/*
 * albedo.h — demodulation by the first-hit albedo before filtering and
 * remodulation after (Schied et al. 2017; bmfr-koskela-2019.md §3.1), so
 * texture detail is not blurred. Shared by every filter that demodulates.
 */
#ifndef HUSH_FILTERS_ALBEDO_H
#define HUSH_FILTERS_ALBEDO_H

#include "core/image.h"

/* Albedo below this counts as this: black texels must not divide by 0. */
#define HUSH_ALBEDO_EPS 1e-3f

/* color[c] /= max(albedo[c], eps), in place (3 channels). */
void hush__demodulate(hush_planar *color, const hush_planar *albedo, int threads);
/* albedo[c] = filtered[c] * max(albedo[c], eps), in place: the albedo planes
 * become the remodulated output (3 channels). */
void hush__remodulate(hush_planar *albedo, const hush_planar *filtered, int threads);

#endif
