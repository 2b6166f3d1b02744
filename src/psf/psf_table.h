/*
 * psf_table.h — the hash table of hashed path-space filtering
 * (hashed-path-space-filtering-binder-2019.md §3.1, §3.3, §3.4).
 *
 * Slots come in cache lines of 16: the primary hash picks a line and a first
 * slot, and linear probing stays inside the line (at most `probes` slots),
 * so resolving a collision costs no extra memory access. A slot's key holds
 * the verification hash in its low 26 bits and an age in its top 6 bits (the
 * priority of §3.4): 0 while the current frame uses the cell, 1 + the frames
 * since the last use after each resolve. A vertex
 *   1. takes the slot whose verification bits match (refreshing its age to 0
 *      with a compare-and-swap, which is the paper's atomicMin: a key of age
 *      0 is smaller than the same key with any other age);
 *   2. else claims an empty slot (compare-and-swap from 0);
 *   3. else evicts the oldest cell not used this frame (compare-and-swap);
 *   4. else gets no cell: the path keeps its own unfiltered radiance.
 * A cell of age 0 is never evicted, so two vertices with different
 * verification hashes never share a slot within a frame.
 *
 * Contributions are summed with C11 atomics (a compare-and-swap loop on each
 * of two 64-bit words: red and green sums, blue sum and count), after each
 * thread has grouped its vertices by key (psf_batch.h). At resolve every cell used this frame
 * averages them and blends the average with its history (§3.3):
 *   mean = mean_old + n_new / (min(n_old, max_samples) + n_new) (avg - mean_old)
 * i.e. a running mean until max_samples vertices, then an exponential average
 * whose weight on new vertices never drops below n_new / (max_samples + n_new).
 * Then every occupied key ages by one frame and keys older than max_age are
 * freed (their history is zeroed when the slot is claimed again).
 *
 * Ownership: the table owns its arrays (hush__psf_table_free).
 */
#ifndef HUSH_PSF_TABLE_H
#define HUSH_PSF_TABLE_H

#include "hush.h"
#include "psf/psf_hash.h"

#include <stdatomic.h>
#include <stdint.h>

#define HUSH_PSF_LINE 16u

/* A slot's data, 32 bytes (two per cache line): what the vertices of this
 * frame add (two 64-bit words, so that one group of vertices (psf_batch.h)
 * costs two compare-and-swaps rather than four atomics), and the cell's filtered
 * radiance with the vertex count behind it. Together so that resolve and
 * lookup touch one line per cell. */
typedef struct hush_psf_cell {
  _Atomic uint64_t rg;     /* float bits: red sum (low 32 bits), green sum (high) */
  _Atomic uint64_t bn;     /* float bits of the blue sum (low), vertex count (high) */
  float mean[3];
  float samples;
} hush_psf_cell;

typedef struct hush_psf_table {
  uint32_t lines;
  uint32_t slots;          /* lines * HUSH_PSF_LINE */
  _Atomic uint32_t *keys;  /* slots, 64-byte aligned; 0 = empty */
  hush_psf_cell *cells;    /* slots, 64-byte aligned */
  uint32_t *used;          /* slots used this frame, used_count of them */
  _Atomic uint32_t used_count;
  _Atomic uint64_t vertices, collisions, failed, evictions;
} hush_psf_table;

/* Per-call settings of the probing. */
typedef struct hush_psf_probe {
  uint32_t probes;         /* slots tried in the line, 1 .. 16 */
} hush_psf_probe;

/* Allocates a table of at least min_slots slots (whole lines), empty.
 * Returns 0 when out of memory (t is then freed). */
int hush__psf_table_init(hush_psf_table *t, uint64_t min_slots);
void hush__psf_table_free(hush_psf_table *t);
/* Forgets every cell (keys, history, frame sums). */
void hush__psf_table_clear(hush_psf_table *t, int threads);
/* Zeroes the per-frame statistics (not the cells). */
void hush__psf_table_begin_frame(hush_psf_table *t);

/* The outcome of probing for a key. */
typedef struct hush_psf_probe_result {
  uint32_t slot;           /* HUSH_PSF_NO_CELL if none */
  int collided;            /* not the first slot probed */
  int evicted;             /* replaced an older cell */
} hush_psf_probe_result;

/* The slot for key k (steps 1-4 above): thread-safe. */
hush_psf_probe_result hush__psf_table_probe(hush_psf_table *t, const hush_psf_probe *p,
                                            hush_psf_key k);

/* The slot a key probes first, for prefetching its key line and cell. */
static inline uint32_t hush__psf_table_first_slot(const hush_psf_table *t, hush_psf_key k) {
  /* line: the top 28 bits of the primary hash scaled to [0, lines) */
  const uint32_t line = (uint32_t)(((uint64_t)(k.i >> 4) * t->lines) >> 28);
  return line * HUSH_PSF_LINE + (k.i & (HUSH_PSF_LINE - 1));
}

/* Adds sum and count (> 0) to a slot's frame sums with atomics (thread-safe).
 * Returns 1 when this was the slot's first contribution of the frame: the
 * caller then puts it on the list of used cells (hush__psf_table_mark_used). */
int hush__psf_table_accumulate(hush_psf_table *t, uint32_t slot, const float sum[3],
                               uint32_t count);

/* Appends n slots to the list of cells used this frame (one atomic). */
void hush__psf_table_mark_used(hush_psf_table *t, const uint32_t *slots, uint32_t n);

/* Adds a caller's per-frame statistics (thread-safe). */
void hush__psf_table_add_stats(hush_psf_table *t, uint64_t vertices, uint64_t collisions,
                               uint64_t failed, uint64_t evictions);

typedef struct hush_psf_resolve_params {
  int temporal;            /* 0: each frame's average alone */
  float max_samples;       /* history bound of the blend */
  uint32_t max_age;        /* frames a cell survives unused */
  int threads;
} hush_psf_resolve_params;

/* Averages and blends the cells used this frame, clears their sums, ages
 * all keys and frees the stale ones. Adds to the eviction count; returns the
 * number of occupied slots after it. Not thread-safe (runs its own threads). */
uint64_t hush__psf_table_resolve(hush_psf_table *t, const hush_psf_resolve_params *p);

#endif
