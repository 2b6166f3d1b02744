/*
 * test_psf.c — hashed path-space filtering (src/psf/, docs/psf.md;
 * hashed-path-space-filtering-binder-2019.md §3): properties of the table
 * and of the filter in the renderer.
 *
 *   - every cell returns the exact mean of the vertices that went into it,
 *     and under uniform radiance every vertex gets exactly that radiance;
 *   - the same with more cells and vertices than a batch holds, in one call
 *     or in many short calls through one batch (as the renderer adds);
 *   - glossy vertices get cells glossy_scale times larger, split by their
 *     normal only with glossy_normals;
 *   - vertices with different keys never share a cell, even when a tiny
 *     table forces collisions, evictions and failures (those keep their own
 *     radiance);
 *   - the same vertices added by 1 thread or by 2 concurrent threads give
 *     the same result up to float rounding (run it under ThreadSanitizer:
 *     docs/psf.md);
 *   - the temporal blend is the running mean up to max_samples and
 *     exponential after it; unused cells are evicted after max_age frames;
 *   - in the renderer, psf keeps the image's energy and lowers the noise;
 *   - records copied to planes (the vectorised transpose and the scalar
 *     tail) land word for word in the right plane.
 */
#include "check.h"

#include "hush.h"
#include "psf/psf_hash.h"
#include "psf/psf_internal.h"
#include "psf/psf_render.h"
#include "render/scene.h"

#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <sys/wait.h>
#include <unistd.h>
#include <stdint.h>
#include <string.h>

static uint32_t rnd_state = 12345u;
static float rnd(void) {
  rnd_state = rnd_state * 1664525u + 1013904223u;
  return (float)(rnd_state >> 8) * (1.0f / 16777216.0f);
}

/* n vertices on the floor plane y = 0 (normal +y) in [0, extent]^2, seen
 * from a camera at (0, 5, 0); radiance random in [0, 2) unless uniform. */
static void make_vertices(hush_psf_vertex *v, uint32_t n, float extent, int uniform) {
  for (uint32_t k = 0; k < n; k++) {
    memset(&v[k], 0, sizeof v[k]);
    v[k].position[0] = rnd() * extent;
    v[k].position[2] = rnd() * extent;
    v[k].normal[1] = 1.0f;
    v[k].origin[1] = 5.0f;
    for (int c = 0; c < 3; c++) v[k].radiance[c] = uniform ? 0.75f + 0.125f * (float)c : 2.0f * rnd();
    v[k].seed = k;
  }
}

static hush_psf make_psf(hush_device dev, uint32_t w, uint32_t h, float table_size, int temporal) {
  hush_psf p = hush_psf_new(dev, w, h);
  REQUIRE(p != NULL);
  CHECK(hush_psf_set_float(p, "table_size", table_size) == HUSH_OK);
  CHECK(hush_psf_set_int(p, "temporal", temporal) == HUSH_OK);
  return p;
}

/* Every ticketed vertex's lookup equals the mean (in double) of the
 * radiance of the vertices with its ticket, and those all share one key. */
static void check_exact_means(hush_psf p, const hush_psf_vertex *v, const uint32_t *t, uint32_t n,
                              const hush_psf_key_params *kp, uint32_t slots) {
  double *sum = calloc((size_t)slots * 3, sizeof *sum);
  uint32_t *count = calloc(slots, sizeof *count);
  hush_psf_key *key = calloc(slots, sizeof *key);
  float *out = malloc((size_t)n * 3 * sizeof *out);
  REQUIRE(sum && count && key && out);
  int mixed = 0, wrong = 0, own_wrong = 0;
  for (uint32_t k = 0; k < n; k++) {
    if (t[k] == HUSH_PSF_NO_CELL) continue;
    REQUIRE(t[k] < slots);
    hush_psf_key kk;
    REQUIRE(hush__psf_key_of(kp, &v[k], &kk));
    if (count[t[k]] && (key[t[k]].i != kk.i || key[t[k]].v != kk.v)) mixed++;
    key[t[k]] = kk;
    count[t[k]]++;
    for (int c = 0; c < 3; c++) sum[3 * t[k] + c] += v[k].radiance[c];
  }
  CHECK(hush_psf_lookup(p, v, t, n, out) == HUSH_OK);
  for (uint32_t k = 0; k < n; k++) {
    for (int c = 0; c < 3; c++) {
      if (t[k] == HUSH_PSF_NO_CELL) {
        own_wrong += out[3 * k + c] != v[k].radiance[c];
        continue;
      }
      const double mean = sum[3 * t[k] + c] / count[t[k]];
      wrong += fabs(out[3 * k + c] - mean) > 1e-5 * (1.0 + fabs(mean));
    }
  }
  CHECK_MSG(mixed == 0, "%d vertices share a slot with another key", mixed);
  CHECK_MSG(wrong == 0, "%d values are not their cell's mean", wrong);
  CHECK_MSG(own_wrong == 0, "%d vertices without a cell did not keep their own radiance",
            own_wrong);
  free(sum);
  free(count);
  free(key);
  free(out);
}

