/*
 * cmd_render.c — `hush render`: path-traces a frame sequence of a scene
 * (a scene.json manifest or a built-in scene) in the foundation's sequence
 * format: frame_NNNN.exr with noisy radiance and the feature buffers, plus
 * cameras.json and render.json. The 1 spp configuration is that of
 * bmfr-koskela-2019.md §3.1; `--spp N` renders the matching references
 * (same frames, cameras and jitter policy), as in §6.
 */
#include "cli.h"
#include "psf_cli.h"
#include "render_progress.h"

#include "core/timer.h"
#include "io/atomic_file.h"
#include "io/export_bmfr.h"
#include "io/sequence.h"
#include "render/camera.h"
#include "render/gradients.h"
#include "render/lights.h"
#include "render/progressive.h"
#include "render/render.h"
#include "render/scene.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

static const char *const help_text =
    "usage: hush render --scene SCENE --out DIR [options]\n"
    "       hush render --list\n"
    "\n"
    "Path-traces a frame sequence: DIR/frame_NNNN.exr (layers color, albedo,\n"
    "normal, position, depth, depth_gradient, motion, id, vis; spp when --spp > 1\n"
    "or --spp-fraction < 1; variance when --spp > 1), DIR/cameras.json and\n"
    "DIR/render.json.\n"
    "The default is the documents' 1 spp configuration: a jittered primary ray,\n"
    "a shadow ray, one BSDF-sampled secondary ray with its own shadow ray, and MIS.\n"
    "\n"
    "options:\n"
    "  --scene SCENE        PATH/scene.json (or its folder) or builtin:NAME (required)\n"
    "  --out DIR            output directory, created if missing (required)\n"
    "  --path MOVE          camera: a camera-path.json file, path (the scene's own\n"
    "                       path), static, orbit or dolly (default: the scene's\n"
    "                       path if it has one, else orbit)\n"
    "  --size WxH           frame size (default: the scene's resolution, else 640x360)\n"
    "  --frames N           frames to render (default: the path's length, else 16)\n"
    "  --first K            first frame of the animation (default 0)\n"
    "  --spp N              samples per pixel, 1..1048576 (default 1); N > 1 renders\n"
    "                       references, with a progress bar per frame\n"
    "  --spp-fraction F     trace only a fraction F in (0, 1] of the pixels per frame\n"
    "                       (F = m/k^2, k <= 16: 0.25, 0.5, 1/9, 0.1 ...): m pixels of\n"
    "                       every k x k block, rotating so each pixel is traced once\n"
    "                       every k^2/m frames; the others are holes: spp 0, all\n"
    "                       other layers 0 (vis -1) (docs/renderer.md)\n"
    "  --bounces N          BSDF-sampled secondary rays per path, 0..64 (default 1:\n"
    "                       the papers' configuration; 0: direct light only)\n"
    "  --mirror-depth N     primary surface replacement: where a pixel's camera ray\n"
    "                       meets planar mirrors (smooth conductors on flat\n"
    "                       triangles), the G-buffer describes the surface behind\n"
    "                       up to N of them, reflected into the mirrors' virtual\n"
    "                       world, and its emission counts as seen directly;\n"
    "                       0..3, at most --bounces (default 3; 0: the mirror's\n"
    "                       own features) (docs/renderer.md)\n"
    "  --seed S             random seed (default 1)\n"
    "  --sampler KIND       random or ld (scrambled Sobol pairs; default random)\n"
    "  --no-jitter          no subpixel jitter (default: Halton(2,3) per frame)\n"
    "  --clamp X            clamp indirect contributions to X (default: off)\n"
    "  --split              also write the layers direct and indirect\n"
    "  --split-lobes        also write the layers diffuse and specular: the\n"
    "                       radiance by the first hit's BSDF lobe (light seen\n"
    "                       directly is diffuse); color is their sum\n"
    "  --gradients          A-SVGF gradient samples (docs/asvgf.md): per 3x3 stratum\n"
    "                       the last frame's brightest sample is forward-projected\n"
    "                       and re-shaded with its old random numbers; layer\n"
    "                       gradient (current and previous luminance, landing\n"
    "                       pixel in the stratum 0..8 or -1); needs --spp 1\n"
    "  --gradient-select R  brightest (default) or random: the pixel of a stratum\n"
    "                       whose sample is re-shaded in the next frame\n"
    "  --gradient-landing M fresh (default): the landing pixel keeps its own fresh\n"
    "                       sample, the re-shaded one measures the gradient only\n"
    "                       (unbiased, +1 path per stratum); sample: the landing\n"
    "                       pixel shows the re-shaded sample (A-SVGF as published;\n"
    "                       with brightest, biased upwards)\n"
    "  --gradient-lobe L    diffuse (default): the gradient compares the first hit's\n"
    "                       diffuse lobe only (a moved eye changes glossy paths);\n"
    "                       all: the whole colour (the papers). These three imply\n"
    "                       --gradients\n"
    "  --png                also write DIR/frame_NNNN.png of the radiance\n"
    "  --export bmfr        also write DIR/bmfr/: colorN.exr (demodulated),\n"
    "                       albedoN.exr, shading_normalN.exr, world_positionN.exr and\n"
    "                       camera_matrices.h, the input of the published BMFR code\n"
    "  --half               write half-float EXRs (depth, position, id, vis stay float)\n"
    "  --psf                also filter with hashed path-space filtering (docs/psf.md):\n"
    "                       each frame gets a layer psf (the filtered radiance; color\n"
    "                       stays the unfiltered one), DIR/psf.csv the per-frame\n"
    "                       statistics, and with --png DIR/frame_NNNN_psf.png\n"
    "  --psf-scale S        cell size in projected pixels (default 8)\n"
    "  --psf-vertex 1|2     filter at the first or second diffuse vertex (default 1)\n"
    "  --psf-table-size T   hash table slots per pixel (default 1)\n"
    "  --psf-jitter J, --psf-probes N, --psf-max-samples N\n"
    "  --psf-set KEY=VALUE  any psf parameter (docs/psf.md); each implies --psf\n"
    "  --psf-bench N        filter each frame N times more and report the median\n"
    "                       times (a benchmark: each repetition also enters the\n"
    "                       history, so the output differs)\n"
    "  --threads N          worker threads, 0 = one per core (default 0)\n"
    "  --quiet              print only warnings and errors (default: progress per\n"
    "                       frame on stderr: time, Mrays/s, time left)\n"
    "  --list               list the built-in scenes and camera moves\n"
    "  -h, --help           show this help\n";

