/*
 * cmd_denoise.c — `hush denoise`: runs one filter over a frame sequence on
 * disk. Each frame's layers are bound to the filter's input images of the
 * same name, the output goes to a new frame written as DIR/frame_NNNN.exr
 * (output as "color", plus any optional outputs), then cameras.json for the
 * frames written. Every library write is atomic, so a failure leaves whole
 * files or none.
 */
#include "cli.h"

#include "core/timer.h"
#include "eval/metrics.h"
#include "eval/synthetic.h"
#include "io/atomic_file.h"
#include "io/sequence.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#define MAX_SETS 64

static const char *const help_text =
    "usage: hush denoise --filter NAME --in SEQ_DIR --out DIR [options]\n"
    "\n"
    "Runs filter NAME over the sequence in SEQ_DIR (cameras.json and one EXR\n"
    "per frame, as `hush synth` writes them). Frame layers are bound to the\n"
    "filter's input images of the same name (see `hush filters NAME`); a\n"
    "required image missing from a frame is an error. The cameras and the\n"
    "motion source (camera or vectors) come from cameras.json. For frame N it\n"
    "writes DIR/frame_NNNN.exr with the filtered image as layer \"color\" (and\n"
    "the filter's optional outputs under their own names), and at the end\n"
    "DIR/cameras.json. DIR is created if missing and must differ from SEQ_DIR.\n"
    "\n"
    "options:\n"
    "  --filter NAME       the filter class (required; `hush filters` lists them)\n"
    "  --in SEQ_DIR        the input sequence (required)\n"
    "  --out DIR           the output directory (required)\n"
    "  --set KEY=VALUE     set a filter parameter; repeatable. Values: numbers,\n"
    "                      true/false, or an enum's value names; nca also takes\n"
    "                      weights=FILE (from `hush train-nca`; builtin: the\n"
    "                      built-in weights)\n"
    "  --frames A:B        only frames A to B-1 (either side may be empty;\n"
    "                      a single A is frame A only); default all\n"
    "  --png               also write DIR/frame_NNNN.png of the output\n"
    "  --exposure E        PNG: scale radiance by 2^E, -64..64 (default 0)\n"
    "  --tonemap T         PNG: clamp, reinhard or aces (default clamp)\n"
    "  --half              write half-float EXRs (default float)\n"
    "  --threads N         worker threads, 0 = one per core (default 0)\n"
    "  --ref LAYER         also measure the error of the input \"color\" and of the\n"
    "                      output against the frames' LAYER (e.g. ref, as `hush\n"
    "                      synth` writes it): mean RMSE and PSNR over the frames,\n"
    "                      printed on stdout (also with --quiet)\n"
    "  --quiet             no progress and no summary, only errors\n"
    "  -h, --help          show this help\n"
    "\n"
    "Progress goes to stderr: \"frame i/N  X.X ms/frame\" (filter time), then\n"
    "one summary line with the median filter time per frame.\n";

typedef struct denoise_options {
  const char *filter, *in, *out;
  const char *sets[MAX_SETS];
  int set_count;
  uint32_t first, last; /* frames [first, last); last UINT32_MAX: to the end */
  int png;
  float exposure;
  hush_tonemap tonemap;
  hush_exr_type exr_type;
  uint32_t threads;
  int quiet;
  const char *ref;
} denoise_options;

/* What one run holds; released by run_free(). */
typedef struct denoise_run {
  const char *cmd;
  const denoise_options *o;
  hush_device device;
  hush_filter filter;
  const hush_filter_class_info *cls;
  hush_sequence seq;
  int have_seq;
  hush_frame out;     /* the output layers, bound once and reused */
  double *ms;         /* filter time of each frame written */
  uint32_t done;
  int progress_tty;   /* overwrite the progress line */
  hush_error_stats in_sum, out_sum; /* --ref: sums over the frames measured */
} denoise_run;

