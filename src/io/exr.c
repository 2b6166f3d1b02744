/*
 * exr.c — frames as OpenEXR files, through OpenEXRCore (the C API).
 *
 * Reading accepts single-part scanline or tiled files (level 0 of mipmaps),
 * any compression, half / float / uint channels, and converts everything to
 * float32 layers. Channels are grouped into layers by name (see
 * plan_layers() and docs/sequence-format.md). Writing produces one
 * ZIP-compressed scanline part with every layer, through a temporary file.
 *
 * OpenEXR never prints: read contexts send their messages to
 * on_read_error(), which keeps the first one for our error message; write
 * contexts get a silent handler (see on_write_error() for why) and we report
 * the failing step and the OS error instead.
 *
 * Pixels are unpacked by our own routine (unpack_to_layers) rather than
 * OpenEXR's default ones: some of the specialised 3- and 4-channel
 * half-to-float paths of OpenEXR 3.1 put the channels in the wrong order,
 * and one routine that checks every size itself is easier to trust with
 * hostile files.
 */
#include "io/exr.h"

#include "core/device.h"
#include "core/half.h"
#include "io/atomic_file.h"
#include "io/frame.h"

#include <openexr.h>

#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#define EXR_MAX_SIZE 65536
/* Layers hold at most 4 channels each. */
#define EXR_MAX_CHANNELS (HUSH_MAX_LAYERS * 4)

/* ------------------------------------------------------------------------ */
/* Channel names and layers                                                 */
/* ------------------------------------------------------------------------ */

/* Component letters of each family; a layer uses one family, in this order. */
static const char *const families[] = {"RGBA", "XYZW", "UV"};
enum { FAMILY_NONE = -1, FAMILY_DEPTH = 3 /* the bare "Z" channel */ };

typedef struct channel_key {
  char layer[HUSH_LAYER_NAME_MAX]; /* the layer it would join */
  int family;                      /* FAMILY_NONE: a layer of its own */
  int comp;                        /* index of its letter in the family */
} channel_key;

static int component_of(char letter, int *family, int *comp) {
  for (int f = 0; f < 3; f++) {
    const char *p = letter ? strchr(families[f], letter) : NULL;
    if (p) {
      *family = f;
      *comp = (int)(p - families[f]);
      return 1;
    }
  }
  return 0;
}

/* N and P are the usual EXR prefixes of shading normals and positions. */
static const char *prefix_of_layer(const char *layer) {
  if (strcmp(layer, "normal") == 0) return "N";
  if (strcmp(layer, "position") == 0) return "P";
  return layer;
}

static const char *layer_of_prefix(const char *prefix) {
  if (strcmp(prefix, "N") == 0) return "normal";
  if (strcmp(prefix, "P") == 0) return "position";
  return prefix;
}

/* How a channel name asks to be grouped: "layer.C" joins "layer" (N and P
 * standing for normal and position) as component C, bare R/G/B/A join
 * "color", bare Z is "depth", anything else stands alone. Conflicts are
 * settled later. */
static void classify_channel(const char *name, channel_key *key) {
  key->layer[0] = '\0';
  key->family = FAMILY_NONE;
  key->comp = 0;
  const char *dot = strrchr(name, '.');
  if (dot && dot != name && dot[1] && !dot[2] && dot - name < HUSH_LAYER_NAME_MAX &&
      component_of(dot[1], &key->family, &key->comp)) {
    char prefix[HUSH_LAYER_NAME_MAX];
    memcpy(prefix, name, (size_t)(dot - name));
    prefix[dot - name] = '\0';
    strcpy(key->layer, layer_of_prefix(prefix));
    return;
  }
  if (name[0] && !name[1]) {
    if (name[0] == 'Z') {
      strcpy(key->layer, "depth");
      key->family = FAMILY_DEPTH;
    } else if (strchr("RGBA", name[0])) {
      strcpy(key->layer, "color");
      component_of(name[0], &key->family, &key->comp);
    }
  }
}

/* Finds a group that cannot stand as a layer — mixed families, a repeated
 * or missing component (G without R), or a name that an ungrouped channel
 * already has — and ungroups its channels. Returns 1 if it changed one. */
static int ungroup_one_bad_group(const char *const *names, const channel_key *keys, int *grouped,
                                 int n) {
  for (int i = 0; i < n; i++) {
    if (!grouped[i]) continue;
    int first = 1;
    for (int j = 0; j < i && first; j++)
      if (grouped[j] && strcmp(keys[j].layer, keys[i].layer) == 0) first = 0;
    if (!first) continue;

    unsigned seen = 0;
    int count = 0, ok = 1;
    for (int j = i; j < n; j++) {
      if (!grouped[j] || strcmp(keys[j].layer, keys[i].layer) != 0) continue;
      if (keys[j].family != keys[i].family || (seen & (1u << keys[j].comp))) ok = 0;
      seen |= 1u << keys[j].comp;
      count++;
    }
    if (count > 4 || seen != (1u << count) - 1) ok = 0;
    for (int k = 0; k < n && ok; k++)
      if (!grouped[k] && strcmp(names[k], keys[i].layer) == 0) ok = 0;
    if (ok) continue;
    for (int j = i; j < n; j++)
      if (grouped[j] && strcmp(keys[j].layer, keys[i].layer) == 0) grouped[j] = 0;
    return 1;
  }
  return 0;
}

