/*
 * fuzz_exr.c — libFuzzer target for the EXR reader. Every input is read as
 * an EXR held in memory (hush__exr_read_memory, the same code as
 * hush_frame_read_exr); a frame that comes back has all its pixels read,
 * then everything is released, so leaks and stray accesses show.
 */
#include "hush.h"
#include "io/exr.h"

#include <stddef.h>
#include <stdint.h>

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

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  hush_device device = hush_device_new("threads=1");
  if (!device) return 0;
  hush_frame frame = NULL;
  if (hush__exr_read_memory(device, "fuzz.exr", data, size, FUZZ_MAX_PIXELS, &frame) == HUSH_OK) {
    volatile float sink = sum_pixels(frame);
    (void)sink;
    hush_frame_release(frame);
  }
  hush_device_get_error(device, NULL);
  hush_device_release(device);
  return 0;
}
