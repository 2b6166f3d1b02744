/*
 * cmd_bench.c — `hush bench`: filter timings only, on synthetic frames (or,
 * with --scene, frames of the path tracer) held in memory (no file I/O in
 * the loop). A few distinct frames of the moving synthetic scene (or of the
 * scene's camera move) are made once and played forwards and backwards, so
 * consecutive frames are always neighbours and history behaves as in a real
 * sequence. Warm-up frames are excluded; per stage and in total it reports
 * the median and the 5th and 95th percentiles, with the thread count and the
 * CPU model, as a table on stdout and optionally as CSV.
 *
 * "psf" (hashed path-space filtering, src/psf/) is not a frame filter: it
 * averages the path tracer's vertices. With --scene the vertices each frame
 * selected while it rendered are kept, and replayed through the public API
 * (hush_psf_add_vertices from the device's threads, 8 rows of vertices per
 * call, then hush_psf_resolve and hush_psf_lookup), as a path tracer using
 * the library would call it.
 */
#include "cli.h"
#include "scene_frames.h"

#include "core/hmath.h"
#include "core/timer.h"
#include "eval/synthetic.h"
#include "io/atomic_file.h"
#include "io/frame.h"

#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define MAX_FILTERS 16
#define MAX_STAGES 16

static const char *const help_text =
    "usage: hush bench [options]\n"
    "\n"
    "Times filters on synthetic frames already in memory (the scene of\n"
    "`hush synth`: orbiting camera, moving object), or with --scene on frames\n"
    "of a scene rendered at 1 spp by the path tracer (as `hush render`). Frames\n"
    "are made once, then played forwards and backwards; the first --warmup\n"
    "frames are not timed.\n"
    "Prints, per filter, the median and 5th/95th percentile of each stage and\n"
    "of the whole execute, in milliseconds per frame.\n"
    "\n"
    "options:\n"
    "  --filters A,B,...   filters to time (default: every filter, and psf with\n"
    "                      --scene)\n"
    "  --size WxH          frame size (default 1280x720)\n"
    "  --frames N          timed frames per filter (default 60)\n"
    "  --warmup N          untimed frames first (default 5)\n"
    "  --distinct N        distinct frames made and cycled (default 8)\n"
    "  --threads N         worker threads, 0 = one per core (default 0)\n"
    "  --set KEY=VALUE     a parameter for every filter that has it; repeatable\n"
    "                      (weights=FILE: nca's weights from `hush train-nca`)\n"
    "  --scene SCENE       render the frames: PATH/scene.json or builtin:NAME\n"
    "                      (default: synthetic frames)\n"
    "  --path MOVE         with --scene: the camera move, as `hush render --path`\n"
    "  --all-outputs       also bind (and so time the export of) each filter's\n"
    "                      optional outputs (fitted, variance_estimate,\n"
    "                      history_length, ...); by default only the\n"
    "                      required output is bound, as a renderer would\n"
    "  --csv FILE          also write the results as CSV\n"
    "  -h, --help          show this help\n"
    "Filters that need the layer 'gradient' (asvgf) get a stand-in: per 3x3\n"
    "stratum the centre pixel's luminance as current and previous value, the\n"
    "previous one doubled in the left quarter of the frame (the lighting\n"
    "changed there: the history is shortened, as after a light went off).\n"
    "psf (hashed path-space filtering) needs --scene: it replays the vertices\n"
    "each frame selected while rendering through hush_psf_add_vertices (the\n"
    "device's threads, 8 rows of vertices per call), hush_psf_resolve and\n"
    "hush_psf_lookup, and also prints the medians of its statistics; --set\n"
    "applies to it too (scale=8 or psf.scale=8, table_size=2, vertex=2, ...).\n";

typedef struct bench_options {
  char filters[512];
  uint32_t width, height, frames, warmup, distinct, threads;
  const char *sets[64];
  int set_count;
  const char *csv;
  const char *scene, *path; /* --scene: rendered frames */
  int psf;                  /* psf is timed (named, or the default list with --scene) */
  int all_outputs;          /* --all-outputs: the optional outputs bound too */
} bench_options;

