/*
 * fuzz_psf.c — libFuzzer target for the path-space filter's API (hush.h,
 * hush_psf_*; Binder et al. 2019): a table for a small frame, parameters,
 * frames of vertices in clusters (so cells fill up, collide and are
 * evicted), corrupted vertices (NaN, Inf, huge, zero normals, negative
 * distances), tickets out of range and calls out of order, all chosen by
 * the input bytes. The vertices are added in several calls on one thread,
 * so the cell sums are the same in every run.
 *
 * What must hold (else abort()): calls that fail say so by their status;
 * every lookup of a vertex with finite radiance (up to 1e15) is finite; the
 * statistics add up (failed <= vertices, occupancy in [0, 1]); and a run with
 * 1 thread and one with 3 give the same lookups bit for bit. Crashes, leaks
 * and undefined behaviour are the sanitizers'.
 */
#include "hush.h"
#include "fuzz_common.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define MAX_VERTICES 2048
#define MAX_FRAMES 4

typedef struct plan {
  uint32_t width, height, frames, vertices, clusters, calls;
  uint32_t seed;
  unsigned reset_mask;
  float pixel_angle;
  int corrupt;        /* 0: none; else which field goes bad in a few vertices */
  int bad_tickets;    /* lookups with tickets past the table */
  int out_of_order;   /* 1: add before begin_frame; 2: lookup before resolve */
  int sets;
  struct {
    int param, how;
  } set[6];
} plan;

static void decode(fuzz_bytes *b, plan *p) {
  memset(p, 0, sizeof *p);
  p->width = 1 + fuzz_u8(b) % 64;
  p->height = 1 + fuzz_u8(b) % 48;
  p->frames = 1 + fuzz_u8(b) % MAX_FRAMES;
  const unsigned hi = fuzz_u8(b), lo = fuzz_u8(b);
  p->vertices = (hi << 3 | lo >> 5) % (MAX_VERTICES + 1);
  p->clusters = 1 + fuzz_u8(b) % 16;
  p->calls = 1 + fuzz_u8(b) % 4;
  p->seed = fuzz_u8(b);
  p->reset_mask = fuzz_u8(b) & 0x0e;
  static const float angles[] = {1e-3f, 0.01f, 1e-6f, 1.0f, 0.0f, -0.01f, NAN, INFINITY};
  p->pixel_angle = angles[fuzz_u8(b) % 8];
  const unsigned c = fuzz_u8(b);
  p->corrupt = c >= 160 ? (int)(1 + c % 7) : 0;
  p->bad_tickets = fuzz_u8(b) >= 224;
  const unsigned o = fuzz_u8(b);
  p->out_of_order = o >= 240 ? (int)(1 + o % 2) : 0;
  uint32_t count = 0;
  hush_psf_params(&count);
  p->sets = (int)(fuzz_u8(b) % 7);
  for (int i = 0; i < p->sets; i++) {
    p->set[i].param = count ? (int)(fuzz_u8(b) % count) : 0;
    p->set[i].how = (int)fuzz_u8(b);
  }
}

static void make_vertex(const plan *p, uint32_t frame, uint32_t i, hush_psf_vertex *v) {
  const uint32_t k = i % p->clusters;
  const float r = fuzz_hash01(p->seed, i * 17 + frame * 131071u);
  const float cx = 4.0f * fuzz_hash01(p->seed, k * 3), cy = 4.0f * fuzz_hash01(p->seed, k * 3 + 1),
              cz = -2.0f - 4.0f * fuzz_hash01(p->seed, k * 3 + 2);
  v->position[0] = cx + 0.05f * (r - 0.5f);
  v->position[1] = cy + 0.05f * (fuzz_hash01(p->seed ^ 1u, i) - 0.5f);
  v->position[2] = cz;
  v->normal[0] = 0.0f;
  v->normal[1] = (k & 1) ? 1.0f : 0.0f;
  v->normal[2] = (k & 1) ? 0.0f : 1.0f;
  v->origin[0] = v->origin[1] = v->origin[2] = 0.0f;
  v->distance = (k & 2) ? 0.0f : 1.5f;
  for (int c = 0; c < 3; c++) v->radiance[c] = 2.0f * fuzz_hash01(p->seed + (uint32_t)c, i + frame * 7919u);
  v->seed = i * 2654435761u + frame;
  v->flags = (k & 4) ? HUSH_PSF_GLOSSY : 0u;
  if (p->corrupt && fuzz_hash01(p->seed ^ 0xabcdu, i) < 0.1f) {
    switch (p->corrupt) {
    case 1: v->position[i % 3] = NAN; break;
    case 2: v->position[i % 3] = (i & 1) ? INFINITY : -3e38f; break;
    case 3: v->normal[0] = v->normal[1] = v->normal[2] = 0.0f; break;
    case 4: v->distance = (i & 1) ? -1.0f : NAN; break;
    case 5: /* large, finite: accepted (and must stay finite), or beyond 1e15: refused */
      v->radiance[i % 3] = (i & 2) ? 3e37f : 1e15f;
      break;
    case 6: v->origin[0] = v->position[0]; /* the vertex seen from itself */
            v->origin[1] = v->position[1];
            v->origin[2] = v->position[2];
            break;
    default: v->flags = 0xffffffffu; break;
    }
  }
}

static int radiance_ok(const hush_psf_vertex *v) {
  for (int c = 0; c < 3; c++)
    if (!(fabsf(v->radiance[c]) <= 1e15f)) return 0;
  return 1;
}

