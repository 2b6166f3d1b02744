/*
 * psf_batch.c — a thread's vertices grouped by key before they reach the
 * hash table, which is then visited once per group with prefetching (see
 * psf_batch.h; hashed-path-space-filtering-binder-2019.md §3.1).
 */
#include "psf/psf_batch.h"

#include <string.h>

/* How many groups ahead the drain prefetches: each group costs a random
 * miss on its key line and one on its cell, and a compare-and-swap cannot
 * start before its line is there, so misses only overlap through prefetches. */
#define AHEAD 16u

static void reset(hush_psf_batch *b) {
  memset(b->index, 0, sizeof b->index);
  b->groups = 0;
  b->segments = 0;
  b->pending = 0;
}

void hush__psf_batch_begin(hush_psf_batch *b, hush_psf_table *t, const hush_psf_probe *p) {
  b->table = t;
  b->probe = *p;
  b->vertices = b->collisions = b->failed = b->evictions = 0;
  reset(b);
}

static inline uint32_t index_of(hush_psf_key k) {
  /* the primary hash alone would do, but keys that share it (normals told
   * apart by the verification hash) then probe further */
  return (k.i ^ (k.v * 0x9e3779b1u)) & (HUSH_PSF_BATCH_INDEX - 1);
}

/* The group of key k, a new one if it has none (the caller ensures room). */
static uint32_t group_of(hush_psf_batch *b, hush_psf_key k) {
  uint32_t h = index_of(k);
  for (;;) {
    const uint32_t e = b->index[h];
    if (e == 0) {
      const uint32_t g = b->groups++;
      b->index[h] = (uint16_t)(g + 1);
      hush_psf_group *grp = &b->group[g];
      grp->key = k;
      grp->sum[0] = grp->sum[1] = grp->sum[2] = 0.0f;
      grp->count = 0;
      return g;
    }
    if (b->group[e - 1].key.i == k.i && b->group[e - 1].key.v == k.v) return e - 1;
    h = (h + 1) & (HUSH_PSF_BATCH_INDEX - 1);
  }
}

static void prefetch_group(const hush_psf_table *t, hush_psf_key k) {
  const uint32_t s = hush__psf_table_first_slot(t, k);
  __builtin_prefetch(&t->keys[s], 1);
  __builtin_prefetch(&t->cells[s], 1);
}

/* Every group to the table: probe (slot), then its sums; then the tickets. */
static void drain(hush_psf_batch *b) {
  hush_psf_table *t = b->table;
  const uint32_t n = b->groups;
  for (uint32_t g = 0; g < n && g < AHEAD; g++) prefetch_group(t, b->group[g].key);
  for (uint32_t g = 0; g < n; g++) {
    if (g + AHEAD < n) prefetch_group(t, b->group[g + AHEAD].key);
    const hush_psf_probe_result r = hush__psf_table_probe(t, &b->probe, b->group[g].key);
    b->slot[g] = r.slot;
    b->evictions += (uint64_t)r.evicted;
    b->collisions += r.collided ? b->group[g].count : 0u;
    b->failed += r.slot == HUSH_PSF_NO_CELL ? b->group[g].count : 0u;
  }
  /* the probes brought the groups' cells into the cache (or a neighbour
   * slot's, a collision): the atomic sums find them there */
  uint32_t nf = 0;
  for (uint32_t g = 0; g < n; g++) {
    const uint32_t s = b->slot[g];
    if (s != HUSH_PSF_NO_CELL && hush__psf_table_accumulate(t, s, b->group[g].sum, b->group[g].count))
      b->fresh[nf++] = s;
  }
  hush__psf_table_mark_used(t, b->fresh, nf);
  for (uint32_t k = 0; k < b->segments; k++) {
    uint32_t *tk = b->segment[k].tickets;
    const uint32_t m = b->segment[k].n;
    for (uint32_t j = 0; j < m; j++) tk[j] = tk[j] == HUSH_PSF_NO_CELL ? HUSH_PSF_NO_CELL : b->slot[tk[j]];
  }
  reset(b);
}

/* Queues tickets[0 .. n) for the drain, draining when the list is full. */
static void queue(hush_psf_batch *b, uint32_t *tickets, uint32_t n) {
  if (!n) return;
  b->segment[b->segments].tickets = tickets;
  b->segment[b->segments].n = n;
  if (++b->segments == HUSH_PSF_BATCH_SEGMENTS) drain(b);
}

void hush__psf_batch_add(hush_psf_batch *b, const hush_psf_key *keys, const float *const r[3],
                         const int *valid, uint32_t n, uint32_t *tickets) {
  uint32_t start = 0;
  for (uint32_t j = 0; j < n; j++) {
    if (b->groups == HUSH_PSF_BATCH_GROUPS || b->pending == HUSH_PSF_BATCH_VERTICES) {
      queue(b, tickets + start, j - start);
      drain(b);
      start = j;
    }
    b->pending++;
    if (!valid[j]) {
      tickets[j] = HUSH_PSF_NO_CELL;
      b->failed++;
      continue;
    }
    const uint32_t g = group_of(b, keys[j]);
    hush_psf_group *grp = &b->group[g];
    for (int c = 0; c < 3; c++) grp->sum[c] += r[c][j];
    grp->count++;
    tickets[j] = g;
  }
  queue(b, tickets + start, n - start);
  b->vertices += n;
}

void hush__psf_batch_end(hush_psf_batch *b) {
  drain(b);
  hush__psf_table_add_stats(b->table, b->vertices, b->collisions, b->failed, b->evictions);
  b->vertices = b->collisions = b->failed = b->evictions = 0;
}
