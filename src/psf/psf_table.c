/*
 * psf_table.c — the cache-line hash table of hashed path-space filtering:
 * probing, atomic accumulation, temporal blending and eviction by age
 * (see psf_table.h; hashed-path-space-filtering-binder-2019.md §3.1, §3.3,
 * §3.4).
 */
#include "psf/psf_table.h"

#include <math.h>
#include <omp.h>
#include <stdlib.h>
#include <string.h>

static void *alloc_lines(size_t bytes) {
  const size_t size = (bytes + 63) / 64 * 64;
  void *p = aligned_alloc(64, size ? size : 64);
  if (p) memset(p, 0, size);
  return p;
}

int hush__psf_table_init(hush_psf_table *t, uint64_t min_slots) {
  memset(t, 0, sizeof *t);
  uint64_t lines = (min_slots + HUSH_PSF_LINE - 1) / HUSH_PSF_LINE;
  if (lines < 1) lines = 1;
  if (lines > (1u << 26)) return 0; /* slots must fit in a ticket */
  t->lines = (uint32_t)lines;
  t->slots = t->lines * HUSH_PSF_LINE;
  t->keys = alloc_lines((size_t)t->slots * sizeof *t->keys);
  t->cells = alloc_lines((size_t)t->slots * sizeof *t->cells);
  t->used = alloc_lines((size_t)t->slots * sizeof *t->used);
  if (!t->keys || !t->cells || !t->used) {
    hush__psf_table_free(t);
    return 0;
  }
  return 1;
}

void hush__psf_table_free(hush_psf_table *t) {
  free(t->keys);
  free(t->cells);
  free(t->used);
  memset(t, 0, sizeof *t);
}

/* Zero sums, count and history. */
static void reset_cell(hush_psf_cell *c) {
  atomic_store_explicit(&c->rg, 0u, memory_order_relaxed);
  atomic_store_explicit(&c->bn, 0u, memory_order_relaxed);
  for (int k = 0; k < 3; k++) c->mean[k] = 0.0f;
  c->samples = 0.0f;
}

void hush__psf_table_clear(hush_psf_table *t, int threads) {
  const int64_t n = t->slots;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int64_t s = 0; s < n; s++) {
    atomic_store_explicit(&t->keys[s], 0u, memory_order_relaxed);
    reset_cell(&t->cells[s]);
  }
  atomic_store(&t->used_count, 0u);
}

void hush__psf_table_begin_frame(hush_psf_table *t) {
  atomic_store(&t->vertices, 0u);
  atomic_store(&t->collisions, 0u);
  atomic_store(&t->failed, 0u);
  atomic_store(&t->evictions, 0u);
}

/* ---- probing --------------------------------------------------------------- */

static inline uint32_t age_of(uint32_t key) { return key >> HUSH_PSF_AGE_SHIFT; }

/* Line of the primary hash: its top 28 bits scaled to [0, lines). */
static inline uint32_t line_of(const hush_psf_table *t, uint32_t i) {
  return (uint32_t)(((uint64_t)(i >> 4) * t->lines) >> 28);
}

typedef struct probe_result {
  uint32_t slot;           /* HUSH_PSF_NO_CELL if none */
  int collided;            /* not the first slot probed */
  int evicted;
} probe_result;

/* Step 1: the slot holding v, refreshed to age 0. */
static int find(hush_psf_table *t, uint32_t base, uint32_t start, uint32_t probes, uint32_t v,
                probe_result *r) {
  for (uint32_t k = 0; k < probes; k++) {
    const uint32_t s = base + ((start + k) & (HUSH_PSF_LINE - 1));
    uint32_t key = atomic_load_explicit(&t->keys[s], memory_order_relaxed);
    while ((key & HUSH_PSF_VMASK) == v && key != 0) {
      if (age_of(key) == 0 ||
          atomic_compare_exchange_weak_explicit(&t->keys[s], &key, v, memory_order_relaxed,
                                                memory_order_relaxed)) {
        r->slot = s;
        r->collided = k > 0;
        return 1;
      }
      /* key now holds what is there: another refresh (retry) or an eviction */
    }
  }
  return 0;
}

