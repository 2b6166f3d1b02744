/*
 * cmd_eval.c — `hush eval`: runs filters side by side on the same frames of
 * a sequence and measures each against references, the comparisons of
 * bmfr-koskela-2019.md §7 (Tables 2-5) and
 * realtime-denoising-comparison-higginson-2023.md §3.5 (Table 3.1).
 *
 * Frames are the outer loop: each input frame and its reference are read
 * once, then every filter (and the baselines "noisy", the input itself, and
 * "accumulate") runs on it with its own history. Per frame and filter it
 * records RMSE, relMSE, PSNR (eval/metrics.h), SSIM and the temporal error
 * (eval/ssim.h), the execute time and the filter's stage times, and writes
 * the output's colour to REPORT_DIR/frames/<filter>/. At the end it writes
 * metrics.csv, timings.csv, status.csv, summary.md and eval.json, the file
 * interface of docs/eval.md. A filter that fails on a frame is marked failed
 * and left out of the later frames; the others complete.
 *
 * `--scene` first renders the 1 spp sequence and its references into
 * REPORT_DIR/seq and REPORT_DIR/ref with the library renderer
 * (scene_frames.h), then evaluates those.
 */
#include "cli.h"
#include "psf_cli.h"
#include "render_progress.h"
#include "scene_frames.h"

#include "core/timer.h"
#include "eval/lag.h"
#include "eval/metrics.h"
#include "eval/report.h"
#include "eval/ssim.h"
#include "io/atomic_file.h"
#include "io/sequence.h"
#include "render/gradients.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define MAX_FILTERS 18 /* the baselines and 16 more */
#define MAX_STAGES 16
#define MAX_SETS 64
#define MESSAGE_MAX 1024
#define MAX_SHOW 16

static const char *const help_text =
    "usage: hush eval --seq NOISY_DIR [--ref REF_DIR] --out REPORT_DIR [options]\n"
    "       hush eval --scene SCENE --out REPORT_DIR [options]\n"
    "\n"
    "Runs every filter of --filters, and always the baselines \"noisy\" (the input\n"
    "itself) and \"accumulate\", on the same frames, and measures each output\n"
    "against the reference: RMSE, relative MSE, PSNR, SSIM and the temporal error\n"
    "(docs/eval.md defines them), the execute time and the time of each stage.\n"
    "The reference of frame N is the \"color\" of REF_DIR's frame N, or without\n"
    "--ref the \"ref\" layer of the input frames (as `hush synth` writes them).\n"
    "\n"
    "REPORT_DIR receives metrics.csv (per filter and frame), timings.csv (per\n"
    "filter and stage: median, 5th, 95th percentile), status.csv (ok or failed,\n"
    "with the error), summary.md (the table of means), eval.json (what was run)\n"
    "and frames/<filter>/frame_NNNN.exr (each output's colour, half float; also\n"
    "frames/noisy and frames/reference), then report.html from them: pictures side\n"
    "by side with insets and error maps, metric plots, the tables, and a video when\n"
    "ffmpeg is installed. The summary table goes to stdout.\n"
    "\n"
    "A filter that fails on a frame is marked failed in status.csv and the\n"
    "others complete: the exit status is 0 with a warning (1 with --strict).\n"
    "Missing references, or references of another length or size, are errors.\n"
    "\n"
    "options:\n"
    "  --seq NOISY_DIR      the input sequence (cameras.json and frame EXRs)\n"
    "  --ref REF_DIR        the reference sequence: same frame count and size\n"
    "  --out REPORT_DIR     where the results go, created if missing (required)\n"
    "  --filters A,B,...    filters to compare (default: every filter; `hush\n"
    "                       filters` lists them). \"psf\" is hashed path-space\n"
    "                       filtering (docs/psf.md): the input's \"psf\" layer, which\n"
    "                       --scene renders (or `hush render --psf`); \"psf+F\" runs\n"
    "                       filter F on it instead of on \"color\" (e.g. psf+svgf);\n"
    "                       NAME=F runs F under the name NAME, for a second set\n"
    "                       of parameters (bmfr,bmfr-tg=bmfr --set\n"
    "                       bmfr-tg.temporal_gradients=on)\n"
    "  --set F.KEY=VALUE    parameter KEY of filter F; repeatable (default: the\n"
    "                       filter's defaults); psf.KEY=VALUE sets a psf parameter\n"
    "                       (psf.vertex=2, psf.scale=4 ...) for --scene;\n"
    "                       nca.weights=FILE loads weights from `hush train-nca`\n"
    "  --frames A:B         --seq: only frames A to B-1 (default all)\n"
    "                       --scene: the number of frames to render (default:\n"
    "                       the camera path's length, else 16)\n"
    "  --threads N          worker threads, 0 = one per core (default 0)\n"
    "  --strict             exit 1 when a filter fails\n"
    "  --show F1,F2,...     report: the frames shown side by side (default: the\n"
    "                       first, middle and last)\n"
    "  --exposure E         report pictures: scale radiance by 2^E (default 0)\n"
    "  --tonemap T          report pictures: clamp, reinhard or aces (default aces)\n"
    "  --no-video           report: no side-by-side video (default: with ffmpeg)\n"
    "  --lag-frame K        the lag after a change at frame K (a light switched\n"
    "                       off, or jumping): frames until each filter's mean over\n"
    "                       the brightened and the darkened region of the\n"
    "                       references is within 10% of the reference's, the\n"
    "                       larger (default: the frame where the references\n"
    "                       change most); lag.csv, lag_series.csv and summary.md\n"
    "                       (docs/eval.md)\n"
    "  --quiet              no progress and no table, only warnings and errors\n"
    "  -h, --help           show this help\n"
    "\n"
    "rendering first (--scene; the inputs go to REPORT_DIR/seq and REPORT_DIR/ref):\n"
    "  --scene SCENE        PATH/scene.json (or its folder) or builtin:NAME\n"
    "  --path MOVE          camera: a camera-path.json, path, static, orbit or dolly\n"
    "                       (as `hush render --path`)\n"
    "  --size WxH           frame size (default: the scene's, else 640x360)\n"
    "  --ref-spp N          samples per pixel of the references (default 64); the\n"
    "                       inputs are the 1 spp configuration of `hush render`\n"
    "  --gradients          render the inputs (not the references) with A-SVGF\n"
    "                       gradient samples, layer \"gradient\" (hush render\n"
    "                       --gradients); automatic when a filter needs them (a\n"
    "                       class requiring \"gradient\", or temporal_gradients on)\n";

typedef struct eval_options {
  const char *seq, *ref, *out;
  const char *scene, *path;
  char filters[512];
  const char *sets[MAX_SETS];
  int set_count;
  const char *frames_text;
  uint32_t width, height;
  uint32_t ref_spp;
  uint32_t threads;
  int strict, quiet;
  uint32_t show[MAX_SHOW]; /* report frames */
  uint32_t show_count;
  float exposure;
  hush_tonemap tonemap;
  int no_video;
  int gradients;           /* --gradients */
  const char *lag_frame;   /* --lag-frame K, NULL: automatic */
} eval_options;

typedef struct stage_times {
  char name[32];
  double *ms;     /* one per frame the stage reported */
  uint32_t count;
} stage_times;

/* One row of metrics.csv; NAN is written as an empty field. */
typedef struct eval_row {
  uint32_t frame;
  double rmse, rel_mse, psnr, ssim, temporal, ref_temporal, ms;
} eval_row;

typedef struct eval_filter {
  const char *name;          /* "noisy", "accumulate", "psf", "psf+svgf" ... */
  const char *cls;           /* the filter class, NULL for "noisy" and "psf" */
  const char *color_layer;   /* the layer bound to "color", or read for no class */
  hush_filter filter;        /* NULL for "noisy" */
  hush_frame out;            /* the filter's output layers ("color", ...) */
  int failed;
  uint32_t failed_frame;
  char message[MESSAGE_MAX];
  float *luma, *prev_luma;   /* display luminance of this and the last output */
  eval_row *rows;            /* one per frame evaluated */
  uint32_t done;
  stage_times stages[MAX_STAGES + 1]; /* the filter's stages, then "total" */
  uint32_t stage_count;
  double *lag_mean[2];       /* mean lag luminance over the event's brightened [0] and
                                darkened [1] region, from the event on */
  float *lag_pixel_sse;      /* shift lag: per pixel and shift (eval/lag.h), owned;
                                4 x 8 bytes a pixel */
  double lag_sse[HUSH_LAG_MAX_SHIFT]; /* ... summed over the shift region at the end */
} eval_filter;

