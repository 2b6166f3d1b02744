/*
 * fuzz_exr.c — libFuzzer target for the EXR reader. Every input is read as
 * an EXR held in memory (hush__exr_read_memory, the same code as
 * hush_frame_read_exr); a frame that comes back has all its pixels read,
 * then everything is released, so leaks and stray accesses show. A frame
 * read is also written back (float) and read again: it must come back bit
 * for bit, or the write must fail with a message (a layer whose name
 * would not read back). That is how OpenEXR 3.1's encoder storing some
 * deflated chunks as raw (exr.c, compress_guarded) would have shown.
 */
#include "hush.h"
#include "io/exr.h"

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* Keeps allocations small whatever size a header claims: 256 x 256. */
#define FUZZ_MAX_PIXELS ((uint64_t)1 << 16)

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static float sum_pixels(hush_frame frame) {
  float sum = 0.0f;
  for (uint32_t i = 0; i < hush_frame_layer_count(frame); i++) {
    hush_image_view view;
    if (hush_frame_get_layer(frame, hush_frame_layer_name(frame, i), &view) != HUSH_OK) continue;
    const float *p = view.data;
    const size_t n = (size_t)view.width * view.height * (size_t)hush_format_channels(view.format);
    for (size_t k = 0; k < n; k++) sum += p[k];
  }
  return sum;
}

/* Same layers, channel counts and pixel bits (NaN payloads included). */
static int same_frames(hush_frame a, hush_frame b) {
  if (hush_frame_width(a) != hush_frame_width(b) || hush_frame_height(a) != hush_frame_height(b) ||
      hush_frame_layer_count(a) != hush_frame_layer_count(b))
    return 0;
  for (uint32_t i = 0; i < hush_frame_layer_count(a); i++) {
    const char *name = hush_frame_layer_name(a, i);
    hush_image_view va, vb;
    if (hush_frame_get_layer(a, name, &va) != HUSH_OK ||
        hush_frame_get_layer(b, name, &vb) != HUSH_OK || va.format != vb.format)
      return 0;
    const size_t n = (size_t)va.width * va.height * (size_t)hush_format_channels(va.format);
    if (memcmp(va.data, vb.data, n * sizeof(float)) != 0) return 0;
  }
  return 1;
}

static void round_trip(hush_device device, hush_frame frame) {
  char path[64];
  snprintf(path, sizeof path, "/tmp/hush-fuzz-exr-%ld.exr", (long)getpid());
  if (hush_frame_write_exr(frame, path, HUSH_EXR_FLOAT) != HUSH_OK) {
    const char *msg = NULL;
    if (hush_device_get_error(device, &msg) == HUSH_OK || !msg || !*msg) abort();
    return;
  }
  hush_frame back = NULL;
  const hush_status s = hush_frame_read_exr(device, path, &back);
  remove(path);
  if (s != HUSH_OK || !same_frames(frame, back)) {
    fprintf(stderr, "fuzz_exr: the frame did not read back as written\n");
    abort();
  }
  hush_frame_release(back);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  hush_device device = hush_device_new("threads=1");
  if (!device) return 0;
  hush_frame frame = NULL;
  if (hush__exr_read_memory(device, "fuzz.exr", data, size, FUZZ_MAX_PIXELS, &frame) == HUSH_OK) {
    volatile float sink = sum_pixels(frame);
    (void)sink;
    round_trip(device, frame);
    hush_frame_release(frame);
  }
  hush_device_get_error(device, NULL);
  hush_device_release(device);
  return 0;
}