/* Step 2: the first empty slot in probe order. */
static int claim(hush_psf_table *t, uint32_t base, uint32_t start, uint32_t probes, uint32_t v,
                 probe_result *r) {
  for (uint32_t k = 0; k < probes; k++) {
    const uint32_t s = base + ((start + k) & (HUSH_PSF_LINE - 1));
    uint32_t key = atomic_load_explicit(&t->keys[s], memory_order_relaxed);
    if (key == 0 && atomic_compare_exchange_strong_explicit(&t->keys[s], &key, v,
                                                            memory_order_relaxed,
                                                            memory_order_relaxed)) {
      r->slot = s;
      r->collided = k > 0;
      return 1;
    }
    if (key == v) { /* another thread claimed it for the same cell */
      r->slot = s;
      r->collided = k > 0;
      return 1;
    }
  }
  return 0;
}

/* Step 3: replaces the oldest cell not used this frame (age > 0). */
static int evict(hush_psf_table *t, uint32_t base, uint32_t start, uint32_t probes, uint32_t v,
                 probe_result *r) {
  uint32_t best = HUSH_PSF_NO_CELL, best_key = 0;
  for (uint32_t k = 0; k < probes; k++) {
    const uint32_t s = base + ((start + k) & (HUSH_PSF_LINE - 1));
    const uint32_t key = atomic_load_explicit(&t->keys[s], memory_order_relaxed);
    if (key == v) { /* another thread has just put this cell here */
      r->slot = s;
      r->collided = k > 0;
      return 1;
    }
    if (age_of(key) > age_of(best_key)) {
      best = s;
      best_key = key;
    }
  }
  if (best == HUSH_PSF_NO_CELL) return 0;
  if (!atomic_compare_exchange_strong_explicit(&t->keys[best], &best_key, v, memory_order_relaxed,
                                               memory_order_relaxed))
    return 0;
  /* only this thread owns the new cell's history this frame: sums are 0
   * (the old cell was not used this frame), the history starts over */
  hush_psf_cell *c = &t->cells[best];
  c->mean[0] = c->mean[1] = c->mean[2] = 0.0f;
  c->samples = 0.0f;
  r->slot = best;
  r->collided = 1;
  r->evicted = 1;
  return 1;
}

static probe_result probe(hush_psf_table *t, uint32_t probes, hush_psf_key key) {
  probe_result r = {HUSH_PSF_NO_CELL, 0, 0};
  const uint32_t base = line_of(t, key.i) * HUSH_PSF_LINE, start = key.i & (HUSH_PSF_LINE - 1);
  /* a few rounds: a failed compare-and-swap means the line changed */
  for (int round = 0; round < 4; round++) {
    if (find(t, base, start, probes, key.v, &r)) return r;
    if (claim(t, base, start, probes, key.v, &r)) return r;
    if (evict(t, base, start, probes, key.v, &r)) return r;
    int any_old = 0;
    for (uint32_t k = 0; k < probes && !any_old; k++)
      any_old = age_of(atomic_load_explicit(&t->keys[base + ((start + k) & (HUSH_PSF_LINE - 1))],
                                            memory_order_relaxed)) > 0;
    if (!any_old) break; /* the line is full of this frame's cells */
  }
  r.slot = HUSH_PSF_NO_CELL;
  return r;
}

/* ---- accumulation ------------------------------------------------------------ */

static inline float lo_float(uint64_t w) {
  const uint32_t u = (uint32_t)w;
  float f;
  memcpy(&f, &u, sizeof f);
  return f;
}

static inline uint64_t float_bits(float f) {
  uint32_t u;
  memcpy(&u, &f, sizeof u);
  return u;
}

