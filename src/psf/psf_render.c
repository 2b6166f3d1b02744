/*
 * psf_render.c — hashed path-space filtering in hush's path tracer: path
 * hooks that record each camera sample's selected vertex, then the
 * add / resolve / lookup passes of the hush_psf object (see psf_render.h;
 * hashed-path-space-filtering-binder-2019.md §3).
 */
#include "psf/psf_render.h"

#include "psf/psf_internal.h"

#include "core/device.h"
#include "core/timer.h"
#include "render/bsdf.h"

#include <math.h>
#include <omp.h>
#include <stdlib.h>
#include <string.h>

/* What the hooks keep for one camera sample, written only by the thread
 * tracing it, in three arrays: the state of the path being traced, what
 * composing the layer reads for a sample with a vertex (so that pass
 * streams 24 bytes per sample), and the path's unfiltered radiance (read
 * only for samples without a vertex, or when the filtered value is not
 * finite). */
typedef struct sample_trace {
  float last[3];           /* the previous vertex (the eye at first) */
  float distance;          /* path length to last */
  uint32_t epoch;          /* frame counter of the last write; stale otherwise */
  uint8_t seen;            /* sufficiently diffuse vertices so far */
  uint8_t selected;        /* the planes hold this sample's vertex */
} sample_trace;

typedef struct sample_result {
  float prefix[3];
  float throughput[3];
} sample_result;

/* The selected vertices, one plane (array over the samples) per component,
 * so that the key loop reads them with vector loads (psf_hash.h). */
enum { POSITION = 0, NORMAL = 3, ORIGIN = 6, DISTANCE = 9, RADIANCE = 10, PLANES = 13 };

/* has[] values, per sample. */
enum { NOT_TRACED = 0, NO_VERTEX = 1, WITH_VERTEX = 2 };

struct hush_psf_renderer {
  hush_device device;
  hush_psf psf;
  int vertex;              /* 1 or 2 */
  uint32_t width, height, spp;
  size_t samples;          /* width * height * spp */
  sample_trace *traces;
  sample_result *results;
  float *total;            /* 3 per sample: the path's unfiltered radiance */
  float *plane;            /* PLANES planes of `samples` floats */
  uint32_t *seed, *flags;  /* per sample, of the selected vertex */
  hush_psf_planes planes;  /* pointing at them */
  uint32_t *tickets;
  hush_psf_batch *batches; /* one per thread of the add pass, batch_threads of them */
  int batch_threads;
  uint8_t *has;            /* per sample: NOT_TRACED, NO_VERTEX, WITH_VERTEX (set at path end) */
  const hush_scene *scene; /* of the frame being rendered */
  float eye[3];
  uint32_t epoch;          /* 1 + frames begun */
  uint64_t frame;          /* of the last begin */
  float pixel_angle;
};

/* Albedo floor of the demodulation: dark channels would amplify noise. */
#define MIN_ALBEDO 0.02f
/* Conductors at least this rough count as sufficiently diffuse (glossy). */
#define GLOSSY_MIN_ROUGHNESS 0.1f