typedef struct render_options {
  const char *scene, *out, *path;
  uint32_t width, height, frames, first;
  int have_size, have_frames;
  hush_render_params params;
  int png, quiet;
  int export_bmfr;
  int gradients;           /* --gradients */
  int gradient_select;     /* hush_gradient_select, --gradient-select */
  int gradient_landing;    /* hush_gradient_landing, --gradient-landing */
  int gradient_lobe;       /* hush_gradient_lobe, --gradient-lobe */
  double spp_fraction;     /* 1: every pixel */
  hush_progressive progressive;
  hush_exr_type exr_type;
  uint32_t threads;
  psf_cli psf;
  uint32_t psf_bench;      /* --psf-bench N */
} render_options;

static void list_builtins(void) {
  printf("built-in scenes (--scene builtin:NAME):\n");
  for (int i = 0; hush__scene_builtin_names[i]; i++)
    printf("  %-16s %s\n", hush__scene_builtin_names[i], hush__scene_builtin_docs[i]);
  printf("\ncamera moves (--path):\n"
         "  path             the scene's camera path (camera-path.json of the manifest)\n"
         "  static           the scene's camera, still\n"
         "  orbit            around the camera's target, %.2g degrees per frame\n"
         "  dolly            towards the target to %.0f%% of the distance and back, every %u "
         "frames\n"
         "  FILE.json        a camera path file: {\"fov_axis\", \"resolution\", \"frames\": "
         "[...]}\n",
         (double)HUSH_ORBIT_DEG_PER_FRAME, (double)(HUSH_DOLLY_MIN * 100.0f), HUSH_DOLLY_PERIOD);
}