/* Adds sum and count to a slot: one compare-and-swap loop per 64-bit word.
 * The thread whose count leaves 0 puts the slot on the list of this frame. */
static void flush(hush_psf_table *t, uint32_t slot, const float sum[3], uint32_t count) {
  if (slot == HUSH_PSF_NO_CELL || count == 0) return;
  hush_psf_cell *a = &t->cells[slot];
  uint64_t old = atomic_load_explicit(&a->rg, memory_order_relaxed), now;
  do {
    now = float_bits(lo_float(old) + sum[0]) | float_bits(lo_float(old >> 32) + sum[1]) << 32;
  } while (!atomic_compare_exchange_weak_explicit(&a->rg, &old, now, memory_order_relaxed,
                                                  memory_order_relaxed));
  old = atomic_load_explicit(&a->bn, memory_order_relaxed);
  do {
    now = float_bits(lo_float(old) + sum[2]) | ((old >> 32) + count) << 32;
  } while (!atomic_compare_exchange_weak_explicit(&a->bn, &old, now, memory_order_relaxed,
                                                  memory_order_relaxed));
  if ((old >> 32) == 0) {
    const uint32_t at = atomic_fetch_add_explicit(&t->used_count, 1u, memory_order_relaxed);
    t->used[at] = slot; /* a slot's count leaves 0 once per frame: at < slots */
  }
}

/* How many vertices ahead the key line and the likely cell are prefetched:
 * the table is far larger than the caches and its accesses are random, so
 * the loop is bound by memory latency unless several misses overlap. */
#define PREFETCH_AHEAD 8u

static inline void prefetch_slot(const hush_psf_table *t, hush_psf_key k) {
  const uint32_t slot = line_of(t, k.i) * HUSH_PSF_LINE + (k.i & (HUSH_PSF_LINE - 1));
  __builtin_prefetch(&t->keys[slot], 1);
  __builtin_prefetch(&t->cells[slot], 1);
}

void hush__psf_combiner_init(hush_psf_combiner *c) { memset(c, 0, sizeof *c); }

static inline uint32_t combine_index(hush_psf_key k) {
  return (k.i ^ (k.v * 0x9e3779b1u)) >> (32 - HUSH_PSF_COMBINE_BITS);
}

void hush__psf_table_add(hush_psf_table *t, const hush_psf_probe *p, hush_psf_combiner *c,
                         const hush_psf_key *keys, const float *radiance, const int *valid,
                         uint32_t n, uint32_t *tickets) {
  for (uint32_t j = 0; j < n && j < PREFETCH_AHEAD; j++)
    if (valid[j]) prefetch_slot(t, keys[j]);
  for (uint32_t j = 0; j < n; j++) {
    if (j + PREFETCH_AHEAD < n && valid[j + PREFETCH_AHEAD])
      prefetch_slot(t, keys[j + PREFETCH_AHEAD]);
    if (!valid[j]) {
      tickets[j] = HUSH_PSF_NO_CELL;
      c->failed++;
      continue;
    }
    hush_psf_combine_entry *e = &c->entries[combine_index(keys[j])];
    if (!e->used || e->key.i != keys[j].i || e->key.v != keys[j].v) {
      if (e->used) flush(t, e->slot, e->sum, e->count);
      const probe_result r = probe(t, p->probes, keys[j]);
      c->evictions += (uint64_t)r.evicted;
      e->used = 1;
      e->key = keys[j];
      e->slot = r.slot;
      e->collided = r.collided;
      e->count = 0;
      e->sum[0] = e->sum[1] = e->sum[2] = 0.0f;
    }
    tickets[j] = e->slot;
    c->collisions += (uint64_t)e->collided;
    if (e->slot == HUSH_PSF_NO_CELL) {
      c->failed++;
      continue;
    }
    for (int k = 0; k < 3; k++) e->sum[k] += radiance[3 * j + k];
    e->count++;
  }
  c->vertices += n;
}

