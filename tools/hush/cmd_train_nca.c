/*
 * cmd_train_nca.c — `hush train-nca`: trains the weights of the "nca"
 * filter (Higginson 2023 §2.4.2) on frames rendered by `hush render`: pairs
 * of a 1 spp frame (color, normal, albedo) and a many-spp reference of the
 * same camera, cut into random square crops. Loss w1 MSE + w2 L_g on the
 * final colour (log space), a random iteration count per batch, Adam;
 * gradients from src/filters/nca/train.c. Writes the weights file and,
 * optionally, the C source of the built-in weights.
 */
#include "cli.h"
#include "core/device.h"
#include "core/image.h"
#include "core/rng.h"
#include "core/timer.h"
#include "filters/nca/train.h"
#include "filters/nca/weights.h"

#include <dirent.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

static const char *const help_text =
    "usage: hush train-nca --data DIR --out FILE [options]\n"
    "\n"
    "Trains the weights of the nca filter (docs/nca.md). DIR holds one folder\n"
    "per training view, each with noisy/frame_0000.exr (1 spp: color, normal,\n"
    "albedo) and ref/frame_0000.exr (the reference color), as written by\n"
    "`hush render` (tools/nca-data.sh makes such a DIR). Never train on the\n"
    "evaluation scenes.\n"
    "\n"
    "options:\n"
    "  --data DIR           training data (required; repeatable)\n"
    "  --out FILE           weights file to write (required)\n"
    "  --c-out FILE         also write the C source of built-in weights\n"
    "                       (src/filters/nca/default_weights.c)\n"
    "  --init FILE          start from these weights (default: W random\n"
    "                       N(0, 0.02^2), bias -0.5: the identity)\n"
    "  --iterations K       iteration count stored as the trained K (default 6)\n"
    "  --min-iterations N   fewest iterations of a batch (default K - 2)\n"
    "  --max-iterations N   most iterations of a batch (default K + 2)\n"
    "  --steps N            Adam steps (default 500)\n"
    "  --time-limit S       stop after S seconds of training (default: none)\n"
    "  --batch N            crops per step (default 4)\n"
    "  --crop N             crop size in pixels (default 128)\n"
    "  --lr X               Adam learning rate (default 0.003)\n"
    "  --w-mse X            weight of the MSE term (default 1)\n"
    "  --w-grad X           weight of the gradient term L_g (default 0.5)\n"
    "  --mse-space S        where the MSE term compares: log (the log1p state:\n"
    "                       default, the committed weights), relative (radiance\n"
    "                       over prediction^2 + 0.01, the weight held constant),\n"
    "                       relative-ref (over reference^2 + 0.01) or linear\n"
    "                       (radiance); docs/nca.md compares them\n"
    "  --keep-emission      train on the colour as it is; by default, as the\n"
    "                       filter's emission_bypass, a frame's 'emission' layer\n"
    "                       (lamps seen directly) is taken off its colour first\n"
    "  --holdout-every N    every N-th view (sorted by name) is validation, not\n"
    "                       training (default 4; 0: none)\n"
    "  --seed S             random seed (default 1)\n"
    "  --threads N          worker threads, 0 = one per core (default 0)\n"
    "  --log N              print the loss every N steps (default 25)\n"
    "  -h, --help           show this help\n";

/* One view: full-size planar state (9) and target (3), colour as log1p. */
typedef struct view_data {
  char name[256];
  uint32_t width, height;
  float *planes; /* 12 * width * height */
} view_data;

typedef struct options {
  const char *data[16];
  int ndata;
  const char *out, *c_out, *init;
  int iterations, kmin, kmax;
  uint32_t steps, batch, crop, holdout_every, seed, threads, log_every;
  double time_limit, lr, w_mse, w_grad;
  hush_nca_mse_space mse_space;
  int keep_emission;
} options;

static int compare_names(const void *a, const void *b) {
  return strcmp(*(const char *const *)a, *(const char *const *)b);
}

/* The first 3 channels of a layer as planes (p initialised by the caller). */
static int read_layer(const char *cmd, hush_device dev, hush_frame frame, const char *layer,
                      const char *path, hush_planar *p) {
  hush_image_view v;
  hush_status s = hush_frame_get_layer(frame, layer, &v);
  if (s) return cli_error(cmd, "%s: no layer '%s'", path, layer);
  size_t replaced = 0;
  s = hush__planar_init(dev, p, 3, v.width, v.height);
  if (!s) s = hush__view_import(dev, &v, layer, p, HUSH_NONFINITE_REPLACE, &replaced);
  return s ? cli_device_error(cmd, dev, s, path) : 0;
}