typedef struct layer_plan {
  int layer_count;
  char names[HUSH_MAX_LAYERS][HUSH_LAYER_NAME_MAX];
  int channels[HUSH_MAX_LAYERS];
  int layer_of[EXR_MAX_CHANNELS]; /* by channel */
  int comp_of[EXR_MAX_CHANNELS];
} layer_plan;

typedef enum plan_result { PLAN_OK, PLAN_TOO_MANY_LAYERS, PLAN_BAD_NAME } plan_result;

/* Maps n <= EXR_MAX_CHANNELS channel names to layers, in the order of their
 * first channel. On PLAN_BAD_NAME, *bad is the channel at fault. */
static plan_result plan_layers(const char *const *names, int n, layer_plan *plan, int *bad) {
  channel_key keys[EXR_MAX_CHANNELS];
  int grouped[EXR_MAX_CHANNELS];
  for (int i = 0; i < n; i++) {
    classify_channel(names[i], &keys[i]);
    grouped[i] = keys[i].family != FAMILY_NONE;
  }
  while (ungroup_one_bad_group(names, keys, grouped, n)) {}
  plan->layer_count = 0;
  for (int i = 0; i < n; i++) {
    const char *name = grouped[i] ? keys[i].layer : names[i];
    const size_t len = strlen(name);
    if (len == 0 || len >= HUSH_LAYER_NAME_MAX) {
      *bad = i;
      return PLAN_BAD_NAME;
    }
    int l = 0;
    while (l < plan->layer_count && strcmp(plan->names[l], name) != 0) l++;
    if (l == plan->layer_count) {
      if (l == HUSH_MAX_LAYERS) return PLAN_TOO_MANY_LAYERS;
      strcpy(plan->names[l], name);
      plan->channels[l] = 0;
      plan->layer_count++;
    }
    plan->layer_of[i] = l;
    plan->comp_of[i] = grouped[i] ? keys[i].comp : 0;
    plan->channels[l]++;
  }
  return PLAN_OK;
}

/* Geometric layers use X, Y, Z, W; everything else R, G, B, A. */
static int is_vector_layer(const char *layer) {
  return strcmp(layer, "normal") == 0 || strcmp(layer, "position") == 0 ||
         strcmp(layer, "motion") == 0;
}

void hush__exr_channel_name(const char *layer, int channels, int comp,
                            char out[HUSH_EXR_NAME_MAX]) {
  if (channels <= 1) {
    snprintf(out, HUSH_EXR_NAME_MAX, "%s", strcmp(layer, "depth") == 0 ? "Z" : layer);
    return;
  }
  const char letter = (is_vector_layer(layer) ? "XYZW" : "RGBA")[comp & 3];
  if (strcmp(layer, "color") == 0)
    snprintf(out, HUSH_EXR_NAME_MAX, "%c", letter);
  else
    snprintf(out, HUSH_EXR_NAME_MAX, "%s.%c", prefix_of_layer(layer), letter);
}

/* ------------------------------------------------------------------------ */
/* Reading: the byte source and OpenEXR's callbacks                         */
/* ------------------------------------------------------------------------ */

typedef struct exr_source {
  int fd;              /* a file, or -1 to read from data */
  const uint8_t *data; /* memory */
  uint64_t size;
  int os_error;      /* errno of a failed read, 0 if none */
  char message[512]; /* first message from OpenEXR since the last clear */
} exr_source;

static int64_t source_read(exr_const_context_t ctxt, void *user, void *buffer, uint64_t size,
                           uint64_t offset, exr_stream_error_func_ptr_t error_cb) {
  (void)ctxt;
  (void)error_cb; /* the short read is reported by OpenEXR, os_error by us */
  exr_source *s = user;
  if (offset >= s->size) return 0;
  if (size > s->size - offset) size = s->size - offset;
  if (s->fd < 0) {
    memcpy(buffer, s->data + offset, size);
    return (int64_t)size;
  }
  uint64_t done = 0;
  while (done < size) {
    const ssize_t n = pread(s->fd, (char *)buffer + done, size - done, (off_t)(offset + done));
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) {
      s->os_error = errno;
      return -1;
    }
    if (n == 0) break;
    done += (uint64_t)n;
  }
  return (int64_t)done;
}

static int64_t source_size(exr_const_context_t ctxt, void *user) {
  (void)ctxt;
  return (int64_t)((const exr_source *)user)->size;
}

/* Read contexts never hold their lock while reporting, so asking for the
 * user data here is safe. OpenEXR quotes attribute names from the file, so
 * bytes outside printable ASCII become '?' before they reach a message. */
static void on_read_error(exr_const_context_t ctxt, exr_result_t code, const char *msg) {
  void *user = NULL;
  if (!ctxt || exr_get_user_data(ctxt, &user) != EXR_ERR_SUCCESS || !user) return;
  exr_source *s = user;
  if (s->message[0]) return;
  snprintf(s->message, sizeof s->message, "%s", msg ? msg : exr_get_default_error_message(code));
  for (char *p = s->message; *p; p++)
    if ((unsigned char)*p < 0x20 || (unsigned char)*p > 0x7e) *p = '?';
}