typedef struct eval_run {
  const char *cmd;
  const eval_options *o;
  int argc;
  char **argv;
  hush_device device;
  int threads;
  char seq_dir[HUSH_PATH_MAX], ref_dir[HUSH_PATH_MAX]; /* ref_dir "": the "ref" layer */
  hush_sequence seq, ref;
  int have_seq, have_ref;
  uint32_t first, last, width, height;
  eval_filter filters[MAX_FILTERS];
  uint32_t filter_count;
  char filter_names[512];    /* storage for the names of --filters */
  size_t pixels;
  float *ref_rgb, *out_rgb;  /* packed RGB of the reference and of one output */
  float *ref_luma, *ref_prev_luma;
  hush_frame picture;        /* one "color" layer: what frames/ receives */
  int tty;
  int psf;                   /* a filter reads the "psf" layer */
  double *psf_ms;            /* --scene: psf time of each frame, else NULL */
  int gradients;             /* --scene: the inputs have the "gradient" layer */
  /* lag (eval/lag.h): the event's region, its frame and size, the
   * reference's region means from it on; the last lag_shifts reference
   * luminances by frame modulo lag_shifts */
  float *lag_mask, *lag_candidate; /* +1 brightened, -1 darkened, 0 (hush__lag_region_signed) */
  float *lag_luma, *lag_ref_luma; /* lag luminance: an output, the reference */
  float *lag_box, *lag_box_prev; /* the reference's box average, this frame and the last */
  uint32_t lag_event;        /* UINT32_MAX: no event (yet) */
  uint32_t lag_fixed;        /* --lag-frame K, else UINT32_MAX */
  size_t lag_region;
  size_t lag_part[2];        /* the brightened and the darkened pixels of the region */
  double *lag_ref_mean[2];
  uint32_t lag_shifts;       /* 0: too few frames for the shift lag */
  float *lag_ring[HUSH_LAG_MAX_SHIFT];
  float *lag_lo, *lag_hi;    /* the box-averaged reference's range over the frames */
  float *lag_shift_mask;     /* the shift region (at the end) */
  size_t lag_shift_region;
} eval_run;

/* ---- options ---------------------------------------------------------------- */

/* --show F1,F2,...: sequence frame numbers. */
static void parse_show(const char *cmd, const char *text, eval_options *o) {
  char buf[256];
  if (strlen(text) >= sizeof buf) cli_usage_error(cmd, "--show: list too long");
  strcpy(buf, text);
  o->show_count = 0;
  for (char *tok = strtok(buf, ","); tok; tok = strtok(NULL, ",")) {
    if (o->show_count == MAX_SHOW) cli_usage_error(cmd, "--show: more than %d frames", MAX_SHOW);
    o->show[o->show_count++] = cli_parse_uint(cmd, "--show", tok, 0, 10000000);
  }
  if (!o->show_count) cli_usage_error(cmd, "--show: no frames");
}

static void parse_options(int argc, char **argv, eval_options *o) {
  cli_args a;
  cli_args_init(&a, "eval", argc, argv);
  memset(o, 0, sizeof *o);
  o->ref_spp = 64;
  o->tonemap = HUSH_TONEMAP_ACES;
  const char *arg, *v;
  while (cli_next(&a, &arg)) {
    if (cli_is_help(arg)) {
      fputs(help_text, stdout);
      exit(0);
    } else if (cli_option(&a, arg, "--seq", &v)) {
      o->seq = v;
    } else if (cli_option(&a, arg, "--ref", &v)) {
      o->ref = v;
    } else if (cli_option(&a, arg, "--out", &v)) {
      o->out = v;
    } else if (cli_option(&a, arg, "--filters", &v)) {
      if (strlen(v) >= sizeof o->filters) cli_usage_error(a.cmd, "--filters: list too long");
      strcpy(o->filters, v);
    } else if (cli_option(&a, arg, "--set", &v)) {
      const char *dot = strchr(v, '.'), *eq = strchr(v, '=');
      if (!dot || !eq || dot == v || dot > eq || eq == dot + 1)
        cli_usage_error(a.cmd, "--set: expected FILTER.KEY=VALUE, got '%s'", v);
      if (o->set_count == MAX_SETS) cli_usage_error(a.cmd, "--set: more than %d", MAX_SETS);
      o->sets[o->set_count++] = v;
    } else if (cli_option(&a, arg, "--frames", &v)) {
      o->frames_text = v;
    } else if (cli_option(&a, arg, "--threads", &v)) {
      o->threads = cli_parse_uint(a.cmd, "--threads", v, 0, 1024);
    } else if (cli_switch(&a, arg, "--strict")) {
      o->strict = 1;
    } else if (cli_option(&a, arg, "--show", &v)) {
      parse_show(a.cmd, v, o);
    } else if (cli_option(&a, arg, "--exposure", &v)) {
      o->exposure = cli_parse_float(a.cmd, "--exposure", v, -64.0f, 64.0f);
    } else if (cli_option(&a, arg, "--tonemap", &v)) {
      o->tonemap = cli_parse_tonemap(a.cmd, "--tonemap", v);
    } else if (cli_switch(&a, arg, "--no-video")) {
      o->no_video = 1;
    } else if (cli_option(&a, arg, "--lag-frame", &v)) {
      o->lag_frame = v;
    } else if (cli_switch(&a, arg, "--gradients")) {
      o->gradients = 1;
    } else if (cli_switch(&a, arg, "--quiet")) {
      o->quiet = 1;
    } else if (cli_option(&a, arg, "--scene", &v)) {
      o->scene = v;
    } else if (cli_option(&a, arg, "--path", &v)) {
      o->path = v;
    } else if (cli_option(&a, arg, "--size", &v)) {
      cli_parse_size(a.cmd, "--size", v, &o->width, &o->height);
    } else if (cli_option(&a, arg, "--ref-spp", &v)) {
      o->ref_spp = cli_parse_uint(a.cmd, "--ref-spp", v, 1, 1u << 20);
    } else if (cli_is_positional(&a, arg)) {
      cli_usage_error(a.cmd, "unexpected argument '%s' (see hush eval --help)", arg);
    } else {
      cli_unknown_option(&a, arg);
    }
  }
  if (!o->out) cli_usage_error(a.cmd, "--out REPORT_DIR is required");
  if (!o->seq == !o->scene)
    cli_usage_error(a.cmd, "give either --seq NOISY_DIR or --scene SCENE (see hush eval --help)");
  if (o->scene && o->ref)
    cli_usage_error(a.cmd, "--ref: with --scene the references are rendered (--ref-spp)");
  if (o->seq && (o->path || o->width))
    cli_usage_error(a.cmd, "--path and --size go with --scene, not --seq");
  if (o->seq && o->gradients)
    cli_usage_error(a.cmd, "--gradients goes with --scene (render the sequence with hush render "
                           "--gradients for --seq)");
}

/* ---- the list of filters ---------------------------------------------------- */

static int has_filter(const eval_run *r, const char *name) {
  for (uint32_t i = 0; i < r->filter_count; i++)
    if (strcmp(r->filters[i].name, name) == 0) return 1;
  return 0;
}

/* Filter `spec` under the name `name` (the same but for NAME=SPEC). */
static int add_filter(eval_run *r, const char *name, const char *spec) {
  if (has_filter(r, name)) return 0;
  for (const char *c = name; *c; c++)
    if (!(*c >= 'a' && *c <= 'z') && !(*c >= 'A' && *c <= 'Z') && !(*c >= '0' && *c <= '9') &&
        !strchr("_-+", *c))
      return cli_error(r->cmd, "--filters: '%s': a name has letters, digits, '_', '-', '+'", name);
  /* "psf" reads the psf layer; "psf+F" runs F with the psf layer as colour */
  const int psf = strcmp(spec, "psf") == 0 || strncmp(spec, "psf+", 4) == 0;
  const char *cls = strcmp(spec, "psf") == 0 ? NULL : psf ? spec + 4 : spec;
  if (cls && strcmp(cls, "noisy") != 0 && !hush_filter_class_find(cls)) {
    char names[512] = "";
    for (uint32_t i = 0; i < hush_filter_class_count(); i++) {
      const size_t len = strlen(names);
      snprintf(names + len, sizeof names - len, "%s%s", i ? ", " : "",
               hush_filter_class_at(i)->name);
    }
    return cli_error(r->cmd, "--filters: unknown filter '%s' (filters: %s, psf, psf+FILTER)",
                     cls, names);
  }
  if (psf && cls && strcmp(cls, "noisy") == 0)
    return cli_error(r->cmd, "--filters: '%s': use psf", spec);
  if (r->filter_count == MAX_FILTERS)
    return cli_error(r->cmd, "--filters: more than %d filters", MAX_FILTERS - 2);
  eval_filter *f = &r->filters[r->filter_count++];
  f->name = name;
  f->cls = cls && strcmp(cls, "noisy") != 0 ? cls : NULL;
  f->color_layer = psf ? "psf" : "color";
  r->psf |= psf;
  return 0;
}

/* The baselines first, then --filters in order (or every class). */
static int filter_list(eval_run *r) {
  int rc = add_filter(r, "noisy", "noisy");
  if (!rc) rc = add_filter(r, "accumulate", "accumulate");
  if (!r->o->filters[0]) {
    for (uint32_t i = 0; !rc && i < hush_filter_class_count(); i++)
      rc = add_filter(r, hush_filter_class_at(i)->name, hush_filter_class_at(i)->name);
    return rc;
  }
  strcpy(r->filter_names, r->o->filters);
  for (char *tok = strtok(r->filter_names, ","); !rc && tok; tok = strtok(NULL, ",")) {
    /* NAME=F: filter F once more under its own name, for its own --set */
    char *eq = strchr(tok, '=');
    if (eq) *eq = '\0';
    rc = eq && (eq == tok || !eq[1]) ? cli_error(r->cmd, "--filters: expected NAME=FILTER")
                                     : add_filter(r, tok, eq ? eq + 1 : tok);
  }
  return rc;
}