static void parse_options(int argc, char **argv, denoise_options *o) {
  cli_args a;
  cli_args_init(&a, "denoise", argc, argv);
  memset(o, 0, sizeof *o);
  o->last = UINT32_MAX;
  o->tonemap = HUSH_TONEMAP_CLAMP;
  o->exr_type = HUSH_EXR_FLOAT;
  const char *arg, *v;
  while (cli_next(&a, &arg)) {
    if (cli_is_help(arg)) {
      fputs(help_text, stdout);
      exit(0);
    } else if (cli_option(&a, arg, "--filter", &v)) {
      o->filter = v;
    } else if (cli_option(&a, arg, "--in", &v)) {
      o->in = v;
    } else if (cli_option(&a, arg, "--out", &v)) {
      o->out = v;
    } else if (cli_option(&a, arg, "--set", &v)) {
      const char *eq = strchr(v, '=');
      if (!eq || eq == v) cli_usage_error(a.cmd, "--set: expected KEY=VALUE, got '%s'", v);
      if (o->set_count == MAX_SETS) cli_usage_error(a.cmd, "--set: more than %d parameters", MAX_SETS);
      o->sets[o->set_count++] = v;
    } else if (cli_option(&a, arg, "--frames", &v)) {
      cli_parse_range(a.cmd, "--frames", v, &o->first, &o->last);
    } else if (cli_switch(&a, arg, "--png")) {
      o->png = 1;
    } else if (cli_option(&a, arg, "--exposure", &v)) {
      o->exposure = cli_parse_float(a.cmd, "--exposure", v, -64.0f, 64.0f);
    } else if (cli_option(&a, arg, "--tonemap", &v)) {
      o->tonemap = cli_parse_tonemap(a.cmd, "--tonemap", v);
    } else if (cli_switch(&a, arg, "--half")) {
      o->exr_type = HUSH_EXR_HALF;
    } else if (cli_option(&a, arg, "--threads", &v)) {
      o->threads = cli_parse_uint(a.cmd, "--threads", v, 0, 1024);
    } else if (cli_switch(&a, arg, "--quiet")) {
      o->quiet = 1;
    } else if (cli_option(&a, arg, "--ref", &v)) {
      o->ref = v;
    } else if (cli_is_positional(&a, arg)) {
      cli_usage_error(a.cmd, "unexpected argument '%s' (see hush denoise --help)", arg);
    } else {
      cli_unknown_option(&a, arg);
    }
  }
  if (!o->filter) cli_usage_error(a.cmd, "--filter NAME is required (`hush filters` lists them)");
  if (!o->in) cli_usage_error(a.cmd, "--in SEQ_DIR is required");
  if (!o->out) cli_usage_error(a.cmd, "--out DIR is required");
}

/* ---- set-up ------------------------------------------------------------- */

static int make_filter(denoise_run *r) {
  r->filter = hush_filter_new(r->device, r->o->filter);
  if (!r->filter) return cli_device_error(r->cmd, r->device, HUSH_ERROR_NOT_FOUND, NULL);
  r->cls = hush_filter_get_class(r->filter);
  for (int i = 0; i < r->o->set_count; i++) {
    const char *kv = r->o->sets[i];
    const char *eq = strchr(kv, '=');
    char key[128];
    if ((size_t)(eq - kv) >= sizeof key) return cli_error(r->cmd, "--set %s: name too long", kv);
    memcpy(key, kv, (size_t)(eq - kv));
    key[eq - kv] = '\0';
    const hush_status st = cli_filter_set(r->filter, key, eq + 1);
    if (st != HUSH_OK) {
      char context[256];
      snprintf(context, sizeof context, "--set %s", kv);
      return cli_device_error(r->cmd, r->device, st, context);
    }
  }
  return 0;
}

/* Writing frame_NNNN.exr into the directory being read would replace the
 * input; compare device and inode so "seq" and "./seq/" count as equal. */
static int same_dir(const char *a, const char *b) {
  struct stat sa, sb;
  if (stat(a, &sa) != 0 || stat(b, &sb) != 0) return 0;
  return sa.st_dev == sb.st_dev && sa.st_ino == sb.st_ino;
}

static int open_sequence(denoise_run *r) {
  const denoise_options *o = r->o;
  if (!cli_is_dir(o->in))
    return cli_error(r->cmd, "input directory '%s' does not exist or is not a directory", o->in);
  const hush_status st = hush__sequence_read(r->device, o->in, &r->seq);
  if (st != HUSH_OK) return cli_device_error(r->cmd, r->device, st, "cameras.json");
  r->have_seq = 1;
  if (o->first >= r->seq.frame_count)
    return cli_error(r->cmd, "--frames starts at %u but %s has %u frames", o->first, o->in,
                     r->seq.frame_count);
  return 0;
}

static int open_output(denoise_run *r) {
  const hush_status st = hush__make_dirs(r->device, r->o->out);
  if (st != HUSH_OK) return cli_device_error(r->cmd, r->device, st, NULL);
  if (same_dir(r->o->in, r->o->out))
    return cli_error(r->cmd, "--out '%s' is the input directory; choose another", r->o->out);
  return 0;
}

