/*
 * png.h — the PNG writer for pictures hush composes itself (the report's
 * side-by-side strips, insets and heat maps), which are already 8-bit
 * display values and must not go through the display transform again.
 */
#ifndef HUSH_IO_PNG_H
#define HUSH_IO_PNG_H

#include "hush.h"

#include <stdint.h>

/* Writes width x height interleaved 8-bit pixels of 1 (gray) or 3 (sRGB)
 * channels, rows top first, through a temporary file. */
hush_status hush__png_write8(hush_device device, const char *path, const uint8_t *pixels,
                             uint32_t width, uint32_t height, int channels);

#endif