static hush_status read_fail(hush_device device, const exr_source *s, exr_result_t rv,
                             const char *path, const char *what) {
  if (rv == EXR_ERR_OUT_OF_MEMORY)
    return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory reading '%s'", path);
  if (s->os_error)
    return hush__fail(device, HUSH_ERROR_IO, "cannot read '%s': %s", path, strerror(s->os_error));
  const char *detail = s->message[0] ? s->message : exr_get_default_error_message(rv);
  const hush_status status =
      rv == EXR_ERR_FEATURE_NOT_IMPLEMENTED ? HUSH_ERROR_UNSUPPORTED : HUSH_ERROR_CORRUPT;
  return hush__fail(device, status, "'%s': %s: %s", path, what, detail);
}

/* ------------------------------------------------------------------------ */
/* Reading: header checks and decoding                                      */
/* ------------------------------------------------------------------------ */

typedef struct exr_reader {
  hush_device device;
  const char *path;
  exr_source *source;
  exr_context_t ctx;
  exr_storage_t storage;
  exr_compression_t compression;
  int32_t width, height;
  int channel_count;
  const exr_attr_chlist_t *chlist;
  hush_frame frame;
  /* per channel, in file order: where its values go */
  float *dest[EXR_MAX_CHANNELS]; /* the layer's pixels, offset by the component */
  int stride[EXR_MAX_CHANNELS];  /* the layer's channel count */
  /* the chunk being decoded, in image pixels */
  int32_t chunk_x, chunk_y;
} exr_reader;

static hush_status check_header(exr_reader *r, uint64_t max_pixels) {
  hush_device device = r->device;
  const char *path = r->path;
  int parts = 0;
  exr_result_t rv = exr_get_count(r->ctx, &parts);
  if (rv != EXR_ERR_SUCCESS) return read_fail(device, r->source, rv, path, "bad header");
  if (parts != 1)
    return hush__fail(device, HUSH_ERROR_UNSUPPORTED,
                      "'%s' has %d parts; hush reads single-part EXR files", path, parts);
  rv = exr_get_storage(r->ctx, 0, &r->storage);
  if (rv != EXR_ERR_SUCCESS) return read_fail(device, r->source, rv, path, "bad header");
  if (r->storage != EXR_STORAGE_SCANLINE && r->storage != EXR_STORAGE_TILED)
    return hush__fail(device, HUSH_ERROR_UNSUPPORTED,
                      "'%s' holds deep data; hush reads flat scanline or tiled images", path);
  rv = exr_get_compression(r->ctx, 0, &r->compression);
  if (rv != EXR_ERR_SUCCESS) return read_fail(device, r->source, rv, path, "bad header");

  exr_attr_box2i_t data, display;
  rv = exr_get_data_window(r->ctx, 0, &data);
  if (rv == EXR_ERR_SUCCESS) rv = exr_get_display_window(r->ctx, 0, &display);
  if (rv != EXR_ERR_SUCCESS) return read_fail(device, r->source, rv, path, "bad header");
  if (memcmp(&data, &display, sizeof data) != 0)
    return hush__fail(device, HUSH_ERROR_UNSUPPORTED,
                      "'%s': data window (%d, %d)-(%d, %d) differs from display window "
                      "(%d, %d)-(%d, %d); hush reads full images only",
                      path, data.min.x, data.min.y, data.max.x, data.max.y, display.min.x,
                      display.min.y, display.max.x, display.max.y);
  const int64_t w = (int64_t)data.max.x - data.min.x + 1;
  const int64_t h = (int64_t)data.max.y - data.min.y + 1;
  if (w < 1 || h < 1 || w > EXR_MAX_SIZE || h > EXR_MAX_SIZE || (uint64_t)(w * h) > max_pixels)
    return hush__fail(device, HUSH_ERROR_UNSUPPORTED,
                      "'%s' is %lldx%lld; hush reads up to %d pixels a side and %llu in all", path,
                      (long long)w, (long long)h, EXR_MAX_SIZE, (unsigned long long)max_pixels);
  r->width = (int32_t)w;
  r->height = (int32_t)h;

  rv = exr_get_channels(r->ctx, 0, &r->chlist);
  if (rv != EXR_ERR_SUCCESS) return read_fail(device, r->source, rv, path, "bad header");
  r->channel_count = r->chlist->num_channels;
  if (r->channel_count < 1 || r->channel_count > EXR_MAX_CHANNELS)
    return hush__fail(device, HUSH_ERROR_UNSUPPORTED, "'%s' has %d channels; hush reads 1 to %d",
                      path, r->channel_count, EXR_MAX_CHANNELS);
  for (int c = 0; c < r->channel_count; c++) {
    const exr_attr_chlist_entry_t *e = &r->chlist->entries[c];
    if (e->x_sampling != 1 || e->y_sampling != 1)
      return hush__fail(device, HUSH_ERROR_UNSUPPORTED,
                        "'%s': channel '%s' is subsampled (%d, %d); hush reads full-resolution "
                        "channels only",
                        path, e->name.str, e->x_sampling, e->y_sampling);
    if (e->pixel_type != EXR_PIXEL_HALF && e->pixel_type != EXR_PIXEL_FLOAT &&
        e->pixel_type != EXR_PIXEL_UINT)
      return hush__fail(device, HUSH_ERROR_CORRUPT, "'%s': channel '%s' has unknown type %d", path,
                        e->name.str, (int)e->pixel_type);
  }
  return HUSH_OK;
}

