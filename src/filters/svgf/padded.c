/*
 * padded.c — row-padded planar images (see padded.h).
 */
#include "filters/svgf/padded.h"

#include "core/device.h"
#include "core/image.h"

#include <string.h>

void svgf_padded_free(svgf_padded *p) {
  for (int c = 0; c < SVGF_PADDED_MAX; c++) hush__free_floats(p->mem[c]);
  memset(p, 0, sizeof *p);
}

hush_status svgf_padded_ensure(hush_device device, svgf_padded *p, int channels, int width,
                               int height, int min_pad) {
  const int pad = (min_pad + 15) / 16 * 16;
  if (p->mem[0] && p->channels == channels && p->width == width && p->height == height &&
      p->pad >= pad)
    return HUSH_OK;
  svgf_padded_free(p);
  p->channels = channels;
  p->width = width;
  p->height = height;
  p->pad = pad;
  p->stride = ((size_t)width + 15) / 16 * 16 + 2 * (size_t)pad;
  for (int c = 0; c < channels; c++) {
    p->mem[c] = hush__alloc_floats(p->stride * (size_t)height);
    if (!p->mem[c]) {
      svgf_padded_free(p);
      return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "svgf: out of memory");
    }
    p->plane[c] = p->mem[c] + pad;
  }
  return HUSH_OK;
}

void svgf_pad_row_sides(float *row, int width, int pad, int left, int right) {
  /* only the side padded is read: another thread may be writing the other
   * end of the row (the a-trous wavefront's column parts) */
  if (left) {
    const float l = row[0];
    for (int i = 1; i <= pad; i++) row[-i] = l;
  }
  if (right) {
    const float r = row[width - 1];
    for (int i = 1; i <= pad; i++) row[width - 1 + i] = r;
  }
}

void svgf_pad_row(float *row, int width, int pad) { svgf_pad_row_sides(row, width, pad, 1, 1); }

void svgf_padded_import(svgf_padded *p, int c, const float *src, int threads) {
  const int W = p->width, H = p->height, pad = p->pad;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < H; y++) {
    float *row = svgf_padded_row(p, c, y);
    memcpy(row, src + (size_t)y * W, (size_t)W * sizeof(float));
    svgf_pad_row(row, W, pad);
  }
}