static hush_psf_key_params key_params(hush_psf p, uint32_t frame, float pixel_angle) {
  hush_psf_key_params kp;
  float f;
  hush_psf_get_float(p, "scale", &f);
  kp.scale = f;
  hush_psf_get_float(p, "glossy_scale", &f);
  kp.glossy_scale = f;
  hush_psf_get_float(p, "jitter", &f);
  kp.jitter = f;
  hush_psf_get_float(p, "normals", &f);
  kp.normals = f != 0.0f;
  hush_psf_get_float(p, "glossy_normals", &f);
  kp.glossy_normals = f != 0.0f;
  kp.pixel_angle = pixel_angle;
  kp.frame = frame;
  return kp;
}

static void test_exact_means(hush_device dev) {
  enum { N = 20000 };
  hush_psf_vertex *v = malloc(N * sizeof *v);
  uint32_t *t = malloc(N * sizeof *t);
  REQUIRE(v && t);
  /* random radiance: each cell's exact mean */
  hush_psf p = make_psf(dev, 160, 100, 2.0f, 0);
  make_vertices(v, N, 2.0f, 0);
  REQUIRE(hush_psf_begin_frame(p, 0, 0.002f, HUSH_HISTORY_RESET) == HUSH_OK);
  REQUIRE(hush_psf_add_vertices(p, v, N, t) == HUSH_OK);
  REQUIRE(hush_psf_resolve(p) == HUSH_OK);
  hush_psf_stats s;
  REQUIRE(hush_psf_get_stats(p, &s) == HUSH_OK);
  CHECK(s.vertices == N);
  CHECK(s.failed == 0);
  CHECK(s.cells_used > 100 && s.cells_used < N / 4); /* cells average several vertices */
  hush_psf_key_params kp = key_params(p, 0, 0.002f);
  check_exact_means(p, v, t, N, &kp, (uint32_t)s.table_size);

  /* uniform radiance: every vertex gets it back */
  make_vertices(v, N, 2.0f, 1);
  REQUIRE(hush_psf_begin_frame(p, 1, 0.002f, HUSH_HISTORY_RESET) == HUSH_OK);
  REQUIRE(hush_psf_add_vertices(p, v, N, t) == HUSH_OK);
  REQUIRE(hush_psf_resolve(p) == HUSH_OK);
  float *out = malloc(N * 3 * sizeof *out);
  REQUIRE(out);
  CHECK(hush_psf_lookup(p, v, t, N, out) == HUSH_OK);
  int off = 0;
  for (uint32_t k = 0; k < N; k++)
    for (int c = 0; c < 3; c++) off += fabsf(out[3 * k + c] - v[k].radiance[c]) > 1e-6f;
  CHECK_MSG(off == 0, "%d values differ from the uniform radiance", off);
  free(out);
  hush_psf_release(p);
  free(v);
  free(t);
}

/* Glossy vertices (their direction in the verification hash) get cells
 * glossy_scale times larger: with jitter on, a glossy vertex's primary hash
 * (position and level only) is that of the same vertex, not glossy, under
 * scale * glossy_scale; through the API they fill that many times fewer
 * cells of a plane, each still the exact mean of its vertices. */
