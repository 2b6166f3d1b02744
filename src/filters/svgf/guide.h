/*
 * guide.h — the per-frame guide of the SVGF spatial passes: depth and normal
 * in row-padded planes (padded.h) for branch-free taps, the screen-space
 * depth gradient, and where the depth weight is switched off because the
 * surface is seen at a very steep angle (Dundr 2018 §4.1.4.3: "we turn off
 * the depth weight function for too steep gradients: normal weight is
 * sufficient in this case").
 */
#ifndef HUSH_FILTERS_SVGF_GUIDE_H
#define HUSH_FILTERS_SVGF_GUIDE_H

#include "core/image.h"
#include "filters/svgf/padded.h"
#include "filters/svgf/weights.h"

typedef struct svgf_guide {
  int width, height;
  const svgf_padded *zn; /* 4 channels: depth, normal x, y, z; pad >= the widest tap */
  const float *gx, *gy;  /* d depth / d pixel, unpadded (read at p only) */
  const float *zon;      /* 1 where the depth weight applies, 0 where it is off */
  float sigma_z;
  svgf_normal_power np;
} svgf_guide;

/* zn <- depth and normal (the padded copy), pads filled. */
void svgf_guide_import(svgf_padded *zn, const float *depth, const float *const normal[3],
                       int threads);

/*
 * grad <- the depth gradient of zn's depth unless has_grad (then grad was
 * imported), as the smaller of the two one-sided differences per axis (at a
 * depth edge one side still sees the surface, so the edge does not inflate
 * the gradient, which would make the depth weight accept the other side).
 * zon <- 0 where steep > 0 and |grad z| > steep * z (a relative slope per
 * pixel: scale-free), else 1. grad: 2 planes, zon: 1 plane, unpadded.
 */
void svgf_guide_gradient(const svgf_padded *zn, int has_grad, hush_planar *grad, float *zon,
                         float steep, int threads);

#endif