hush_status hush__psf_renderer_new(hush_device device, uint32_t width, uint32_t height,
                                   uint32_t spp, int vertex, hush_psf_renderer **out) {
  *out = NULL;
  if (vertex != 1 && vertex != 2)
    return hush__fail(device, HUSH_ERROR_OUT_OF_RANGE, "psf: vertex %d is not 1 or 2", vertex);
  if (spp == 0) spp = 1;
  hush_psf_renderer *r = calloc(1, sizeof *r);
  if (!r) return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "psf: out of memory");
  r->device = device;
  r->vertex = vertex;
  r->width = width;
  r->height = height;
  r->spp = spp;
  r->samples = (size_t)width * height * spp;
  r->psf = hush_psf_new(device, width, height);
  r->traces = calloc(r->samples, sizeof *r->traces);
  r->results = calloc(r->samples, sizeof *r->results);
  r->total = calloc(r->samples * 3, sizeof *r->total);
  r->plane = calloc(r->samples * PLANES, sizeof *r->plane);
  r->seed = calloc(r->samples, sizeof *r->seed);
  r->flags = calloc(r->samples, sizeof *r->flags);
  r->tickets = calloc(r->samples, sizeof *r->tickets);
  r->has = calloc(r->samples, 1);
  if (!r->psf || !r->traces || !r->results || !r->total || !r->plane || !r->seed || !r->flags ||
      !r->tickets || !r->has) {
    const int had_psf = r->psf != NULL;
    hush__psf_renderer_free(r);
    return had_psf ? hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "psf: out of memory")
                   : HUSH_ERROR_OUT_OF_MEMORY;
  }
  for (int c = 0; c < 3; c++) {
    r->planes.position[c] = r->plane + (POSITION + c) * r->samples;
    r->planes.normal[c] = r->plane + (NORMAL + c) * r->samples;
    r->planes.origin[c] = r->plane + (ORIGIN + c) * r->samples;
    r->planes.radiance[c] = r->plane + (RADIANCE + c) * r->samples;
  }
  r->planes.distance = r->plane + DISTANCE * r->samples;
  r->planes.seed = r->seed;
  r->planes.flags = r->flags;
  *out = r;
  return HUSH_OK;
}

void hush__psf_renderer_free(hush_psf_renderer *r) {
  if (!r) return;
  hush_psf_release(r->psf);
  free(r->traces);
  free(r->results);
  free(r->total);
  free(r->plane);
  free(r->seed);
  free(r->flags);
  free(r->tickets);
  free(r->batches);
  free(r->has);
  free(r);
}

hush_psf hush__psf_renderer_psf(hush_psf_renderer *r) { return r->psf; }

hush_status hush__psf_renderer_set(hush_psf_renderer *r, const char *name, const char *value) {
  if (name && strcmp(name, "vertex") == 0) {
    if (value && (strcmp(value, "1") == 0 || strcmp(value, "2") == 0)) {
      r->vertex = value[0] - '0';
      return HUSH_OK;
    }
    return hush__fail(r->device, HUSH_ERROR_OUT_OF_RANGE, "psf.vertex: '%s' is not 1 or 2",
                      value ? value : "(null)");
  }
  return hush_psf_set_string(r->psf, name, value);
}

/* ---- hooks (worker threads) ------------------------------------------------------ */

static size_t sample_index(const hush_psf_renderer *r, uint32_t x, uint32_t y, uint32_t s) {
  return ((size_t)y * r->width + x) * r->spp + s;
}

static void reset(const hush_psf_renderer *r, sample_trace *tr, sample_result *res) {
  memset(tr, 0, sizeof *tr);
  memset(res, 0, sizeof *res);
  memcpy(tr->last, r->eye, sizeof tr->last);
  tr->epoch = r->epoch;
}

/* 0: passed through (smooth specular, glass, emitters), 1: diffuse,
 * 2: glossy (a rough conductor). */
static int vertex_kind(const hush_material *m) {
  if (m->emission[0] > 0.0f || m->emission[1] > 0.0f || m->emission[2] > 0.0f) return 0;
  switch (m->type) {
  case HUSH_MAT_DIFFUSE:
  case HUSH_MAT_PLASTIC: return 1;
  case HUSH_MAT_CONDUCTOR: return m->roughness >= GLOSSY_MIN_ROUGHNESS ? 2 : 0;
  default: return 0;
  }
}

static float *plane_of(const hush_psf_renderer *r, int component) {
  return r->plane + (size_t)component * r->samples;
}

