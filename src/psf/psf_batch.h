/*
 * psf_batch.h — one thread's vertices on their way into the hash table of
 * hashed path-space filtering (hashed-path-space-filtering-binder-2019.md
 * §3.1: "all contributions with identical hashes are atomically added").
 *
 * The table is far larger than the caches and a slot is reached by a random
 * access plus a few atomic read-modify-writes, which wait for the line. So
 * a thread first groups its vertices by key in a small local hash table
 * (exactly: every distinct (primary, verification) key pending is one
 * group, summed locally in vertex order), and only when the batch is full or
 * ends does it visit the table, once per group, with the lines of the next
 * groups prefetched so that their misses overlap. Neighbouring pixels share
 * cells (a cell spans several pixels), so a batch of a few image rows has a
 * few times fewer groups than vertices.
 *
 * Until then a vertex's ticket holds its group number; the drain rewrites
 * it to the group's slot. Tickets are written only by the batch's thread.
 *
 * Ownership: a batch is the caller's (about 150 KB: on the heap, not on a
 * thread's stack);
 * it points into the table and the tickets arrays it was given, which must
 * live until hush__psf_batch_end.
 */
#ifndef HUSH_PSF_BATCH_H
#define HUSH_PSF_BATCH_H

#include "psf/psf_table.h"

#include <stdint.h>

/* Distinct keys pending: a band of 8 rows of 1280 pixels has about 3000
 * cells, so it fits in one batch (2048 groups: add 7% slower on the
 * courtyard at 1280x720, 1024: 15%). */
#define HUSH_PSF_BATCH_GROUPS 4096u
#define HUSH_PSF_BATCH_INDEX 8192u    /* local hash slots: a power of 2, twice the groups */
#define HUSH_PSF_BATCH_SEGMENTS 256u  /* ticket arrays pending */
#define HUSH_PSF_BATCH_VERTICES 16384u /* vertices pending (their tickets stay in cache) */

typedef struct hush_psf_group {
  hush_psf_key key;
  float sum[3];
  uint32_t count;
} hush_psf_group;

typedef struct hush_psf_segment {
  uint32_t *tickets;       /* the caller's: group numbers until the drain */
  uint32_t n;
} hush_psf_segment;

typedef struct hush_psf_batch {
  hush_psf_table *table;
  hush_psf_probe probe;
  uint32_t groups, segments, pending;
  uint16_t index[HUSH_PSF_BATCH_INDEX]; /* 1 + group, 0: empty */
  hush_psf_group group[HUSH_PSF_BATCH_GROUPS];
  uint32_t slot[HUSH_PSF_BATCH_GROUPS]; /* of each group, at the drain */
  uint32_t fresh[HUSH_PSF_BATCH_GROUPS]; /* slots first used this frame, at the drain */
  hush_psf_segment segment[HUSH_PSF_BATCH_SEGMENTS];
  uint64_t vertices, collisions, failed, evictions;
} hush_psf_batch;

/* An empty batch for table t. */
void hush__psf_batch_begin(hush_psf_batch *b, hush_psf_table *t, const hush_psf_probe *p);

/* Adds n vertices with keys keys[j] (usable where valid[j]) and radiance
 * (r[0][j], r[1][j], r[2][j]); tickets[j] receives the vertex's slot or
 * HUSH_PSF_NO_CELL by hush__psf_batch_end at the latest. */
void hush__psf_batch_add(hush_psf_batch *b, const hush_psf_key *keys, const float *const r[3],
                         const int *valid, uint32_t n, uint32_t *tickets);

/* Takes every pending group to the table, writes the pending tickets and
 * adds the batch's statistics to the table; b is then empty again. */
void hush__psf_batch_end(hush_psf_batch *b);

#endif