static void test_glossy_cells(hush_device dev) {
  enum { N = 20000 };
  hush_psf_vertex *v = malloc(N * sizeof *v), *plain = malloc(N * sizeof *plain);
  uint32_t *t = malloc(N * sizeof *t);
  REQUIRE(v && plain && t);
  make_vertices(v, N, 2.0f, 0);
  for (uint32_t k = 0; k < N; k++) {
    v[k].origin[0] = 4.0f * rnd() - 2.0f; /* some distance and a direction of view */
    v[k].distance = 3.0f * rnd();
    v[k].flags = HUSH_PSF_GLOSSY;
    plain[k] = v[k];
    plain[k].flags = 0;
  }
  const float glossy[3] = {1.0f, 4.0f, 0.5f};
  for (int g = 0; g < 3; g++) {
    hush_psf_key_params kg = {.scale = 3.0f, .glossy_scale = glossy[g], .pixel_angle = 0.002f,
                              .jitter = 1.0f, .normals = 1, .frame = 7u};
    hush_psf_key_params kn = kg;
    kn.scale = kg.scale * glossy[g];
    int differ = 0, same_v = 0;
    for (uint32_t k = 0; k < N; k++) {
      hush_psf_key a, b;
      REQUIRE(hush__psf_key_of(&kg, &v[k], &a) && hush__psf_key_of(&kn, &plain[k], &b));
      differ += a.i != b.i;
      same_v += a.v == b.v;
    }
    CHECK_MSG(differ == 0, "glossy_scale %g: %d glossy vertices not in the cells of scale %g",
              glossy[g], differ, kn.scale);
    CHECK_MSG(same_v < N / 100, "glossy_scale %g: the direction is not in %d verification hashes",
              glossy[g], same_v);
  }

  /* the normal splits glossy cells only with glossy_normals; diffuse ones
   * always (normals): a vertex and its copy with another normal (no
   * jitter: it moves the vertex in the normal's tangent plane) */
  for (int gn = 0; gn < 2; gn++) {
    hush_psf_key_params kp = {.scale = 3.0f, .glossy_scale = 4.0f, .pixel_angle = 0.002f,
                              .jitter = 0.0f, .normals = 1, .glossy_normals = gn, .frame = 7u};
    int glossy_same = 0, plain_same = 0;
    for (uint32_t k = 0; k < 1000; k++) {
      hush_psf_vertex tilted = v[k], tilted_plain = plain[k];
      tilted.normal[0] = tilted_plain.normal[0] = 0.6f; /* (0.6, 0.8, 0): another quantum */
      tilted.normal[1] = tilted_plain.normal[1] = 0.8f;
      hush_psf_key a, b, c, d;
      REQUIRE(hush__psf_key_of(&kp, &v[k], &a) && hush__psf_key_of(&kp, &tilted, &b));
      REQUIRE(hush__psf_key_of(&kp, &plain[k], &c) && hush__psf_key_of(&kp, &tilted_plain, &d));
      glossy_same += a.v == b.v;
      plain_same += c.v == d.v;
    }
    CHECK_MSG(plain_same == 0, "%d diffuse vertices kept their key with another normal", plain_same);
    CHECK_MSG(gn ? glossy_same == 0 : glossy_same == 1000,
              "glossy_normals %d: %d of 1000 glossy vertices kept their key with another normal",
              gn, glossy_same);
  }

  uint64_t cells[2];
  for (int g = 0; g < 2; g++) {
    hush_psf p = make_psf(dev, 160, 100, 2.0f, 0);
    CHECK(hush_psf_set_float(p, "glossy_scale", glossy[g]) == HUSH_OK);
    for (uint32_t k = 0; k < N; k++) memcpy(v[k].origin, (float[3]){0.0f, 5.0f, 0.0f}, sizeof v[k].origin);
    REQUIRE(hush_psf_begin_frame(p, 0, 0.002f, HUSH_HISTORY_RESET) == HUSH_OK);
    REQUIRE(hush_psf_add_vertices(p, v, N, t) == HUSH_OK);
    REQUIRE(hush_psf_resolve(p) == HUSH_OK);
    hush_psf_stats s;
    REQUIRE(hush_psf_get_stats(p, &s) == HUSH_OK);
    CHECK(s.failed == 0);
    cells[g] = s.cells_used;
    hush_psf_key_params kp = key_params(p, 0, 0.002f);
    CHECK(kp.glossy_scale == glossy[g]);
    check_exact_means(p, v, t, N, &kp, (uint32_t)s.table_size);
    hush_psf_release(p);
  }
  /* 16 times the area per cell (a few directions split some of them) */
  CHECK_MSG(cells[1] * 8 < cells[0] && cells[1] * 32 > cells[0],
            "glossy_scale 4 used %llu cells, 1 used %llu", (unsigned long long)cells[1],
            (unsigned long long)cells[0]);
  free(v);
  free(plain);
  free(t);
}

/* Batches (psf_batch.h): more distinct cells than a batch groups and more
 * vertices than it keeps pending, given in one call and in many short calls
 * through one batch kept across them (as the renderer adds a band): every
 * cell still holds the exact mean of its vertices. */