/* What psf replays: per distinct frame, the vertices it selected. */
typedef struct psf_frames {
  hush_psf_vertex *vertices[256]; /* owned */
  uint32_t count[256];
  float pixel_angle[256];
} psf_frames;

typedef struct stage_times {
  const char *name;
  double *ms; /* one per timed frame */
} stage_times;

typedef struct bench_result {
  const char *filter;
  stage_times stages[MAX_STAGES + 1]; /* the last used one is "total" */
  uint32_t stage_count;
} bench_result;

static void parse_options(int argc, char **argv, bench_options *o) {
  cli_args a;
  cli_args_init(&a, "bench", argc, argv);
  memset(o, 0, sizeof *o);
  o->width = 1280;
  o->height = 720;
  o->frames = 60;
  o->warmup = 5;
  o->distinct = 8;
  const char *arg, *v;
  while (cli_next(&a, &arg)) {
    if (cli_is_help(arg)) {
      fputs(help_text, stdout);
      exit(0);
    } else if (cli_option(&a, arg, "--filters", &v)) {
      if (strlen(v) >= sizeof o->filters) cli_usage_error(a.cmd, "--filters: list too long");
      strcpy(o->filters, v);
    } else if (cli_option(&a, arg, "--size", &v)) {
      cli_parse_size(a.cmd, "--size", v, &o->width, &o->height);
    } else if (cli_option(&a, arg, "--frames", &v)) {
      o->frames = cli_parse_uint(a.cmd, "--frames", v, 1, 100000);
    } else if (cli_option(&a, arg, "--warmup", &v)) {
      o->warmup = cli_parse_uint(a.cmd, "--warmup", v, 0, 10000);
    } else if (cli_option(&a, arg, "--distinct", &v)) {
      o->distinct = cli_parse_uint(a.cmd, "--distinct", v, 1, 256);
    } else if (cli_option(&a, arg, "--threads", &v)) {
      o->threads = cli_parse_uint(a.cmd, "--threads", v, 0, 1024);
    } else if (cli_option(&a, arg, "--set", &v)) {
      if (!strchr(v, '=') || v[0] == '=') cli_usage_error(a.cmd, "--set: expected KEY=VALUE, got '%s'", v);
      if (o->set_count == 64) cli_usage_error(a.cmd, "--set: too many");
      o->sets[o->set_count++] = v;
    } else if (cli_switch(&a, arg, "--all-outputs")) {
      o->all_outputs = 1;
    } else if (cli_option(&a, arg, "--csv", &v)) {
      o->csv = v;
    } else if (cli_option(&a, arg, "--scene", &v)) {
      o->scene = v;
    } else if (cli_option(&a, arg, "--path", &v)) {
      o->path = v;
    } else if (cli_is_positional(&a, arg)) {
      cli_usage_error(a.cmd, "unexpected argument '%s' (see hush bench --help)", arg);
    } else {
      cli_unknown_option(&a, arg);
    }
  }
  if (o->path && !o->scene) cli_usage_error(a.cmd, "--path goes with --scene");
}

/* Frame index played at step k: 0 1 .. d-1 d-2 .. 1 0 1 .. (a triangle wave). */
static uint32_t played_frame(uint32_t k, uint32_t distinct) {
  if (distinct < 2) return 0;
  const uint32_t period = 2 * (distinct - 1);
  const uint32_t t = k % period;
  return t < distinct ? t : period - t;
}

static int compare_double(const void *a, const void *b) {
  const double x = *(const double *)a, y = *(const double *)b;
  return (x > y) - (x < y);
}

/* Nearest-rank percentile of sorted values. */
static double percentile(const double *sorted, uint32_t n, double q) {
  if (n == 0) return 0.0;
  double pos = q * (double)(n - 1);
  uint32_t i = (uint32_t)pos;
  const double f = pos - i;
  return i + 1 < n ? sorted[i] * (1.0 - f) + sorted[i + 1] * f : sorted[i];
}

