/*
 * psf.c — the public hashed path-space filtering object (hush_psf_*, see
 * hush.h): parameters, frames, keying of vertices (psf_hash.h) and the
 * table (psf_table.h). Follows hashed-path-space-filtering-binder-2019.md
 * §3 (Algorithm 1, §3.1-3.4).
 */
#include "psf/psf_hash.h"
#include "psf/psf_internal.h"
#include "psf/psf_table.h"

#include "core/device.h"
#include "core/timer.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

enum {
  P_SCALE,
  P_GLOSSY_SCALE,
  P_TABLE_SIZE,
  P_JITTER,
  P_NORMALS,
  P_GLOSSY_NORMALS,
  P_PROBES,
  P_MAX_SAMPLES,
  P_MAX_AGE,
  P_TEMPORAL,
  P_COUNT
};

static const hush_param_info params[P_COUNT] = {
    {"scale", HUSH_PARAM_FLOAT, 8.0, 0.01, 1024.0,
     "cell size in projected pixels at the vertex's distance (s of Algorithm 1)", NULL},
    {"glossy_scale", HUSH_PARAM_FLOAT, 4.0, 0.01, 1024.0,
     "cells of glossy vertices (HUSH_PSF_GLOSSY) this many times larger: the direction "
     "of view splits them further (section 4)", NULL},
    {"table_size", HUSH_PARAM_FLOAT, 1.0, 0.001, 64.0,
     "slots per pixel of the frame (rounded up to 64-byte lines of 16 slots)", NULL},
    {"jitter", HUSH_PARAM_FLOAT, 1.0, 0.0, 4.0,
     "tangent-plane jitter of the position before quantisation, in cells (0: none)", NULL},
    {"normals", HUSH_PARAM_BOOL, 1.0, 0.0, 1.0,
     "quantised normal in the verification hash: no averaging across edges", NULL},
    {"glossy_normals", HUSH_PARAM_BOOL, 0.0, 0.0, 1.0,
     "the normal also in glossy vertices' verification hash (their direction of view is "
     "always in it)", NULL},
    {"probes", HUSH_PARAM_INT, 8.0, 1.0, 16.0,
     "slots probed linearly inside the 16-slot cache line", NULL},
    {"max_samples", HUSH_PARAM_FLOAT, 1024.0, 1.0, 1e9,
     "history bound: running mean up to this many vertices, then exponential", NULL},
    {"max_age", HUSH_PARAM_INT, 16.0, 1.0, 62.0,
     "frames a cell survives unused before it is evicted", NULL},
    {"temporal", HUSH_PARAM_BOOL, 1.0, 0.0, 1.0,
     "blend cell averages across frames (section 3.3); 0: each frame alone", NULL},
};

struct hush_psf_t {
  int refcount;
  hush_device device;
  uint32_t width, height;
  double params[P_COUNT];
  hush_psf_table table;
  double table_built;      /* table_size of the table, 0: none yet */
  int state;               /* 0: no frame, 1: adding, 2: resolved */
  hush_psf_key_params key; /* of the current frame */
  hush_psf_stats stats;
};

const hush_param_info *hush_psf_params(uint32_t *count) {
  if (count) *count = P_COUNT;
  return params;
}

hush_psf hush_psf_new(hush_device device, uint32_t width, uint32_t height) {
  if (!device) {
    hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT, "psf: device is NULL");
    return NULL;
  }
  if (width == 0 || height == 0 || (uint64_t)width * height > (1u << 28)) {
    hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "psf: frame size %ux%u is out of range",
               width, height);
    return NULL;
  }
  hush_psf p = calloc(1, sizeof *p);
  if (!p) {
    hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "psf: out of memory");
    return NULL;
  }
  p->refcount = 1;
  p->device = device;
  hush_device_retain(device);
  p->width = width;
  p->height = height;
  for (int i = 0; i < P_COUNT; i++) p->params[i] = params[i].default_value;
  return p;
}

void hush_psf_retain(hush_psf psf) {
  if (psf) psf->refcount++;
}