/* --spp-fraction: a decimal ("0.25") or a ratio ("1/9"). */
static void parse_fraction(const char *cmd, const char *text, render_options *o) {
  const char *slash = strchr(text, '/');
  if (slash) {
    char num[32];
    const size_t len = (size_t)(slash - text);
    if (len == 0 || len >= sizeof num)
      cli_usage_error(cmd, "--spp-fraction: '%s' is not A/B", text);
    memcpy(num, text, len);
    num[len] = '\0';
    const uint32_t a = cli_parse_uint(cmd, "--spp-fraction", num, 1, 1u << 16);
    const uint32_t b = cli_parse_uint(cmd, "--spp-fraction", slash + 1, 1, 1u << 16);
    o->spp_fraction = (double)a / (double)b;
  } else {
    o->spp_fraction = cli_parse_float(cmd, "--spp-fraction", text, 1e-6f, 1.0f);
  }
  if (!hush__progressive_init(&o->progressive, o->spp_fraction))
    cli_usage_error(cmd,
                    "--spp-fraction: %s is not in (0, 1] or not m/k^2 for a block of k x k "
                    "pixels, k <= %u (try 0.25, 0.5, 1/9, 0.1)",
                    text, HUSH_PROGRESSIVE_MAX_K);
}

static void parse_options(int argc, char **argv, render_options *o) {
  cli_args a;
  cli_args_init(&a, "render", argc, argv);
  memset(o, 0, sizeof *o);
  hush__render_defaults(&o->params);
  o->exr_type = HUSH_EXR_FLOAT;
  o->spp_fraction = 1.0;
  const char *arg, *v;
  while (cli_next(&a, &arg)) {
    if (cli_is_help(arg)) {
      fputs(help_text, stdout);
      exit(0);
    } else if (cli_switch(&a, arg, "--list")) {
      list_builtins();
      exit(0);
    } else if (cli_option(&a, arg, "--scene", &v)) {
      o->scene = v;
    } else if (cli_option(&a, arg, "--out", &v)) {
      o->out = v;
    } else if (cli_option(&a, arg, "--path", &v)) {
      o->path = v;
    } else if (cli_option(&a, arg, "--size", &v)) {
      cli_parse_size(a.cmd, "--size", v, &o->width, &o->height);
      o->have_size = 1;
    } else if (cli_option(&a, arg, "--frames", &v)) {
      o->frames = cli_parse_uint(a.cmd, "--frames", v, 1, 100000);
      o->have_frames = 1;
    } else if (cli_option(&a, arg, "--first", &v)) {
      o->first = cli_parse_uint(a.cmd, "--first", v, 0, 1000000);
    } else if (cli_option(&a, arg, "--spp", &v)) {
      o->params.spp = cli_parse_uint(a.cmd, "--spp", v, 1, 1u << 20);
    } else if (cli_option(&a, arg, "--bounces", &v)) {
      o->params.bounces = (int)cli_parse_uint(a.cmd, "--bounces", v, 0, 64);
    } else if (cli_option(&a, arg, "--seed", &v)) {
      o->params.seed = cli_parse_uint(a.cmd, "--seed", v, 0, UINT32_MAX);
    } else if (cli_option(&a, arg, "--sampler", &v)) {
      if (strcmp(v, "random") == 0)
        o->params.sampler = HUSH_SAMPLER_RANDOM;
      else if (strcmp(v, "ld") == 0)
        o->params.sampler = HUSH_SAMPLER_LD;
      else
        cli_usage_error(a.cmd, "--sampler: unknown sampler '%s' (random or ld)", v);
    } else if (cli_option(&a, arg, "--mirror-depth", &v)) {
      o->params.mirror_depth =
          (int)cli_parse_uint(a.cmd, "--mirror-depth", v, 0, HUSH_RENDER_MIRROR_DEPTH_MAX);
    } else if (cli_switch(&a, arg, "--no-jitter")) {
      o->params.jitter = 0;
    } else if (cli_option(&a, arg, "--clamp", &v)) {
      o->params.clamp = cli_parse_float(a.cmd, "--clamp", v, 1e-6f, 1e30f);
    } else if (cli_switch(&a, arg, "--split")) {
      o->params.split = 1;
    } else if (cli_switch(&a, arg, "--split-lobes")) {
      o->params.split_lobes = 1;
    } else if (cli_option(&a, arg, "--spp-fraction", &v)) {
      parse_fraction(a.cmd, v, o);
    } else if (cli_option(&a, arg, "--export", &v)) {
      if (strcmp(v, "bmfr") != 0)
        cli_usage_error(a.cmd, "--export: unknown layout '%s' (bmfr)", v);
      o->export_bmfr = 1;
    } else if (cli_switch(&a, arg, "--gradients")) {
      o->gradients = 1;
    } else if (cli_option(&a, arg, "--gradient-select", &v)) {
      if (strcmp(v, "brightest") == 0)
        o->gradient_select = HUSH_GRADIENT_SELECT_BRIGHTEST;
      else if (strcmp(v, "random") == 0)
        o->gradient_select = HUSH_GRADIENT_SELECT_RANDOM;
      else
        cli_usage_error(a.cmd, "--gradient-select: unknown rule '%s' (brightest, random)", v);
      o->gradients = 1;
    } else if (cli_option(&a, arg, "--gradient-lobe", &v)) {
      if (strcmp(v, "all") == 0)
        o->gradient_lobe = HUSH_GRADIENT_LOBE_ALL;
      else if (strcmp(v, "diffuse") == 0)
        o->gradient_lobe = HUSH_GRADIENT_LOBE_DIFFUSE;
      else
        cli_usage_error(a.cmd, "--gradient-lobe: unknown lobe '%s' (all, diffuse)", v);
      o->gradients = 1;
    } else if (cli_option(&a, arg, "--gradient-landing", &v)) {
      if (strcmp(v, "fresh") == 0)
        o->gradient_landing = HUSH_GRADIENT_LANDING_FRESH;
      else if (strcmp(v, "sample") == 0)
        o->gradient_landing = HUSH_GRADIENT_LANDING_SAMPLE;
      else
        cli_usage_error(a.cmd, "--gradient-landing: unknown mode '%s' (fresh, sample)", v);
      o->gradients = 1;
    } else if (cli_switch(&a, arg, "--png")) {
      o->png = 1;
    } else if (cli_switch(&a, arg, "--half")) {
      o->exr_type = HUSH_EXR_HALF;
    } else if (cli_option(&a, arg, "--threads", &v)) {
      o->threads = cli_parse_uint(a.cmd, "--threads", v, 0, 1024);
    } else if (cli_switch(&a, arg, "--quiet")) {
      o->quiet = 1;
    } else if (cli_option(&a, arg, "--psf-bench", &v)) {
      o->psf_bench = cli_parse_uint(a.cmd, "--psf-bench", v, 1, 10000);
      o->psf.on = 1;
    } else if (psf_cli_option(&a, arg, &o->psf)) {
      continue;
    } else if (cli_is_positional(&a, arg)) {
      cli_usage_error(a.cmd, "unexpected argument '%s' (the scene goes to --scene)", arg);
    } else {
      cli_unknown_option(&a, arg);
    }
  }
  if (!o->scene) cli_usage_error(a.cmd, "--scene is required (see hush render --help)");
  if (!o->out) cli_usage_error(a.cmd, "--out DIR is required (see hush render --help)");
  if (o->gradients && (o->params.spp != 1 || o->spp_fraction < 1.0))
    cli_usage_error(a.cmd, "--gradients needs one sample on every pixel (--spp 1, no "
                           "--spp-fraction)");
  if (o->path && strcmp(o->path, "path") && strcmp(o->path, "static") &&
      strcmp(o->path, "orbit") && strcmp(o->path, "dolly")) {
    char ext[16];
    cli_extension(o->path, ext, sizeof ext);
    if (strcmp(ext, "json") != 0)
      cli_usage_error(a.cmd,
                      "--path: '%s' is neither a camera move (path, static, orbit, dolly) nor a "
                      ".json camera path",
                      o->path);
  }
}

