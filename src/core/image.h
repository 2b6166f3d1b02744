/*
 * image.h — planar float buffers (one 64-byte aligned plane per channel) and
 * the conversion between caller views (strided, float or half, interleaved)
 * and planes. Filters work on planes so their inner loops are plain,
 * branch-free and vectorizable.
 */
#ifndef HUSH_CORE_IMAGE_H
#define HUSH_CORE_IMAGE_H

#include "hush.h"

#include <stddef.h>
#include <stdint.h>

#define HUSH_ALIGN 64

/* 64-byte aligned allocation of n floats (zeroed); NULL on failure or n == 0.
 * Free with hush__free_floats() only: the pointer is not the start of the
 * underlying allocation (image.c staggers the page offsets of buffers). */
float *hush__alloc_floats(size_t n);
void hush__free_floats(float *p);

/* calloc(count, size) counted against the cap below, for the per-pixel
 * arrays that are not float planes (the reprojection plan's bytes, sort
 * keys, scratch); NULL on failure or a zero size. Free with free(). */
void *hush__alloc_counted(size_t count, size_t size);

/* While open, the calling thread's hush__alloc_floats and
 * hush__alloc_counted calls fail (NULL) once they would take more than
 * `bytes` in all, before a page is touched: a filter committed (or run) at
 * a size the machine cannot hold then fails with HUSH_ERROR_OUT_OF_MEMORY, where zeroing its planes would have had the
 * kernel kill the process (Linux grants more memory than it has). The
 * first refusal records `why` as the device's error (HUSH_ERROR_OUT_OF_MEMORY);
 * `why` is the caller's and must stay valid until close. Not nested; close
 * returns whether an allocation was refused. */
void hush__alloc_cap_open(hush_device device, size_t bytes, const char *why);
int hush__alloc_cap_close(void);
/* What the last cap opened on this thread had left when it closed. */
size_t hush__alloc_cap_left(void);

/* A planar image: `channels` planes of width * height floats each, rows
 * packed (plane[c][y * width + x]). Owned by whoever called hush__planar_init. */
typedef struct hush_planar {
  float *plane[4];
  int channels;
  uint32_t width, height;
} hush_planar;

/* Allocates zeroed planes. On failure returns HUSH_ERROR_OUT_OF_MEMORY
 * (reported on device) and leaves *img empty. */
hush_status hush__planar_init(hush_device device, hush_planar *img, int channels, uint32_t width,
                              uint32_t height);
void hush__planar_free(hush_planar *img);
static inline size_t hush__planar_pixels(const hush_planar *img) {
  return (size_t)img->width * img->height;
}

/* Element size of a format's channel (4 or 2), 0 if invalid. */
size_t hush__format_element_size(hush_format format);

/*
 * Checks a view: non-NULL data, valid format, non-zero size, strides that are
 * multiples of the element size, pixels that do not overlap, and the given
 * channel count (at least min_channels, or exactly if exact). `what` names
 * the image in the message ("color"). Returns HUSH_OK or reports on device.
 */
hush_status hush__view_validate(hush_device device, const hush_image_view *view, const char *what,
                                int min_channels, int exact);

/* Resolved strides (0 replaced by the packed values). */
size_t hush__view_pixel_stride(const hush_image_view *view);
size_t hush__view_row_stride(const hush_image_view *view);

/* The largest input magnitude a filter accepts: a value beyond it counts as
 * NaN and Inf do (the policy below). The filters square and sum their
 * inputs (luminance moments after a demodulation that may scale by 50,
 * sums of squares over a 1024-pixel block), which overflow float from
 * about 1e17; no renderer's radiance, depth or position comes near 1e15. */
#define HUSH_INPUT_MAX 1e15f

typedef enum hush_nonfinite_policy {
  HUSH_NONFINITE_ERROR = 0,   /* report HUSH_ERROR_NONFINITE naming the pixel (also for
                                 values beyond HUSH_INPUT_MAX) */
  HUSH_NONFINITE_REPLACE = 1  /* write 0 instead and count it */
} hush_nonfinite_policy;