void hush_psf_release(hush_psf psf) {
  if (!psf || --psf->refcount > 0) return;
  hush__psf_table_free(&psf->table);
  hush_device_release(psf->device);
  free(psf);
}

/* ---- parameters --------------------------------------------------------------- */

static hush_status find_param(hush_psf p, const char *name, int *index) {
  if (!name) return hush__fail(p->device, HUSH_ERROR_INVALID_ARGUMENT, "psf: parameter name is NULL");
  for (int i = 0; i < P_COUNT; i++)
    if (strcmp(params[i].name, name) == 0) {
      *index = i;
      return HUSH_OK;
    }
  char names[512] = "";
  for (int i = 0; i < P_COUNT; i++) {
    const size_t len = strlen(names);
    snprintf(names + len, sizeof names - len, "%s%s", i ? ", " : "", params[i].name);
  }
  return hush__fail(p->device, HUSH_ERROR_NOT_FOUND, "psf has no parameter '%s' (it has: %s)",
                    name, names);
}

static hush_status store(hush_psf p, int i, double value) {
  const hush_param_info *in = &params[i];
  if (!isfinite(value))
    return hush__fail(p->device, HUSH_ERROR_OUT_OF_RANGE, "psf.%s: value is not finite", in->name);
  if (in->type == HUSH_PARAM_BOOL && value != 0.0 && value != 1.0)
    return hush__fail(p->device, HUSH_ERROR_OUT_OF_RANGE, "psf.%s: a bool is 0 or 1, got %g",
                      in->name, value);
  if (in->type == HUSH_PARAM_INT && value != floor(value))
    return hush__fail(p->device, HUSH_ERROR_TYPE_MISMATCH, "psf.%s is an int parameter, got %g",
                      in->name, value);
  if (value < in->min_value || value > in->max_value)
    return hush__fail(p->device, HUSH_ERROR_OUT_OF_RANGE, "psf.%s = %g is outside [%g, %g]",
                      in->name, value, in->min_value, in->max_value);
  p->params[i] = value;
  return HUSH_OK;
}

hush_status hush_psf_set_float(hush_psf psf, const char *name, float value) {
  if (!psf) return hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT, "psf is NULL");
  int i = 0;
  const hush_status st = find_param(psf, name, &i);
  return st ? st : store(psf, i, (double)value);
}

hush_status hush_psf_set_int(hush_psf psf, const char *name, int value) {
  if (!psf) return hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT, "psf is NULL");
  int i = 0;
  const hush_status st = find_param(psf, name, &i);
  return st ? st : store(psf, i, (double)value);
}

hush_status hush_psf_set_string(hush_psf psf, const char *name, const char *value) {
  if (!psf) return hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT, "psf is NULL");
  int i = 0;
  const hush_status st = find_param(psf, name, &i);
  if (st) return st;
  if (!value) return hush__fail(psf->device, HUSH_ERROR_INVALID_ARGUMENT, "psf.%s: value is NULL", name);
  if (strcmp(value, "true") == 0) return store(psf, i, 1.0);
  if (strcmp(value, "false") == 0) return store(psf, i, 0.0);
  char *end;
  errno = 0;
  const double v = strtod(value, &end);
  if (!*value || errno || *end)
    return hush__fail(psf->device, HUSH_ERROR_TYPE_MISMATCH, "psf.%s: '%s' is not a number", name,
                      value);
  return store(psf, i, v);
}

hush_status hush_psf_get_float(hush_psf psf, const char *name, float *value) {
  if (!psf || !value) return hush__fail(psf ? psf->device : NULL, HUSH_ERROR_INVALID_ARGUMENT,
                                        "psf: NULL argument");
  int i = 0;
  const hush_status st = find_param(psf, name, &i);
  if (!st) *value = (float)psf->params[i];
  return st;
}

/* ---- frames -------------------------------------------------------------------- */