/* --set F.KEY=VALUE on filter f when F is its name. */
static int apply_sets(eval_run *r, eval_filter *f) {
  for (int i = 0; i < r->o->set_count; i++) {
    const char *s = r->o->sets[i];
    const char *dot = strchr(s, '.'), *eq = strchr(s, '=');
    if (strlen(f->name) != (size_t)(dot - s) || strncmp(s, f->name, (size_t)(dot - s)) != 0)
      continue;
    char key[128];
    if ((size_t)(eq - dot - 1) >= sizeof key) return cli_error(r->cmd, "--set %s: name too long", s);
    memcpy(key, dot + 1, (size_t)(eq - dot - 1));
    key[eq - dot - 1] = '\0';
    const hush_status st = cli_filter_set(f->filter, key, eq + 1);
    if (st != HUSH_OK) {
      char context[256];
      snprintf(context, sizeof context, "--set %s", s);
      return cli_device_error(r->cmd, r->device, st, context);
    }
  }
  return 0;
}

/* Every --set must name a filter that runs: a typo must not go unnoticed. */
static int check_sets(eval_run *r) {
  for (int i = 0; i < r->o->set_count; i++) {
    const char *s = r->o->sets[i];
    const size_t len = (size_t)(strchr(s, '.') - s);
    int found = 0;
    for (uint32_t k = 1; k < r->filter_count && !found; k++)
      found = strlen(r->filters[k].name) == len && strncmp(s, r->filters[k].name, len) == 0;
    if (!found && len == 3 && strncmp(s, "psf", 3) == 0 && r->psf) {
      if (!r->o->scene)
        return cli_error(r->cmd, "--set %s: psf parameters apply when rendering (--scene)", s);
      found = 1;
    }
    if (!found)
      return cli_error(r->cmd, "--set %s: '%.*s' is not one of the filters run", s, (int)len, s);
  }
  return 0;
}

/* Whether filter f reads the "gradient" layer (A-SVGF gradient samples):
 * its class requires it, or the class takes it optionally and has the
 * switch temporal_gradients, which --set turns on (bmfr). Asked of a
 * throw-away filter with the --set values, before anything is rendered. */
static int wants_gradients(eval_run *r, eval_filter *f, int *wants) {
  *wants = 0;
  const hush_filter_class_info *cls = f->cls ? hush_filter_class_find(f->cls) : NULL;
  int optional = 0;
  for (uint32_t i = 0; cls && i < cls->image_count; i++) {
    const hush_image_info *im = &cls->images[i];
    if (im->role != HUSH_IMAGE_INPUT || strcmp(im->name, "gradient") != 0) continue;
    if (im->required) {
      *wants = 1;
      return 0;
    }
    optional = 1;
  }
  if (!optional) return 0;
  f->filter = hush_filter_new(r->device, f->cls);
  if (!f->filter) return cli_device_error(r->cmd, r->device, HUSH_ERROR_NOT_FOUND, f->cls);
  int rc = apply_sets(r, f);
  if (!rc && hush_filter_get_bool(f->filter, "temporal_gradients", wants) != HUSH_OK) {
    hush_device_get_error(r->device, NULL); /* no such switch: not wanted */
    *wants = 0;
  }
  hush_filter_release(f->filter);
  f->filter = NULL;
  return rc;
}

static int setup_filter(eval_run *r, eval_filter *f) {
  const uint32_t n = r->last - r->first;
  f->rows = calloc(n, sizeof *f->rows);
  f->luma = malloc(r->pixels * sizeof *f->luma);
  f->prev_luma = malloc(r->pixels * sizeof *f->prev_luma);
  f->lag_mean[0] = calloc(n, sizeof *f->lag_mean[0]);
  f->lag_mean[1] = calloc(n, sizeof *f->lag_mean[1]);
  if (!f->rows || !f->luma || !f->prev_luma || !f->lag_mean[0] || !f->lag_mean[1])
    return cli_error(r->cmd, "out of memory");
  if (r->lag_shifts &&
      !(f->lag_pixel_sse = calloc(r->pixels * r->lag_shifts, sizeof *f->lag_pixel_sse)))
    return cli_error(r->cmd, "out of memory");
  if (!f->cls) return 0;
  f->filter = hush_filter_new(r->device, f->cls);
  if (!f->filter) return cli_device_error(r->cmd, r->device, HUSH_ERROR_NOT_FOUND, f->cls);
  int rc = apply_sets(r, f);
  if (rc) return rc;
  f->out = hush_frame_new(r->device, r->width, r->height);
  if (!f->out) return cli_device_error(r->cmd, r->device, HUSH_ERROR_OUT_OF_MEMORY, f->name);
  const hush_filter_class_info *cls = hush_filter_get_class(f->filter);
  for (uint32_t i = 0; i < cls->image_count; i++) {
    const hush_image_info *im = &cls->images[i];
    if (im->role != HUSH_IMAGE_OUTPUT) continue;
    /* the main output is the "color" of the frames written, as in hush denoise */
    const char *layer = strcmp(im->name, "output") == 0 ? "color" : im->name;
    hush_image_view view;
    hush_status st = hush_frame_add_layer(f->out, layer, im->channels, &view);
    if (st == HUSH_OK) st = hush_filter_set_image(f->filter, im->name, &view);
    if (st != HUSH_OK) return cli_device_error(r->cmd, r->device, st, f->name);
  }
  return 0;
}

/* ---- inputs ------------------------------------------------------------------ */

static int open_sequence(eval_run *r, const char *dir, const char *what, hush_sequence *seq,
                         int *have) {
  if (!cli_is_dir(dir))
    return cli_error(r->cmd, "%s directory '%s' does not exist or is not a directory", what, dir);
  const hush_status st = hush__sequence_read(r->device, dir, seq);
  if (st != HUSH_OK) {
    char context[HUSH_PATH_MAX + 32];
    snprintf(context, sizeof context, "%s/cameras.json", dir);
    return cli_device_error(r->cmd, r->device, st, context);
  }
  *have = 1;
  return 0;
}

/* Opens the input and the reference sequence and checks that they match. */
static int open_inputs(eval_run *r) {
  int rc = open_sequence(r, r->seq_dir, "input", &r->seq, &r->have_seq);
  if (!rc && r->ref_dir[0]) rc = open_sequence(r, r->ref_dir, "reference", &r->ref, &r->have_ref);
  if (rc) return rc;
  const hush_sequence *s = &r->seq;
  if (r->have_ref && r->ref.frame_count != s->frame_count)
    return cli_error(r->cmd,
                     "the reference %s has %u frames, the input %s has %u: references must "
                     "match the input frame for frame",
                     r->ref_dir, r->ref.frame_count, r->seq_dir, s->frame_count);
  if (r->have_ref && (r->ref.width != s->width || r->ref.height != s->height))
    return cli_error(r->cmd, "the reference %s is %ux%u, the input %s is %ux%u", r->ref_dir,
                     r->ref.width, r->ref.height, r->seq_dir, s->width, s->height);
  r->width = s->width;
  r->height = s->height;
  r->pixels = (size_t)s->width * s->height;
  r->first = 0;
  r->last = UINT32_MAX;
  if (r->o->frames_text && !r->o->scene)
    cli_parse_range(r->cmd, "--frames", r->o->frames_text, &r->first, &r->last);
  if (r->last > s->frame_count) r->last = s->frame_count;
  if (r->first >= r->last)
    return cli_error(r->cmd, "--frames %s: %s has %u frames", r->o->frames_text, r->seq_dir,
                     s->frame_count);
  return 0;
}

/* The first three channels of a view, packed, into rgb. */
static void pack_rgb(const hush_image_view *v, float *rgb) {
  const int c = hush_format_channels(v->format);
  const float *src = v->data;
  const size_t n = (size_t)v->width * v->height;
  for (size_t i = 0; i < n; i++) memcpy(rgb + 3 * i, src + (size_t)c * i, 3 * sizeof(float));
}

/* A colour layer of at least 3 channels, or an error naming the file. */
static int get_color(eval_run *r, hush_frame frame, const char *layer, const char *file,
                     const char *hint, hush_image_view *view) {
  if (hush_frame_get_layer(frame, layer, view) != HUSH_OK) {
    hush_device_get_error(r->device, NULL);
    return cli_error(r->cmd, "%s has no '%s' layer%s", file, layer, hint);
  }
  if (hush_format_channels(view->format) < 3)
    return cli_error(r->cmd, "%s: layer '%s' has %d channels, 3 are needed", file, layer,
                     hush_format_channels(view->format));
  return 0;
}