/* ---- one run ------------------------------------------------------------------ */

typedef struct render_run {
  const render_options *o;
  hush_device device;
  hush_scene scene;
  int have_scene;
  hush_lights lights;
  int have_lights;
  hush_camera_path file_path; /* --path FILE */
  hush_camera_move move;
  const hush_camera_path *path;
  hush_sequence seq;
  int have_seq;
  int tty;
  render_progress progress;
  char bmfr_dir[HUSH_PATH_MAX]; /* --export bmfr */
  psf_cli psf;             /* --psf: the renderer, owned */
  FILE *psf_csv;           /* DIR/psf.csv */
} render_run;

static int fail(render_run *r, hush_status st, const char *context) {
  render_progress_break(&r->progress);
  return cli_device_error("render", r->device, st, context);
}

static int load_scene(render_run *r) {
  const char *s = r->o->scene;
  hush_status st;
  if (strncmp(s, "builtin:", 8) == 0)
    st = hush__scene_builtin(r->device, s + 8, &r->scene);
  else
    st = hush__scene_load(r->device, s, &r->scene);
  if (st != HUSH_OK) return fail(r, st, s);
  r->have_scene = 1;
  st = hush__scene_commit(r->device, &r->scene);
  if (st != HUSH_OK) return fail(r, st, s);
  /* a log line, not a warning: real scenes have a few (living-room 190) */
  if (r->scene.skipped_triangles && !r->o->quiet)
    fprintf(stderr,
            "hush render: %s: skipped %u triangles (zero area, or NaN or infinite vertices)\n", s,
            r->scene.skipped_triangles);
  st = hush__lights_init(r->device, &r->lights, &r->scene);
  if (st != HUSH_OK) return fail(r, st, s);
  r->have_lights = 1;
  return 0;
}