static void test_batches(hush_device dev) {
  enum { N = 3 * HUSH_PSF_BATCH_VERTICES / 2, RUN = 7 };
  hush_psf_vertex *v = malloc(N * sizeof *v);
  uint32_t *t = malloc(N * sizeof *t);
  hush_psf_batch *batch = malloc(sizeof *batch);
  REQUIRE(v && t && batch);
  make_vertices(v, N, 8.0f, 0);
  uint64_t cells[2] = {0, 0};
  for (int calls = 0; calls < 2; calls++) {
    hush_psf p = make_psf(dev, 400, 200, 4.0f, 0); /* occupancy below 10%: every vertex has a cell */
    CHECK(hush_psf_set_float(p, "scale", 4.0f) == HUSH_OK); /* cells small enough to be many */
    REQUIRE(hush_psf_begin_frame(p, 0, 0.002f, HUSH_HISTORY_RESET) == HUSH_OK);
    if (calls == 0) {
      REQUIRE(hush_psf_add_vertices(p, v, N, t) == HUSH_OK);
    } else {
      REQUIRE(hush__psf_batch_open(p, batch) == HUSH_OK);
      for (uint32_t at = 0; at < N; at += RUN)
        REQUIRE(hush__psf_batch_vertices(p, batch, v + at, N - at < RUN ? N - at : RUN, t + at) ==
                HUSH_OK);
      hush__psf_batch_end(batch);
    }
    REQUIRE(hush_psf_resolve(p) == HUSH_OK);
    hush_psf_stats s;
    REQUIRE(hush_psf_get_stats(p, &s) == HUSH_OK);
    CHECK(s.vertices == N);
    CHECK(s.failed == 0);
    CHECK_MSG(s.cells_used > 2 * HUSH_PSF_BATCH_GROUPS, "only %llu cells",
              (unsigned long long)s.cells_used);
    CHECK(s.occupancy < 0.1);
    cells[calls] = s.cells_used;
    hush_psf_key_params kp = key_params(p, 0, 0.002f);
    check_exact_means(p, v, t, N, &kp, (uint32_t)s.table_size);
    hush_psf_release(p);
  }
  CHECK(cells[0] == cells[1]);
  free(v);
  free(t);
  free(batch);
}

/* Equal positions, different normals: same primary hash, different
 * verification hash; and a table of one cache line under pressure. */
static void test_no_mixing(hush_device dev) {
  enum { N = 4000 };
  hush_psf_vertex *v = malloc(N * sizeof *v);
  uint32_t *t = malloc(N * sizeof *t);
  float *out = malloc(N * 3 * sizeof *out);
  REQUIRE(v && t && out);
  hush_psf p = make_psf(dev, 64, 64, 2.0f, 0);
  CHECK(hush_psf_set_float(p, "jitter", 0.0f) == HUSH_OK);
  make_vertices(v, 200, 0.01f, 1);
  for (uint32_t k = 0; k < 200; k++) {
    const int up = k % 2 == 0; /* a floor and a ceiling in the same cells */
    v[k].normal[1] = up ? 1.0f : -1.0f;
    for (int c = 0; c < 3; c++) v[k].radiance[c] = up ? 1.0f : 100.0f;
  }
  REQUIRE(hush_psf_begin_frame(p, 0, 0.002f, HUSH_HISTORY_RESET) == HUSH_OK);
  REQUIRE(hush_psf_add_vertices(p, v, 200, t) == HUSH_OK);
  REQUIRE(hush_psf_resolve(p) == HUSH_OK);
  CHECK(hush_psf_lookup(p, v, t, 200, out) == HUSH_OK);
  int bad = 0;
  for (uint32_t k = 0; k < 200; k++) bad += out[3 * k] != v[k].radiance[0];
  CHECK_MSG(bad == 0, "%d vertices mixed with the other side's radiance", bad);
  hush_psf_release(p);

  /* 16 slots for thousands of cells over several frames: collisions,
   * evictions and vertices without a cell, but never a mixed cell */
  p = make_psf(dev, 8, 8, 0.2f, 1);
  CHECK(hush_psf_set_int(p, "max_age", 1) == HUSH_OK);
  uint64_t evictions = 0, failed = 0, collisions = 0;
  for (uint32_t f = 0; f < 4; f++) {
    make_vertices(v, N, 5.0f, 0);
    REQUIRE(hush_psf_begin_frame(p, f, 0.002f, HUSH_HISTORY_CONTINUE) == HUSH_OK);
    REQUIRE(hush_psf_add_vertices(p, v, N, t) == HUSH_OK);
    REQUIRE(hush_psf_resolve(p) == HUSH_OK);
    hush_psf_stats s;
    hush_psf_get_stats(p, &s);
    CHECK(s.table_size == 16);
    evictions += s.evictions;
    failed += s.failed;
    collisions += s.collisions;
    /* temporal is on: cells keep history, so the mean is not this frame's;
     * check without history on frame 0 only */
    if (f == 0) {
      hush_psf_key_params kp = key_params(p, f, 0.002f);
      check_exact_means(p, v, t, N, &kp, 16);
    }
  }
  CHECK(failed > 0);
  CHECK(collisions > 0);
  CHECK(evictions > 0);
  hush_psf_release(p);
  free(v);
  free(t);
  free(out);
}

/* ---- 1 thread vs 2 threads ---------------------------------------------------- */

typedef struct add_job {
  hush_psf psf;
  const hush_psf_vertex *v;
  uint32_t *t;
  uint32_t begin, end, step; /* chunks of `step`, every other one */
} add_job;

static void *add_worker(void *arg) {
  const add_job *j = arg;
  for (uint32_t at = j->begin; at < j->end; at += 2 * j->step) {
    const uint32_t n = at + j->step <= j->end ? j->step : j->end - at;
    hush_psf_add_vertices(j->psf, j->v + at, n, j->t + at);
  }
  return NULL;
}

