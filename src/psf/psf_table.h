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
 * of two 64-bit words: red and green sums, blue sum and count), after write
 * combining in each thread (below). At resolve every cell used this frame
 * averages them and blends the average with its history (§3.3):
 *   mean = mean_old + n_new / (min(n_old, max_samples) + n_new) (avg - mean_old)
 * i.e. a running mean until max_samples vertices, then an exponential average
 * whose weight on new vertices never drops below n_new / (max_samples + n_new).
 * Then every occupied key ages by one frame and keys older than max_age are
 * freed.
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
 * frame add (two 64-bit words, so that one vertex, or one combined run,
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

/*
 * Write combining: a thread's recent cells, direct-mapped by key, whose
 * vertices are summed locally and added to the table with one set of
 * atomics when the entry is replaced or flushed. Neighbouring pixels fall
 * into the same few cells (interleaved by the jitter), so this saves most of
 * the atomics and probes. One per thread (on its stack), not shared.
 */
#define HUSH_PSF_COMBINE_BITS 5u
#define HUSH_PSF_COMBINE (1u << HUSH_PSF_COMBINE_BITS)

typedef struct hush_psf_combine_entry {
  hush_psf_key key;
  uint32_t slot;           /* HUSH_PSF_NO_CELL when the key found none */
  uint32_t count;
  float sum[3];
  int collided, used;
} hush_psf_combine_entry;

typedef struct hush_psf_combiner {
  hush_psf_combine_entry entries[HUSH_PSF_COMBINE];
  uint64_t vertices, collisions, failed, evictions;
} hush_psf_combiner;

void hush__psf_combiner_init(hush_psf_combiner *c);

/*
 * Adds n vertices with keys keys[] and radiance radiance[3 * j] (valid[j]
 * says whether the key is usable), in order, writing each one's slot (or
 * HUSH_PSF_NO_CELL) to tickets[]. Thread-safe for different combiners; the
 * sums reach the table at hush__psf_combiner_flush at the latest.
 */
void hush__psf_table_add(hush_psf_table *t, const hush_psf_probe *p, hush_psf_combiner *c,
                         const hush_psf_key *keys, const float *radiance, const int *valid,
                         uint32_t n, uint32_t *tickets);

/* Adds c's pending sums and statistics to the table and empties c. */
void hush__psf_combiner_flush(hush_psf_table *t, hush_psf_combiner *c);

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