static int choose_camera(render_run *r) {
  const char *p = r->o->path;
  r->path = r->scene.path.frame_count ? &r->scene.path : NULL;
  if (!p) {
    r->move = r->path ? HUSH_MOVE_PATH : HUSH_MOVE_ORBIT;
    return 0;
  }
  if (strcmp(p, "static") == 0) {
    r->move = HUSH_MOVE_STATIC;
  } else if (strcmp(p, "orbit") == 0) {
    r->move = HUSH_MOVE_ORBIT;
  } else if (strcmp(p, "dolly") == 0) {
    r->move = HUSH_MOVE_DOLLY;
  } else if (strcmp(p, "path") == 0) {
    if (!r->path)
      return cli_error("render", "--path path: scene '%s' has no camera path", r->scene.name);
    r->move = HUSH_MOVE_PATH;
  } else {
    const hush_status st = hush__camera_path_load(r->device, p, &r->file_path);
    if (st != HUSH_OK) return fail(r, st, p);
    r->path = &r->file_path;
    r->move = HUSH_MOVE_PATH;
  }
  return 0;
}

static int sequence_motion_vectors(const hush_scene *s) {
  for (uint32_t i = 0; i < s->object_count; i++)
    if (s->objects[i].motion.animated) return 1;
  for (uint32_t i = 0; i < s->sphere_count; i++) {
    const float *v = s->spheres[i].velocity;
    if (v[0] != 0.0f || v[1] != 0.0f || v[2] != 0.0f) return 1;
  }
  return 0;
}

static void progress(void *user, uint32_t done, uint32_t rows) {
  render_run *r = user;
  render_progress_rows(&r->progress, done, rows);
}

static int write_render_json(render_run *r, int argc, char **argv, double seconds, uint64_t rays) {
  char path[HUSH_PATH_MAX], tmp[HUSH_PATH_MAX];
  if ((size_t)snprintf(path, sizeof path, "%s/render.json", r->o->out) >= sizeof path)
    return cli_error("render", "--out: path too long");
  FILE *f = hush__atomic_open(r->device, path, tmp);
  if (!f) return fail(r, HUSH_ERROR_IO, path);
  const hush_render_params *p = &r->o->params;
  static const char *const moves[] = {"path", "static", "orbit", "dolly"};
  fprintf(f, "{\n  \"format\": \"hush-render/1\",\n  \"scene\": ");
  cli_json_string(f, r->o->scene);
  fprintf(f, ",\n  \"scene_name\": ");
  cli_json_string(f, r->scene.name);
  fprintf(f, ",\n  \"camera\": ");
  cli_json_string(f, r->o->path && r->move == HUSH_MOVE_PATH && r->path == &r->file_path
                     ? r->o->path
                     : moves[r->move]);
  fprintf(f,
          ",\n  \"width\": %u,\n  \"height\": %u,\n  \"first_frame\": %u,\n  \"frame_count\": %u,\n"
          "  \"spp\": %u,\n  \"bounces\": %d,\n  \"seed\": %u,\n  \"sampler\": \"%s\",\n"
          "  \"mirror_depth\": %d,\n  \"jitter\": %s,\n  \"clamp\": %.9g,\n  \"split\": %s,\n  \"split_lobes\": %s,\n"
          "  \"spp_fraction\": %.9g,\n  \"progressive_block\": [%u, %u],\n  \"export\": %s,\n"
          "  \"psf\": %s,\n  \"gradients\": %s,\n  \"triangles\": %u,\n  \"skipped_triangles\": %u,\n"
          "  \"seconds\": %.3f,\n  \"rays\": %llu,\n  \"command\": [",
          r->seq.width, r->seq.height, r->o->first, r->seq.frame_count, p->spp, p->bounces, p->seed,
          p->sampler == HUSH_SAMPLER_LD ? "ld" : "random", p->mirror_depth, p->jitter ? "\"halton23\"" : "null",
          (double)p->clamp, p->split ? "true" : "false", p->split_lobes ? "true" : "false",
          r->o->spp_fraction,
          r->o->spp_fraction < 1.0 ? r->o->progressive.k : 1u,
          r->o->spp_fraction < 1.0 ? r->o->progressive.m : 1u,
          r->o->export_bmfr ? "\"bmfr\"" : "null", r->psf.on ? "true" : "false",
          r->o->gradients ? "true" : "false",
          r->scene.triangle_count,
          r->scene.skipped_triangles, seconds, (unsigned long long)rays);
  cli_json_string(f, "hush");
  for (int i = 0; i < argc; i++) {
    fputs(", ", f);
    cli_json_string(f, argv[i]);
  }
  fprintf(f, "]\n}\n");
  const hush_status st = hush__atomic_commit(r->device, f, tmp, path);
  return st == HUSH_OK ? 0 : fail(r, st, path);
}