/* The value of the first line of /proc/cpuinfo's text whose key is `key`
 * into buf (empty when absent). */
static void cpuinfo_value(const char *text, const char *key, char *buf, size_t size) {
  buf[0] = '\0';
  const size_t klen = strlen(key);
  for (const char *line = text; line; line = strchr(line, '\n')) {
    if (*line == '\n') line++;
    if (strncmp(line, key, klen) != 0) continue;
    /* the whole key: only blanks between it and the colon ("model" is not
     * "model name") */
    const char *colon = line + klen;
    while (*colon == ' ' || *colon == '\t') colon++;
    if (*colon != ':') continue;
    colon++;
    while (*colon == ' ') colon++;
    snprintf(buf, size, "%.*s", (int)strcspn(colon, "\n"), colon);
    return;
  }
}

/* The CPU as the bench reports it: its name, family and model (the VMs'
 * names do not tell their generations apart: "AMD EPYC" was a Zen 4 in
 * some sessions, a Zen 3 in others), and the vector loops this build
 * runs, which set most of the filters' speed. No commas: it is a CSV
 * field. */
static void cpu_model(char *buf, size_t size) {
  /* the first processor's lines are enough: read its part once */
  char text[8192] = "";
  FILE *f = fopen("/proc/cpuinfo", "r");
  if (f) {
    text[fread(text, 1, sizeof text - 1, f)] = '\0';
    fclose(f);
  }
  char name[128], family[16], model[16];
  cpuinfo_value(text, "model name", name, sizeof name);
  cpuinfo_value(text, "cpu family", family, sizeof family);
  cpuinfo_value(text, "model", model, sizeof model);
#if defined(__AVX512F__)
  const char *isa = "AVX-512";
#elif defined(__AVX2__)
  const char *isa = "AVX2";
#elif defined(__SSE2__)
  const char *isa = "SSE2";
#else
  const char *isa = "scalar";
#endif
  snprintf(buf, size, "%s (family %s model %s; %s build)", name[0] ? name : "unknown CPU",
           family[0] ? family : "?", model[0] ? model : "?", isa);
  for (char *c = buf; *c; c++)
    if (*c == ',') *c = ';';
}

#define SET_KEY_MAX 128

/* The name of --set value i (before its '=', checked at parsing) into key;
 * returns its value, or NULL (printed) when the name is too long. */
static const char *set_key(const bench_options *o, int i, char key[SET_KEY_MAX]) {
  const char *eq = strchr(o->sets[i], '=');
  const size_t len = (size_t)(eq - o->sets[i]);
  if (len >= SET_KEY_MAX) {
    cli_error("bench", "--set %s: name too long", o->sets[i]);
    return NULL;
  }
  memcpy(key, o->sets[i], len);
  key[len] = '\0';
  return eq + 1;
}

static int apply_sets(const bench_options *o, hush_device device, hush_filter f) {
  for (int i = 0; i < o->set_count; i++) {
    char key[SET_KEY_MAX];
    const char *value = set_key(o, i, key);
    if (!value) return CLI_EXIT_RUNTIME;
    /* parameters are per filter; skip those this one lacks */
    if (!cli_filter_has_param(f, key)) continue;
    const hush_status st = cli_filter_set(f, key, value);
    if (st != HUSH_OK) return cli_device_error("bench", device, st, o->sets[i]);
  }
  return 0;
}

/* Is `name` one of psf's parameters (those of the table, or the renderer's
 * "vertex")? */
static int is_psf_param(const char *name) {
  if (strcmp(name, "vertex") == 0) return 1;
  uint32_t n;
  const hush_param_info *p = hush_psf_params(&n);
  for (uint32_t i = 0; i < n; i++)
    if (strcmp(p[i].name, name) == 0) return 1;
  return 0;
}

/* Applies the --set values psf has: to the renderer (r, for "vertex") or to
 * the filter object (psf); one of them is NULL. */
