/*
 * psf_render.h — hashed path-space filtering inside hush's path tracer
 * (hashed-path-space-filtering-binder-2019.md §3, Figures 2 and 10): the
 * glue between the renderer's path hooks (render/integrator.h) and the
 * public hush_psf object.
 *
 * While a frame renders, the hooks record for every camera sample its
 * selected vertex: the first (or, with vertex = 2, the second) sufficiently
 * diffuse one, i.e. diffuse or plastic, or a rough conductor (then flagged
 * glossy); smooth conductors, glass and emitters are passed through, as the
 * paper's "first sufficiently diffuse vertex". With it go
 *   prefix      radiance the path gathered before the vertex (unfiltered),
 *   throughput  camera to vertex times the vertex's albedo,
 *   radiance    (path total - prefix) / throughput: what the vertex's cell
 *               averages (demodulated, so texture is not blurred).
 * After the frame, hush__psf_renderer_finish adds the vertices to the table
 * (row bands over the device's threads, concurrently), resolves it, and
 * writes the layer "psf": per pixel, the mean over its samples of
 * prefix + throughput * (cell average), or the unfiltered path radiance for
 * samples without a selected vertex (sky, or only specular hits).
 *
 * Ownership: the renderer owns its hush_psf and its per-sample buffers.
 */
#ifndef HUSH_PSF_RENDER_H
#define HUSH_PSF_RENDER_H

#include "hush.h"
#include "render/render.h"

typedef struct hush_psf_renderer hush_psf_renderer;

/* Stage times of the last finish, milliseconds. */
typedef struct hush_psf_timings {
  double add;              /* keys + atomic accumulation */
  double resolve;          /* averages, temporal blend, ageing */
  double lookup;           /* per-sample cell average + compose the layer */
  double cpu;              /* CPU time of the three, all threads (process CPU time) */
} hush_psf_timings;

/* A renderer for frames of width x height at spp samples per pixel,
 * filtering at vertex 1 or 2. *out is owned by the caller. */
hush_status hush__psf_renderer_new(hush_device device, uint32_t width, uint32_t height,
                                   uint32_t spp, int vertex, hush_psf_renderer **out);
void hush__psf_renderer_free(hush_psf_renderer *r);

/* The filter object, for its parameters and statistics (owned by r). */
hush_psf hush__psf_renderer_psf(hush_psf_renderer *r);

/* Sets a parameter: "vertex" (1 or 2) here, anything else on the hush_psf. */
hush_status hush__psf_renderer_set(hush_psf_renderer *r, const char *name, const char *value);

/* Installs the path hooks in params (before hush__render_ctx_init). */
void hush__psf_renderer_hook(hush_psf_renderer *r, hush_render_params *params);

/* Starts a frame rendered with ctx (whose params came through _hook). */
hush_status hush__psf_renderer_begin(hush_psf_renderer *r, const hush_render_ctx *ctx,
                                     hush_history_mode history);

/* Starts the same frame again (for benchmarks: the next finish filters the
 * same vertices once more, and blends them into the history once more). */
hush_status hush__psf_renderer_repeat(hush_psf_renderer *r);

/* Filters the frame just rendered and writes the "psf" layer of frame. */
hush_status hush__psf_renderer_finish(hush_psf_renderer *r, hush_frame frame,
                                      hush_psf_timings *timings);

/* The selected vertices of the frame just rendered, in sample order, as the
 * records a path tracer gives hush_psf_add_vertices (for `hush bench`, which
 * replays them through the public API). *out is allocated here and owned by
 * the caller (free); *count may be 0. *pixel_angle receives the frame's. */
hush_status hush__psf_renderer_vertices(const hush_psf_renderer *r, hush_psf_vertex **out,
                                        uint32_t *count, float *pixel_angle);

#endif