static void select_vertex(hush_psf_renderer *r, size_t idx, sample_trace *tr,
                          sample_result *res, const hush_path_vertex *v, const hush_material *m,
                          int kind) {
  const float p[3] = {v->p.x, v->p.y, v->p.z}, n[3] = {v->n.x, v->n.y, v->n.z};
  for (int c = 0; c < 3; c++) {
    plane_of(r, POSITION + c)[idx] = p[c];
    plane_of(r, NORMAL + c)[idx] = n[c];
    plane_of(r, ORIGIN + c)[idx] = tr->last[c];
  }
  plane_of(r, DISTANCE)[idx] = tr->distance;
  r->seed[idx] = (uint32_t)idx;
  r->flags[idx] = kind == 2 ? HUSH_PSF_GLOSSY : 0u;
  float albedo[3];
  hush__bsdf_albedo(m, v->surface, albedo);
  for (int c = 0; c < 3; c++)
    res->throughput[c] = v->throughput[c] * fmaxf(albedo[c], MIN_ALBEDO);
  tr->selected = 1;
}

static void on_vertex(void *user, const hush_path_vertex *v) {
  hush_psf_renderer *r = user;
  const size_t idx = sample_index(r, v->x, v->y, v->sample);
  sample_trace *tr = &r->traces[idx];
  sample_result *res = &r->results[idx];
  if (v->depth == 0) reset(r, tr, res);
  if (tr->selected) return;
  const hush_material *m = &r->scene->materials[v->material];
  const int kind = vertex_kind(m);
  if (kind && ++tr->seen == r->vertex) {
    select_vertex(r, idx, tr, res, v, m, kind);
    return;
  }
  for (int c = 0; c < 3; c++) res->prefix[c] += v->contribution[c];
  const float p[3] = {v->p.x, v->p.y, v->p.z};
  const float dx = p[0] - tr->last[0], dy = p[1] - tr->last[1], dz = p[2] - tr->last[2];
  tr->distance += sqrtf(dx * dx + dy * dy + dz * dz);
  memcpy(tr->last, p, sizeof p);
}

static void on_path_end(void *user, uint32_t x, uint32_t y, uint32_t sample,
                        const float radiance[3]) {
  hush_psf_renderer *r = user;
  const size_t idx = sample_index(r, x, y, sample);
  sample_trace *tr = &r->traces[idx];
  sample_result *res = &r->results[idx];
  if (tr->epoch != r->epoch) reset(r, tr, res); /* no surface: the sky or a light */
  memcpy(r->total + 3 * idx, radiance, 3 * sizeof *radiance);
  r->has[idx] = tr->selected ? WITH_VERTEX : NO_VERTEX;
  if (!tr->selected) return;
  for (int c = 0; c < 3; c++) {
    const float t = res->throughput[c];
    plane_of(r, RADIANCE + c)[idx] = t > 1e-20f ? (radiance[c] - res->prefix[c]) / t : 0.0f;
  }
}

void hush__psf_renderer_hook(hush_psf_renderer *r, hush_render_params *params) {
  params->vertex_fn = on_vertex;
  params->path_end_fn = on_path_end;
  params->vertex_user = r;
}

hush_status hush__psf_renderer_begin(hush_psf_renderer *r, const hush_render_ctx *ctx,
                                     hush_history_mode history) {
  const hush_render_params *p = &ctx->params;
  if (p->width != r->width || p->height != r->height || p->spp != r->spp ||
      p->vertex_user != r)
    return hush__fail(r->device, HUSH_ERROR_INVALID_ARGUMENT,
                      "psf: the frame (%ux%u, %u spp) is not the renderer's (%ux%u, %u spp) or "
                      "its hooks are not installed",
                      p->width, p->height, p->spp, r->width, r->height, r->spp);
  r->scene = ctx->scene;
  r->eye[0] = ctx->cam.eye.x;
  r->eye[1] = ctx->cam.eye.y;
  r->eye[2] = ctx->cam.eye.z;
  r->epoch++;
  memset(r->has, 0, r->samples);
  r->frame = ctx->frame;
  r->pixel_angle = 2.0f * ctx->cam.tan_half_y / (float)r->height;
  return hush_psf_begin_frame(r->psf, r->frame, r->pixel_angle, history);
}