static int apply_psf_sets(const bench_options *o, hush_device device, hush_psf_renderer *r,
                          hush_psf psf) {
  for (int i = 0; i < o->set_count; i++) {
    char key[SET_KEY_MAX];
    const char *value = set_key(o, i, key);
    if (!value) return CLI_EXIT_RUNTIME;
    const char *name = strncmp(key, "psf.", 4) == 0 ? key + 4 : key; /* as hush eval's */
    if (!is_psf_param(name)) continue;
    hush_status st = HUSH_OK;
    if (r) st = hush__psf_renderer_set(r, name, value);
    else if (strcmp(name, "vertex") != 0) st = hush_psf_set_string(psf, name, value);
    if (st != HUSH_OK) return cli_device_error("bench", device, st, o->sets[i]);
  }
  return 0;
}

static stage_times *stage_slot(bench_result *r, const char *name, uint32_t frames) {
  for (uint32_t i = 0; i < r->stage_count; i++)
    if (strcmp(r->stages[i].name, name) == 0) return &r->stages[i];
  if (r->stage_count == MAX_STAGES + 1) return NULL;
  stage_times *s = &r->stages[r->stage_count++];
  s->name = name;
  s->ms = calloc(frames, sizeof *s->ms);
  return s->ms ? s : NULL;
}

static int bench_filter(const bench_options *o, hush_device device, hush_frame *frames,
                        const hush_camera *cams, const char *name, bench_result *res) {
  hush_filter f = hush_filter_new(device, name);
  if (!f) return cli_device_error("bench", device, HUSH_ERROR_NOT_FOUND, NULL);
  res->filter = hush_filter_get_class(f)->name;
  int rc = apply_sets(o, device, f);
  hush_frame out = rc ? NULL : hush_frame_new(device, o->width, o->height);
  const hush_filter_class_info *cls = hush_filter_get_class(f);
  for (uint32_t i = 0; !rc && out && i < cls->image_count; i++) {
    if (cls->images[i].role != HUSH_IMAGE_OUTPUT) continue;
    if (!cls->images[i].required && !o->all_outputs) continue;
    hush_image_view view;
    hush_status st = hush_frame_add_layer(out, cls->images[i].name, cls->images[i].channels, &view);
    if (st == HUSH_OK) st = hush_filter_set_image(f, cls->images[i].name, &view);
    if (st != HUSH_OK) rc = cli_device_error("bench", device, st, cls->images[i].name);
  }
  if (!out && !rc) rc = cli_device_error("bench", device, HUSH_ERROR_OUT_OF_MEMORY, NULL);
  const uint32_t total = o->warmup + o->frames;
  uint32_t prev = 0;
  for (uint32_t k = 0; k < total && !rc; k++) {
    const uint32_t idx = played_frame(k, o->distinct);
    rc = cli_bind_inputs("bench", device, f, frames[idx], "synthetic frame");
    if (!rc && k == 0) {
      const hush_status st = hush_filter_commit(f);
      if (st != HUSH_OK) rc = cli_device_error("bench", device, st, NULL);
    }
    if (rc) break;
    hush_frame_info info;
    hush_frame_info_init(&info);
    info.frame_index = k;
    memcpy(info.world_to_view, cams[idx].world_to_view, sizeof info.world_to_view);
    memcpy(info.view_to_clip, cams[idx].view_to_clip, sizeof info.view_to_clip);
    memcpy(info.prev_world_to_view, cams[prev].world_to_view, sizeof info.prev_world_to_view);
    memcpy(info.prev_view_to_clip, cams[prev].view_to_clip, sizeof info.prev_view_to_clip);
    /* the synthetic motion vectors are relative to frame idx-1, which is the
     * previous frame only on the way forwards: use the cameras */
    info.motion = HUSH_MOTION_CAMERA;
    info.history = k == 0 ? HUSH_HISTORY_RESET : HUSH_HISTORY_CONTINUE;
    const double t0 = hush__now_ms();
    const hush_status st = hush_filter_execute(f, &info);
    const double ms = hush__now_ms() - t0;
    if (st != HUSH_OK) {
      rc = cli_device_error("bench", device, st, name);
      break;
    }
    prev = idx;
    if (k < o->warmup) continue;
    const char *const *names;
    const double *stage_ms;
    uint32_t count;
    hush_filter_get_timings(f, &names, &stage_ms, &count);
    for (uint32_t s = 0; s < count; s++) {
      stage_times *slot = stage_slot(res, names[s], o->frames);
      if (slot) slot->ms[k - o->warmup] = stage_ms[s];
    }
    stage_times *slot = stage_slot(res, "total", o->frames);
    if (slot) slot->ms[k - o->warmup] = ms;
  }
  hush_frame_release(out);
  hush_filter_release(f);
  return rc;
}