/* Makes the frame and its layers, and points every channel at its place. */
static hush_status make_frame(exr_reader *r) {
  const char *names[EXR_MAX_CHANNELS];
  for (int c = 0; c < r->channel_count; c++) names[c] = r->chlist->entries[c].name.str;
  layer_plan plan;
  int bad = 0;
  switch (plan_layers(names, r->channel_count, &plan, &bad)) {
  case PLAN_OK: break;
  case PLAN_TOO_MANY_LAYERS:
    return hush__fail(r->device, HUSH_ERROR_UNSUPPORTED,
                      "'%s': its channels make more than %d layers", r->path, HUSH_MAX_LAYERS);
  case PLAN_BAD_NAME:
    return hush__fail(r->device, HUSH_ERROR_UNSUPPORTED,
                      "'%s': channel name '%.80s' is empty or longer than %d characters", r->path,
                      names[bad], HUSH_LAYER_NAME_MAX - 1);
  }
  r->frame = hush_frame_new(r->device, (uint32_t)r->width, (uint32_t)r->height);
  if (!r->frame) return HUSH_ERROR_OUT_OF_MEMORY;
  for (int l = 0; l < plan.layer_count; l++) {
    const hush_status status =
        hush_frame_add_layer(r->frame, plan.names[l], plan.channels[l], NULL);
    if (status != HUSH_OK) return status;
  }
  for (int c = 0; c < r->channel_count; c++) {
    const hush_layer *layer = &r->frame->layers[plan.layer_of[c]];
    r->dest[c] = layer->pixels + plan.comp_of[c];
    r->stride[c] = layer->channels;
  }
  return HUSH_OK;
}

/* Converts one line of one channel from the file's little-endian form. */
static const uint8_t *convert_line(const uint8_t *src, uint16_t type, int32_t width, float *dst,
                                   int stride) {
  for (int32_t x = 0; x < width; x++, dst += stride) {
    if (type == EXR_PIXEL_HALF) {
      *dst = hush__half_to_float((uint16_t)(src[0] | src[1] << 8));
      src += 2;
      continue;
    }
    const uint32_t bits =
        (uint32_t)src[0] | (uint32_t)src[1] << 8 | (uint32_t)src[2] << 16 | (uint32_t)src[3] << 24;
    src += 4;
    if (type == EXR_PIXEL_UINT) {
      *dst = (float)bits;
    } else {
      memcpy(dst, &bits, sizeof *dst);
    }
  }
  return src;
}

/* Our unpack_and_convert_fn: the uncompressed chunk holds, for each line,
 * each channel's values in file order. decode_chunk() has checked that the
 * chunk lies in the image and that the buffer has exactly this size. */
static exr_result_t unpack_to_layers(exr_decode_pipeline_t *d) {
  const exr_reader *r = d->decoding_user_data;
  const uint8_t *src = d->unpacked_buffer;
  if (!src) return EXR_ERR_CORRUPT_CHUNK;
  for (int32_t y = 0; y < d->chunk.height; y++) {
    const size_t pixel = (size_t)(r->chunk_y + y) * (size_t)r->width + (size_t)r->chunk_x;
    for (int c = 0; c < d->channel_count; c++)
      src = convert_line(src, d->channels[c].data_type, d->chunk.width,
                         r->dest[c] + pixel * (size_t)r->stride[c], r->stride[c]);
  }
  return EXR_ERR_SUCCESS;
}

static hush_status decode_chunk(exr_reader *r, exr_decode_pipeline_t *d, const exr_chunk_info_t *ci,
                                int32_t x0, int32_t y0, int32_t w, int32_t h, const char *what) {
  exr_source *s = r->source;
  if (ci->width != w || ci->height != h)
    return hush__fail(r->device, HUSH_ERROR_CORRUPT, "'%s': %s: chunk is %dx%d, expected %dx%d",
                      r->path, what, ci->width, ci->height, w, h);
  const int first = d->channels == NULL;
  exr_result_t rv =
      first ? exr_decoding_initialize(r->ctx, 0, ci, d) : exr_decoding_update(r->ctx, 0, ci, d);
  if (rv == EXR_ERR_SUCCESS && first) {
    /* With no channel pointers set, OpenEXR picks its generic read and
     * decompress steps; the unpacking is ours. */
    rv = exr_decoding_choose_default_routines(r->ctx, 0, d);
    d->decoding_user_data = r;
    d->unpack_and_convert_fn = unpack_to_layers;
  }
  if (rv != EXR_ERR_SUCCESS) return read_fail(r->device, s, rv, r->path, what);

  if (d->channel_count != r->channel_count)
    return hush__fail(r->device, HUSH_ERROR_CORRUPT, "'%s': %s: inconsistent channel list", r->path,
                      what);
  uint64_t expected = 0;
  for (int c = 0; c < d->channel_count; c++) {
    if (d->channels[c].width != w || d->channels[c].height != h)
      return hush__fail(r->device, HUSH_ERROR_CORRUPT, "'%s': %s: inconsistent channel size",
                        r->path, what);
    expected += (uint64_t)w * (uint64_t)h * (uint64_t)d->channels[c].bytes_per_element;
  }
  if (ci->unpacked_size != expected ||
      (r->compression == EXR_COMPRESSION_NONE && ci->packed_size != expected))
    return hush__fail(r->device, HUSH_ERROR_CORRUPT,
                      "'%s': %s: chunk holds %llu bytes (%llu packed), expected %llu", r->path,
                      what, (unsigned long long)ci->unpacked_size,
                      (unsigned long long)ci->packed_size, (unsigned long long)expected);
  r->chunk_x = x0;
  r->chunk_y = y0;
  rv = exr_decoding_run(r->ctx, 0, d);
  if (rv != EXR_ERR_SUCCESS) return read_fail(r->device, s, rv, r->path, what);
  return HUSH_OK;
}