static hush_status apply_set(hush_psf f, const hush_param_info *pi, int how) {
  const double lo = pi->min_value, hi = pi->max_value;
  double v;
  switch (how % 6) {
  case 0: v = lo; break;
  case 1: v = hi; break;
  case 2: v = pi->default_value; break;
  case 3: v = lo + (hi - lo) * (how / 6) / 42.0; break;
  case 4: return hush_psf_set_float(f, pi->name, NAN);
  default: return hush_psf_set_string(f, pi->name, how & 8 ? "1e40" : "no-such-value");
  }
  if (pi->type == HUSH_PARAM_FLOAT) return hush_psf_set_float(f, pi->name, (float)v);
  return hush_psf_set_int(f, pi->name, (int)(v > 2e9 ? 2e9 : v < -2e9 ? -2e9 : v));
}

typedef struct record {
  float *rgb;
  size_t count, cap;
} record;

static void run(const plan *p, int threads, record *rec) {
  char config[32];
  snprintf(config, sizeof config, "threads=%d", threads);
  hush_device dev = hush_device_new(config);
  if (!dev) abort();
  hush_psf f = hush_psf_new(dev, p->width, p->height);
  if (!f) abort();
  uint32_t nparams = 0;
  const hush_param_info *params = hush_psf_params(&nparams);
  for (int i = 0; i < p->sets && nparams; i++) {
    const hush_status s = apply_set(f, &params[p->set[i].param], p->set[i].how);
    const char *msg = NULL;
    if (s != HUSH_OK && (hush_device_get_error(dev, &msg) == HUSH_OK || !msg || !msg[0])) abort();
  }
  static hush_psf_vertex v[MAX_VERTICES];
  static uint32_t tickets[MAX_VERTICES];
  static float rgb[MAX_VERTICES * 3];
  const uint32_t n = p->vertices;
  if (p->out_of_order == 1 && n && hush_psf_add_vertices(f, v, n, tickets) == HUSH_OK) abort();
  for (uint32_t k = 0; k < p->frames; k++) {
    for (uint32_t i = 0; i < n; i++) make_vertex(p, k, i, &v[i]);
    const hush_history_mode h = (p->reset_mask >> k) & 1 ? HUSH_HISTORY_RESET : HUSH_HISTORY_CONTINUE;
    if (hush_psf_begin_frame(f, k, p->pixel_angle, h) != HUSH_OK) {
      const char *msg = NULL;
      if (hush_device_get_error(dev, &msg) == HUSH_OK || !msg || !msg[0]) abort();
      break; /* a pixel angle it refuses: every frame would be refused */
    }
    for (uint32_t c = 0, at = 0; c < p->calls; c++) {
      const uint32_t part = c + 1 == p->calls ? n - at : n / p->calls;
      if (hush_psf_add_vertices(f, v + at, part, tickets + at) != HUSH_OK) abort();
      at += part;
    }
    if (p->out_of_order == 2 && n && hush_psf_lookup(f, v, tickets, n, rgb) == HUSH_OK) {
      /* before resolve a lookup may answer, but never with garbage */
      for (uint32_t i = 0; i < n * 3; i++)
        if (radiance_ok(&v[i / 3]) && !isfinite(rgb[i])) abort();
    }
    if (hush_psf_resolve(f) != HUSH_OK) abort();
    hush_psf_stats st;
    if (hush_psf_get_stats(f, &st) != HUSH_OK) abort();
    if (st.failed > st.vertices || st.vertices != n || !(st.occupancy >= 0.0 && st.occupancy <= 1.0) ||
        st.cells_occupied > st.table_size) {
      fprintf(stderr, "fuzz_psf: stats do not add up: %llu vertices, %llu failed, occupancy %g\n",
              (unsigned long long)st.vertices, (unsigned long long)st.failed, st.occupancy);
      abort();
    }
    if (p->bad_tickets && n) tickets[n / 2] = 0xfffffff0u; /* past the table, not NO_CELL */
    if (hush_psf_lookup(f, v, tickets, n, rgb) != HUSH_OK) abort();
    for (uint32_t i = 0; i < n; i++) {
      if (!radiance_ok(&v[i])) continue;
      for (int c = 0; c < 3; c++)
        if (!isfinite(rgb[3 * i + c])) {
          fprintf(stderr, "fuzz_psf: vertex %u of frame %u: lookup %g from finite radiance\n", i, k,
                  (double)rgb[3 * i + c]);
          abort();
        }
    }
    if (!n) continue;
    if (rec->count + n * 3 > rec->cap) {
      rec->cap = (rec->count + n * 3) * 2 + 64;
      rec->rgb = realloc(rec->rgb, rec->cap * sizeof *rec->rgb);
      if (!rec->rgb) abort();
    }
    memcpy(rec->rgb + rec->count, rgb, n * 3 * sizeof *rgb);
    rec->count += n * 3;
  }
  hush_psf_release(f);
  hush_device_release(dev);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  fuzz_bytes b = {data, size};
  plan p;
  decode(&b, &p);
  record r1 = {0}, r3 = {0};
  run(&p, 1, &r1);
  run(&p, 3, &r3);
  if (r1.count != r3.count || (r1.count && memcmp(r1.rgb, r3.rgb, r1.count * sizeof *r1.rgb))) {
    fprintf(stderr, "fuzz_psf: lookups differ between 1 and 3 threads\n");
    abort();
  }
  free(r1.rgb);
  free(r3.rgb);
  return 0;
}