hush_status hush__psf_renderer_repeat(hush_psf_renderer *r) {
  return hush_psf_begin_frame(r->psf, r->frame, r->pixel_angle, HUSH_HISTORY_CONTINUE);
}

/* ---- after the frame ---------------------------------------------------------------- */

/* has[] is cleared at begin and set at each path's end, so it is
 * NOT_TRACED for the holes of a progressive frame. */
static int has_vertex(const hush_psf_renderer *r, size_t i) { return r->has[i] == WITH_VERTEX; }

/* The next run of consecutive samples with a vertex in [*i, end): returns
 * its first sample, its length in *n (0: none left), and moves *i past it.
 * The runs go to the table in place, without a copy. */
static size_t next_run(const hush_psf_renderer *r, size_t *i, size_t end, uint32_t *n) {
  size_t k = *i;
  while (k < end && !has_vertex(r, k)) k++;
  const size_t start = k;
  while (k < end && has_vertex(r, k)) k++;
  *n = (uint32_t)(k - start);
  *i = k;
  return start;
}

/* Adds the selected vertices of rows [y0, y1) through one batch, so that
 * the cells they share are visited once (psf_batch.h). */
static void add_rows(hush_psf_renderer *r, hush_psf_batch *batch, uint32_t y0, uint32_t y1) {
  if (hush__psf_batch_open(r->psf, batch) != HUSH_OK) return;
  const size_t row = (size_t)r->width * r->spp;
  for (size_t i = y0 * row; i < y1 * row;) {
    uint32_t n;
    const size_t start = next_run(r, &i, y1 * row, &n);
    if (n) hush__psf_batch_planes(r->psf, batch, &r->planes, start, n, r->tickets + start);
  }
  hush__psf_batch_end(batch);
}

/* How many samples ahead compose prefetches the cell of a ticket: the
 * cells of a band are scattered over the table. */
#define LOOKUP_AHEAD 64u

/* The "psf" layer of rows [y0, y1): per sample its cell's average (what
 * hush_psf_lookup returns, read here in the same pass) times the
 * throughput plus the prefix. */
static void compose_rows(hush_psf_renderer *r, const hush_psf_table *t, uint32_t y0, uint32_t y1,
                         float *out) {
  const size_t end = (size_t)y1 * r->width * r->spp;
  for (uint32_t y = y0; y < y1; y++)
    for (uint32_t x = 0; x < r->width; x++) {
      float sum[3] = {0.0f, 0.0f, 0.0f};
      for (uint32_t s = 0; s < r->spp; s++) {
        const size_t i = sample_index(r, x, y, s);
        if (i + LOOKUP_AHEAD < end && has_vertex(r, i + LOOKUP_AHEAD) &&
            r->tickets[i + LOOKUP_AHEAD] < t->slots)
          __builtin_prefetch(&t->cells[r->tickets[i + LOOKUP_AHEAD]]);
        const sample_result *rec = &r->results[i];
        if (r->has[i] == NOT_TRACED) continue; /* a hole of a progressive frame */
        if (r->has[i] == NO_VERTEX) {
          for (int c = 0; c < 3; c++) sum[c] += r->total[3 * i + c];
          continue;
        }
        const uint32_t tk = r->tickets[i];
        float own[3];
        const float *f = own;
        if (tk < t->slots) /* else no cell: the vertex keeps its own radiance (rare) */
          f = t->cells[tk].mean;
        else
          for (int c = 0; c < 3; c++) own[c] = r->planes.radiance[c][i];
        float v[3];
        for (int c = 0; c < 3; c++) v[c] = rec->prefix[c] + rec->throughput[c] * f[c];
        if (!(isfinite(v[0]) && isfinite(v[1]) && isfinite(v[2]))) /* rare: then total is read */
          for (int c = 0; c < 3; c++) v[c] = isfinite(v[c]) ? v[c] : r->total[3 * i + c];
        for (int c = 0; c < 3; c++) sum[c] += v[c];
      }
      float *o = out + 3 * ((size_t)y * r->width + x);
      for (int c = 0; c < 3; c++) o[c] = sum[c] / (float)r->spp;
    }
}