static hush_status read_scanlines(exr_reader *r, exr_decode_pipeline_t *d) {
  exr_attr_box2i_t dw;
  int32_t lines = 0;
  exr_result_t rv = exr_get_data_window(r->ctx, 0, &dw);
  if (rv == EXR_ERR_SUCCESS) rv = exr_get_scanlines_per_chunk(r->ctx, 0, &lines);
  if (rv == EXR_ERR_SUCCESS && lines < 1) rv = EXR_ERR_INVALID_ATTR;
  if (rv != EXR_ERR_SUCCESS)
    return read_fail(r->device, r->source, rv, r->path, "bad scanline layout");
  for (int32_t y = 0; y < r->height; y += lines) {
    const int32_t h = r->height - y < lines ? r->height - y : lines;
    char what[64];
    snprintf(what, sizeof what, "cannot read scanlines %d..%d", y, y + h - 1);
    r->source->message[0] = '\0';
    exr_chunk_info_t ci;
    rv = exr_read_scanline_chunk_info(r->ctx, 0, dw.min.y + y, &ci);
    if (rv != EXR_ERR_SUCCESS) return read_fail(r->device, r->source, rv, r->path, what);
    const hush_status status = decode_chunk(r, d, &ci, 0, y, r->width, h, what);
    if (status != HUSH_OK) return status;
  }
  return HUSH_OK;
}

static hush_status read_tiles(exr_reader *r, exr_decode_pipeline_t *d) {
  uint32_t tw = 0, th = 0;
  exr_tile_level_mode_t level_mode;
  exr_tile_round_mode_t round_mode;
  exr_result_t rv = exr_get_tile_descriptor(r->ctx, 0, &tw, &th, &level_mode, &round_mode);
  if (rv == EXR_ERR_SUCCESS && (tw < 1 || th < 1 || tw > EXR_MAX_SIZE || th > EXR_MAX_SIZE))
    rv = EXR_ERR_INVALID_ATTR;
  if (rv != EXR_ERR_SUCCESS)
    return read_fail(r->device, r->source, rv, r->path, "bad tile description");
  /* Level 0 of a mipmap or ripmap is the full image; we read only that. */
  for (int32_t ty = 0; (int64_t)ty * th < r->height; ty++) {
    for (int32_t tx = 0; (int64_t)tx * tw < r->width; tx++) {
      const int32_t x0 = tx * (int32_t)tw, y0 = ty * (int32_t)th;
      const int32_t w = r->width - x0 < (int32_t)tw ? r->width - x0 : (int32_t)tw;
      const int32_t h = r->height - y0 < (int32_t)th ? r->height - y0 : (int32_t)th;
      char what[64];
      snprintf(what, sizeof what, "cannot read tile (%d, %d)", tx, ty);
      r->source->message[0] = '\0';
      exr_chunk_info_t ci;
      rv = exr_read_tile_chunk_info(r->ctx, 0, tx, ty, 0, 0, &ci);
      if (rv != EXR_ERR_SUCCESS) return read_fail(r->device, r->source, rv, r->path, what);
      const hush_status status = decode_chunk(r, d, &ci, x0, y0, w, h, what);
      if (status != HUSH_OK) return status;
    }
  }
  return HUSH_OK;
}

static hush_status read_exr(hush_device device, const char *path, exr_source *source,
                            uint64_t max_pixels, hush_frame *out) {
  exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
  init.error_handler_fn = on_read_error;
  init.user_data = source;
  init.read_fn = source_read;
  init.size_fn = source_size;
  init.max_image_width = init.max_image_height = EXR_MAX_SIZE;
  init.max_tile_width = init.max_tile_height = EXR_MAX_SIZE;
  /* A damaged chunk table is an error, not something to guess around. */
  init.flags = EXR_CONTEXT_FLAG_DISABLE_CHUNK_RECONSTRUCTION;

  exr_reader r;
  memset(&r, 0, sizeof r);
  r.device = device;
  r.path = path;
  r.source = source;
  exr_result_t rv = exr_start_read(&r.ctx, path, &init);
  if (rv != EXR_ERR_SUCCESS)
    return read_fail(device, source, rv, path, "not a readable OpenEXR file");

  hush_status status = check_header(&r, max_pixels ? max_pixels : HUSH_EXR_MAX_PIXELS);
  if (status == HUSH_OK) status = make_frame(&r);
  if (status == HUSH_OK) {
    exr_decode_pipeline_t decoder = EXR_DECODE_PIPELINE_INITIALIZER;
    status =
        r.storage == EXR_STORAGE_TILED ? read_tiles(&r, &decoder) : read_scanlines(&r, &decoder);
    exr_decoding_destroy(r.ctx, &decoder);
  }
  exr_finish(&r.ctx);
  if (status != HUSH_OK) {
    hush_frame_release(r.frame);
    return status;
  }
  *out = r.frame;
  return HUSH_OK;
}

hush_status hush__exr_read_memory(hush_device device, const char *name, const void *data,
                                  size_t size, uint64_t max_pixels, hush_frame *frame) {
  if (!device)
    return hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT, "hush__exr_read_memory: device is NULL");
  if (!frame || !name || !*name || (!data && size))
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "hush__exr_read_memory: bad argument");
  *frame = NULL;
  exr_source source;
  memset(&source, 0, sizeof source);
  source.fd = -1;
  source.data = data;
  source.size = size;
  return read_exr(device, name, &source, max_pixels, frame);
}