/* The filter's output is the "color" layer of the frame written; optional
 * outputs keep their own names. */
static const char *output_layer_name(const char *image) {
  return strcmp(image, "output") == 0 ? "color" : image;
}

static int bind_outputs(denoise_run *r) {
  r->out = hush_frame_new(r->device, r->seq.width, r->seq.height);
  if (!r->out) return cli_device_error(r->cmd, r->device, HUSH_ERROR_OUT_OF_MEMORY, NULL);
  for (uint32_t i = 0; i < r->cls->image_count; i++) {
    const hush_image_info *im = &r->cls->images[i];
    if (im->role != HUSH_IMAGE_OUTPUT) continue;
    hush_image_view view;
    hush_status st = hush_frame_add_layer(r->out, output_layer_name(im->name), im->channels, &view);
    if (st == HUSH_OK) st = hush_filter_set_image(r->filter, im->name, &view);
    if (st != HUSH_OK) return cli_device_error(r->cmd, r->device, st, im->name);
  }
  return 0;
}

/* ---- per frame ---------------------------------------------------------- */

static int write_frame(denoise_run *r, uint32_t index) {
  char path[HUSH_PATH_MAX];
  snprintf(path, sizeof path, "%s/frame_%04u.exr", r->o->out, index);
  hush_status st = hush_frame_write_exr(r->out, path, r->o->exr_type);
  if (st != HUSH_OK) return cli_device_error(r->cmd, r->device, st, path);
  if (!r->o->png) return 0;
  hush_image_view view;
  snprintf(path, sizeof path, "%s/frame_%04u.png", r->o->out, index);
  st = hush_frame_get_layer(r->out, "color", &view);
  if (st == HUSH_OK) st = hush_image_write_png(r->device, &view, path, r->o->exposure, r->o->tonemap);
  if (st != HUSH_OK) return cli_device_error(r->cmd, r->device, st, path);
  return 0;
}

/* On a terminal the line ends in '\r', not '\n': the next progress line,
 * an error or the summary then overwrites it (the padding covers the rest),
 * with no need to remember that a line is open. */
static void progress(const denoise_run *r, uint32_t n, double ms) {
  if (r->o->quiet) return;
  char line[96];
  snprintf(line, sizeof line, "frame %u/%u  %.1f ms/frame", r->done, n, ms);
  if (r->progress_tty)
    fprintf(stderr, "%-48s\r", line);
  else
    fprintf(stderr, "%s\n", line);
}

/* Adds the error of `test` against the frame's reference layer (first three
 * channels of each) to *sum. */
static int measure(denoise_run *r, hush_frame frame, hush_frame test, const char *file,
                   hush_error_stats *sum) {
  hush_image_view ref, img;
  if (hush_frame_get_layer(frame, r->o->ref, &ref) != HUSH_OK ||
      hush_frame_get_layer(test, "color", &img) != HUSH_OK) {
    hush_device_get_error(r->device, NULL);
    return cli_error(r->cmd, "%s has no '%s' layer to measure against (--ref)", file, r->o->ref);
  }
  const int rc = hush_format_channels(ref.format), ic = hush_format_channels(img.format);
  if (rc != ic)
    return cli_error(r->cmd, "%s: --ref layer '%s' has %d channels, 'color' has %d", file,
                     r->o->ref, rc, ic);
  const hush_error_stats s =
      hush__error_stats(img.data, ref.data, (size_t)ref.width * ref.height, rc);
  sum->rmse += s.rmse;
  sum->psnr += s.psnr;
  sum->mse += s.mse;
  sum->rel_mse += s.rel_mse;
  return 0;
}