/* Imports the first 3 channels of a layer into planes; colour (log_color)
 * as log1p; minus_emission: less the frame's 'emission' layer (what the
 * filter's emission_bypass feeds it). */
static int import_layer(const char *cmd, hush_device dev, hush_frame frame, const char *layer,
                        const char *path, float *planes, int log_color, int minus_emission) {
  hush_planar p, e;
  memset(&p, 0, sizeof p);
  memset(&e, 0, sizeof e);
  int rc = read_layer(cmd, dev, frame, layer, path, &p);
  if (!rc && minus_emission) rc = read_layer(cmd, dev, frame, "emission", path, &e);
  if (!rc) {
    const size_t n = (size_t)p.width * p.height;
    for (int c = 0; c < 3; c++)
      for (size_t i = 0; i < n; i++) {
        const float x = p.plane[c][i] - (minus_emission ? e.plane[c][i] : 0.0f);
        planes[(size_t)c * n + i] = log_color ? log1pf(x > 0.0f ? x : 0.0f) : x;
      }
  }
  hush__planar_free(&p);
  hush__planar_free(&e);
  return rc;
}

/* The reference's colour loses its own (converged) emission, not the noisy
 * frame's: where a 1 spp sample missed a lamp's edge the target is still
 * the light off the surfaces, and the filter adds the frame's emission
 * back, whose mean is the reference's. */
static int load_view(const char *cmd, hush_device dev, const char *dir, int minus_emission,
                     view_data *v) {
  char noisy[4096], ref[4096];
  snprintf(noisy, sizeof noisy, "%s/noisy/frame_0000.exr", dir);
  snprintf(ref, sizeof ref, "%s/ref/frame_0000.exr", dir);
  hush_frame fn = NULL, fr = NULL;
  hush_status s = hush_frame_read_exr(dev, noisy, &fn);
  if (s) return cli_device_error(cmd, dev, s, noisy);
  s = hush_frame_read_exr(dev, ref, &fr);
  if (s) {
    hush_frame_release(fn);
    return cli_device_error(cmd, dev, s, ref);
  }
  int rc = 0;
  v->width = hush_frame_width(fn);
  v->height = hush_frame_height(fn);
  if (hush_frame_width(fr) != v->width || hush_frame_height(fr) != v->height)
    rc = cli_error(cmd, "%s: input and reference sizes differ", dir);
  hush_image_view ev;
  const int en = hush_frame_get_layer(fn, "emission", &ev) == HUSH_OK,
            er = hush_frame_get_layer(fr, "emission", &ev) == HUSH_OK;
  const int minus = minus_emission && en; /* en == er past the check */
  if (!rc && minus_emission && en != er)
    rc = cli_error(cmd, "%s: only the %s has an 'emission' layer (both or neither; or "
                   "--keep-emission)", dir, en ? "input" : "reference");
  const size_t n = (size_t)v->width * v->height;
  v->planes = rc ? NULL : malloc(12 * n * sizeof(float));
  if (!rc && !v->planes) rc = cli_error(cmd, "out of memory");
  if (!rc) rc = import_layer(cmd, dev, fn, "color", noisy, v->planes, 1, minus);
  if (!rc) rc = import_layer(cmd, dev, fn, "normal", noisy, v->planes + 3 * n, 0, 0);
  if (!rc) rc = import_layer(cmd, dev, fn, "albedo", noisy, v->planes + 6 * n, 0, 0);
  if (!rc) rc = import_layer(cmd, dev, fr, "color", ref, v->planes + 9 * n, 1, minus);
  hush_frame_release(fn);
  hush_frame_release(fr);
  return rc;
}