/* --psf: the statistics of frame f to psf.csv and, unless quiet, stderr. */
static void psf_report(render_run *r, uint32_t f, const hush_psf_timings *t) {
  psf_cli_csv_row(r->psf_csv, &r->psf, f, t);
  if (r->o->quiet) return;
  char line[512];
  psf_cli_stats_line(&r->psf, t, line, sizeof line);
  render_progress_break(&r->progress);
  fprintf(stderr, "frame %u %s\n", f, line);
}

static int compare_ms(const void *a, const void *b) {
  const double x = *(const double *)a, y = *(const double *)b;
  return (x > y) - (x < y);
}

/* --psf-bench N: filters the frame N more times; *t receives the median of
 * each stage over them. */
static hush_status psf_bench(render_run *r, hush_frame frame, hush_psf_timings *t) {
  const uint32_t n = r->o->psf_bench;
  double *ms = malloc((size_t)n * 4 * sizeof *ms);
  if (!ms) return HUSH_ERROR_OUT_OF_MEMORY;
  hush_status st = HUSH_OK;
  for (uint32_t k = 0; k < n && st == HUSH_OK; k++) {
    st = hush__psf_renderer_repeat(r->psf.renderer);
    hush_psf_timings one;
    if (st == HUSH_OK) st = hush__psf_renderer_finish(r->psf.renderer, frame, &one);
    ms[k] = one.add;
    ms[n + k] = one.resolve;
    ms[2 * n + k] = one.lookup;
    ms[3 * n + k] = one.cpu;
  }
  if (st == HUSH_OK) {
    double *out[4] = {&t->add, &t->resolve, &t->lookup, &t->cpu};
    for (int c = 0; c < 4; c++) {
      qsort(ms + (size_t)c * n, n, sizeof *ms, compare_ms);
      *out[c] = ms[(size_t)c * n + n / 2];
    }
  }
  free(ms);
  return st;
}

/* --psf --png: frame_NNNN_psf.png next to frame_NNNN.png (png_path). */
static hush_status write_psf_png(render_run *r, hush_frame frame, const char *png_path) {
  char path[HUSH_PATH_MAX];
  const size_t len = strlen(png_path);
  if (len + 5 > sizeof path) return HUSH_ERROR_IO; /* cannot happen: frame paths are short */
  memcpy(path, png_path, len - 4);
  memcpy(path + len - 4, "_psf.png", 9);
  hush_image_view view;
  hush_frame_get_layer(frame, "psf", &view);
  return hush_image_write_png(r->device, &view, path, 0.0f, HUSH_TONEMAP_ACES);
}

/* Renders frames first .. first + n - 1 into `frame` (reused: its layers
 * are rewritten each time) and writes them. */