/* Vertices per hush_psf_add_vertices call: 8 rows, as the renderer's bands
 * (each call groups its vertices by cell before it visits the table). */
static uint32_t psf_call_size(const bench_options *o) { return 8u * o->width; }

enum { PSF_ADD, PSF_LOOKUP };

/* Adds (PSF_ADD) or looks up (PSF_LOOKUP) the n vertices v in calls of
 * `call` vertices from the device's threads; returns the first failure. */
static hush_status psf_calls(hush_psf psf, int kind, const hush_psf_vertex *v, uint32_t n,
                             uint32_t call, uint32_t *tickets, float *rgb, int threads) {
  const int64_t calls = ((int64_t)n + call - 1) / call;
  hush_status first = HUSH_OK;
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads)
  for (int64_t c = 0; c < calls; c++) {
    const uint32_t at = (uint32_t)c * call, m = n - at < call ? n - at : call;
    const hush_status st = kind == PSF_ADD ? hush_psf_add_vertices(psf, v + at, m, tickets + at)
                                     : hush_psf_lookup(psf, v + at, tickets + at, m, rgb + 3 * (size_t)at);
    if (st != HUSH_OK) {
#pragma omp critical(psf_bench_status)
      if (first == HUSH_OK) first = st;
    }
  }
  return first;
}

/* The statistics kept per timed frame, medians printed after the stage table. */
enum { S_VERTICES, S_CELLS, S_COLLISIONS, S_FAILED, S_OCCUPANCY, S_COUNT };

static double median_of(double *v, uint32_t n) {
  qsort(v, n, sizeof *v, compare_double);
  return percentile(v, n, 0.5);
}

/* psf through the public API on the recorded vertices, frames played as the
 * filters' (history continues; the first step resets it). */
