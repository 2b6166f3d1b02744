/*
 * frame.c — the hush_frame object: a reference-counted set of named,
 * interleaved float32 layers of one size. The frame owns the pixels and holds
 * a reference to its device, which receives every error about it.
 */
#include "io/frame.h"

#include "core/device.h"
#include "core/image.h"

#include <stdlib.h>
#include <string.h>

/* Frames are never larger than the views the rest of the library accepts. */
#define FRAME_MAX_SIZE 65536u

static hush_status check_layer_name(hush_device device, const char *name) {
  if (!name) return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "layer name is NULL");
  const size_t len = strlen(name);
  if (len == 0) return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "layer name is empty");
  if (len >= HUSH_LAYER_NAME_MAX)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                      "layer name '%.20s...' is %zu characters long, the limit is %d", name, len,
                      HUSH_LAYER_NAME_MAX - 1);
  return HUSH_OK;
}

static void layer_view(const hush_frame frame, const hush_layer *layer, hush_image_view *view) {
  memset(view, 0, sizeof *view);
  view->data = layer->pixels;
  /* HUSH_FORMAT_FLOAT..FLOAT4 are 1..4 */
  view->format = (hush_format)layer->channels;
  view->width = frame->width;
  view->height = frame->height;
  view->pixel_stride = (size_t)layer->channels * sizeof(float);
  view->row_stride = view->pixel_stride * frame->width;
}

hush_frame hush_frame_new(hush_device device, uint32_t width, uint32_t height) {
  if (!device) {
    hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT, "hush_frame_new: device is NULL");
    return NULL;
  }
  if (width == 0 || height == 0 || width > FRAME_MAX_SIZE || height > FRAME_MAX_SIZE) {
    hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "hush_frame_new: size %ux%u is outside 1..%u",
               width, height, FRAME_MAX_SIZE);
    return NULL;
  }
  hush_frame frame = calloc(1, sizeof *frame);
  if (!frame) {
    hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory creating a %ux%u frame", width,
               height);
    return NULL;
  }
  frame->refcount = 1;
  frame->device = device;
  frame->width = width;
  frame->height = height;
  hush_device_retain(device);
  return frame;
}

void hush_frame_retain(hush_frame frame) {
  if (frame) frame->refcount++;
}

void hush_frame_release(hush_frame frame) {
  if (!frame || --frame->refcount > 0) return;
  for (uint32_t i = 0; i < frame->layer_count; i++) hush__free_floats(frame->layers[i].pixels);
  hush_device device = frame->device;
  free(frame);
  hush_device_release(device);
}

uint32_t hush_frame_width(hush_frame frame) { return frame ? frame->width : 0; }

uint32_t hush_frame_height(hush_frame frame) { return frame ? frame->height : 0; }

hush_layer *hush__frame_find(hush_frame frame, const char *name) {
  if (!frame || !name) return NULL;
  for (uint32_t i = 0; i < frame->layer_count; i++)
    if (strcmp(frame->layers[i].name, name) == 0) return &frame->layers[i];
  return NULL;
}

hush_status hush_frame_add_layer(hush_frame frame, const char *name, int channels,
                                 hush_image_view *view) {
  if (!frame)
    return hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT, "hush_frame_add_layer: frame is NULL");
  hush_device device = frame->device;
  hush_status status = check_layer_name(device, name);
  if (status != HUSH_OK) return status;
  if (channels < 1 || channels > 4)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                      "layer '%s': %d channels, a layer has 1 to 4", name, channels);
  hush_layer *layer = hush__frame_find(frame, name);
  if (!layer && frame->layer_count == HUSH_MAX_LAYERS)
    return hush__fail(device, HUSH_ERROR_UNSUPPORTED,
                      "cannot add layer '%s': a frame holds at most %d layers", name,
                      HUSH_MAX_LAYERS);
  /* Allocate before touching the frame, so a failure leaves it as it was. */
  float *pixels = hush__alloc_floats((size_t)frame->width * frame->height * (size_t)channels);
  if (!pixels)
    return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY,
                      "out of memory for layer '%s' (%ux%u, %d channels)", name, frame->width,
                      frame->height, channels);
  if (layer) {
    hush__free_floats(layer->pixels);
  } else {
    layer = &frame->layers[frame->layer_count++];
    strcpy(layer->name, name); /* length checked above */
  }
  layer->channels = channels;
  layer->pixels = pixels;
  if (view) layer_view(frame, layer, view);
  return HUSH_OK;
}

/* view may be NULL, which makes this a test for the layer's presence. */
hush_status hush_frame_get_layer(hush_frame frame, const char *name, hush_image_view *view) {
  if (!frame)
    return hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT, "hush_frame_get_layer: frame is NULL");
  if (!name) return hush__fail(frame->device, HUSH_ERROR_INVALID_ARGUMENT, "layer name is NULL");
  const hush_layer *layer = hush__frame_find(frame, name);
  if (!layer)
    return hush__fail(frame->device, HUSH_ERROR_NOT_FOUND, "the frame has no layer '%s'", name);
  if (view) layer_view(frame, layer, view);
  return HUSH_OK;
}

uint32_t hush_frame_layer_count(hush_frame frame) { return frame ? frame->layer_count : 0; }

const char *hush_frame_layer_name(hush_frame frame, uint32_t index) {
  if (!frame || index >= frame->layer_count) return NULL;
  return frame->layers[index].name;
}
