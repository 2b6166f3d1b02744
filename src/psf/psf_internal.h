/*
 * psf_internal.h — entry points of the hush_psf object (psf.c) for hush's
 * own path-tracer glue (psf_render.c): adding vertices through a batch the
 * caller keeps across many calls (psf_batch.h), so that the vertices of a
 * band of rows given as many short runs are grouped together (the public
 * hush_psf_add_vertices is one such batch per call), and reading the cell
 * averages directly while composing the image.
 * (hashed-path-space-filtering-binder-2019.md §3.1.)
 */
#ifndef HUSH_PSF_INTERNAL_H
#define HUSH_PSF_INTERNAL_H

#include "hush.h"
#include "psf/psf_batch.h"

/* Starts a batch on psf's table (between begin_frame and resolve). */
hush_status hush__psf_batch_open(hush_psf psf, hush_psf_batch *b);

/* hush_psf_add_vertices through batch b: the tickets are final only after
 * hush__psf_batch_end(b). Thread-safe for different batches. */
hush_status hush__psf_batch_vertices(hush_psf psf, hush_psf_batch *b,
                                     const hush_psf_vertex *vertices, uint32_t count,
                                     uint32_t *tickets);

/* The same for vertices first .. first + count - 1 of planes v (the
 * caller's arrays), without copying them to planes first. */
hush_status hush__psf_batch_planes(hush_psf psf, hush_psf_batch *b, const hush_psf_planes *v,
                                   size_t first, uint32_t count, uint32_t *tickets);

/* The table after hush_psf_resolve, for composing in the same pass as the
 * look-up: a vertex with ticket k < slots has the average cells[k].mean,
 * any other keeps its own radiance (what hush_psf_lookup returns). */
const hush_psf_table *hush__psf_resolved_table(hush_psf psf);

#endif