static int bench_psf(const bench_options *o, hush_device device, const psf_frames *pf,
                     bench_result *res, char *line, size_t line_size) {
  res->filter = "psf";
  uint32_t most = 0;
  for (uint32_t i = 0; i < o->distinct; i++) most = pf->count[i] > most ? pf->count[i] : most;
  hush_psf psf = hush_psf_new(device, o->width, o->height);
  if (!psf) return cli_device_error("bench", device, HUSH_ERROR_OUT_OF_MEMORY, "psf");
  int rc = apply_psf_sets(o, device, NULL, psf);
  uint32_t *tickets = malloc(((size_t)most + 1) * sizeof *tickets);
  float *rgb = malloc(((size_t)most + 1) * 3 * sizeof *rgb);
  double *stat = calloc((size_t)S_COUNT * o->frames, sizeof *stat); /* [S_*][frame] */
  if (!rc && !(tickets && rgb && stat)) rc = cli_error("bench", "out of memory");
  const int threads = hush_device_threads(device);
  const uint32_t call = psf_call_size(o);
  const char *names[3] = {"add", "resolve", "lookup"};
  for (uint32_t k = 0; k < o->warmup + o->frames && !rc; k++) {
    const uint32_t idx = played_frame(k, o->distinct);
    const hush_psf_vertex *v = pf->vertices[idx];
    const uint32_t n = pf->count[idx];
    const double t0 = hush__now_ms();
    hush_status s = hush_psf_begin_frame(psf, k, pf->pixel_angle[idx],
                                         k == 0 ? HUSH_HISTORY_RESET : HUSH_HISTORY_CONTINUE);
    if (s == HUSH_OK) s = psf_calls(psf, PSF_ADD, v, n, call, tickets, rgb, threads);
    const double t1 = hush__now_ms();
    if (s == HUSH_OK) s = hush_psf_resolve(psf);
    const double t2 = hush__now_ms();
    if (s == HUSH_OK) s = psf_calls(psf, PSF_LOOKUP, v, n, call, tickets, rgb, threads);
    const double t3 = hush__now_ms();
    if (s != HUSH_OK) {
      rc = cli_device_error("bench", device, s, "psf");
      break;
    }
    if (k < o->warmup) continue;
    const uint32_t f = k - o->warmup;
    const double ms[4] = {t1 - t0, t2 - t1, t3 - t2, t3 - t0};
    for (int i = 0; i < 4; i++) {
      stage_times *slot = stage_slot(res, i < 3 ? names[i] : "total", o->frames);
      if (slot) slot->ms[f] = ms[i];
    }
    hush_psf_stats ps;
    hush_psf_get_stats(psf, &ps);
    const double nv = ps.vertices ? (double)ps.vertices : 1.0;
    const double of_frame[S_COUNT] = {(double)ps.vertices, (double)ps.cells_used,
                                      100.0 * (double)ps.collisions / nv,
                                      100.0 * (double)ps.failed / nv, 100.0 * ps.occupancy};
    for (int i = 0; i < S_COUNT; i++) stat[(size_t)i * o->frames + f] = of_frame[i];
  }
  double med[S_COUNT] = {0};
  for (int i = 0; !rc && i < S_COUNT; i++) med[i] = median_of(stat + (size_t)i * o->frames, o->frames);
  if (!rc)
    snprintf(line, line_size, "%-12s medians per frame: %.0f vertices, %.0f cells, collisions %.1f%%, no cell %.2f%%, "
           "occupancy %.1f%% (%u vertices per hush_psf_add_vertices call)\n", "",
           med[S_VERTICES], med[S_CELLS], med[S_COLLISIONS], med[S_FAILED], med[S_OCCUPANCY], call);
  free(stat);
  free(tickets);
  free(rgb);
  hush_psf_release(psf);
  return rc;
}

static void print_result(const bench_result *r, uint32_t frames, FILE *csv, const char *cpu,
                         int threads, const bench_options *o) {
  printf("%-12s %-14s %9s %9s %9s\n", r->filter, "stage", "median", "p5", "p95");
  for (uint32_t i = 0; i < r->stage_count; i++) {
    qsort(r->stages[i].ms, frames, sizeof(double), compare_double);
    const double med = percentile(r->stages[i].ms, frames, 0.5);
    const double p5 = percentile(r->stages[i].ms, frames, 0.05);
    const double p95 = percentile(r->stages[i].ms, frames, 0.95);
    printf("%-12s %-14s %9.3f %9.3f %9.3f\n", "", r->stages[i].name, med, p5, p95);
    if (csv)
      fprintf(csv, "%s,%s,%u,%u,%u,%d,\"%s\",%.4f,%.4f,%.4f\n", r->filter, r->stages[i].name,
              o->width, o->height, frames, threads, cpu, med, p5, p95);
  }
}

static void free_result(bench_result *r) {
  for (uint32_t i = 0; i < r->stage_count; i++) free(r->stages[i].ms);
  memset(r, 0, sizeof *r);
}

/* The distinct frames rendered by the path tracer at 1 spp, frames 0 ..
 * distinct-1 of the camera move; with pf, also the vertices psf selected in
 * each. */