hush_status hush_frame_read_exr(hush_device device, const char *path, hush_frame *frame) {
  if (!device)
    return hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT, "hush_frame_read_exr: device is NULL");
  if (!frame)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "hush_frame_read_exr: frame is NULL");
  *frame = NULL;
  if (!path || !*path)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                      "hush_frame_read_exr: path is NULL or empty");
  const int fd = open(path, O_RDONLY | O_CLOEXEC);
  if (fd < 0)
    return hush__fail(device, HUSH_ERROR_IO, "cannot open '%s': %s", path, strerror(errno));
  struct stat st;
  const int have_stat = fstat(fd, &st) == 0;
  if (!have_stat || !S_ISREG(st.st_mode)) {
    const char *why = !have_stat            ? strerror(errno)
                      : S_ISDIR(st.st_mode) ? strerror(EISDIR)
                                            : "not a regular file";
    close(fd);
    return hush__fail(device, HUSH_ERROR_IO, "cannot open '%s': %s", path, why);
  }
  exr_source source;
  memset(&source, 0, sizeof source);
  source.fd = fd;
  source.size = (uint64_t)st.st_size;
  const hush_status status = read_exr(device, path, &source, 0, frame);
  close(fd);
  return status;
}

/* ------------------------------------------------------------------------ */
/* Writing                                                                  */
/* ------------------------------------------------------------------------ */

typedef struct exr_sink {
  int fd;
  int os_error; /* errno of a failed write, 0 if none */
} exr_sink;

static int64_t sink_write(exr_const_context_t ctxt, void *user, const void *buffer, uint64_t size,
                          uint64_t offset, exr_stream_error_func_ptr_t error_cb) {
  (void)ctxt;
  (void)error_cb;
  exr_sink *s = user;
  uint64_t done = 0;
  while (done < size) {
    const ssize_t n =
        pwrite(s->fd, (const char *)buffer + done, size - done, (off_t)(offset + done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      s->os_error = n < 0 ? errno : EIO;
      return -1;
    }
    done += (uint64_t)n;
  }
  return (int64_t)done;
}

/* A write context may report while it holds its own (non-recursive) lock,
 * so this handler must not call back into OpenEXR, which is the only way to
 * reach our data. It drops the message; write_fail() says what failed. */
static void on_write_error(exr_const_context_t ctxt, exr_result_t code, const char *msg) {
  (void)ctxt;
  (void)code;
  (void)msg;
}

static hush_status write_fail(hush_device device, const exr_sink *sink, exr_result_t rv,
                              const char *path, const char *step) {
  if (rv == EXR_ERR_OUT_OF_MEMORY)
    return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory writing '%s'", path);
  if (sink->os_error)
    return hush__fail(device, HUSH_ERROR_IO, "cannot write '%s': %s", path,
                      strerror(sink->os_error));
  return hush__fail(device, HUSH_ERROR_IO, "cannot write '%s': OpenEXR failed to %s: %s", path,
                    step, exr_get_default_error_message(rv));
}

typedef struct out_channel {
  char name[HUSH_EXR_NAME_MAX];
  const hush_layer *layer;
  int comp;
  exr_pixel_type_t type;
} out_channel;

static int compare_channels(const void *a, const void *b) {
  return strcmp(((const out_channel *)a)->name, ((const out_channel *)b)->name);
}

/* Geometry that must stay exact is stored as float even in half files. */
static int needs_float(const char *layer) {
  /* vis holds triangle indices and barycentrics: half would scramble both */
  return strcmp(layer, "id") == 0 || strcmp(layer, "depth") == 0 ||
         strcmp(layer, "position") == 0 || strcmp(layer, "vis") == 0;
}

/* Lists the channels of every layer, sorted as EXR requires, and checks
 * that reading them back gives the same layers. */
static hush_status list_channels(hush_frame frame, const char *path, hush_exr_type type,
                                 out_channel *out, int *count) {
  hush_device device = frame->device;
  int n = 0;
  for (uint32_t l = 0; l < frame->layer_count; l++) {
    const hush_layer *layer = &frame->layers[l];
    for (int c = 0; c < layer->channels; c++, n++) {
      hush__exr_channel_name(layer->name, layer->channels, c, out[n].name);
      out[n].layer = layer;
      out[n].comp = c;
      out[n].type =
          type == HUSH_EXR_FLOAT || needs_float(layer->name) ? EXR_PIXEL_FLOAT : EXR_PIXEL_HALF;
    }
  }
  qsort(out, (size_t)n, sizeof *out, compare_channels);
  const char *names[EXR_MAX_CHANNELS] = {0};
  for (int i = 0; i < n; i++) {
    if (i > 0 && strcmp(out[i].name, out[i - 1].name) == 0)
      return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                        "cannot write '%s': layers '%s' and '%s' both map to channel '%s'", path,
                        out[i - 1].layer->name, out[i].layer->name, out[i].name);
    names[i] = out[i].name;
  }
  layer_plan plan;
  int bad = 0;
  const plan_result planned = plan_layers(names, n, &plan, &bad);
  for (int i = 0; i < n; i++) {
    const hush_layer *layer = out[i].layer;
    if (planned != PLAN_OK || strcmp(plan.names[plan.layer_of[i]], layer->name) != 0 ||
        plan.channels[plan.layer_of[i]] != layer->channels || plan.comp_of[i] != out[i].comp)
      return hush__fail(device, HUSH_ERROR_UNSUPPORTED,
                        "cannot write '%s': layer '%s' would not read back under its name "
                        "(channel '%s')",
                        path, layer->name, out[i].name);
  }
  *count = n;
  return HUSH_OK;
}