/* ---- lag (eval/lag.h) ------------------------------------------------------------ */

/* --lag-frame, the region masks, the reference's series and the ring of
 * reference luminances for the shift lag (S = half the frames, at most
 * HUSH_LAG_MAX_SHIFT: the shift sums run over the frames that have S
 * references before them, at least half of them). */
static int lag_setup(eval_run *r) {
  const uint32_t n = r->last - r->first;
  r->lag_event = r->lag_fixed = UINT32_MAX;
  if (r->o->lag_frame) {
    r->lag_fixed = cli_parse_uint(r->cmd, "--lag-frame", r->o->lag_frame, 0, 10000000);
    if (r->lag_fixed <= r->first || r->lag_fixed >= r->last)
      return cli_error(r->cmd,
                       "--lag-frame %u: the change must follow an evaluated frame (frames %u to "
                       "%u were evaluated)",
                       r->lag_fixed, r->first, r->last - 1);
  }
  r->lag_shifts = n / 2 < HUSH_LAG_MAX_SHIFT ? n / 2 : HUSH_LAG_MAX_SHIFT;
  if (r->lag_shifts < 2) r->lag_shifts = 0;
  r->lag_mask = malloc(r->pixels * sizeof *r->lag_mask);
  r->lag_candidate = malloc(r->pixels * sizeof *r->lag_candidate);
  r->lag_ref_mean[0] = calloc(n, sizeof *r->lag_ref_mean[0]);
  r->lag_ref_mean[1] = calloc(n, sizeof *r->lag_ref_mean[1]);
  r->lag_luma = malloc(r->pixels * sizeof *r->lag_luma);
  r->lag_ref_luma = malloc(r->pixels * sizeof *r->lag_ref_luma);
  r->lag_box = malloc(r->pixels * sizeof *r->lag_box);
  r->lag_box_prev = malloc(r->pixels * sizeof *r->lag_box_prev);
  if (!r->lag_mask || !r->lag_candidate || !r->lag_ref_mean[0] || !r->lag_ref_mean[1] ||
      !r->lag_luma ||
      !r->lag_ref_luma || !r->lag_box || !r->lag_box_prev)
    return cli_error(r->cmd, "out of memory");
  for (uint32_t k = 0; k < r->lag_shifts; k++)
    if (!(r->lag_ring[k] = malloc(r->pixels * sizeof(float))))
      return cli_error(r->cmd, "out of memory");
  if (!r->lag_shifts) return 0;
  r->lag_shift_mask = malloc(r->pixels * sizeof(float));
  r->lag_lo = malloc(r->pixels * sizeof(float));
  r->lag_hi = malloc(r->pixels * sizeof(float));
  if (!r->lag_shift_mask || !r->lag_lo || !r->lag_hi) return cli_error(r->cmd, "out of memory");
  for (size_t p = 0; p < r->pixels; p++) r->lag_lo[p] = INFINITY, r->lag_hi[p] = -INFINITY;
  return 0;
}

/* Frame i's reference (r->ref_rgb; r->lag_box_prev holds frame i - 1's
 * box-averaged lag luminance): the event's region at --lag-frame, or, without it, at the frame whose
 * change from the one before is the largest so far (the series start over
 * there: only the frames from the event on count). */
static void lag_reference(eval_run *r, uint32_t i) {
  float *t = r->lag_box_prev;
  r->lag_box_prev = r->lag_box;
  r->lag_box = t;
  hush__lag_luminance(r->ref_rgb, r->pixels, r->lag_ref_luma);
  /* lag_luma and lag_candidate are free here: scratch. The box is NaN
   * within the box of a saturated pixel, so that both regions below leave
   * out what is saturated in either of their frames (the light itself and
   * its clamped glow: every filter follows a light seen directly, and the
   * clamped edges would outweigh the shading). The shift region once took
   * this frame's box unmarked: the pixels the moving light had just
   * reached then dominated its sums and pinned every filter's shift lag
   * near 0 (docs/results/asvgf-lag.md). */
  hush__lag_box(r->lag_ref_luma, r->width, r->height, HUSH_LAG_RADIUS, r->lag_luma, r->lag_box);
  hush__lag_mark_saturated(r->lag_ref_luma, r->width, r->height, HUSH_LAG_RADIUS, r->lag_luma,
                           r->lag_candidate, r->lag_box);
  if (i > r->first && (r->lag_fixed == UINT32_MAX || r->lag_fixed == i)) {
    size_t part[2];
    const size_t c = hush__lag_region_signed(r->lag_box_prev, r->lag_box, r->pixels,
                                             HUSH_LAG_THRESHOLD, r->lag_candidate, part);
    const int fixed = r->lag_fixed == i;
    if (c > 0 && (fixed || (c > r->lag_region && c >= HUSH_LAG_MIN_REGION * (double)r->pixels))) {
      t = r->lag_mask;
      r->lag_mask = r->lag_candidate;
      r->lag_candidate = t;
      r->lag_region = c;
      r->lag_part[0] = part[0];
      r->lag_part[1] = part[1];
      r->lag_event = i;
    }
  }
  if (r->lag_event != UINT32_MAX && i >= r->lag_event)
    for (int s = 0; s < 2; s++)
      r->lag_ref_mean[s][i - r->lag_event] =
          hush__lag_region_mean_of(r->lag_ref_luma, r->lag_mask, s ? -1.0f : 1.0f, r->pixels);
  if (!r->lag_shifts) return;
  const uint32_t S = r->lag_shifts;
  memcpy(r->lag_ring[i % S], r->lag_ref_luma, r->pixels * sizeof(float));
  hush__lag_range_add(r->lag_box, r->pixels, r->lag_lo, r->lag_hi);
}

/* After the last frame: the shift region over the run and each filter's
 * shift sums over it. */
static void lag_finish(eval_run *r) {
  if (!r->lag_shifts) return;
  r->lag_shift_region = hush__lag_range_region(r->lag_lo, r->lag_hi, r->pixels,
                                               HUSH_LAG_THRESHOLD, r->lag_shift_mask);
  for (uint32_t k = 0; k < r->filter_count; k++)
    hush__lag_shift_sum(r->filters[k].lag_pixel_sse, r->lag_shift_mask, r->lag_shifts, r->pixels,
                        r->filters[k].lag_sse);
}

/* Filter f's output of frame i (r->out_rgb) into its series. */
static void lag_filter(eval_run *r, eval_filter *f, uint32_t i) {
  hush__lag_luminance(r->out_rgb, r->pixels, r->lag_luma);
  if (r->lag_event != UINT32_MAX && i >= r->lag_event)
    for (int s = 0; s < 2; s++)
      f->lag_mean[s][i - r->lag_event] =
          hush__lag_region_mean_of(r->lag_luma, r->lag_mask, s ? -1.0f : 1.0f, r->pixels);
  if (r->lag_shifts && i + 1 >= r->first + r->lag_shifts) {
    const float *ring[HUSH_LAG_MAX_SHIFT];
    for (uint32_t k = 0; k < r->lag_shifts; k++) ring[k] = r->lag_ring[(i - k) % r->lag_shifts];
    hush__lag_shift_add_pixels(r->lag_luma, ring, r->lag_shifts, r->pixels, f->lag_pixel_sse);
  }
}

/* Whether part s (0: brightened, 1: darkened) of the event's region is
 * large enough to be lagged. */
static int lag_part_used(const eval_run *r, int s) {
  return r->lag_event != UINT32_MAX && r->lag_part[s] > 0 &&
         (double)r->lag_part[s] >= HUSH_LAG_MIN_PART * (double)r->pixels;
}

/* The event lag of part s (0, 1), or of both (s = 2: the larger). NaN: not
 * measured (no event, the part too small, or the filter failed); +inf:
 * never within the tolerance in the frames evaluated. */
static double event_lag(const eval_run *r, const eval_filter *f, int s) {
  if (r->lag_event == UINT32_MAX || f->failed) return NAN;
  const int use[2] = {(s == 0 || s == 2) && lag_part_used(r, 0),
                      (s == 1 || s == 2) && lag_part_used(r, 1)};
  const double *const out[2] = {f->lag_mean[0], f->lag_mean[1]};
  const double *const ref[2] = {r->lag_ref_mean[0], r->lag_ref_mean[1]};
  const int k = hush__lag_event_signed(out, ref, use, r->last - r->lag_event, HUSH_LAG_TOLERANCE);
  return k == -2 ? NAN : k < 0 ? INFINITY : (double)k;
}

static double shift_lag(const eval_run *r, const eval_filter *f) {
  return r->lag_shifts && !f->failed ? hush__lag_shift(f->lag_sse, r->lag_shifts) : NAN;
}

/* ---- one frame ---------------------------------------------------------------- */