/* Rows per band of the add pass: a batch of 8 rows of 1280 pixels holds
 * about 3000 cells, so most cells are visited once or twice (a cell is cut
 * where a band or a full batch ends). */
#define ADD_BAND 8u
/* Rows per band of the lookup pass. */
#define BAND 4u

hush_status hush__psf_renderer_finish(hush_psf_renderer *r, hush_frame frame,
                                      hush_psf_timings *timings) {
  hush_image_view view;
  hush_status st = hush_frame_add_layer(frame, "psf", 3, &view);
  if (st != HUSH_OK) return st;
  const int threads = hush_device_threads(r->device);
  if (threads > r->batch_threads) {
    free(r->batches);
    r->batch_threads = 0;
    r->batches = malloc((size_t)threads * sizeof *r->batches);
    if (!r->batches) return hush__fail(r->device, HUSH_ERROR_OUT_OF_MEMORY, "psf: out of memory");
    r->batch_threads = threads;
  }
  const int64_t add_bands = (r->height + ADD_BAND - 1) / ADD_BAND;
  const int64_t bands = (r->height + BAND - 1) / BAND;
  const double t0 = hush__now_ms(), cpu0 = hush__cpu_seconds();
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads)
  for (int64_t b = 0; b < add_bands; b++) {
    const uint32_t y0 = (uint32_t)b * ADD_BAND;
    add_rows(r, &r->batches[omp_get_thread_num()], y0,
             y0 + ADD_BAND < r->height ? y0 + ADD_BAND : r->height);
  }
  const double t1 = hush__now_ms();
  st = hush_psf_resolve(r->psf);
  if (st != HUSH_OK) return st;
  const double t2 = hush__now_ms();
  float *out = view.data;
  const hush_psf_table *table = hush__psf_resolved_table(r->psf);
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads)
  for (int64_t b = 0; b < bands; b++) {
    const uint32_t y0 = (uint32_t)b * BAND;
    compose_rows(r, table, y0, y0 + BAND < r->height ? y0 + BAND : r->height, out);
  }
  const double t3 = hush__now_ms();
  if (timings) {
    timings->cpu = (hush__cpu_seconds() - cpu0) * 1e3;
    timings->add = t1 - t0;
    timings->resolve = t2 - t1;
    timings->lookup = t3 - t2;
  }
  return HUSH_OK;
}

hush_status hush__psf_renderer_vertices(const hush_psf_renderer *r, hush_psf_vertex **out,
                                        uint32_t *count, float *pixel_angle) {
  *out = NULL;
  *count = 0;
  *pixel_angle = r->pixel_angle;
  size_t n = 0;
  for (size_t i = 0; i < r->samples; i++) n += has_vertex(r, i);
  if (n > UINT32_MAX)
    return hush__fail(r->device, HUSH_ERROR_OUT_OF_RANGE, "psf: more than 2^32 vertices");
  hush_psf_vertex *v = malloc((n ? n : 1) * sizeof *v);
  if (!v) return hush__fail(r->device, HUSH_ERROR_OUT_OF_MEMORY, "psf: out of memory");
  size_t k = 0;
  for (size_t i = 0; i < r->samples; i++) {
    if (!has_vertex(r, i)) continue;
    hush_psf_vertex *o = &v[k++];
    for (int c = 0; c < 3; c++) {
      o->position[c] = r->planes.position[c][i];
      o->normal[c] = r->planes.normal[c][i];
      o->origin[c] = r->planes.origin[c][i];
      o->radiance[c] = r->planes.radiance[c][i];
    }
    o->distance = r->planes.distance[i];
    o->seed = r->seed[i];
    o->flags = r->flags[i];
  }
  *out = v;
  *count = (uint32_t)n;
  return HUSH_OK;
}