static void run_frames(hush_psf p, hush_psf_vertex *v, uint32_t *t, uint32_t n, int threads,
                       float *out) {
  for (uint32_t f = 0; f < 3; f++) {
    for (uint32_t k = 0; k < n; k++) v[k].radiance[0] = (float)((k * 7919u + f * 31u) % 97u) / 48.0f;
    REQUIRE(hush_psf_begin_frame(p, f, 0.002f, f ? HUSH_HISTORY_CONTINUE : HUSH_HISTORY_RESET) ==
            HUSH_OK);
    if (threads == 1) {
      hush_psf_add_vertices(p, v, n, t);
    } else {
      pthread_t th[2];
      add_job jobs[2] = {{p, v, t, 0, n, 64}, {p, v, t, 64, n, 64}};
      for (int k = 0; k < 2; k++) REQUIRE(pthread_create(&th[k], NULL, add_worker, &jobs[k]) == 0);
      for (int k = 0; k < 2; k++) pthread_join(th[k], NULL);
    }
    REQUIRE(hush_psf_resolve(p) == HUSH_OK);
  }
  CHECK(hush_psf_lookup(p, v, t, n, out) == HUSH_OK);
}

static void test_threads(hush_device dev) {
  enum { N = 30000 };
  hush_psf_vertex *v = malloc(N * sizeof *v);
  uint32_t *t = malloc(N * sizeof *t);
  float *a = malloc(N * 3 * sizeof *a), *b = malloc(N * 3 * sizeof *b);
  REQUIRE(v && t && a && b);
  make_vertices(v, N, 3.0f, 0);
  hush_psf p1 = make_psf(dev, 200, 150, 2.0f, 1), p2 = make_psf(dev, 200, 150, 2.0f, 1);
  run_frames(p1, v, t, N, 1, a);
  run_frames(p2, v, t, N, 2, b);
  int differ = 0;
  double worst = 0.0;
  for (uint32_t k = 0; k < 3 * N; k++) {
    const double d = fabs((double)a[k] - b[k]) / (1.0 + fabs((double)a[k]));
    worst = d > worst ? d : worst;
    differ += d > 1e-5;
  }
  CHECK_MSG(differ == 0, "%d values differ beyond rounding between 1 and 2 threads (worst %g)",
            differ, worst);
  hush_psf_stats s1, s2;
  hush_psf_get_stats(p1, &s1);
  hush_psf_get_stats(p2, &s2);
  CHECK(s1.cells_used == s2.cells_used);
  CHECK(s1.vertices == N && s2.vertices == N);
  hush_psf_release(p1);
  hush_psf_release(p2);
  free(v);
  free(t);
  free(a);
  free(b);
}

/* ---- temporal blend and eviction ------------------------------------------------ */

static void one_frame(hush_psf p, hush_psf_vertex *v, uint32_t *t, uint32_t n, uint32_t f,
                      float radiance, float *out) {
  for (uint32_t k = 0; k < n; k++)
    for (int c = 0; c < 3; c++) v[k].radiance[c] = radiance;
  REQUIRE(hush_psf_begin_frame(p, f, 0.002f, f ? HUSH_HISTORY_CONTINUE : HUSH_HISTORY_RESET) ==
          HUSH_OK);
  REQUIRE(hush_psf_add_vertices(p, v, n, t) == HUSH_OK);
  REQUIRE(hush_psf_resolve(p) == HUSH_OK);
  if (out) CHECK(hush_psf_lookup(p, v, t, n, out) == HUSH_OK);
}