/* Like cli_bind_inputs, but the message goes to the filter's status. */
static int bind_inputs(eval_run *r, eval_filter *f, hush_frame frame, const char *file) {
  const hush_filter_class_info *cls = hush_filter_get_class(f->filter);
  for (uint32_t i = 0; i < cls->image_count; i++) {
    const hush_image_info *im = &cls->images[i];
    if (im->role != HUSH_IMAGE_INPUT) continue;
    hush_image_view view;
    const char *layer = strcmp(im->name, "color") == 0 ? f->color_layer : im->name;
    if (hush_frame_get_layer(frame, layer, &view) != HUSH_OK) {
      hush_device_get_error(r->device, NULL);
      if (im->required) {
        char channels[128];
        cli_layer_channels(im->name, im->channels, channels, sizeof channels);
        snprintf(f->message, sizeof f->message,
                 "%s has no '%s' layer (channels %s), which filter '%s' requires", file, layer,
                 channels, f->name);
        return 1;
      }
      hush_filter_unset_image(f->filter, im->name);
      continue;
    }
    const int have = hush_format_channels(view.format);
    if (have < im->channels) {
      snprintf(f->message, sizeof f->message, "%s: layer '%s' has %d channel%s, filter '%s' needs %d",
               file, im->name, have, have == 1 ? "" : "s", cls->name, im->channels);
      return 1;
    }
    if (hush_filter_set_image(f->filter, im->name, &view) != HUSH_OK) return -1;
  }
  return 0;
}

/* The device's error, or the status name, as the filter's message. */
static void take_device_error(eval_run *r, eval_filter *f, hush_status st, const char *file) {
  const char *msg = "";
  const hush_status first = hush_device_get_error(r->device, &msg);
  snprintf(f->message, sizeof f->message, "%s: %s", file,
           first != HUSH_OK ? msg : hush_status_name(st));
  while (hush_device_get_error(r->device, NULL) != HUSH_OK) {
  }
}

static stage_times *stage_slot(eval_filter *f, const char *name, uint32_t frames) {
  for (uint32_t i = 0; i < f->stage_count; i++)
    if (strcmp(f->stages[i].name, name) == 0) return &f->stages[i];
  if (f->stage_count == MAX_STAGES + 1) return NULL;
  stage_times *s = &f->stages[f->stage_count];
  snprintf(s->name, sizeof s->name, "%s", name);
  s->ms = calloc(frames, sizeof *s->ms);
  if (!s->ms) return NULL;
  f->stage_count++;
  return s;
}

static void record_stage(eval_filter *f, const char *name, double ms, uint32_t frames) {
  stage_times *s = stage_slot(f, name, frames);
  if (s && s->count < frames) s->ms[s->count++] = ms;
}

/* Runs filter f on frame i; on failure marks it failed and returns 1. */
static int execute(eval_run *r, eval_filter *f, hush_frame frame, uint32_t i, const char *file,
                   double *ms) {
  int b = bind_inputs(r, f, frame, file);
  hush_status st = HUSH_OK;
  if (b < 0) st = HUSH_ERROR_INVALID_ARGUMENT;
  if (!b && f->done == 0) st = hush_filter_commit(f->filter);
  if (!b && st == HUSH_OK) {
    hush_frame_info info;
    hush__sequence_frame_info(&r->seq, i, &info);
    if (f->done == 0) info.history = HUSH_HISTORY_RESET; /* the first frame run has no history */
    const double t0 = hush__now_ms();
    st = hush_filter_execute(f->filter, &info);
    *ms = hush__now_ms() - t0;
  }
  if (b > 0 || st != HUSH_OK) {
    if (b <= 0) take_device_error(r, f, st, file);
    f->failed = 1;
    f->failed_frame = i;
    return 1;
  }
  const uint32_t n = r->last - r->first;
  const char *const *names;
  const double *stage_ms;
  uint32_t count = 0;
  if (hush_filter_get_timings(f->filter, &names, &stage_ms, &count) != HUSH_OK) count = 0;
  for (uint32_t s = 0; s < count; s++) record_stage(f, names[s], stage_ms[s], n);
  record_stage(f, "total", *ms, n);
  return 0;
}

static int write_picture(eval_run *r, const char *name, uint32_t i, const float *rgb) {
  hush_image_view view;
  hush_frame_get_layer(r->picture, "color", &view);
  memcpy(view.data, rgb, r->pixels * 3 * sizeof(float));
  char path[HUSH_PATH_MAX];
  if ((size_t)snprintf(path, sizeof path, "%s/frames/%s/frame_%04u.exr", r->o->out, name, i) >=
      sizeof path)
    return cli_error(r->cmd, "--out: path too long");
  const hush_status st = hush_frame_write_exr(r->picture, path, HUSH_EXR_HALF);
  return st == HUSH_OK ? 0 : cli_device_error(r->cmd, r->device, st, path);
}

/* Runs f on frame i and measures its output. Returns non-zero only for
 * errors that stop the whole evaluation (writing files). */
static int filter_frame(eval_run *r, eval_filter *f, hush_frame frame, uint32_t i,
                        const char *file, double ref_temporal) {
  if (f->failed) return 0;
  double ms = NAN;
  hush_image_view out;
  const int psf = strcmp(f->color_layer, "psf") == 0;
  const double psf_ms = psf && r->psf_ms ? r->psf_ms[i] : NAN;
  if (!f->filter) {
    if (get_color(r, frame, f->color_layer, file,
                  psf ? " (render it with --scene, or hush render --psf)" : "", &out))
      return CLI_EXIT_RUNTIME;
    ms = psf_ms;
    if (!isnan(ms)) record_stage(f, "total", ms, r->last - r->first);
  } else {
    if (execute(r, f, frame, i, file, &ms)) return 0;
    if (!isnan(psf_ms)) {
      /* psf+F: the time of both; the stages stay F's alone */
      ms += psf_ms;
      f->stages[f->stage_count - 1].ms[f->stages[f->stage_count - 1].count - 1] = ms;
    }
    hush_frame_get_layer(f->out, "color", &out);
  }
  pack_rgb(&out, r->out_rgb);
  const hush_error_stats e = hush__error_stats(r->out_rgb, r->ref_rgb, r->pixels, 3);
  hush__display_luma_plane(r->out_rgb, 3, r->pixels, f->luma);
  lag_filter(r, f, i);
  eval_row *row = &f->rows[f->done];
  row->frame = i;
  row->rmse = e.rmse;
  row->rel_mse = e.rel_mse;
  row->psnr = e.psnr;
  row->ms = ms;
  const hush_status st = hush__ssim(f->luma, r->ref_luma, r->width, r->height, r->threads, &row->ssim);
  if (st != HUSH_OK) return cli_device_error(r->cmd, r->device, st, "SSIM");
  row->temporal = f->done ? hush__temporal_error(f->prev_luma, f->luma, r->pixels) : NAN;
  row->ref_temporal = ref_temporal;
  float *t = f->prev_luma;
  f->prev_luma = f->luma;
  f->luma = t;
  f->done++;
  return write_picture(r, f->name, i, r->out_rgb);
}

static void progress(const eval_run *r, uint32_t k, uint32_t n, double seconds) {
  if (r->o->quiet) return;
  char line[160];
  snprintf(line, sizeof line, "frame %u/%u  %.2f s", k, n, seconds);
  if (r->tty)
    fprintf(stderr, "%-60s\r", line);
  else
    fprintf(stderr, "%s\n", line);
}

/* Reads frame i and its reference, then runs every filter on it. */
static int eval_frame(eval_run *r, uint32_t i) {
  const double t0 = hush__now_ms();
  const char *file = cli_basename(r->seq.files[i]);
  hush_frame frame = NULL, ref = NULL;
  hush_status st = hush__sequence_read_frame(r->device, &r->seq, i, &frame);
  if (st != HUSH_OK) return cli_device_error(r->cmd, r->device, st, file);
  hush_image_view rv;
  int rc = 0;
  if (r->have_ref) {
    st = hush__sequence_read_frame(r->device, &r->ref, i, &ref);
    if (st != HUSH_OK) rc = cli_device_error(r->cmd, r->device, st, r->ref.files[i]);
    if (!rc) rc = get_color(r, ref, "color", r->ref.files[i], "", &rv);
  } else {
    rc = get_color(r, frame, "ref", file,
                   " to compare with; give the references with --ref REF_DIR", &rv);
  }
  double ref_temporal = NAN;
  if (!rc) {
    pack_rgb(&rv, r->ref_rgb);
    hush__display_luma_plane(r->ref_rgb, 3, r->pixels, r->ref_luma);
    if (i > r->first) ref_temporal = hush__temporal_error(r->ref_prev_luma, r->ref_luma, r->pixels);
    lag_reference(r, i);
    rc = write_picture(r, "reference", i, r->ref_rgb);
  }
  for (uint32_t k = 0; !rc && k < r->filter_count; k++)
    rc = filter_frame(r, &r->filters[k], frame, i, file, ref_temporal);
  float *t = r->ref_prev_luma;
  r->ref_prev_luma = r->ref_luma;
  r->ref_luma = t;
  hush_frame_release(ref);
  hush_frame_release(frame);
  if (!rc) progress(r, i - r->first + 1, r->last - r->first, (hush__now_ms() - t0) / 1000.0);
  return rc;
}