/* The library's compressor, wrapped by compress_guarded. */
typedef struct zip_guard {
  exr_result_t (*compress)(exr_encode_pipeline_t *pipeline);
} zip_guard;

/* OpenEXRCore's ZIP encoder (Debian 12 has 3.1.5; fixed upstream in March
 * 2026, OpenEXR issue 2306) keeps the deflated bytes of a chunk whose
 * deflated size equals its raw size, and every reader takes a chunk of its
 * raw size for raw pixels: the chunk reads back as garbage (here 3 of 6
 * frames of `hush synth --size 2x1`). Such a chunk is stored raw, as the
 * fixed encoder does. */
static exr_result_t compress_guarded(exr_encode_pipeline_t *e) {
  const zip_guard *guard = e->encoding_user_data;
  const exr_result_t rv = guard->compress(e);
  if (rv == EXR_ERR_SUCCESS && e->compressed_bytes == e->packed_bytes && e->compressed_buffer &&
      e->packed_buffer && e->compressed_buffer != e->packed_buffer)
    memcpy(e->compressed_buffer, e->packed_buffer, e->packed_bytes);
  return rv;
}

/* Rows [y, y + rows) of a channel as halves into dst (width per row),
 * saturating: OpenEXR's conversion makes finite values beyond the half
 * range Inf, which hush itself refuses as input (a renderer's highlight
 * written with --half came back as a NaN/Inf error). */
static void half_rows(const out_channel *oc, size_t width, int32_t y, int32_t rows,
                      uint16_t *dst) {
  const int n = oc->layer->channels;
  for (int32_t r = 0; r < rows; r++) {
    const float *src = oc->layer->pixels + ((size_t)(y + r) * width) * (size_t)n + (size_t)oc->comp;
    uint16_t *row = dst + (size_t)r * width;
    for (size_t x = 0; x < width; x++)
      row[x] = hush__float_to_half_saturating(src[x * (size_t)n]);
  }
}

static hush_status encode_scanlines(exr_context_t ctx, hush_frame frame,
                                    const out_channel *channels, int count, const exr_sink *sink,
                                    const char *path) {
  hush_device device = frame->device;
  int32_t lines = 0;
  exr_result_t rv = exr_get_scanlines_per_chunk(ctx, 0, &lines);
  if (rv != EXR_ERR_SUCCESS || lines < 1)
    return write_fail(device, sink, rv, path, "lay out scanlines");
  exr_encode_pipeline_t encoder = EXR_ENCODE_PIPELINE_INITIALIZER;
  zip_guard guard = {NULL};
  const int32_t height = (int32_t)frame->height;
  const size_t width = frame->width;
  /* the half channels' rows of a chunk, converted by half_rows */
  int halves = 0;
  for (int i = 0; i < count; i++) halves += channels[i].type == EXR_PIXEL_HALF;
  const size_t slot = (size_t)(lines < height ? lines : height) * width;
  uint16_t *half_buf = halves ? malloc((size_t)halves * slot * sizeof *half_buf) : NULL;
  if (halves && !half_buf)
    return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "cannot write '%s': out of memory", path);
  hush_status status = HUSH_OK;
  for (int32_t y = 0; y < height && status == HUSH_OK; y += lines) {
    const int32_t rows = height - y < lines ? height - y : lines;
    int half_slot = 0;
    exr_chunk_info_t ci;
    rv = exr_write_scanline_chunk_info(ctx, 0, y, &ci);
    if (rv == EXR_ERR_SUCCESS)
      rv = y == 0 ? exr_encoding_initialize(ctx, 0, &ci, &encoder)
                  : exr_encoding_update(ctx, 0, &ci, &encoder);
    if (rv != EXR_ERR_SUCCESS) {
      status = write_fail(device, sink, rv, path, "start a chunk");
      break;
    }
    for (int c = 0; c < encoder.channel_count; c++) {
      exr_coding_channel_info_t *ch = &encoder.channels[c];
      const out_channel *oc = NULL;
      for (int i = 0; i < count && !oc; i++)
        if (strcmp(channels[i].name, ch->channel_name) == 0) oc = &channels[i];
      if (!oc) { /* cannot happen: the part has exactly our channels */
        status = hush__fail(device, HUSH_ERROR_UNKNOWN, "cannot write '%s': lost channel '%s'",
                            path, ch->channel_name);
        break;
      }
      const int n = oc->layer->channels;
      if (oc->type == EXR_PIXEL_HALF) {
        uint16_t *dst = half_buf + (size_t)half_slot++ * slot;
        half_rows(oc, width, y, rows, dst);
        ch->encode_from_ptr = (const uint8_t *)dst;
        ch->user_pixel_stride = (int32_t)sizeof *dst;
        ch->user_line_stride = (int32_t)(width * sizeof *dst);
        ch->user_bytes_per_element = sizeof *dst;
        ch->user_data_type = EXR_PIXEL_HALF;
        continue;
      }
      ch->encode_from_ptr =
          (const uint8_t *)(oc->layer->pixels + (size_t)y * width * (size_t)n + (size_t)oc->comp);
      ch->user_pixel_stride = n * (int32_t)sizeof(float);
      ch->user_line_stride = (int32_t)(width * (size_t)n * sizeof(float));
      ch->user_bytes_per_element = sizeof(float);
      ch->user_data_type = EXR_PIXEL_FLOAT;
    }
    if (status != HUSH_OK) break;
    if (y == 0) {
      rv = exr_encoding_choose_default_routines(ctx, 0, &encoder);
      if (rv == EXR_ERR_SUCCESS && encoder.compress_fn) {
        guard.compress = encoder.compress_fn;
        encoder.compress_fn = compress_guarded;
        encoder.encoding_user_data = &guard;
      }
    }
    if (rv == EXR_ERR_SUCCESS) rv = exr_encoding_run(ctx, 0, &encoder);
    if (rv != EXR_ERR_SUCCESS) status = write_fail(device, sink, rv, path, "encode scanlines");
  }
  exr_encoding_destroy(ctx, &encoder);
  free(half_buf);
  return status;
}