/* Lists DIR/<name> folders that have both frames, sorted, and loads them. */
static int load_views(const char *cmd, hush_device dev, const options *o, view_data **views,
                      int *count) {
  char *names[1024];
  int n = 0;
  for (int d = 0; d < o->ndata; d++) {
    DIR *dp = opendir(o->data[d]);
    if (!dp) return cli_error(cmd, "%s: cannot open the data folder", o->data[d]);
    struct dirent *e;
    while ((e = readdir(dp)) && n < 1024) {
      if (e->d_name[0] == '.') continue;
      char probe[4096];
      snprintf(probe, sizeof probe, "%s/%s/ref/frame_0000.exr", o->data[d], e->d_name);
      struct stat st;
      if (stat(probe, &st) != 0) continue;
      const size_t len = strlen(o->data[d]) + strlen(e->d_name) + 2;
      names[n] = malloc(len);
      if (!names[n]) break;
      snprintf(names[n], len, "%s/%s", o->data[d], e->d_name);
      n++;
    }
    closedir(dp);
  }
  if (n == 0) return cli_error(cmd, "no training views (DIR/*/noisy and DIR/*/ref) found");
  qsort(names, (size_t)n, sizeof names[0], compare_names);
  *views = calloc((size_t)n, sizeof **views);
  int rc = *views ? 0 : cli_error(cmd, "out of memory");
  for (int i = 0; i < n && !rc; i++) {
    snprintf((*views)[i].name, sizeof (*views)[i].name, "%s", cli_basename(names[i]));
    rc = load_view(cmd, dev, names[i], !o->keep_emission, &(*views)[i]);
    if (!rc && ((*views)[i].width < o->crop || (*views)[i].height < o->crop))
      rc = cli_error(cmd, "%s: %ux%u is smaller than the crop %u", names[i], (*views)[i].width,
                     (*views)[i].height, o->crop);
  }
  for (int i = 0; i < n; i++) free(names[i]);
  *count = n;
  return rc;
}

/* Copies the crop at (x0, y0) of a view into buf (12 * crop^2) and points
 * the sample at it. */
static void make_crop(const view_data *v, uint32_t x0, uint32_t y0, uint32_t crop, float *buf,
                      hush_nca_sample *s) {
  const size_t n = (size_t)v->width * v->height, m = (size_t)crop * crop;
  for (int c = 0; c < 12; c++)
    for (uint32_t y = 0; y < crop; y++)
      memcpy(buf + c * m + (size_t)y * crop,
             v->planes + c * n + (size_t)(y0 + y) * v->width + x0, crop * sizeof(float));
  s->width = s->height = crop;
  for (int c = 0; c < HUSH_NCA_CHANNELS; c++) s->state[c] = buf + c * m;
  for (int c = 0; c < 3; c++) s->target[c] = buf + (size_t)(9 + c) * m;
}

static int is_holdout(const options *o, int index) {
  return o->holdout_every > 0 && (uint32_t)index % o->holdout_every == o->holdout_every - 1;
}

/* Mean loss over the centre crop of every validation view, at K iterations
 * (K = 0: the noisy input itself). */
static double validation_loss(const options *o, const view_data *views, int count,
                              const double *params, int k, float *buf, int *used) {
  const hush_nca_loss_weights lw = {o->w_mse, o->w_grad, o->mse_space, HUSH_NCA_LOG1P, NULL};
  double sum = 0.0;
  int n = 0;
  for (int i = 0; i < count; i++) {
    if (!is_holdout(o, i)) continue;
    hush_nca_sample s;
    make_crop(&views[i], (views[i].width - o->crop) / 2, (views[i].height - o->crop) / 2, o->crop,
              buf, &s);
    sum += hush__nca_loss(params, k, &s, &lw, NULL);
    n++;
  }
  *used = n;
  return n ? sum / n : 0.0;
}