/* ---- results ------------------------------------------------------------------ */

static int compare_double(const void *a, const void *b) {
  const double x = *(const double *)a, y = *(const double *)b;
  return (x > y) - (x < y);
}

/* Linearly interpolated percentile of sorted values (as hush bench). */
static double percentile(const double *sorted, uint32_t n, double q) {
  if (n == 0) return NAN;
  const double pos = q * (double)(n - 1);
  const uint32_t i = (uint32_t)pos;
  const double f = pos - i;
  return i + 1 < n ? sorted[i] * (1.0 - f) + sorted[i + 1] * f : sorted[i];
}

/* A number for a CSV field: empty for NaN (not measured), inf for +inf. */
static void put_number(FILE *f, double v) {
  if (isnan(v)) return;
  if (isinf(v))
    fputs(v > 0 ? "inf" : "-inf", f);
  else
    fprintf(f, "%.9g", v);
}

static void put_csv_text(FILE *f, const char *s) {
  fputc('"', f);
  for (; *s; s++) {
    if (*s == '"') fputc('"', f);
    fputc(*s == '\n' ? ' ' : *s, f);
  }
  fputc('"', f);
}

typedef void (*writer_fn)(const eval_run *r, FILE *f);

static int write_file(eval_run *r, const char *name, writer_fn write) {
  char path[HUSH_PATH_MAX], tmp[HUSH_PATH_MAX];
  if ((size_t)snprintf(path, sizeof path, "%s/%s", r->o->out, name) >= sizeof path)
    return cli_error(r->cmd, "--out: path too long");
  FILE *f = hush__atomic_open(r->device, path, tmp);
  if (!f) return cli_device_error(r->cmd, r->device, HUSH_ERROR_IO, path);
  write(r, f);
  const hush_status st = hush__atomic_commit(r->device, f, tmp, path);
  return st == HUSH_OK ? 0 : cli_device_error(r->cmd, r->device, st, path);
}

static void write_metrics(const eval_run *r, FILE *f) {
  fputs("filter,frame,rmse,rel_mse,psnr,ssim,temporal_error,ref_temporal_error,ms\n", f);
  for (uint32_t k = 0; k < r->filter_count; k++) {
    const eval_filter *fl = &r->filters[k];
    for (uint32_t j = 0; j < fl->done; j++) {
      const eval_row *w = &fl->rows[j];
      fprintf(f, "%s,%u,", fl->name, w->frame);
      const double v[] = {w->rmse, w->rel_mse, w->psnr, w->ssim, w->temporal, w->ref_temporal, w->ms};
      for (int c = 0; c < 7; c++) {
        put_number(f, v[c]);
        fputc(c < 6 ? ',' : '\n', f);
      }
    }
  }
}

/* Sorts the stage samples in place (they are not needed in order after). */
static void write_timings(const eval_run *r, FILE *f) {
  fputs("filter,stage,median_ms,p5_ms,p95_ms\n", f);
  for (uint32_t k = 0; k < r->filter_count; k++) {
    const eval_filter *fl = &r->filters[k];
    for (uint32_t s = 0; s < fl->stage_count; s++) {
      const stage_times *st = &fl->stages[s];
      if (st->count == 0) continue;
      qsort(st->ms, st->count, sizeof *st->ms, compare_double);
      fprintf(f, "%s,%s,%.6f,%.6f,%.6f\n", fl->name, st->name, percentile(st->ms, st->count, 0.5),
              percentile(st->ms, st->count, 0.05), percentile(st->ms, st->count, 0.95));
    }
  }
}

static void write_lag(const eval_run *r, FILE *f) {
  fputs("filter,event_frame,region_pixels,event_lag,shift_lag,brightened_pixels,darkened_pixels,"
        "event_lag_brightened,event_lag_darkened\n",
        f);
  for (uint32_t k = 0; k < r->filter_count; k++) {
    const eval_filter *fl = &r->filters[k];
    fprintf(f, "%s,", fl->name);
    if (r->lag_event != UINT32_MAX) fprintf(f, "%u,%zu,", r->lag_event, r->lag_region);
    else fputs(",,", f);
    put_number(f, event_lag(r, fl, 2));
    fputc(',', f);
    put_number(f, shift_lag(r, fl));
    if (r->lag_event != UINT32_MAX) fprintf(f, ",%zu,%zu,", r->lag_part[0], r->lag_part[1]);
    else fputs(",,,", f);
    put_number(f, event_lag(r, fl, 0));
    fputc(',', f);
    put_number(f, event_lag(r, fl, 1));
    fputc('\n', f);
  }
}

/* The series behind the event lag: per frame from the event on and per
 * part, the reference's and each filter's mean lag luminance over it
 * (empty without an event). */
static void write_lag_series(const eval_run *r, FILE *f) {
  fputs("frame,part,reference", f);
  for (uint32_t k = 0; k < r->filter_count; k++) fprintf(f, ",%s", r->filters[k].name);
  fputc('\n', f);
  if (r->lag_event == UINT32_MAX) return;
  for (uint32_t i = r->lag_event; i < r->last; i++)
    for (int s = 0; s < 2; s++) {
      fprintf(f, "%u,%s,", i, s ? "darkened" : "brightened");
      put_number(f, r->lag_ref_mean[s][i - r->lag_event]);
      for (uint32_t k = 0; k < r->filter_count; k++) {
        const eval_filter *fl = &r->filters[k];
        fputc(',', f);
        put_number(f, fl->failed ? NAN : fl->lag_mean[s][i - r->lag_event]);
      }
      fputc('\n', f);
    }
}

static void write_status(const eval_run *r, FILE *f) {
  fputs("filter,status,message\n", f);
  for (uint32_t k = 0; k < r->filter_count; k++) {
    const eval_filter *fl = &r->filters[k];
    fprintf(f, "%s,%s,", fl->name, fl->failed ? "failed" : "ok");
    put_csv_text(f, fl->failed ? fl->message : "");
    fputc('\n', f);
  }
}

/* Means over the frames a filter completed. */
typedef struct means {
  double rmse, rel_mse, psnr, ssim, temporal, ref_temporal, ms;
} means;

static means filter_means(const eval_filter *fl) {
  means m = {0, 0, 0, 0, 0, 0, 0};
  uint32_t nt = 0;
  for (uint32_t j = 0; j < fl->done; j++) {
    const eval_row *w = &fl->rows[j];
    m.rmse += w->rmse;
    m.rel_mse += w->rel_mse;
    m.psnr += w->psnr;
    m.ssim += w->ssim;
    if (!isnan(w->temporal)) {
      m.temporal += w->temporal;
      m.ref_temporal += w->ref_temporal;
      nt++;
    }
  }
  const double n = fl->done ? (double)fl->done : NAN;
  m.rmse /= n;
  m.rel_mse /= n;
  m.psnr /= n;
  m.ssim /= n;
  m.temporal = nt ? m.temporal / nt : NAN;
  m.ref_temporal = nt ? m.ref_temporal / nt : NAN;
  m.ms = NAN;
  for (uint32_t s = 0; s < fl->stage_count; s++)
    if (strcmp(fl->stages[s].name, "total") == 0 && fl->stages[s].count) {
      /* stages are sorted by write_timings; sort again in case it did not run */
      qsort(fl->stages[s].ms, fl->stages[s].count, sizeof(double), compare_double);
      m.ms = percentile(fl->stages[s].ms, fl->stages[s].count, 0.5);
    }
  return m;
}

static void put_cell(FILE *f, double v, const char *fmt) {
  fputs(" | ", f);
  if (isnan(v))
    fputs("-", f);
  else if (isinf(v))
    fputs("inf", f);
  else
    fprintf(f, fmt, v);
}

/* The lag table of summary.md (its first column is not "filter": tools
 * that take the table starting "| filter" get the main one). */
