/*
 * view_rows.h — reads a caller's image view (float or half, any strides) one
 * row at a time into packed float32, for the file writers.
 */
#ifndef HUSH_IO_VIEW_ROWS_H
#define HUSH_IO_VIEW_ROWS_H

#include "core/half.h"
#include "core/image.h"

#include <stdint.h>
#include <string.h>

/* Copies channels [0, n) of row y of a validated view to out (width * n
 * floats, interleaved). n must not exceed the view's channel count. */
static inline void hush__view_load_row(const hush_image_view *view, uint32_t y, int n, float *out) {
  const size_t ps = hush__view_pixel_stride(view);
  const char *p =
      (const char *)view->data + view->byte_offset + (size_t)y * hush__view_row_stride(view);
  const int half = hush__format_element_size(view->format) == 2;
  for (uint32_t x = 0; x < view->width; x++, p += ps, out += n) {
    if (!half) {
      memcpy(out, p, (size_t)n * sizeof(float));
      continue;
    }
    for (int c = 0; c < n; c++) {
      uint16_t h;
      memcpy(&h, p + 2 * c, sizeof h);
      out[c] = hush__half_to_float(h);
    }
  }
}

#endif