static int render_frames(const bench_options *o, hush_device device, hush_frame *frames,
                         hush_camera *cams, psf_frames *pf) {
  scene_frames sf;
  int rc = scene_frames_open(&sf, "bench", device, o->scene, o->path, o->width, o->height,
                             o->distinct);
  hush_render_params params;
  hush__render_defaults(&params);
  hush_psf_renderer *r = NULL;
  if (!rc && pf) {
    const hush_status st =
        hush__psf_renderer_new(device, sf.width, sf.height, params.spp, 1, &r);
    rc = st == HUSH_OK ? apply_psf_sets(o, device, r, NULL) : cli_device_error("bench", device, st, "psf");
    sf.psf = r;
  }
  for (uint32_t i = 0; !rc && i < o->distinct; i++) {
    rc = scene_frames_render(&sf, i, &params, (int)o->threads, NULL, &frames[i], &cams[i]);
    if (!rc && r) {
      const hush_status st = hush__psf_renderer_vertices(r, &pf->vertices[i], &pf->count[i],
                                                         &pf->pixel_angle[i]);
      if (st != HUSH_OK) rc = cli_device_error("bench", device, st, "psf");
    }
  }
  scene_frames_close(&sf);
  hush__psf_renderer_free(r);
  return rc;
}

static int make_frames(const bench_options *o, hush_device device, hush_frame *frames,
                       hush_camera *cams, psf_frames *pf) {
  if (o->scene) return render_frames(o, device, frames, cams, pf);
  hush_synth_params p;
  hush__synth_defaults(&p);
  p.width = o->width;
  p.height = o->height;
  p.frames = o->distinct;
  hush_status st = hush__synth_validate(device, &p);
  for (uint32_t i = 0; st == HUSH_OK && i < o->distinct; i++)
    st = hush__synth_frame(device, &p, i, &frames[i], &cams[i]);
  return st == HUSH_OK ? 0 : cli_device_error("bench", device, st, "synthetic frames");
}

/* Does a selected filter need the image `image` (a required input)? */
static int needs_image(const char *const *names, uint32_t count, const char *image) {
  for (uint32_t k = 0; k < count; k++) {
    const hush_filter_class_info *c = hush_filter_class_find(names[k]);
    for (uint32_t i = 0; c && i < c->image_count; i++)
      if (c->images[i].required && strcmp(c->images[i].name, image) == 0) return 1;
  }
  return 0;
}

/* A stand-in for the renderer's temporal gradient samples (`hush render
 * --gradients`; the frames here are played back and forth, so real ones
 * would not match): per 3x3 stratum, landing index 4 (its centre pixel, or
 * the last one of a partial stratum), current luminance c = that pixel's,
 * previous p = c, except p = 2c in the left quarter of the frame (lambda
 * 0.5 there), so the history lowering of asvgf and the spatial variance
 * estimate it brings on are timed as on a frame where the lighting changed
 * in part of the view. Frames that already have the layer keep it. */
static int add_gradients(hush_device device, hush_frame *frames, uint32_t count) {
  for (uint32_t k = 0; k < count; k++) {
    if (hush__frame_find(frames[k], "gradient")) continue;
    const hush_layer *color = hush__frame_find(frames[k], "color");
    if (!color) return cli_error("bench", "frame without a color layer");
    hush_status st = hush_frame_add_layer(frames[k], "gradient", 3, NULL);
    if (st != HUSH_OK) return cli_device_error("bench", device, st, "gradient");
    color = hush__frame_find(frames[k], "color"); /* adding may have moved it */
    const hush_layer *g = hush__frame_find(frames[k], "gradient");
    const uint32_t W = hush_frame_width(frames[k]), H = hush_frame_height(frames[k]);
    for (uint32_t y = 0; y < H; y++)
      for (uint32_t x = 0; x < W; x++) {
        const uint32_t sx = x / 3, sy = y / 3;
        const uint32_t lx = 3 * sx + 1 < W ? 3 * sx + 1 : W - 1;
        const uint32_t ly = 3 * sy + 1 < H ? 3 * sy + 1 : H - 1;
        const float *c = color->pixels + ((size_t)ly * W + lx) * color->channels;
        const float l = hush_luminance(c[0], c[1], c[2]);
        float *o = g->pixels + ((size_t)y * W + x) * 3;
        o[0] = l;
        o[1] = x < W / 4 ? 2.0f * l : l;
        o[2] = (float)((ly - 3 * sy) * 3 + (lx - 3 * sx));
      }
  }
  return 0;
}

/* Fills names[] from the comma list (or every class) and checks each;
 * "psf" sets o->psf instead (and needs --scene). */