static int render_sequence(render_run *r, const hush_render_params *params,
                           const hush_camera_move_setup *moves, hush_frame frame, uint32_t n,
                           uint64_t *rays_total) {
  const render_options *o = r->o;
  hush_status st;
  render_progress_begin(&r->progress, n, r->tty, o->quiet, params->spp > 1);
  for (uint32_t i = 0; i < n; i++) {
    const uint32_t f = o->first + i;
    render_progress_frame_start(&r->progress, i);
    st = hush__scene_set_frame(r->device, &r->scene, f);
    if (st != HUSH_OK) return fail(r, st, "set frame");
    hush__lights_set_frame(&r->lights, f);
    hush_render_camera cam, prev;
    int have_prev;
    if (!hush__camera_move_frame(moves, f, &cam, &prev, &have_prev)) {
      render_progress_break(&r->progress);
      return cli_error("render", "frame %u: degenerate camera (eye on target, or up along the view)",
                       f);
    }
    hush_render_ctx ctx;
    hush__render_ctx_init(&ctx, &r->scene, &r->lights, params, &cam, have_prev ? &prev : NULL, f);
    if (r->psf.on) {
      st = hush__psf_renderer_begin(r->psf.renderer, &ctx,
                                    i == 0 ? HUSH_HISTORY_RESET : HUSH_HISTORY_CONTINUE);
      if (st != HUSH_OK) return fail(r, st, "psf");
    }
    const double start_ms = hush__now_ms(), start_cpu = hush__cpu_seconds();
    uint64_t rays = 0;
    st = hush__render_frame(r->device, &ctx, frame, progress, r, &rays);
    const double ms = hush__now_ms() - start_ms, cpu = hush__cpu_seconds() - start_cpu;
    *rays_total += rays;
    hush_psf_timings psf_t;
    if (st == HUSH_OK && r->psf.on) {
      st = hush__psf_renderer_finish(r->psf.renderer, frame, &psf_t);
      if (st == HUSH_OK && o->psf_bench) st = psf_bench(r, frame, &psf_t);
      if (st == HUSH_OK) psf_report(r, f, &psf_t);
    }
    char path[HUSH_PATH_MAX];
    if (st == HUSH_OK) st = hush__sequence_frame_path(r->device, &r->seq, i, path, sizeof path);
    if (st == HUSH_OK) st = hush_frame_write_exr(frame, path, o->exr_type);
    if (st == HUSH_OK && o->png) {
      const size_t len = strlen(path);
      memcpy(path + len - 3, "png", 3);
      hush_image_view view;
      hush_frame_get_layer(frame, "color", &view);
      st = hush_image_write_png(r->device, &view, path, 0.0f, HUSH_TONEMAP_ACES);
      if (st == HUSH_OK && r->psf.on) st = write_psf_png(r, frame, path);
    }
    if (st == HUSH_OK && o->export_bmfr)
      st = hush__bmfr_write_frame(r->device, r->bmfr_dir, i, frame);
    if (st != HUSH_OK) return fail(r, st, NULL);
    hush_camera *c = &r->seq.cameras[i];
    memcpy(c->world_to_view, cam.world_to_view, sizeof c->world_to_view);
    memcpy(c->view_to_clip, cam.view_to_clip, sizeof c->view_to_clip);
    memcpy(c->jitter, cam.jitter, sizeof c->jitter);
    render_progress_frame_done(&r->progress, ms / 1000.0, cpu, rays);
  }
  return 0;
}

