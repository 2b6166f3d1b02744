/*
 * padded.h — planar float images with `pad` replicated pixels on both sides
 * of every row, so that a filter tap at x + dx with |dx| <= pad reads the
 * clamped-to-the-border pixel without a branch or an index clamp (the inner
 * loops of the SVGF a-trous and spatial variance stay plain vector loops).
 * Rows are still clamped by the caller (one clamp per tap row, not per pixel).
 *
 * Layout: plane[c] points at pixel (0, 0); row y starts at plane[c] +
 * y * stride; stride and pad are multiples of 16 floats, so every row start
 * is 64-byte aligned.
 */
#ifndef HUSH_FILTERS_SVGF_PADDED_H
#define HUSH_FILTERS_SVGF_PADDED_H

#include "hush.h"

#include <stddef.h>

#define SVGF_PADDED_MAX 6

typedef struct svgf_padded {
  float *mem[SVGF_PADDED_MAX];   /* owned allocations */
  float *plane[SVGF_PADDED_MAX]; /* pixel (0, 0) of each channel */
  int channels;
  int width, height, pad;
  size_t stride; /* floats from one row to the next */
} svgf_padded;

/* Makes sure p has `channels` planes of width x height with a pad of at
 * least min_pad (reallocating, contents lost, when it had less or another
 * size). Reports HUSH_ERROR_OUT_OF_MEMORY on device. */
hush_status svgf_padded_ensure(hush_device device, svgf_padded *p, int channels, int width,
                               int height, int min_pad);
void svgf_padded_free(svgf_padded *p);

static inline float *svgf_padded_row(const svgf_padded *p, int c, int y) {
  return p->plane[c] + (size_t)y * p->stride;
}

/* Replicates pixel 0 and pixel width-1 of row `row` (pointer to its pixel 0)
 * into the pad on each side. */
void svgf_pad_row(float *row, int width, int pad);
/* The same for one side or both (left: from pixel 0, right: from pixel
 * width-1), for a row written in parts by several threads. */
void svgf_pad_row_sides(float *row, int width, int pad, int left, int right);

/* Copies an unpadded plane (width floats a row) into channel c, pads filled. */
void svgf_padded_import(svgf_padded *p, int c, const float *src, int threads);

#endif
