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

typedef hush_psf_probe_result probe_result;

/* A slot (re)claimed for a new cell: only the claiming thread touches its
 * history this frame (its sums are 0: an unused or freed cell's sums were
 * cleared at resolve), so the history starts over without atomics. */
static void start_history(hush_psf_cell *c) {
  c->mean[0] = c->mean[1] = c->mean[2] = 0.0f;
  c->samples = 0.0f;
}

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
      start_history(&t->cells[s]);
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
  start_history(&t->cells[best]);
  r->slot = best;
  r->collided = 1;
  r->evicted = 1;
  return 1;
}

hush_psf_probe_result hush__psf_table_probe(hush_psf_table *t, const hush_psf_probe *p,
                                            hush_psf_key key) {
  probe_result r = {HUSH_PSF_NO_CELL, 0, 0};
  const uint32_t probes = p->probes;
  const uint32_t first = hush__psf_table_first_slot(t, key);
  const uint32_t base = first & ~(HUSH_PSF_LINE - 1), start = first & (HUSH_PSF_LINE - 1);
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

int hush__psf_table_accumulate(hush_psf_table *t, uint32_t slot, const float sum[3],
                               uint32_t count) {
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
  return (old >> 32) == 0; /* a slot's count leaves 0 once per frame */
}

void hush__psf_table_mark_used(hush_psf_table *t, const uint32_t *slots, uint32_t n) {
  if (!n) return;
  /* each slot is marked once per frame, so at + n <= slots */
  const uint32_t at = atomic_fetch_add_explicit(&t->used_count, n, memory_order_relaxed);
  memcpy(t->used + at, slots, (size_t)n * sizeof *slots);
}

void hush__psf_table_add_stats(hush_psf_table *t, uint64_t vertices, uint64_t collisions,
                               uint64_t failed, uint64_t evictions) {
  atomic_fetch_add_explicit(&t->vertices, vertices, memory_order_relaxed);
  atomic_fetch_add_explicit(&t->collisions, collisions, memory_order_relaxed);
  atomic_fetch_add_explicit(&t->failed, failed, memory_order_relaxed);
  atomic_fetch_add_explicit(&t->evictions, evictions, memory_order_relaxed);
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

/* How many used cells ahead resolve prefetches: the list is in the order
 * the cells were first filled, so their lines are scattered over the table. */
#define RESOLVE_AHEAD 16

/* Work items per chunk of resolve's loops: dynamic chunks, so that on a
 * shared machine a thread that loses its core does not hold the other up
 * for its whole half. */
#define BLEND_CHUNK 4096
#define AGE_CHUNK 65536

uint64_t hush__psf_table_resolve(hush_psf_table *t, const hush_psf_resolve_params *p) {
  const int64_t used = atomic_load(&t->used_count);
  const int64_t slots = t->slots;
  const uint32_t max_age = p->max_age < HUSH_PSF_AGE_MAX ? p->max_age : HUSH_PSF_AGE_MAX - 1;
  /* every thread that added has returned (the API's contract), so the keys
   * are read and written as plain integers here: the ageing loop then
   * vectorises (atomic accesses do not), and it touches every slot */
  _Static_assert(sizeof(_Atomic uint32_t) == sizeof(uint32_t), "atomic keys are plain words");
  uint32_t *restrict keys = (uint32_t *)t->keys;
  uint64_t occupied = 0, freed = 0;
  /* blending (cells) and ageing (keys) touch different arrays: one
   * parallel region, no barrier between them */
#pragma omp parallel num_threads(p->threads)
  {
#pragma omp for schedule(dynamic, BLEND_CHUNK) nowait
    for (int64_t k = 0; k < used; k++) {
      if (k + RESOLVE_AHEAD < used) __builtin_prefetch(&t->cells[t->used[k + RESOLVE_AHEAD]], 1);
      blend(t, t->used[k], p);
    }
    /* age every key by one frame (the cells just used go from 0 to 1) and
     * free those unused for more than max_age frames; a freed cell's
     * history is zeroed when its slot is claimed again (start_history) */
#pragma omp for schedule(dynamic, AGE_CHUNK) reduction(+ : occupied, freed)
    for (int64_t s = 0; s < slots; s++) {
      const uint32_t key = keys[s];
      const uint32_t age = age_of(key) + 1;
      const uint32_t full = key != 0, keep = full & (age <= max_age);
      keys[s] = ((key & HUSH_PSF_VMASK) | age << HUSH_PSF_AGE_SHIFT) & (0u - keep);
      occupied += keep;
      freed += full & !keep;
    }
  }
  atomic_store(&t->used_count, 0u);
  atomic_fetch_add(&t->evictions, freed);
  return occupied;
}