static void test_temporal(hush_device dev) {
  enum { N = 64 };
  hush_psf_vertex v[N];
  uint32_t t[N];
  float out[3 * N];
  /* all vertices at one point: one cell of N vertices per frame */
  make_vertices(v, N, 0.0f, 1);
  hush_psf p = make_psf(dev, 16, 16, 1.0f, 1);
  CHECK(hush_psf_set_float(p, "jitter", 0.0f) == HUSH_OK);
  CHECK(hush_psf_set_float(p, "max_samples", 1e6f) == HUSH_OK);
  one_frame(p, v, t, N, 0, 1.0f, out);
  one_frame(p, v, t, N, 1, 3.0f, out);
  CHECK_NEAR(out[0], 2.0f, 1e-6); /* running mean of 2 N vertices */
  one_frame(p, v, t, N, 2, 5.0f, out);
  CHECK_NEAR(out[0], 3.0f, 1e-6);
  /* bound of 16: weight of the new frame N / (16 + N) */
  CHECK(hush_psf_set_float(p, "max_samples", 16.0f) == HUSH_OK);
  const float w = (float)N / (16.0f + (float)N);
  one_frame(p, v, t, N, 3, 1.0f, out);
  const float m3 = 3.0f + w * (1.0f - 3.0f);
  CHECK_NEAR(out[0], m3, 1e-5);
  one_frame(p, v, t, N, 4, 11.0f, out);
  CHECK_NEAR(out[0], m3 + w * (11.0f - m3), 1e-5);
  /* temporal off: the frame alone */
  CHECK(hush_psf_set_int(p, "temporal", 0) == HUSH_OK);
  one_frame(p, v, t, N, 5, 7.0f, out);
  CHECK_NEAR(out[0], 7.0f, 1e-6);
  hush_psf_release(p);

  /* eviction by age: unused for more than max_age frames */
  p = make_psf(dev, 16, 16, 1.0f, 1);
  CHECK(hush_psf_set_int(p, "max_age", 2) == HUSH_OK);
  make_vertices(v, N, 1.0f, 1);
  one_frame(p, v, t, N, 0, 1.0f, NULL);
  hush_psf_stats s;
  hush_psf_get_stats(p, &s);
  const uint64_t cells = s.cells_occupied;
  CHECK(cells > 0);
  uint64_t evicted = 0;
  for (uint32_t f = 1; f <= 3; f++) {
    one_frame(p, v, t, 0, f, 1.0f, NULL);
    hush_psf_get_stats(p, &s);
    evicted += s.evictions;
    if (f < 2) CHECK(s.cells_occupied == cells); /* ages 2 <= max_age: kept */
  }
  CHECK(s.cells_occupied == 0);
  CHECK(evicted == cells);
  hush_psf_release(p);
}

/* ---- errors ------------------------------------------------------------------------ */

static void test_errors(hush_device dev) {
  CHECK(hush_psf_new(dev, 0, 10) == NULL);
  CHECK(hush_device_get_error(dev, NULL) == HUSH_ERROR_INVALID_ARGUMENT);
  hush_psf p = make_psf(dev, 8, 8, 1.0f, 1);
  CHECK(hush_psf_set_float(p, "scale", -1.0f) == HUSH_ERROR_OUT_OF_RANGE);
  CHECK(hush_psf_set_float(p, "nope", 1.0f) == HUSH_ERROR_NOT_FOUND);
  CHECK(hush_psf_set_float(p, "probes", 2.5f) == HUSH_ERROR_TYPE_MISMATCH);
  CHECK(hush_psf_set_string(p, "normals", "false") == HUSH_OK);
  CHECK(hush_psf_set_string(p, "scale", "abc") == HUSH_ERROR_TYPE_MISMATCH);
  while (hush_device_get_error(dev, NULL) != HUSH_OK) {
  }
  hush_psf_vertex v;
  uint32_t t;
  memset(&v, 0, sizeof v);
  CHECK(hush_psf_add_vertices(p, &v, 1, &t) == HUSH_ERROR_INVALID_OPERATION);
  CHECK(hush_psf_resolve(p) == HUSH_ERROR_INVALID_OPERATION);
  CHECK(hush_psf_begin_frame(p, 0, -1.0f, HUSH_HISTORY_RESET) == HUSH_ERROR_OUT_OF_RANGE);
  while (hush_device_get_error(dev, NULL) != HUSH_OK) {
  }
  /* a non-finite vertex gets no cell and keeps its radiance */
  REQUIRE(hush_psf_begin_frame(p, 0, 0.01f, HUSH_HISTORY_RESET) == HUSH_OK);
  v.normal[1] = 1.0f;
  v.position[0] = NAN;
  v.radiance[0] = 3.0f;
  CHECK(hush_psf_add_vertices(p, &v, 1, &t) == HUSH_OK);
  CHECK(t == HUSH_PSF_NO_CELL);
  CHECK(hush_psf_resolve(p) == HUSH_OK);
  float out[3];
  CHECK(hush_psf_lookup(p, &v, &t, 1, out) == HUSH_OK);
  CHECK(out[0] == 3.0f);
  hush_psf_stats s;
  hush_psf_get_stats(p, &s);
  CHECK(s.failed == 1);
  hush_psf_release(p);
  uint32_t count = 0;
  CHECK(hush_psf_params(&count) != NULL && count >= 8);
}

/* ---- in the renderer ------------------------------------------------------------------- */

static double mean_of(const float *x, size_t n) {
  double s = 0.0;
  for (size_t i = 0; i < n; i++) s += x[i];
  return s / (double)n;
}

/* Mean absolute difference between horizontally adjacent pixels: noise. */
static double roughness(const float *x, uint32_t w, uint32_t h) {
  double s = 0.0;
  for (uint32_t y = 0; y < h; y++)
    for (uint32_t i = 1; i < w; i++) s += fabs(x[3 * (y * w + i)] - x[3 * (y * w + i - 1)]);
  return s / ((double)(w - 1) * h);
}