static void write_lag_table(const eval_run *r, FILE *f) {
  if (r->lag_event == UINT32_MAX && !r->lag_shifts) return;
  fputs("\n## Lag\n\n", f);
  if (r->lag_event != UINT32_MAX)
    fprintf(f,
            "Event at frame %u: %zu pixels (%.1f%%) of the reference changed by more than %.2f "
            "in luminance (linear, clamped to 1, averaged over %dx%d boxes) from frame %u: "
            "%zu brightened, %zu darkened. Event lag: frames after it until the filter's "
            "mean over each part (of %.0f%% of the frame or more) is within %.0f%% of the "
            "reference's, the larger of the two (`> M`: not in the M frames evaluated after "
            "it).",
            r->lag_event, r->lag_region, 100.0 * (double)r->lag_region / (double)r->pixels,
            (double)HUSH_LAG_THRESHOLD, 2 * HUSH_LAG_RADIUS + 1, 2 * HUSH_LAG_RADIUS + 1,
            r->lag_event - 1, r->lag_part[0], r->lag_part[1], 100.0 * HUSH_LAG_MIN_PART,
            100.0 * HUSH_LAG_TOLERANCE);
  else
    fprintf(f, "No event: no frame's reference changed on %.1f%% of the pixels or more.",
            100.0 * HUSH_LAG_MIN_REGION);
  if (r->lag_shifts)
    fprintf(f,
            " Shift lag: the delay, 0 to %u frames, of the reference sequence that the output "
            "matches best (least squares over frames %u to %u and the %zu pixels, %.1f%%, whose "
            "box-averaged reference ranges over more than %.2f across the run).",
            r->lag_shifts - 1, r->first + r->lag_shifts - 1, r->last - 1, r->lag_shift_region,
            100.0 * (double)r->lag_shift_region / (double)r->pixels, (double)HUSH_LAG_THRESHOLD);
  fputs(" docs/eval.md defines both.\n\n"
        "| lag | event (frames) | brightened | darkened | shift (frames) |\n"
        "| --- | ---: | ---: | ---: | ---: |\n",
        f);
  for (uint32_t k = 0; k < r->filter_count; k++) {
    const eval_filter *fl = &r->filters[k];
    fprintf(f, "| %s%s", fl->name, fl->failed ? " (failed)" : "");
    static const int parts[3] = {2, 0, 1}; /* both, brightened, darkened */
    for (int j = 0; j < 3; j++) {
      const double e = event_lag(r, fl, parts[j]);
      if (isinf(e))
        fprintf(f, " | > %u", r->last - 1 - r->lag_event);
      else
        put_cell(f, e, "%.0f");
    }
    put_cell(f, shift_lag(r, fl), "%.2f");
    fputs(" |\n", f);
  }
}

static void write_summary(const eval_run *r, FILE *f) {
  fprintf(f, "# hush eval\n\n");
  fprintf(f, "Input `%s`, reference `%s`, frames %u to %u (%u frames of %ux%u).\n\n", r->seq_dir,
          r->have_ref ? r->ref_dir : "the input's \"ref\" layer", r->first, r->last - 1,
          r->last - r->first, r->width, r->height);
  fprintf(f, "| filter | RMSE | relMSE | SSIM | PSNR (dB) | temporal error | ms/frame |\n");
  fprintf(f, "| --- | ---: | ---: | ---: | ---: | ---: | ---: |\n");
  double ref_temporal = NAN;
  for (uint32_t k = 0; k < r->filter_count; k++) {
    const eval_filter *fl = &r->filters[k];
    const means m = filter_means(fl);
    if (strcmp(fl->name, "noisy") == 0) ref_temporal = m.ref_temporal;
    fprintf(f, "| %s%s", fl->name, fl->failed ? " (failed)" : "");
    put_cell(f, m.rmse, "%.5f");
    put_cell(f, m.rel_mse, "%.5f");
    put_cell(f, m.ssim, "%.4f");
    put_cell(f, m.psnr, "%.2f");
    put_cell(f, m.temporal, "%.5f");
    put_cell(f, m.ms, "%.2f");
    fputs(" |\n", f);
  }
  fputs("| reference", f);
  for (int c = 0; c < 4; c++) put_cell(f, NAN, "");
  put_cell(f, ref_temporal, "%.5f");
  put_cell(f, NAN, "");
  fputs(" |\n\n", f);
  fprintf(f,
          "Means over the frames each filter completed. SSIM and the temporal error are on "
          "display luminance (docs/eval.md); the temporal error is the mean absolute change "
          "between consecutive frames, and the reference's own is its last row: a filter close "
          "to it flickers as little as the converged image changes. ms/frame is the median "
          "execute time.\n");
  write_lag_table(r, f);
  for (uint32_t k = 0; k < r->filter_count; k++) {
    const eval_filter *fl = &r->filters[k];
    if (fl->failed)
      fprintf(f, "\n**%s failed** at frame %u: %s\n", fl->name, fl->failed_frame, fl->message);
  }
}

static void write_json(const eval_run *r, FILE *f) {
  fputs("{\n  \"format\": \"hush-eval/1\",\n  \"seq\": ", f);
  cli_json_string(f, r->seq_dir);
  /* always a string, for people to read: ref_layer says where it came from */
  char ref[HUSH_PATH_MAX + 32];
  if (r->have_ref)
    snprintf(ref, sizeof ref, "%s", r->ref_dir);
  else
    snprintf(ref, sizeof ref, "%s (layer ref)", r->seq_dir);
  fputs(",\n  \"ref\": ", f);
  cli_json_string(f, ref);
  fprintf(f, ",\n  \"ref_layer\": \"%s\"", r->have_ref ? "color" : "ref");
  fputs(",\n  \"scene\": ", f);
  if (r->o->scene)
    cli_json_string(f, r->o->scene);
  else
    fputs("null", f);
  if (r->o->scene)
    fprintf(f, ",\n  \"ref_spp\": %u,\n  \"gradients\": %s", r->o->ref_spp,
            r->gradients ? "true" : "false");
  fprintf(f, ",\n  \"frames\": [%u, %u],\n  \"width\": %u,\n  \"height\": %u,\n  \"filters\": [",
          r->first, r->last, r->width, r->height);
  for (uint32_t k = 0; k < r->filter_count; k++) {
    if (k) fputs(", ", f);
    cli_json_string(f, r->filters[k].name);
  }
  fprintf(f, "],\n  \"threads\": %d,\n  \"command\": [", r->threads);
  cli_json_string(f, "hush");
  for (int i = 0; i < r->argc; i++) {
    fputs(", ", f);
    cli_json_string(f, r->argv[i]);
  }
  fputs("]\n}\n", f);
}

static void print_summary(const eval_run *r) {
  char path[HUSH_PATH_MAX];
  snprintf(path, sizeof path, "%s/summary.md", r->o->out);
  FILE *f = fopen(path, "r");
  if (!f) return;
  char line[1024];
  while (fgets(line, sizeof line, f))
    if (line[0] == '|') fputs(line, stdout);
  fclose(f);
}

/* ---- rendering first (--scene) -------------------------------------------------- */

/* --scene with psf: the psf renderer from the psf.* settings of --set,
 * installed in sf; REPORT_DIR/psf.csv receives the statistics. */
static int open_psf(eval_run *r, scene_frames *sf, psf_cli *pc, FILE **csv) {
  memset(pc, 0, sizeof *pc);
  for (int i = 0; i < r->o->set_count; i++)
    if (strncmp(r->o->sets[i], "psf.", 4) == 0) psf_cli_add_set(r->cmd, pc, r->o->sets[i] + 4);
  int rc = psf_cli_open(pc, r->cmd, r->device, sf->width, sf->height, 1);
  if (rc) return rc;
  char path[HUSH_PATH_MAX];
  if ((size_t)snprintf(path, sizeof path, "%s/psf.csv", r->o->out) >= sizeof path)
    return cli_error(r->cmd, "--out: path too long");
  *csv = fopen(path, "w");
  if (!*csv) return cli_error(r->cmd, "%s: cannot write", path);
  psf_cli_csv_header(*csv);
  r->psf_ms = calloc(sf->frames, sizeof *r->psf_ms);
  if (!r->psf_ms) return cli_error(r->cmd, "out of memory");
  sf->psf = pc->renderer;
  return 0;
}

static int render_sequence(eval_run *r, scene_frames *sf, const char *dir, uint32_t spp,
                           uint32_t seed) {
  hush_sequence seq;
  hush_status st = hush__make_dirs(r->device, dir);
  if (st == HUSH_OK) st = hush__sequence_init(r->device, &seq, dir, sf->width, sf->height, sf->frames);
  if (st != HUSH_OK) return cli_device_error(r->cmd, r->device, st, dir);
  seq.motion = sf->motion;
  hush_render_params params;
  hush__render_defaults(&params);
  params.spp = spp;
  params.seed = seed;
  render_progress p;
  if (!r->o->quiet)
    fprintf(stderr, "hush eval: rendering %u frames of %ux%u at %u spp into %s\n", sf->frames,
            sf->width, sf->height, spp, dir);
  /* the per-row bar only on a terminal: in a log it would be a line per row */
  render_progress_begin(&p, sf->frames, r->tty, r->o->quiet, spp > 1 && r->tty);
  int rc = 0;
  psf_cli pc;
  memset(&pc, 0, sizeof pc);
  FILE *csv = NULL;
  sf->psf = NULL;
  if (spp == 1 && r->psf) rc = open_psf(r, sf, &pc, &csv);
  /* only the input gets gradient samples: they replace a pixel's sample */
  hush_gradients gradients;
  memset(&gradients, 0, sizeof gradients);
  if (!rc && spp == 1 && r->gradients) {
    st = hush__gradients_init(r->device, &gradients, sf->width, sf->height);
    if (st != HUSH_OK) rc = cli_device_error(r->cmd, r->device, st, "gradients");
    params.gradients = &gradients;
  }
  for (uint32_t i = 0; !rc && i < sf->frames; i++) {
    hush_frame frame = NULL;
    rc = scene_frames_render(sf, i, &params, (int)r->o->threads, &p, &frame, &seq.cameras[i]);
    if (!rc && sf->psf) {
      psf_cli_csv_row(csv, &pc, i, &sf->psf_timings);
      const hush_psf_timings *t = &sf->psf_timings;
      r->psf_ms[i] = t->add + t->resolve + t->lookup;
    }
    char path[HUSH_PATH_MAX];
    if (!rc) st = hush__sequence_frame_path(r->device, &seq, i, path, sizeof path);
    if (!rc && st == HUSH_OK) st = hush_frame_write_exr(frame, path, HUSH_EXR_FLOAT);
    if (!rc && st != HUSH_OK) rc = cli_device_error(r->cmd, r->device, st, path);
    hush_frame_release(frame);
  }
  render_progress_break(&p);
  hush__gradients_free(&gradients);
  sf->psf = NULL;
  if (csv && fclose(csv) != 0 && !rc) rc = cli_error(r->cmd, "psf.csv: write failed");
  psf_cli_close(&pc);
  if (!rc) st = hush__sequence_write_cameras(r->device, &seq);
  if (!rc && st != HUSH_OK) rc = cli_device_error(r->cmd, r->device, st, dir);
  hush__sequence_free(&seq);
  return rc;
}