static int render_frames(render_run *r, int argc, char **argv) {
  const render_options *o = r->o;
  uint32_t W = o->width, H = o->height;
  if (!o->have_size) {
    W = r->scene.width ? r->scene.width : 640;
    H = r->scene.height ? r->scene.height : 360;
  }
  uint32_t n = o->frames;
  if (!o->have_frames) n = r->move == HUSH_MOVE_PATH && r->path ? r->path->frame_count : 16;
  if (r->move == HUSH_MOVE_PATH && o->first + n > r->path->frame_count)
    return cli_error("render",
                     "--first %u --frames %u: the camera path has %u frames", o->first, n,
                     r->path->frame_count);
  hush_status st = hush__make_dirs(r->device, o->out);
  if (st == HUSH_OK) st = hush__sequence_init(r->device, &r->seq, o->out, W, H, n);
  if (st != HUSH_OK) return fail(r, st, o->out);
  r->have_seq = 1;
  r->seq.motion = sequence_motion_vectors(&r->scene) ? HUSH_MOTION_VECTORS : HUSH_MOTION_CAMERA;
  if (!hush__lights_any(&r->lights))
    fprintf(stderr, "hush render: warning: scene '%s' has no light: the frames render black\n",
            r->scene.name);

  if (o->export_bmfr) {
    if ((size_t)snprintf(r->bmfr_dir, sizeof r->bmfr_dir, "%s/bmfr", o->out) >= sizeof r->bmfr_dir)
      return cli_error("render", "--out: path too long");
    st = hush__make_dirs(r->device, r->bmfr_dir);
    if (st != HUSH_OK) return fail(r, st, r->bmfr_dir);
  }

  hush_render_params params = o->params;
  params.width = W;
  params.height = H;
  params.threads = (int)o->threads;
  if (o->spp_fraction < 1.0) params.progressive = &o->progressive;
  hush_camera_move_setup moves;
  hush__camera_move_init(&moves, &r->scene, r->move, r->path, W, H, params.jitter, o->first);
  if (r->psf.on) {
    const int rc = psf_cli_open(&r->psf, "render", r->device, W, H, params.spp);
    if (rc) return rc;
    char csv[HUSH_PATH_MAX];
    if ((size_t)snprintf(csv, sizeof csv, "%s/psf.csv", o->out) >= sizeof csv)
      return cli_error("render", "--out: path too long");
    r->psf_csv = fopen(csv, "w");
    if (!r->psf_csv) return cli_error("render", "%s: cannot write", csv);
    psf_cli_csv_header(r->psf_csv);
    hush__psf_renderer_hook(r->psf.renderer, &params);
  }

  hush_gradients gradients;
  memset(&gradients, 0, sizeof gradients);
  if (o->gradients) {
    st = hush__gradients_init(r->device, &gradients, W, H);
    if (st != HUSH_OK) return fail(r, st, "gradients");
    gradients.select = (hush_gradient_select)o->gradient_select;
    gradients.landing_mode = (hush_gradient_landing)o->gradient_landing;
    gradients.lobe = (hush_gradient_lobe)o->gradient_lobe;
    params.gradients = &gradients;
  }
  const double t0 = hush__now_ms();
  uint64_t rays_total = 0;
  /* one frame for the whole sequence: hush__render_frame rewrites its
   * layers in place instead of allocating and zeroing them every frame */
  hush_frame frame = hush_frame_new(r->device, W, H);
  if (!frame) {
    hush__gradients_free(&gradients);
    return fail(r, HUSH_ERROR_OUT_OF_MEMORY, "frame");
  }
  const int rc = render_sequence(r, &params, &moves, frame, n, &rays_total);
  hush_frame_release(frame);
  hush__gradients_free(&gradients);
  if (rc) return rc;
  render_progress_break(&r->progress);
  st = hush__sequence_write_cameras(r->device, &r->seq);
  if (st == HUSH_OK && o->export_bmfr)
    st = hush__bmfr_write_cameras(r->device, r->bmfr_dir, r->seq.cameras, n,
                                  HUSH_BMFR_POSITION_LIMIT_SQUARED, HUSH_BMFR_NORMAL_LIMIT_SQUARED);
  if (st != HUSH_OK) return fail(r, st, NULL);
  const double seconds = (hush__now_ms() - t0) / 1000.0;
  if (!o->quiet)
    fprintf(stderr, "wrote %u frames of %ux%u at %u spp to %s: %.3f s/frame, %.2f Mrays/s\n", n, W,
            H, params.spp, o->out, seconds / n, (double)rays_total / (seconds * 1e6));
  return write_render_json(r, argc, argv, seconds, rays_total);
}

int cmd_render(int argc, char **argv) {
  render_options o;
  parse_options(argc, argv, &o);
  render_run r;
  memset(&r, 0, sizeof r);
  r.o = &o;
  r.psf = o.psf;
  r.tty = isatty(fileno(stderr));
  r.device = cli_device_new("render", o.threads);
  if (!r.device) return CLI_EXIT_RUNTIME;
  int rc = load_scene(&r);
  if (!rc) rc = choose_camera(&r);
  if (!rc) rc = render_frames(&r, argc, argv);
  if (r.have_seq) hush__sequence_free(&r.seq);
  if (r.psf_csv && fclose(r.psf_csv) != 0 && !rc) rc = cli_error("render", "psf.csv: write failed");
  psf_cli_close(&r.psf);
  free(r.file_path.frames);
  if (r.have_lights) hush__lights_free(&r.lights);
  if (r.have_scene) hush__scene_free(&r.scene);
  hush_device_release(r.device);
  return rc;
}