static void test_renderer(hush_device dev) {
  hush_scene scene;
  REQUIRE(hush__scene_builtin(dev, "furnace", &scene) == HUSH_OK);
  REQUIRE(hush__scene_commit(dev, &scene) == HUSH_OK);
  hush_lights lights;
  REQUIRE(hush__lights_init(dev, &lights, &scene) == HUSH_OK);
  const uint32_t W = 96, H = 64;
  hush_render_params params;
  hush__render_defaults(&params);
  params.width = W;
  params.height = H;
  params.bounces = 3;
  hush_psf_renderer *pr = NULL;
  REQUIRE(hush__psf_renderer_new(dev, W, H, 1, 1, &pr) == HUSH_OK);
  CHECK(hush__psf_renderer_set(pr, "vertex", "3") == HUSH_ERROR_OUT_OF_RANGE);
  while (hush_device_get_error(dev, NULL) != HUSH_OK) {
  }
  hush__psf_renderer_hook(pr, &params);
  hush_camera_move_setup moves;
  hush__camera_move_init(&moves, &scene, HUSH_MOVE_STATIC, NULL, W, H, params.jitter, 0);
  double color_mean = 0.0, psf_mean = 0.0, color_rough = 0.0, psf_rough = 0.0;
  for (uint32_t f = 0; f < 4; f++) {
    hush_render_camera cam, prev;
    int have_prev;
    REQUIRE(hush__camera_move_frame(&moves, f, &cam, &prev, &have_prev));
    hush_render_ctx ctx;
    hush__render_ctx_init(&ctx, &scene, &lights, &params, &cam, have_prev ? &prev : NULL, f);
    REQUIRE(hush__psf_renderer_begin(pr, &ctx, f ? HUSH_HISTORY_CONTINUE : HUSH_HISTORY_RESET) ==
            HUSH_OK);
    hush_frame frame = hush_frame_new(dev, W, H);
    REQUIRE(frame);
    REQUIRE(hush__render_frame(dev, &ctx, frame, NULL, NULL, NULL) == HUSH_OK);
    hush_psf_timings tm;
    REQUIRE(hush__psf_renderer_finish(pr, frame, &tm) == HUSH_OK);
    hush_image_view c, q;
    REQUIRE(hush_frame_get_layer(frame, "color", &c) == HUSH_OK);
    REQUIRE(hush_frame_get_layer(frame, "psf", &q) == HUSH_OK);
    int finite = 1;
    for (size_t i = 0; i < (size_t)W * H * 3; i++) finite &= isfinite(((float *)q.data)[i]);
    CHECK(finite);
    color_mean += mean_of(c.data, (size_t)W * H * 3);
    psf_mean += mean_of(q.data, (size_t)W * H * 3);
    color_rough = roughness(c.data, W, H);
    psf_rough = roughness(q.data, W, H);
    hush_frame_release(frame);
  }
  /* the furnace is uniform: filtering keeps the energy and removes noise */
  CHECK_MSG(fabs(psf_mean / color_mean - 1.0) < 0.02, "psf mean %g, color mean %g", psf_mean,
            color_mean);
  CHECK_MSG(psf_rough < 0.5 * color_rough, "roughness psf %g, color %g", psf_rough, color_rough);
  hush_psf_stats s;
  hush_psf_get_stats(hush__psf_renderer_psf(pr), &s);
  CHECK(s.vertices > 0 && s.failed == 0);
  hush__psf_renderer_free(pr);
  hush__lights_free(&lights);
  hush__scene_free(&scene);
}

/* ---- the command line ------------------------------------------------------------------ */

#define WORK HUSH_BINARY_DIR "/test_psf_work"

static int run(const char *args) {
  char line[2048];
  snprintf(line, sizeof line, "'%s' %s > '%s/out.txt' 2>&1", HUSH_CLI, args, WORK);
  const int s = system(line);
  return s == -1 ? -1 : WEXITSTATUS(s);
}

static int file_contains(const char *path, const char *what) {
  FILE *f = fopen(path, "rb");
  if (!f) return 0;
  static char text[1 << 16];
  const size_t n = fread(text, 1, sizeof text - 1, f);
  fclose(f);
  text[n] = '\0';
  return strstr(text, what) != NULL;
}

