/*
 * weights.h — the "nca" weights file: a small, versioned, checksummed
 * binary format (docs/nca.md), read by the filter and written by
 * `hush train-nca`.
 *
 * Layout, all little-endian, HUSH_NCA_FILE_SIZE = 1476 bytes:
 *   0   8 bytes  magic "HUSHNCA\0"
 *   8   u32      version (1)
 *   12  u32      channels (9)
 *   16  u32      perception size (39)
 *   20  u32      iterations K the weights were trained for (1..64)
 *   24  u32      colour transform (0 linear, 1 log1p)
 *   28  u32      parameter count (360 = 39 * 9 + 9)
 *   32  f32[351] W, row-major: W[k][j] at index k * 9 + j
 *   1436 f32[9]  bias
 *   1472 u32     checksum: FNV-1a (32 bit) of bytes 0..1471
 */
#ifndef HUSH_FILTERS_NCA_WEIGHTS_H
#define HUSH_FILTERS_NCA_WEIGHTS_H

#include "core/device.h"
#include "filters/nca/model.h"

#define HUSH_NCA_FILE_VERSION 1u
#define HUSH_NCA_FILE_HEADER 32u
#define HUSH_NCA_FILE_SIZE (HUSH_NCA_FILE_HEADER + 4u * HUSH_NCA_PARAM_COUNT + 4u)

/* Checks ranges and finiteness; HUSH_ERROR_CORRUPT with a message naming
 * `what` (a path or "weights") otherwise. */
hush_status hush__nca_weights_check(hush_device device, const hush_nca_weights *w,
                                    const char *what);

/* Encodes w into buf (HUSH_NCA_FILE_SIZE bytes). */
void hush__nca_weights_encode(const hush_nca_weights *w, unsigned char *buf);

/* Decodes a whole file image of `size` bytes into *w (unchanged on error):
 * HUSH_ERROR_CORRUPT (bad magic, size, dimensions, checksum, values) or
 * HUSH_ERROR_UNSUPPORTED (another version), each with a message. */
hush_status hush__nca_weights_decode(hush_device device, const unsigned char *buf, size_t size,
                                     const char *what, hush_nca_weights *w);

/* File versions of decode and encode; HUSH_ERROR_IO when the file cannot be
 * read or written. */
hush_status hush__nca_weights_load(hush_device device, const char *path, hush_nca_weights *w);
hush_status hush__nca_weights_save(hush_device device, const char *path,
                                   const hush_nca_weights *w);

#endif