static int write_c_source(const char *cmd, const char *path, const hush_nca_weights *w) {
  FILE *f = fopen(path, "w");
  if (!f) return cli_error(cmd, "%s: cannot write", path);
  fprintf(f,
          "/*\n"
          " * default_weights.c — the built-in weights of the \"nca\" filter, generated by\n"
          " * `hush train-nca --c-out` from the run that wrote data/nca/weights-v1.bin\n"
          " * (docs/nca.md has the command); do not edit. Hexadecimal floats, so the\n"
          " * values are bit-identical to the file (tests/test_nca.c checks it).\n"
          " * Trained for K = %u iterations. Row k of W: perception value k (model.h).\n"
          " */\n"
          "#include \"filters/nca/model.h\"\n\n"
          "const hush_nca_weights hush__nca_default_weights = {\n    {\n",
          w->iterations);
  for (int k = 0; k < HUSH_NCA_PERCEPTION; k++) {
    fprintf(f, "        /* %2d */", k);
    for (int j = 0; j < HUSH_NCA_CHANNELS; j++)
      fprintf(f, "%s%a,", j > 0 && j % 3 == 0 ? "\n               " : " ",
              (double)w->w[k * HUSH_NCA_CHANNELS + j]);
    fprintf(f, "\n");
  }
  fprintf(f, "    },\n    {");
  for (int j = 0; j < HUSH_NCA_CHANNELS; j++)
    fprintf(f, "%s%a,", j == 0 ? "" : j % 3 == 0 ? "\n     " : " ", (double)w->bias[j]);
  fprintf(f, "},\n    %u,\n    %s,\n};\n", w->iterations,
          w->color_transform == HUSH_NCA_LOG1P ? "HUSH_NCA_LOG1P" : "HUSH_NCA_LINEAR");
  if (fclose(f) != 0) return cli_error(cmd, "%s: write error", path);
  return 0;
}

static void parse(int argc, char **argv, options *o) {
  const char *cmd = "train-nca";
  memset(o, 0, sizeof *o);
  o->iterations = 6;
  o->kmin = o->kmax = -1;
  o->steps = 500;
  o->batch = 4;
  o->crop = 128;
  o->holdout_every = 4;
  o->seed = 1;
  o->log_every = 25;
  o->lr = 0.003;
  o->w_mse = 1.0;
  o->w_grad = 0.5;
  o->mse_space = HUSH_NCA_MSE_STATE;
  cli_args args;
  cli_args_init(&args, cmd, argc, argv);
  const char *arg, *val;
  while (cli_next(&args, &arg)) {
    if (cli_is_help(arg)) {
      fputs(help_text, stdout);
      exit(0);
    } else if (cli_option(&args, arg, "--data", &val)) {
      if (o->ndata == 16) cli_usage_error(cmd, "--data: at most 16 folders");
      o->data[o->ndata++] = val;
    } else if (cli_option(&args, arg, "--out", &val)) {
      o->out = val;
    } else if (cli_option(&args, arg, "--c-out", &val)) {
      o->c_out = val;
    } else if (cli_option(&args, arg, "--init", &val)) {
      o->init = val;
    } else if (cli_option(&args, arg, "--iterations", &val)) {
      o->iterations = (int)cli_parse_uint(cmd, "--iterations", val, 1, HUSH_NCA_MAX_ITERATIONS);
    } else if (cli_option(&args, arg, "--min-iterations", &val)) {
      o->kmin = (int)cli_parse_uint(cmd, "--min-iterations", val, 1, HUSH_NCA_MAX_ITERATIONS);
    } else if (cli_option(&args, arg, "--max-iterations", &val)) {
      o->kmax = (int)cli_parse_uint(cmd, "--max-iterations", val, 1, HUSH_NCA_MAX_ITERATIONS);
    } else if (cli_option(&args, arg, "--steps", &val)) {
      o->steps = cli_parse_uint(cmd, "--steps", val, 0, 100000000);
    } else if (cli_option(&args, arg, "--time-limit", &val)) {
      o->time_limit = cli_parse_float(cmd, "--time-limit", val, 0.0f, 1e7f);
    } else if (cli_option(&args, arg, "--batch", &val)) {
      o->batch = cli_parse_uint(cmd, "--batch", val, 1, 256);
    } else if (cli_option(&args, arg, "--crop", &val)) {
      o->crop = cli_parse_uint(cmd, "--crop", val, 8, 4096);
    } else if (cli_option(&args, arg, "--lr", &val)) {
      o->lr = cli_parse_float(cmd, "--lr", val, 1e-7f, 1.0f);
    } else if (cli_option(&args, arg, "--w-mse", &val)) {
      o->w_mse = cli_parse_float(cmd, "--w-mse", val, 0.0f, 1e6f);
    } else if (cli_option(&args, arg, "--w-grad", &val)) {
      o->w_grad = cli_parse_float(cmd, "--w-grad", val, 0.0f, 1e6f);
    } else if (cli_option(&args, arg, "--mse-space", &val)) {
      if (!strcmp(val, "relative")) o->mse_space = HUSH_NCA_MSE_RELATIVE_PREDICTED;
      else if (!strcmp(val, "relative-ref")) o->mse_space = HUSH_NCA_MSE_RELATIVE;
      else if (!strcmp(val, "linear")) o->mse_space = HUSH_NCA_MSE_LINEAR;
      else if (!strcmp(val, "log")) o->mse_space = HUSH_NCA_MSE_STATE;
      else cli_usage_error(cmd, "--mse-space: unknown space '%s' (log, relative, relative-ref or linear)", val);
    } else if (!strcmp(arg, "--keep-emission")) {
      o->keep_emission = 1;
    } else if (cli_option(&args, arg, "--holdout-every", &val)) {
      o->holdout_every = cli_parse_uint(cmd, "--holdout-every", val, 0, 1000);
    } else if (cli_option(&args, arg, "--seed", &val)) {
      o->seed = cli_parse_uint(cmd, "--seed", val, 0, UINT32_MAX);
    } else if (cli_option(&args, arg, "--threads", &val)) {
      o->threads = cli_parse_uint(cmd, "--threads", val, 0, 1024);
    } else if (cli_option(&args, arg, "--log", &val)) {
      o->log_every = cli_parse_uint(cmd, "--log", val, 1, 100000000);
    } else {
      cli_unknown_option(&args, arg);
    }
  }
  if (o->ndata == 0) cli_usage_error(cmd, "--data is required");
  if (!o->out) cli_usage_error(cmd, "--out is required");
  if (o->kmin < 0) o->kmin = o->iterations > 2 ? o->iterations - 2 : 1;
  if (o->kmax < 0)
    o->kmax = o->iterations + 2 < HUSH_NCA_MAX_ITERATIONS ? o->iterations + 2
                                                          : HUSH_NCA_MAX_ITERATIONS;
  if (o->kmin > o->kmax) cli_usage_error(cmd, "--min-iterations is above --max-iterations");
  if (o->w_mse == 0.0 && o->w_grad == 0.0) cli_usage_error(cmd, "both loss weights are 0");
}