hush_status hush_psf_begin_frame(hush_psf psf, uint64_t frame_index, float pixel_angle,
                                 hush_history_mode history) {
  if (!psf) return hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT, "psf is NULL");
  if (!(pixel_angle > 0.0f) || !isfinite(pixel_angle))
    return hush__fail(psf->device, HUSH_ERROR_OUT_OF_RANGE,
                      "psf: pixel_angle %g is not a positive finite number", (double)pixel_angle);
  const int threads = hush_device_threads(psf->device);
  const double size = psf->params[P_TABLE_SIZE];
  if (psf->table_built != size) {
    hush__psf_table_free(&psf->table);
    psf->table_built = 0.0;
    const uint64_t slots = (uint64_t)ceil(size * (double)psf->width * (double)psf->height);
    if (!hush__psf_table_init(&psf->table, slots))
      return hush__fail(psf->device, HUSH_ERROR_OUT_OF_MEMORY,
                        "psf: no memory for a table of %llu slots", (unsigned long long)slots);
    psf->table_built = size;
  } else if (history == HUSH_HISTORY_RESET) {
    hush__psf_table_clear(&psf->table, threads);
  }
  hush__psf_table_begin_frame(&psf->table);
  psf->key.scale = (float)psf->params[P_SCALE];
  psf->key.glossy_scale = (float)psf->params[P_GLOSSY_SCALE];
  psf->key.pixel_angle = pixel_angle;
  psf->key.jitter = (float)psf->params[P_JITTER];
  psf->key.normals = psf->params[P_NORMALS] != 0.0;
  psf->key.glossy_normals = psf->params[P_GLOSSY_NORMALS] != 0.0;
  psf->key.frame = (uint32_t)frame_index;
  psf->state = 1;
  return HUSH_OK;
}

/* Vertices per chunk of keys computed before they go into the batch. */
#define CHUNK 256u

hush_status hush__psf_batch_open(hush_psf psf, hush_psf_batch *b) {
  if (!psf || !b) return HUSH_ERROR_INVALID_ARGUMENT;
  if (psf->state != 1) return HUSH_ERROR_INVALID_OPERATION;
  const hush_psf_probe probe = {(uint32_t)psf->params[P_PROBES]};
  hush__psf_batch_begin(b, &psf->table, &probe);
  return HUSH_OK;
}

hush_status hush__psf_batch_vertices(hush_psf psf, hush_psf_batch *b,
                                     const hush_psf_vertex *vertices, uint32_t count,
                                     uint32_t *tickets) {
  if (!psf || !b || (count && (!vertices || !tickets))) return HUSH_ERROR_INVALID_ARGUMENT;
  if (psf->state != 1) return HUSH_ERROR_INVALID_OPERATION;
  hush_psf_block block;
  hush_psf_planes planes;
  hush_psf_key keys[HUSH_PSF_KEY_BLOCK];
  int valid[HUSH_PSF_KEY_BLOCK];
  for (uint32_t at = 0; at < count; at += HUSH_PSF_KEY_BLOCK) {
    const uint32_t n = count - at < HUSH_PSF_KEY_BLOCK ? count - at : HUSH_PSF_KEY_BLOCK;
    hush__psf_block_fill(&block, vertices + at, n, &planes);
    hush__psf_keys_planar(&psf->key, &planes, 0, n, keys, valid);
    hush__psf_batch_add(b, keys, planes.radiance, valid, n, tickets + at);
  }
  return HUSH_OK;
}

hush_status hush__psf_batch_planes(hush_psf psf, hush_psf_batch *b, const hush_psf_planes *v,
                                   size_t first, uint32_t count, uint32_t *tickets) {
  if (!psf || !b || !v || (count && !tickets)) return HUSH_ERROR_INVALID_ARGUMENT;
  if (psf->state != 1) return HUSH_ERROR_INVALID_OPERATION;
  hush_psf_key keys[CHUNK];
  int valid[CHUNK];
  for (uint32_t at = 0; at < count; at += CHUNK) {
    const uint32_t n = count - at < CHUNK ? count - at : CHUNK;
    hush__psf_keys_planar(&psf->key, v, first + at, n, keys, valid);
    const float *const r[3] = {v->radiance[0] + first + at, v->radiance[1] + first + at,
                               v->radiance[2] + first + at};
    hush__psf_batch_add(b, keys, r, valid, n, tickets + at);
  }
  return HUSH_OK;
}