void hush__psf_combiner_flush(hush_psf_table *t, hush_psf_combiner *c) {
  for (uint32_t k = 0; k < HUSH_PSF_COMBINE; k++)
    if (c->entries[k].used) flush(t, c->entries[k].slot, c->entries[k].sum, c->entries[k].count);
  atomic_fetch_add_explicit(&t->vertices, c->vertices, memory_order_relaxed);
  atomic_fetch_add_explicit(&t->collisions, c->collisions, memory_order_relaxed);
  atomic_fetch_add_explicit(&t->failed, c->failed, memory_order_relaxed);
  atomic_fetch_add_explicit(&t->evictions, c->evictions, memory_order_relaxed);
  hush__psf_combiner_init(c);
}

/* ---- resolve ----------------------------------------------------------------- */

static void blend(hush_psf_table *t, uint32_t slot, const hush_psf_resolve_params *p) {
  hush_psf_cell *cell = &t->cells[slot];
  const uint64_t rg = atomic_load_explicit(&cell->rg, memory_order_relaxed);
  const uint64_t bn = atomic_load_explicit(&cell->bn, memory_order_relaxed);
  const uint32_t count = (uint32_t)(bn >> 32);
  const float avg[3] = {lo_float(rg) / (float)count, lo_float(rg >> 32) / (float)count,
                        lo_float(bn) / (float)count};
  atomic_store_explicit(&cell->rg, 0u, memory_order_relaxed);
  atomic_store_explicit(&cell->bn, 0u, memory_order_relaxed);
  const float n_new = (float)count;
  if (!(isfinite(avg[0]) && isfinite(avg[1]) && isfinite(avg[2]))) return; /* keep the history */
  if (!p->temporal || cell->samples <= 0.0f) {
    memcpy(cell->mean, avg, sizeof avg);
    cell->samples = n_new;
    return;
  }
  const float n_old = fminf(cell->samples, p->max_samples);
  const float w = n_new / (n_old + n_new);
  for (int c = 0; c < 3; c++) cell->mean[c] += w * (avg[c] - cell->mean[c]);
  cell->samples = fminf(n_old + n_new, p->max_samples);
}

uint64_t hush__psf_table_resolve(hush_psf_table *t, const hush_psf_resolve_params *p) {
  const int64_t used = atomic_load(&t->used_count);
#pragma omp parallel for schedule(static) num_threads(p->threads)
  for (int64_t k = 0; k < used; k++) {
    if (k + PREFETCH_AHEAD < used) __builtin_prefetch(&t->cells[t->used[k + PREFETCH_AHEAD]], 1);
    blend(t, t->used[k], p);
  }
  atomic_store(&t->used_count, 0u);

  /* age every key by one frame (the cells just used go from 0 to 1) and
   * free those unused for more than max_age frames */
  const int64_t lines = t->lines;
  const uint32_t max_age = p->max_age < HUSH_PSF_AGE_MAX ? p->max_age : HUSH_PSF_AGE_MAX - 1;
  uint64_t occupied = 0, freed = 0;
#pragma omp parallel for schedule(static) num_threads(p->threads) reduction(+ : occupied, freed)
  for (int64_t l = 0; l < lines; l++)
    for (uint32_t s = (uint32_t)l * HUSH_PSF_LINE; s < (uint32_t)(l + 1) * HUSH_PSF_LINE; s++) {
      const uint32_t key = atomic_load_explicit(&t->keys[s], memory_order_relaxed);
      if (!key) continue;
      const uint32_t age = age_of(key) + 1;
      if (age > max_age) {
        atomic_store_explicit(&t->keys[s], 0u, memory_order_relaxed);
        reset_cell(&t->cells[s]);
        freed++;
        continue;
      }
      atomic_store_explicit(&t->keys[s], (key & HUSH_PSF_VMASK) | age << HUSH_PSF_AGE_SHIFT,
                            memory_order_relaxed);
      occupied++;
    }
  atomic_fetch_add(&t->evictions, freed);
  return occupied;
}