/*
 * Copies the first dst->channels channels of a validated view into dst's
 * planes (same size), rows split over the device's threads. NaN/Inf (and values beyond
 * HUSH_INPUT_MAX) are handled by policy; *replaced (if not NULL)
 * receives how many values were replaced.
 */
hush_status hush__view_import(hush_device device, const hush_image_view *view, const char *what,
                              hush_planar *dst, hush_nonfinite_policy policy, size_t *replaced);

/* hush__view_import in parts, for callers that fuse more work into the row
 * pass (e.g. albedo.h's demodulating import): row y of the view into dst's
 * planes (no threads), returning how many values are NaN/Inf or beyond
 * HUSH_INPUT_MAX; then, with
 * the sum over the rows, the policy (zeroes them; the error names the
 * first). hush__view_import_row may write with streaming stores, which
 * leave the row out of the cache (a frame's planes outgrow it anyway, and
 * no line is read for ownership); a caller that works on the row right
 * away takes hush__view_import_row_cached. */
size_t hush__view_import_row(const hush_image_view *view, uint32_t y, hush_planar *dst);
size_t hush__view_import_row_cached(const hush_image_view *view, uint32_t y, hush_planar *dst);

/* A normal whose squared length is this far from 1 is not of unit length
 * (gbuffer.h's hush__unit_normals rescales it): unit normals keep their
 * bits, and so do half-float ones (off by up to 1e-3 in the squared
 * length), which are not worth a pass. */
#define HUSH_UNIT_TOLERANCE 2e-3f

/* Whether one of the n normals (a, b, c) is neither 0 nor of unit length
 * (its squared length a a + b b + c c within HUSH_UNIT_TOLERANCE of 1, in
 * float, in that order); NaN counts as not unit. */
int hush__normals_odd(const float *a, const float *b, const float *c, size_t n);

/* hush__view_import_row of a 3-channel view of normals that also sets *odd
 * when the row holds a normal that hush__normals_odd would report, taken
 * from the registers where the row is streamed, so that it is not read
 * again (a row with a NaN counts, whatever the policy then makes of it). */
size_t hush__view_import_row_normals(const hush_image_view *view, uint32_t y, hush_planar *dst,
                                     int *odd);
/* Row y of a 3-channel view into dst (3 planes), each channel divided by
 * max(divisor's plane, floor) (albedo demodulation, albedo.h), in one
 * streamed pass, with *bad the count of NaN/Inf values read (the row is
 * then to be redone: the quotients of those are not the policy's). Returns
 * 0, doing nothing, where that path does not apply (a view that is not
 * packed float32, a width not a multiple of 16, a build without AVX-512):
 * the caller imports, then divides. */
int hush__view_import_row_divided(const hush_image_view *view, uint32_t y, hush_planar *dst,
                                  const hush_planar *divisor, float floor, size_t *bad);
/* Row y of two 3-channel views at once: divisor_view into divisor's planes
 * and view into dst's, each channel of the latter divided by max(the
 * former, floor) from the registers (hush__view_import_row_divided's
 * values, without reading the divisor's row back), both streamed past the
 * caches (stream 1) or stored in them (0: for rows read again soon); *bad
 * and *bad_divisor the counts of NaN/Inf values read in each. Returns 0
 * (nothing read) where the pair cannot take that path: the callers then
 * import the divisor's row and hush__view_import_row_divided it. */
int hush__view_import_row_pair_divided(const hush_image_view *view,
                                       const hush_image_view *divisor_view, uint32_t y,
                                       hush_planar *dst, hush_planar *divisor, float floor,
                                       int stream, size_t *bad, size_t *bad_divisor);
hush_status hush__view_import_nonfinite(hush_device device, const hush_image_view *view,
                                        const char *what, hush_planar *dst,
                                        hush_nonfinite_policy policy, size_t bad);

/* Copies src's planes into a validated view with src->channels channels,
 * rows split over `threads` threads. */
void hush__view_export(const hush_planar *src, const hush_image_view *view, int threads);
/* One span of it: in[c][0 .. w-1] (nc planes' values) into pixels x0 ..
 * x0 + w - 1 of row y of the view (no threads). */
void hush__view_export_span(const float *const *in, int nc, const hush_image_view *view,
                            uint32_t y, uint32_t x0, uint32_t w);

#endif