hush_status hush_psf_add_vertices(hush_psf psf, const hush_psf_vertex *vertices, uint32_t count,
                                  uint32_t *tickets) {
  hush_psf_batch *batch = malloc(sizeof *batch);
  if (!batch) return HUSH_ERROR_OUT_OF_MEMORY;
  hush_status st = hush__psf_batch_open(psf, batch);
  if (st == HUSH_OK) {
    st = hush__psf_batch_vertices(psf, batch, vertices, count, tickets);
    hush__psf_batch_end(batch);
  }
  free(batch);
  return st;
}

hush_status hush_psf_resolve(hush_psf psf) {
  if (!psf) return hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT, "psf is NULL");
  if (psf->state != 1)
    return hush__fail(psf->device, HUSH_ERROR_INVALID_OPERATION,
                      "psf: resolve without hush_psf_begin_frame");
  const double t0 = hush__now_ms();
  hush_psf_table *t = &psf->table;
  const uint32_t used = atomic_load(&t->used_count);
  hush_psf_resolve_params rp;
  rp.temporal = psf->params[P_TEMPORAL] != 0.0;
  rp.max_samples = (float)psf->params[P_MAX_SAMPLES];
  rp.max_age = (uint32_t)psf->params[P_MAX_AGE];
  rp.threads = hush_device_threads(psf->device);
  const uint64_t occupied = hush__psf_table_resolve(t, &rp);
  hush_psf_stats *s = &psf->stats;
  memset(s, 0, sizeof *s);
  s->vertices = atomic_load(&t->vertices);
  s->collisions = atomic_load(&t->collisions);
  s->failed = atomic_load(&t->failed);
  s->evictions = atomic_load(&t->evictions);
  s->cells_used = used;
  s->cells_occupied = occupied;
  s->table_size = t->slots;
  s->occupancy = (double)occupied / (double)t->slots;
  s->ms_resolve = hush__now_ms() - t0;
  psf->state = 2;
  return HUSH_OK;
}

/* How many vertices ahead hush_psf_lookup prefetches a cell (the cells are
 * scattered over the table): 8 -> 64 took its time from 2.75 to 1.85 ms
 * per 1280x720 frame (`hush bench --filters psf`, classroom, 2 threads;
 * 128: the same). */
#define LOOKUP_AHEAD 64u

hush_status hush_psf_lookup(hush_psf psf, const hush_psf_vertex *vertices, const uint32_t *tickets,
                            uint32_t count, float *rgb) {
  if (!psf || (count && (!vertices || !tickets || !rgb))) return HUSH_ERROR_INVALID_ARGUMENT;
  if (psf->state != 2) return HUSH_ERROR_INVALID_OPERATION;
  const hush_psf_cell *cells = psf->table.cells;
  const uint32_t slots = psf->table.slots;
  for (uint32_t j = 0; j < count; j++) {
    if (j + LOOKUP_AHEAD < count && tickets[j + LOOKUP_AHEAD] < slots)
      __builtin_prefetch(&cells[tickets[j + LOOKUP_AHEAD]]);
    const float *src = tickets[j] < slots ? cells[tickets[j]].mean : vertices[j].radiance;
    memcpy(rgb + 3 * j, src, 3 * sizeof(float));
  }
  return HUSH_OK;
}

const hush_psf_table *hush__psf_resolved_table(hush_psf psf) { return &psf->table; }

hush_status hush_psf_get_stats(hush_psf psf, hush_psf_stats *stats) {
  if (!psf || !stats) return hush__fail(psf ? psf->device : NULL, HUSH_ERROR_INVALID_ARGUMENT,
                                        "psf: NULL argument");
  *stats = psf->stats;
  return HUSH_OK;
}