static int filter_list(bench_options *o, char *buf, const char **names, uint32_t *count) {
  *count = 0;
  if (!o->filters[0]) {
    for (uint32_t i = 0; i < hush_filter_class_count() && i < MAX_FILTERS; i++)
      names[(*count)++] = hush_filter_class_at(i)->name;
    o->psf = o->scene != NULL;
    return 0;
  }
  strcpy(buf, o->filters);
  for (char *tok = strtok(buf, ","); tok; tok = strtok(NULL, ",")) {
    if (strcmp(tok, "psf") == 0) {
      if (!o->scene)
        return cli_error("bench", "psf filters the path tracer's vertices: it needs --scene "
                                  "(e.g. --scene builtin:courtyard)");
      o->psf = 1;
      continue;
    }
    if (!hush_filter_class_find(tok)) return cli_error("bench", "unknown filter '%s'", tok);
    if (*count == MAX_FILTERS) return cli_error("bench", "more than %d filters", MAX_FILTERS);
    names[(*count)++] = tok;
  }
  return *count || o->psf ? 0 : cli_error("bench", "--filters is empty");
}

int cmd_bench(int argc, char **argv) {
  bench_options o;
  parse_options(argc, argv, &o);
  char list_buf[512];
  const char *names[MAX_FILTERS];
  uint32_t nf;
  if (filter_list(&o, list_buf, names, &nf)) return CLI_EXIT_RUNTIME;

  hush_device device = cli_device_new("bench", o.threads);
  if (!device) return CLI_EXIT_RUNTIME;
  hush_frame *frames = calloc(o.distinct, sizeof *frames);
  hush_camera *cams = calloc(o.distinct, sizeof *cams);
  psf_frames *pf = o.psf ? calloc(1, sizeof *pf) : NULL;
  int rc = frames && cams && (pf || !o.psf) ? make_frames(&o, device, frames, cams, pf)
                                            : cli_error("bench", "out of memory");
  if (!rc && needs_image(names, nf, "gradient")) rc = add_gradients(device, frames, o.distinct);

  char cpu[256];
  cpu_model(cpu, sizeof cpu);
  const int threads = hush_device_threads(device);
  FILE *csv = NULL;
  char tmp[HUSH_PATH_MAX];
  if (!rc && o.csv) {
    csv = hush__atomic_open(device, o.csv, tmp);
    if (!csv) rc = cli_device_error("bench", device, HUSH_ERROR_IO, o.csv);
    else fprintf(csv, "filter,stage,width,height,frames,threads,cpu,median_ms,p5_ms,p95_ms\n");
  }
  if (!rc)
    printf("hush bench: %ux%u, %u timed frames (+%u warm-up), %d thread(s), %s\n", o.width,
           o.height, o.frames, o.warmup, threads, cpu);
  for (uint32_t i = 0; i < nf && !rc; i++) {
    bench_result res;
    memset(&res, 0, sizeof res);
    rc = bench_filter(&o, device, frames, cams, names[i], &res);
    if (!rc) print_result(&res, o.frames, csv, cpu, threads, &o);
    free_result(&res);
  }
  if (!rc && pf) {
    bench_result res;
    memset(&res, 0, sizeof res);
    char line[512];
    rc = bench_psf(&o, device, pf, &res, line, sizeof line);
    if (!rc) {
      print_result(&res, o.frames, csv, cpu, threads, &o);
      fputs(line, stdout);
    }
    free_result(&res);
  }
  if (csv) {
    if (rc)
      hush__atomic_abort(csv, tmp);
    else if (hush__atomic_commit(device, csv, tmp, o.csv) != HUSH_OK)
      rc = cli_device_error("bench", device, HUSH_ERROR_IO, o.csv);
  }
  for (uint32_t i = 0; frames && i < o.distinct; i++) hush_frame_release(frames[i]);
  free(frames);
  free(cams);
  for (uint32_t i = 0; pf && i < o.distinct; i++) free(pf->vertices[i]);
  free(pf);
  hush_device_release(device);
  return rc;
}