/* A standard normal number from two uniforms (Box-Muller). */
static double normal01(uint32_t seed, uint32_t counter) {
  const double u1 = (hush_rng_u32(seed, 101, counter) + 1.0) / 4294967297.0;
  const double u2 = hush_rng_u32(seed, 102, counter) / 4294967296.0;
  return sqrt(-2.0 * log(u1)) * cos(6.283185307179586 * u2);
}

int cmd_train_nca(int argc, char **argv) {
  const char *cmd = "train-nca";
  options o;
  parse(argc, argv, &o);
  hush_device dev = cli_device_new(cmd, o.threads);
  if (!dev) return CLI_EXIT_RUNTIME;
  const int threads = dev->threads > 0 ? dev->threads : 1;
  view_data *views = NULL;
  int count = 0, rc = load_views(cmd, dev, &o, &views, &count);
  int ntrain = 0;
  for (int i = 0; i < count; i++) ntrain += !is_holdout(&o, i);
  if (!rc && ntrain == 0) rc = cli_error(cmd, "every view is held out: lower --holdout-every");

  double params[HUSH_NCA_PARAM_COUNT];
  hush_nca_weights w;
  memset(&w, 0, sizeof w);
  if (!rc && o.init) {
    const hush_status s = hush__nca_weights_load(dev, o.init, &w);
    if (s) rc = cli_device_error(cmd, dev, s, o.init);
    hush__nca_params_from_weights(&w, params);
  } else {
    for (int i = 0; i < HUSH_NCA_WEIGHT_COUNT; i++) params[i] = 0.02 * normal01(o.seed, (uint32_t)i);
    for (int j = 0; j < HUSH_NCA_CHANNELS; j++) params[HUSH_NCA_P_BIAS + j] = -0.5;
  }
  const size_t crop_floats = (size_t)12 * o.crop * o.crop;
  float *bufs = rc ? NULL : malloc(crop_floats * o.batch * sizeof(float));
  double *grads = rc ? NULL : malloc((size_t)HUSH_NCA_PARAM_COUNT * o.batch * sizeof(double));
  double *losses = rc ? NULL : malloc(o.batch * sizeof(double));
  if (!rc && (!bufs || !grads || !losses)) rc = cli_error(cmd, "out of memory");

  if (!rc) {
    int nval = 0;
    const double v_noisy = validation_loss(&o, views, count, params, 0, bufs, &nval);
    fprintf(stderr,
            "hush %s: %d views (%d for training, %d held out), %u steps of %u crops of %ux%u, "
            "K %d..%d, %d thread(s)\n",
            cmd, count, ntrain, nval, o.steps, o.batch, o.crop, o.crop, o.kmin, o.kmax, threads);
    if (nval) fprintf(stderr, "  validation loss of the noisy input: %.6f\n", v_noisy);
  }
  hush_nca_adam adam;
  hush__nca_adam_init(&adam, o.lr);
  const hush_nca_loss_weights lw = {o.w_mse, o.w_grad, o.mse_space, HUSH_NCA_LOG1P, NULL};
  const double t0 = hush__now_ms();
  double running = 0.0;
  int running_n = 0;
  uint32_t step = 0;
  for (; !rc && step < o.steps; step++) {
    const uint32_t span = (uint32_t)(o.kmax - o.kmin + 1);
    const int k = o.kmin + (int)(hush_rng_u32(o.seed, 1, step) % span);
    int failed = 0;
#pragma omp parallel for num_threads(threads) schedule(dynamic) reduction(| : failed)
    for (int b = 0; b < (int)o.batch; b++) {
      const uint32_t ctr = step * o.batch + (uint32_t)b;
      /* a random training view and crop position */
      int pick = (int)(hush_rng_u32(o.seed, 2, ctr) % (uint32_t)ntrain), vi = -1;
      for (int i = 0; i < count && vi < 0; i++)
        if (!is_holdout(&o, i) && pick-- == 0) vi = i;
      const view_data *v = &views[vi];
      const uint32_t x0 = hush_rng_u32(o.seed, 3, ctr) % (v->width - o.crop + 1);
      const uint32_t y0 = hush_rng_u32(o.seed, 4, ctr) % (v->height - o.crop + 1);
      hush_nca_sample s;
      make_crop(v, x0, y0, o.crop, bufs + crop_floats * (size_t)b, &s);
      double *g = grads + (size_t)HUSH_NCA_PARAM_COUNT * b;
      memset(g, 0, HUSH_NCA_PARAM_COUNT * sizeof(double));
      losses[b] = hush__nca_loss(params, k, &s, &lw, g);
      failed |= losses[b] < 0.0;
    }
    if (failed) {
      rc = cli_error(cmd, "out of memory in the training pass");
      break;
    }
    double g[HUSH_NCA_PARAM_COUNT] = {0};
    for (uint32_t b = 0; b < o.batch; b++) {
      for (int i = 0; i < HUSH_NCA_PARAM_COUNT; i++)
        g[i] += grads[(size_t)HUSH_NCA_PARAM_COUNT * b + i] / o.batch;
      running += losses[b];
      running_n++;
    }
    hush__nca_adam_step(&adam, params, g);
    const double elapsed = (hush__now_ms() - t0) / 1000.0;
    if ((step + 1) % o.log_every == 0) {
      fprintf(stderr, "  step %6u  loss %.6f  %.0f s\n", step + 1, running / running_n, elapsed);
      running = 0.0;
      running_n = 0;
    }
    if (o.time_limit > 0.0 && elapsed >= o.time_limit) {
      step++;
      fprintf(stderr, "  time limit reached after %u steps\n", step);
      break;
    }
  }
  if (!rc) {
    o.steps = step;
    int nval = 0;
    const double v = validation_loss(&o, views, count, params, o.iterations, bufs, &nval);
    if (nval) fprintf(stderr, "  validation loss after training, K = %d: %.6f\n", o.iterations, v);
    hush__nca_weights_from_params(params, &w);
    w.iterations = (uint32_t)o.iterations;
    w.color_transform = HUSH_NCA_LOG1P;
    const hush_status s = hush__nca_weights_save(dev, o.out, &w);
    if (s) rc = cli_device_error(cmd, dev, s, o.out);
  }
  if (!rc && o.c_out) rc = write_c_source(cmd, o.c_out, &w);
  for (int i = 0; i < count; i++) free(views[i].planes);
  free(views);
  free(bufs);
  free(grads);
  free(losses);
  hush_device_release(dev);
  return rc;
}
