/*
 * variance.h — the spatial luminance-variance estimate of SVGF for pixels
 * with a short history (Dundr 2018 §4.4; Schied et al. 2017 in
 * papers/NOTES.md): where fewer than min_age frames were accumulated, the
 * temporal moments are averaged over a 7x7 window with the depth and normal
 * weights (weights.h; no luminance weight) and var = max(0, m2 - m1^2).
 *
 * Vectorised like the a-trous (atrous.h): mirrored tap pairs sharing the
 * depth-gradient denominator, the guide's padding for its columns, the
 * moments read in place or, where a block's window passes the frame's
 * border, from a copy with clamped columns and rows; a block (a vector
 * of 16 pixels in the AVX-512 loop) with no short-history pixel is
 * skipped. Progressive frames
 * (Dundr §4.2): a pixel without data (age 0, a hole nothing reached) is
 * no sample of the window, the centre included; such blocks go through a
 * per-pixel path, and a window without data gives variance 0.
 */
#ifndef HUSH_FILTERS_SVGF_VARIANCE_H
#define HUSH_FILTERS_SVGF_VARIANCE_H

#include "filters/svgf/guide.h"
#include "filters/svgf/padded.h"

/* The window radius (7x7); the guide's pads must be at least this. */
#define SVGF_SPATIAL_VARIANCE_RADIUS 3

/* moments: 2 unpadded planes (E[l], E[l^2]), read where a young pixel's
 * window lies (the windows past the frame's border through a clamped copy:
 * no padded copy of the whole planes); age: unpadded history lengths;
 * var (unpadded) is overwritten where age < min_age and kept elsewhere.
 * normal_exp: the normal weight as svgf's normal_weight=exp (weights.h,
 * SVGF_NORMAL_EXP), else the power; fast_exp, with normal_exp: the weights
 * by svgf's weight_exp=fast (weights.h, svgf_exp2_neg_fast). holes: some
 * pixel may have no data (age 0: progressive frames); 0 promises none. */
void svgf_spatial_variance(const svgf_guide *g, const float *const moments[2], const float *age,
                           float min_age, float *var, int normal_exp, int fast_exp, int holes,
                           int threads);

#endif