/* Everything from the header to the last chunk, into an open context. */
static hush_status write_part(exr_context_t ctx, hush_frame frame, const out_channel *channels,
                              int count, const exr_sink *sink, const char *path) {
  hush_device device = frame->device;
  int part = 0;
  exr_result_t rv = exr_add_part(ctx, NULL, EXR_STORAGE_SCANLINE, &part);
  if (rv == EXR_ERR_SUCCESS)
    rv = exr_initialize_required_attr_simple(ctx, part, (int32_t)frame->width,
                                             (int32_t)frame->height, EXR_COMPRESSION_ZIP);
  /* zlib's fastest level: the files are ~10% larger than at the library's default, written
   * several times faster (the deflate of a rendered frame's many layers took three times as
   * long as rendering it); any reader decodes them the same */
  if (rv == EXR_ERR_SUCCESS) rv = exr_set_zip_compression_level(ctx, part, 1);
  if (rv != EXR_ERR_SUCCESS) return write_fail(device, sink, rv, path, "set up the header");
  for (int i = 0; i < count; i++) {
    /* Names over 31 characters need the "long names" flag of EXR 2.0. */
    if (strlen(channels[i].name) > 31) rv = exr_set_longname_support(ctx, 1);
    if (rv == EXR_ERR_SUCCESS)
      rv = exr_add_channel(ctx, part, channels[i].name, channels[i].type,
                           EXR_PERCEPTUALLY_LOGARITHMIC, 1, 1);
    if (rv != EXR_ERR_SUCCESS) return write_fail(device, sink, rv, path, "add a channel");
  }
  rv = exr_write_header(ctx);
  if (rv != EXR_ERR_SUCCESS) return write_fail(device, sink, rv, path, "write the header");
  return encode_scanlines(ctx, frame, channels, count, sink, path);
}

static hush_status write_to_temp(hush_frame frame, const char *tmp, const char *path,
                                 const out_channel *channels, int count) {
  hush_device device = frame->device;
  exr_sink sink = {open(tmp, O_WRONLY | O_TRUNC | O_CLOEXEC), 0};
  if (sink.fd < 0)
    return hush__fail(device, HUSH_ERROR_IO, "cannot write '%s': %s", path, strerror(errno));
  exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
  init.error_handler_fn = on_write_error;
  init.user_data = &sink;
  init.write_fn = sink_write;
  /* zlib level 4, the default of later OpenEXR releases: a 1080p frame of
   * a dozen float channels writes about a quarter faster than at level 6,
   * for files about a quarter larger. */
  init.zip_level = 4;
  exr_context_t ctx = NULL;
  exr_result_t rv = exr_start_write(&ctx, tmp, EXR_WRITE_FILE_DIRECTLY, &init);
  hush_status status = rv == EXR_ERR_SUCCESS
                           ? write_part(ctx, frame, channels, count, &sink, path)
                           : write_fail(device, &sink, rv, path, "start the file");
  /* exr_finish writes the chunk offset table. */
  rv = exr_finish(&ctx);
  if (status == HUSH_OK && rv != EXR_ERR_SUCCESS)
    status = write_fail(device, &sink, rv, path, "finish the file");
  if (close(sink.fd) != 0 && status == HUSH_OK)
    status = hush__fail(device, HUSH_ERROR_IO, "cannot write '%s': %s", path, strerror(errno));
  return status;
}

hush_status hush_frame_write_exr(hush_frame frame, const char *path, hush_exr_type type) {
  if (!frame)
    return hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT, "hush_frame_write_exr: frame is NULL");
  hush_device device = frame->device;
  if (!path || !*path)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                      "hush_frame_write_exr: path is NULL or empty");
  if (type != HUSH_EXR_HALF && type != HUSH_EXR_FLOAT)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "cannot write '%s': unknown EXR type %d",
                      path, (int)type);
  if (frame->layer_count == 0)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                      "cannot write '%s': the frame has no layers", path);
  out_channel channels[EXR_MAX_CHANNELS];
  int count = 0;
  hush_status status = list_channels(frame, path, type, channels, &count);
  if (status != HUSH_OK) return status;

  char tmp[HUSH_PATH_MAX];
  status = hush__atomic_reserve(device, path, tmp);
  if (status != HUSH_OK) return status;
  status = write_to_temp(frame, tmp, path, channels, count);
  if (status != HUSH_OK) {
    hush__atomic_abort(NULL, tmp);
    return status;
  }
  return hush__atomic_commit(device, NULL, tmp, path);
}
