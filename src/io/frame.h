/*
 * frame.h — the hush_frame object: named interleaved float32 layers of one
 * size, owned by the frame. The EXR, PNG and PFM readers and writers and the
 * sequence module fill and read it.
 */
#ifndef HUSH_IO_FRAME_H
#define HUSH_IO_FRAME_H

#include "hush.h"

#define HUSH_MAX_LAYERS 32
#define HUSH_LAYER_NAME_MAX 64

typedef struct hush_layer {
  char name[HUSH_LAYER_NAME_MAX];
  int channels;  /* 1..4 */
  float *pixels; /* width * height * channels, interleaved, 64-byte aligned */
} hush_layer;

struct hush_frame_t {
  int refcount;
  hush_device device;
  uint32_t width, height;
  hush_layer layers[HUSH_MAX_LAYERS];
  uint32_t layer_count;
};

/* Layer by name, NULL if absent. */
hush_layer *hush__frame_find(hush_frame frame, const char *name);

#endif