static void test_cli(hush_device dev) {
#if defined(__SANITIZE_THREAD__)
  /* the CLI renders with OpenMP threads, and gcc's libgomp is not
   * instrumented: ThreadSanitizer would report its barriers as races.
   * (`make test-tsan` builds with clang, libomp and Archer, which TSan
   * understands: there these checks run.) */
  printf("skipping the command-line checks under ThreadSanitizer\n");
  return;
#endif
  if (access(HUSH_CLI, X_OK) != 0) {
    printf("skipping the command-line checks: %s is not built\n", HUSH_CLI);
    return;
  }
  REQUIRE(system("rm -rf '" WORK "' && mkdir -p '" WORK "'") == 0);
  /* hush render --psf: a psf layer in every frame, statistics per frame */
  CHECK(run("render --scene builtin:cornell --out '" WORK "/r' --size 48x32 --frames 2 --psf "
            "--psf-scale 6 --psf-vertex 2 --threads 2") == 0);
  CHECK(file_contains(WORK "/out.txt", "psf: "));
  CHECK(file_contains(WORK "/r/psf.csv", "frame,vertices,collisions"));
  CHECK(file_contains(WORK "/r/psf.csv", "\n1,"));
  hush_frame fr = NULL;
  CHECK(hush_frame_read_exr(dev, WORK "/r/frame_0001.exr", &fr) == HUSH_OK);
  CHECK(fr && hush_frame_get_layer(fr, "psf", NULL) == HUSH_OK);
  hush_frame_release(fr);
  CHECK(run("render --scene builtin:cornell --out '" WORK "/bad' --psf-vertex 3") != 0);
  CHECK(file_contains(WORK "/out.txt", "vertex"));
  /* hush eval: psf and psf+FILTER are filters */
  CHECK(run("eval --scene builtin:cornell --out '" WORK "/e' --size 40x24 --frames 3 --ref-spp 4 "
            "--filters psf,psf+accumulate --set psf.scale=3 --no-video --quiet --strict") == 0);
  CHECK(file_contains(WORK "/e/summary.md", "| psf |"));
  CHECK(file_contains(WORK "/e/summary.md", "| psf+accumulate |"));
  CHECK(file_contains(WORK "/e/status.csv", "psf+accumulate,ok"));
  CHECK(file_contains(WORK "/e/psf.csv", "\n2,"));
  CHECK(run("eval --scene builtin:cornell --out '" WORK "/e2' --size 40x24 --frames 2 "
            "--filters psf+nosuch --quiet") != 0);
}

/* docs/psf.md has a row for every parameter of the table. */
static void test_docs(void) {
  FILE *f = fopen(HUSH_SOURCE_DIR "/docs/psf.md", "rb");
  REQUIRE(f);
  static char text[1 << 16];
  const size_t n = fread(text, 1, sizeof text - 1, f);
  fclose(f);
  text[n] = '\0';
  uint32_t count = 0;
  const hush_param_info *p = hush_psf_params(&count);
  for (uint32_t i = 0; i < count; i++) {
    char row[64];
    snprintf(row, sizeof row, "| `%s` |", p[i].name);
    CHECK_MSG(strstr(text, row) != NULL, "docs/psf.md has no row for parameter %s", p[i].name);
  }
}

/* Records of random words (NaN and Inf patterns too) to planes, for
 * lengths that take the 16-record transpose, the tail, or both. */
static void test_block_fill(void) {
  enum { N = HUSH_PSF_KEY_BLOCK };
  static hush_psf_vertex v[N];
  static uint32_t words[15 * N];
  for (size_t k = 0; k < 15 * N; k++) words[k] = (uint32_t)(rnd() * 4294967040.0f) ^ (uint32_t)k;
  memcpy(v, words, sizeof v);
  const uint32_t lengths[] = {1, 15, 16, 17, 37, 48, N};
  int wrong = 0;
  for (size_t t = 0; t < sizeof lengths / sizeof *lengths; t++) {
    static hush_psf_block b;
    memset(&b, 0xa5, sizeof b);
    hush_psf_planes planes;
    hush__psf_block_fill(&b, v, lengths[t], &planes);
    for (uint32_t j = 0; j < lengths[t]; j++) {
      const uint32_t *rec = words + 15 * (size_t)j;
      for (int w = 0; w < 13; w++) wrong += memcmp(&b.f[w][j], &rec[w], 4) != 0;
      wrong += b.seed[j] != rec[13];
      wrong += b.flags[j] != rec[14];
    }
    for (int c = 0; c < 3; c++) {
      wrong += planes.position[c] != b.f[c] || planes.normal[c] != b.f[3 + c];
      wrong += planes.origin[c] != b.f[6 + c] || planes.radiance[c] != b.f[10 + c];
    }
    wrong += planes.distance != b.f[9] || planes.seed != b.seed || planes.flags != b.flags;
  }
  CHECK_MSG(wrong == 0, "block fill: %d words in the wrong place", wrong);
}

int main(void) {
  /* one worker thread for the library's own loops: the concurrency under
   * test is test_threads's pthreads (ThreadSanitizer understands them) */
  hush_device dev = hush_device_new("threads=1");
  REQUIRE(dev);
  test_block_fill();
  test_exact_means(dev);
  test_glossy_cells(dev);
  test_batches(dev);
  test_no_mixing(dev);
  test_threads(dev);
  test_temporal(dev);
  test_errors(dev);
  test_renderer(dev);
  test_docs();
  test_cli(dev);
  hush_device_release(dev);
  return check_summary();
}