static int run_frame(denoise_run *r, uint32_t i, uint32_t n) {
  const char *file = cli_basename(r->seq.files[i]);
  hush_frame frame = NULL;
  hush_status st = hush__sequence_read_frame(r->device, &r->seq, i, &frame);
  if (st != HUSH_OK) return cli_device_error(r->cmd, r->device, st, file);
  int rc = cli_bind_inputs(r->cmd, r->device, r->filter, frame, file);
  if (!rc && r->done == 0) {
    st = hush_filter_commit(r->filter);
    if (st != HUSH_OK) rc = cli_device_error(r->cmd, r->device, st, file);
  }
  double ms = 0.0;
  if (!rc) {
    hush_frame_info info;
    hush__sequence_frame_info(&r->seq, i, &info);
    /* the first frame run has no history, whichever frame it is */
    if (r->done == 0) info.history = HUSH_HISTORY_RESET;
    const double t0 = hush__now_ms();
    st = hush_filter_execute(r->filter, &info);
    ms = hush__now_ms() - t0;
    if (st != HUSH_OK) rc = cli_device_error(r->cmd, r->device, st, file);
  }
  if (!rc && r->o->ref) rc = measure(r, frame, frame, file, &r->in_sum);
  if (!rc && r->o->ref) rc = measure(r, frame, r->out, file, &r->out_sum);
  hush_frame_release(frame);
  if (!rc) rc = write_frame(r, i);
  if (rc) return rc;
  r->ms[r->done++] = ms;
  progress(r, n, ms);
  return 0;
}

/* cameras.json for the frames written, named as write_frame names them. */
static int write_cameras(denoise_run *r, uint32_t first, uint32_t n) {
  hush_sequence out;
  memset(&out, 0, sizeof out);
  out.dir = (char *)r->o->out;
  out.width = r->seq.width;
  out.height = r->seq.height;
  out.frame_count = n;
  out.motion = r->seq.motion;
  out.cameras = r->seq.cameras + first;
  out.files = calloc(n, sizeof *out.files);
  char *names = calloc(n, 32);
  int rc = 0;
  if (!out.files || !names) {
    rc = cli_error(r->cmd, "out of memory");
  } else {
    for (uint32_t k = 0; k < n; k++) {
      out.files[k] = names + 32 * (size_t)k;
      snprintf(out.files[k], 32, "frame_%04u.exr", first + k);
    }
    const hush_status st = hush__sequence_write_cameras(r->device, &out);
    if (st != HUSH_OK) rc = cli_device_error(r->cmd, r->device, st, NULL);
  }
  free(names);
  free(out.files);
  return rc;
}

static int compare_double(const void *a, const void *b) {
  const double x = *(const double *)a, y = *(const double *)b;
  return (x > y) - (x < y);
}

static double median(double *v, uint32_t n) {
  if (n == 0) return 0.0;
  qsort(v, n, sizeof *v, compare_double);
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

static int run(denoise_run *r) {
  int rc = make_filter(r);
  if (!rc) rc = open_sequence(r);
  if (!rc) rc = open_output(r);
  if (!rc) rc = bind_outputs(r);
  if (rc) return rc;

  const uint32_t first = r->o->first;
  const uint32_t last = r->o->last < r->seq.frame_count ? r->o->last : r->seq.frame_count;
  const uint32_t n = last - first;
  r->ms = calloc(n, sizeof *r->ms);
  if (!r->ms) return cli_error(r->cmd, "out of memory");
  const double t0 = hush__now_ms();
  for (uint32_t i = first; i < last && !rc; i++) rc = run_frame(r, i, n);
  if (!rc) rc = write_cameras(r, first, n);
  if (!rc && r->o->ref)
    printf("%s: RMSE %.4f (input %.4f), PSNR %.2f dB (input %.2f dB) against '%s', mean of %u frames\n",
           r->cls->name, r->out_sum.rmse / n, r->in_sum.rmse / n, r->out_sum.psnr / n,
           r->in_sum.psnr / n, r->o->ref, n);
  if (rc || r->o->quiet) return rc;
  const double total_s = (hush__now_ms() - t0) * 1e-3;
  fprintf(stderr, "denoised %u frames of %ux%u with '%s' into %s: median %.2f ms/frame in the filter, %.1f s in all\n",
          n, r->seq.width, r->seq.height, r->cls->name, r->o->out, median(r->ms, n), total_s);
  return 0;
}

int cmd_denoise(int argc, char **argv) {
  denoise_options o;
  parse_options(argc, argv, &o);
  denoise_run r;
  memset(&r, 0, sizeof r);
  r.cmd = "denoise";
  r.o = &o;
  r.progress_tty = isatty(fileno(stderr));
  r.device = cli_device_new(r.cmd, o.threads);
  if (!r.device) return CLI_EXIT_RUNTIME;
  const int rc = run(&r);
  free(r.ms);
  hush_frame_release(r.out);
  hush_filter_release(r.filter);
  if (r.have_seq) hush__sequence_free(&r.seq);
  hush_device_release(r.device);
  return rc;
}