/* Renders REPORT_DIR/seq (1 spp, seed 1) and REPORT_DIR/ref (--ref-spp,
 * seed 2: a reference that contained the input's own samples would favour
 * the input). Same cameras and jitter: both come from the frame index. */
static int render_inputs(eval_run *r) {
  const eval_options *o = r->o;
  uint32_t frames = 0;
  if (o->frames_text) frames = cli_parse_uint(r->cmd, "--frames", o->frames_text, 1, 100000);
  if ((size_t)snprintf(r->seq_dir, sizeof r->seq_dir, "%s/seq", o->out) >= sizeof r->seq_dir ||
      (size_t)snprintf(r->ref_dir, sizeof r->ref_dir, "%s/ref", o->out) >= sizeof r->ref_dir)
    return cli_error(r->cmd, "--out: path too long");
  scene_frames sf;
  int rc = scene_frames_open(&sf, r->cmd, r->device, o->scene, o->path, o->width, o->height,
                             frames);
  if (!rc) rc = render_sequence(r, &sf, r->seq_dir, 1, 1);
  if (!rc) rc = render_sequence(r, &sf, r->ref_dir, o->ref_spp, 2);
  scene_frames_close(&sf);
  return rc;
}

/* ---- the run -------------------------------------------------------------------- */

static int make_output_dirs(eval_run *r) {
  char dir[HUSH_PATH_MAX];
  for (uint32_t k = 0; k <= r->filter_count; k++) {
    const char *name = k < r->filter_count ? r->filters[k].name : "reference";
    if ((size_t)snprintf(dir, sizeof dir, "%s/frames/%s", r->o->out, name) >= sizeof dir)
      return cli_error(r->cmd, "--out: path too long");
    const hush_status st = hush__make_dirs(r->device, dir);
    if (st != HUSH_OK) return cli_device_error(r->cmd, r->device, st, dir);
  }
  return 0;
}

static int allocate(eval_run *r) {
  r->ref_rgb = malloc(r->pixels * 3 * sizeof *r->ref_rgb);
  r->out_rgb = malloc(r->pixels * 3 * sizeof *r->out_rgb);
  r->ref_luma = malloc(r->pixels * sizeof *r->ref_luma);
  r->ref_prev_luma = malloc(r->pixels * sizeof *r->ref_prev_luma);
  r->picture = hush_frame_new(r->device, r->width, r->height);
  if (!r->ref_rgb || !r->out_rgb || !r->ref_luma || !r->ref_prev_luma || !r->picture)
    return cli_error(r->cmd, "out of memory");
  const hush_status st = hush_frame_add_layer(r->picture, "color", 3, NULL);
  return st == HUSH_OK ? 0 : cli_device_error(r->cmd, r->device, st, NULL);
}

static int write_results(eval_run *r) {
  int rc = write_file(r, "metrics.csv", write_metrics);
  if (!rc) rc = write_file(r, "timings.csv", write_timings);
  if (!rc) rc = write_file(r, "status.csv", write_status);
  if (!rc) rc = write_file(r, "lag.csv", write_lag);
  if (!rc) rc = write_file(r, "lag_series.csv", write_lag_series);
  if (!rc) rc = write_file(r, "summary.md", write_summary);
  if (!rc) rc = write_file(r, "eval.json", write_json);
  return rc;
}

/* report.html, made from the files just written (docs/eval.md). */
static int write_report(eval_run *r) {
  const eval_options *o = r->o;
  for (uint32_t k = 0; k < o->show_count; k++)
    if (o->show[k] < r->first || o->show[k] >= r->last)
      return cli_error(r->cmd, "--show %u: frames %u to %u were evaluated", o->show[k], r->first,
                       r->last - 1);
  hush_report_options opt;
  memset(&opt, 0, sizeof opt);
  opt.frames = o->show_count ? o->show : NULL;
  opt.frame_count = o->show_count;
  opt.exposure = o->exposure;
  opt.tonemap = o->tonemap;
  opt.video = !o->no_video;
  const hush_status st = hush__report_write(r->device, o->out, &opt);
  return st == HUSH_OK ? 0 : cli_device_error(r->cmd, r->device, st, "report");
}

static int run(eval_run *r) {
  int rc = filter_list(r);
  if (!rc) rc = check_sets(r);
  r->gradients = r->o->gradients;
  for (uint32_t k = 0; !rc && r->o->scene && k < r->filter_count; k++) {
    int wants = 0;
    rc = wants_gradients(r, &r->filters[k], &wants);
    r->gradients |= wants;
  }
  if (!rc && r->o->scene) {
    rc = render_inputs(r);
  } else if (!rc) {
    snprintf(r->seq_dir, sizeof r->seq_dir, "%s", r->o->seq);
    snprintf(r->ref_dir, sizeof r->ref_dir, "%s", r->o->ref ? r->o->ref : "");
  }
  if (!rc) rc = open_inputs(r);
  if (!rc) rc = allocate(r);
  if (!rc) rc = lag_setup(r);
  for (uint32_t k = 0; !rc && k < r->filter_count; k++) rc = setup_filter(r, &r->filters[k]);
  if (!rc) rc = make_output_dirs(r);
  for (uint32_t i = r->first; !rc && i < r->last; i++) rc = eval_frame(r, i);
  if (rc) return rc;
  if (r->tty && !r->o->quiet) fputc('\n', stderr);
  lag_finish(r);
  rc = write_results(r);
  if (!rc) rc = write_report(r);
  if (rc) return rc;
  if (!r->o->quiet) {
    print_summary(r);
    fprintf(stderr, "hush eval: report in %s/report.html (and summary.md, metrics.csv, timings.csv)\n",
            r->o->out);
  }
  int failed = 0;
  for (uint32_t k = 0; k < r->filter_count; k++) {
    const eval_filter *fl = &r->filters[k];
    if (!fl->failed) continue;
    failed++;
    fprintf(stderr, "hush eval: warning: filter '%s' failed at frame %u: %s\n", fl->name,
            fl->failed_frame, fl->message);
  }
  return failed && r->o->strict ? CLI_EXIT_RUNTIME : 0;
}

static void run_free(eval_run *r) {
  for (uint32_t k = 0; k < r->filter_count; k++) {
    eval_filter *f = &r->filters[k];
    hush_filter_release(f->filter);
    hush_frame_release(f->out);
    free(f->luma);
    free(f->prev_luma);
    free(f->rows);
    free(f->lag_pixel_sse);
    free(f->lag_mean[0]);
    free(f->lag_mean[1]);
    for (uint32_t s = 0; s < f->stage_count; s++) free(f->stages[s].ms);
  }
  free(r->psf_ms);
  free(r->ref_rgb);
  free(r->out_rgb);
  free(r->ref_luma);
  free(r->ref_prev_luma);
  free(r->lag_mask);
  free(r->lag_candidate);
  free(r->lag_ref_mean[0]);
  free(r->lag_ref_mean[1]);
  free(r->lag_luma);
  free(r->lag_ref_luma);
  free(r->lag_box);
  free(r->lag_box_prev);
  for (uint32_t k = 0; k < HUSH_LAG_MAX_SHIFT; k++) {
    free(r->lag_ring[k]);
  }
  free(r->lag_shift_mask);
  free(r->lag_lo);
  free(r->lag_hi);
  hush_frame_release(r->picture);
  if (r->have_seq) hush__sequence_free(&r->seq);
  if (r->have_ref) hush__sequence_free(&r->ref);
}

int cmd_eval(int argc, char **argv) {
  eval_options o;
  parse_options(argc, argv, &o);
  eval_run r;
  memset(&r, 0, sizeof r);
  r.cmd = "eval";
  r.o = &o;
  r.argc = argc;
  r.argv = argv;
  r.tty = isatty(fileno(stderr));
  r.device = cli_device_new(r.cmd, o.threads);
  if (!r.device) return CLI_EXIT_RUNTIME;
  r.threads = hush_device_threads(r.device);
  const int rc = run(&r);
  run_free(&r);
  hush_device_release(r.device);
  return rc;
}
