/*
 * svgf.c — the "svgf" filter: spatiotemporal variance-guided filtering.
 *
 *   import -> demodulate by albedo -> temporal accumulation of colour and
 *   luminance moments (src/temporal, shared with "accumulate") -> variance
 *   from the moments, or a 7x7 bilateral spatial estimate while the history
 *   is short -> edge-avoiding a-trous (5x5 B3 or 3x3 kernel, steps 2^i in
 *   increasing, decreasing or 0-then-decreasing order), guided by
 *   depth (with its screen-space gradient), normal and luminance (scaled by
 *   the 3x3-blurred variance), the variance filtered along with squared
 *   weights -> the first level fed back as the colour history -> remodulate
 *   -> optionally TAA (src/temporal/taa.h, parameter "taa"; off by default,
 *   the "taa" filter can also follow svgf).
 *
 * Follows Dundr 2018 §4.1.4-4.1.5 (a-trous, weights, variance propagation)
 * and §4.4 (spatial variance while history < 4 samples), with the published
 * defaults of Schied et al. 2017 given in papers/NOTES.md ("SVGF"); §4.3
 * (more than 1 spp: 'spp' and 'variance' merged into the moments) and §4.2
 * (fewer than 1 spp: holes with spp 0) when those images are bound; direct
 * and indirect light filtered separately when both are bound (Schied 2017).
 *
 * Files: guide.c (padded depth/normal, depth gradient), variance.c (7x7
 * spatial estimate), atrous.c (one fused pass per level: Gaussian of the
 * variance, weights, colour and variance), weights.h (one exp per tap),
 * padded.c (row padding so every inner loop is branch-free), samples.c
 * (§4.3), progressive.c (§4.2); svgf.h (the parameter and image tables and
 * svgf_run, shared with the "asvgf" class of asvgf.c, whose adaptive
 * temporal stage, adaptive.c, svgf_run calls when given one). Every pixel
 * is computed on its own (the progressive scatter breaks depth ties by
 * source index): the result does not depend on the thread count.
 */
#include "filters/albedo.h"
#include "filters/emission.h"
#include "filters/filter.h"
#include "filters/gbuffer.h"
#include "filters/holes.h"
#include "filters/svgf/adaptive.h"
#include "filters/svgf/atrous.h"
#include "filters/svgf/guide.h"
#include "filters/svgf/padded.h"
#include "filters/svgf/progressive.h"
#include "filters/svgf/samples.h"
#include "filters/svgf/svgf.h"
#include "filters/svgf/variance.h"
#include "temporal/accumulation.h"
#include "temporal/reproject.h"
#include "temporal/taa.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

const char *const svgf_kernel_names[] = {"5x5", "3x3"};
enum { ORDER_INCREASING = 0, ORDER_DECREASING, ORDER_ZERO_THEN_DECREASING };
const char *const svgf_order_names[] = {"increasing", "decreasing", "0-then-decreasing"};
const char *const svgf_normal_weight_names[] = {"exp", "pow"};
const char *const svgf_weight_exp_names[] = {"accurate", "fast"};

static const hush_param_info svgf_params[P_COUNT] = {SVGF_PARAM_ROWS};

static const hush_image_info svgf_images[I_COUNT] = {SVGF_IMAGE_ROWS};

static const hush_filter_class_info svgf_info = {
    "svgf",
    "spatiotemporal variance-guided filtering: accumulation, variance, edge-avoiding a-trous",
    "Dundr 2018 §4.1.4-4.1.5, §4.4; Schied et al. 2017 (papers/NOTES.md)",
    svgf_params,
    P_COUNT,
    svgf_images,
    I_COUNT,
};

/* One filtered signal: 'color', or each of 'direct' and 'indirect'. */
typedef struct svgf_component {
  hush_accum acc;     /* its history */
  hush_planar color;  /* this frame, demodulated in place */
  hush_planar result; /* 3: its last a-trous level */
} svgf_component;

typedef struct svgf_state {
  hush_reprojector rp;
  svgf_component comp[2]; /* [1] allocated when 'direct' and 'indirect' are first bound */
  hush_planar grad;    /* 2: depth gradient (imported or computed) */
  hush_planar zon;     /* 1: 1 where the depth weight applies (guide.h) */
  hush_planar var;     /* 1: variance from the moments or the spatial estimate */
  hush_planar samples; /* 1: samples behind the moments, age * spp */
  svgf_padded zn;        /* depth + normal, padded for the widest tap */
  svgf_padded signal[2]; /* SVGF_SIGNAL_CHANNELS: a-trous ping-pong */
  int threads;
  int split; /* the components' histories are of direct and indirect */
  svgf_progressive prog; /* allocated on the first frame with holes */
  hush_planar eps;       /* 1: progressive luminance epsilon */
  /* allocated on first use: */
  hush_planar albedo;
  hush_planar emission; /* imported emission, then the output (emission.h) */
  hush_emission_history eh; /* the emission added back, accumulated */
  hush_planar spp, sample_var; /* 1 each: the 'spp' and 'variance' inputs */
  hush_gbuffer_inputs gin; /* position and motion between import and build */
  hush_taa taa; /* its planes allocated when "taa" is first on */
  float *line;  /* 3 planes of SVGF_WAVEFRONT_RING rows: the last level's rows on their way out */
} svgf_state;

static void component_free(svgf_component *c) {
  hush__accum_free(&c->acc);
  hush__planar_free(&c->color);
  hush__planar_free(&c->result);
}

static hush_status component_init(hush_device device, svgf_component *c, uint32_t W, uint32_t H) {
  hush_status s = hush__accum_init(device, &c->acc, 3, W, H);
  if (!s) s = hush__planar_init(device, &c->color, 3, W, H);
  if (!s) s = hush__planar_init(device, &c->result, 3, W, H);
  if (s) component_free(c);
  return s;
}

void svgf_destroy(void *state) {
  svgf_state *st = state;
  if (!st) return;
  hush__reprojector_free(&st->rp);
  component_free(&st->comp[0]);
  component_free(&st->comp[1]);
  hush__planar_free(&st->grad);
  hush__planar_free(&st->zon);
  hush__planar_free(&st->var);
  hush__planar_free(&st->samples);
  svgf_padded_free(&st->zn);
  svgf_padded_free(&st->signal[0]);
  svgf_padded_free(&st->signal[1]);
  hush__planar_free(&st->albedo);
  hush__planar_free(&st->emission);
  hush__emission_history_free(&st->eh);
  hush__planar_free(&st->spp);
  hush__planar_free(&st->sample_var);
  hush__gbuffer_inputs_free(&st->gin);
  hush__free_floats(st->line);
  hush__taa_free(&st->taa);
  svgf_progressive_free(&st->prog);
  hush__planar_free(&st->eps);
  free(st);
}

hush_status svgf_create(hush_filter f, void **state) {
  svgf_state *st = calloc(1, sizeof *st);
  if (!st) return hush__fail(f->device, HUSH_ERROR_OUT_OF_MEMORY, "svgf: out of memory");
  const uint32_t W = f->width, H = f->height;
  st->threads = hush__filter_threads(f);
  hush_status s = hush__reprojector_init(f->device, &st->rp, W, H);
  if (!s) s = component_init(f->device, &st->comp[0], W, H);
  if (!s) s = hush__planar_init(f->device, &st->grad, 2, W, H);
  if (!s) s = hush__planar_init(f->device, &st->zon, 1, W, H);
  if (!s) s = hush__planar_init(f->device, &st->var, 1, W, H);
  if (!s) s = hush__planar_init(f->device, &st->samples, 1, W, H);
  /* here, not at the first frame that uses it: an execute refused by the
   * memory cap after its history moved on would leave it half a frame */
  if (!s && !(st->line = hush__alloc_floats((size_t)3 * SVGF_WAVEFRONT_RING * W)))
    s = hush__fail(f->device, HUSH_ERROR_OUT_OF_MEMORY, "svgf: out of memory");
  if (s) {
    svgf_destroy(st);
    return s;
  }
  *state = st;
  return HUSH_OK;
}

/* The pad the a-trous taps and the spatial estimate need. */
static int needed_pad(const svgf_kernel *k, int levels) {
  const int widest = levels > 0 ? k->radius << (levels - 1) : 0;
  return widest > SVGF_SPATIAL_VARIANCE_RADIUS ? widest : SVGF_SPATIAL_VARIANCE_RADIUS;
}

/* Tap step of the i-th level run out of `levels` in the given order. */
static int level_step(int order, int i, int levels) {
  switch (order) {
  case ORDER_DECREASING: return 1 << (levels - 1 - i);
  case ORDER_ZERO_THEN_DECREASING: return i == 0 ? 1 : 1 << (levels - i);
  default: return 1 << i;
  }
}

/* The a-trous input of the first level: colour, variance and luminance,
 * and with `valid` (frames with holes, the only ones whose levels read it)
 * the validity. */
/* The a-trous's first input: the accumulated colour and its variance,
 * the luminance, and with holes the validity (age > 0). */
typedef struct first_signal {
  const hush_planar *color;
  const float *var, *age;
  int valid;
  svgf_padded *sig;
  int pad; /* pixels of pad written on each side: what the first level reads */
} first_signal;

/* Pixels [xa, xb) of row y of the first signal, and the pads of the sides
 * the part holds. */
static void first_signal_span(const first_signal *fs, int y, int xa, int xb) {
  const svgf_padded *sig = fs->sig;
  const int W = sig->width, n = xb - xa;
  const size_t o = (size_t)y * W + (size_t)xa;
  const float *restrict r = fs->color->plane[0] + o, *restrict g = fs->color->plane[1] + o,
                        *restrict b = fs->color->plane[2] + o, *restrict v = fs->var + o;
  float *restrict sr = svgf_padded_row(sig, SVGF_R, y) + xa,
                  *restrict sg = svgf_padded_row(sig, SVGF_G, y) + xa,
                  *restrict sb = svgf_padded_row(sig, SVGF_B, y) + xa,
                  *restrict sv = svgf_padded_row(sig, SVGF_VAR, y) + xa,
                  *restrict sl = svgf_padded_row(sig, SVGF_LUM, y) + xa;
  if (fs->valid) {
    float *restrict ok = svgf_padded_row(sig, SVGF_VALID, y) + xa;
    const float *restrict a = fs->age + o;
#pragma omp simd
    for (int x = 0; x < n; x++) ok[x] = hush__select_bits(a[x] > 0.0f, 1.0f, 0.0f);
  }
#pragma omp simd
  for (int x = 0; x < n; x++) {
    sr[x] = r[x];
    sg[x] = g[x];
    sb[x] = b[x];
    sv[x] = v[x];
    sl[x] = hush_luminance(r[x], g[x], b[x]);
  }
  for (int c = 0; c < SVGF_SIGNAL_CHANNELS; c++)
    if (fs->valid || c != SVGF_VALID)
      svgf_pad_row_sides(svgf_padded_row(sig, c, y), W, fs->pad, xa == 0, xb == W);
}

/* The whole first signal, one pass. (Made row by row inside the a-trous's
 * wavefront instead, it cost the a-trous what it saved here:
 * docs/svgf-speed.md, twenty-seventh round.) */
static void first_signal_pass(const first_signal *fs, int threads) {
  const int W = fs->sig->width, H = fs->sig->height;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < H; y++) first_signal_span(fs, y, 0, W);
}

/* dst <- the colour of a level's output where age >= 1 (Dundr §4.2.2:
 * fed back only once a full sample was accumulated; a hole's state averaged
 * from its neighbours can hold a fraction) or age 0 (no data: the spatial
 * estimate is a placeholder, so that backward reprojection taps there do
 * not mix in black; its age stays 0). */
static void copy_color_where(const svgf_level_out *src, hush_planar *dst, const float *age,
                             int threads) {
  const int W = (int)dst->width, H = (int)dst->height;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < H; y++)
    for (int c = 0; c < 3; c++) {
      float *restrict d = dst->plane[c] + (size_t)y * W;
      const float *restrict sp = src->plane[c] + (size_t)y * src->stride;
      const float *restrict a = age + (size_t)y * W;
#pragma omp simd
      for (int x = 0; x < W; x++)
        d[x] = hush__select_bits((a[x] >= 1.0f) | (a[x] == 0.0f), sp[x], d[x]);
    }
}

/* dst (3 unpadded planes) <- the colour of a level's output. */
static void copy_color(const svgf_level_out *src, hush_planar *dst, int threads) {
  const int W = (int)dst->width, H = (int)dst->height;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < H; y++)
    for (int c = 0; c < 3; c++)
      memcpy(dst->plane[c] + (size_t)y * W, src->plane[c] + (size_t)y * src->stride,
             (size_t)W * sizeof(float));
}

/* Per frame: what every component's pass shares. */
typedef struct frame_ctx {
  hush_filter f;
  svgf_state *st;
  const svgf_guide *gd;
  hush_accum_params ap;
  int demod, merge, iterations, order, threads;
  int demod_fused; /* the colour was demodulated as it was imported */
  int demod_emission; /* the first component's, as its emission came off */
  int holes; /* progressive: this frame has untraced pixels */
  const svgf_kernel *kernel;
  svgf_adaptive *ad; /* asvgf: the adaptive temporal stage, else NULL */
  /* non-NULL: the last level's rows go straight to this view (times the
   * albedo's planes unless NULL) as they are written, through st->line,
   * instead of into the component's result */
  const hush_image_view *out_view;
  const hush_planar *out_albedo;
  int out_emission; /* with out_view: the emission accumulated and added as the rows go out */
} frame_ctx;

/* Where the last level's finished rows go (svgf_level_out.span_done). */
typedef struct row_export {
  const svgf_level_out *level; /* where the rows are: a ring of SVGF_WAVEFRONT_RING rows */
  const hush_planar *albedo;
  const hush_planar *add;    /* the accumulated emission, added after the remodulation */
  const float *add_rows;     /* its rows' flags (hush__emission_rows_of), or NULL */
  const hush_image_view *view;
} row_export;

static void export_span(void *ctx, int y, int xa, int xb) {
  const row_export *e = ctx;
  const size_t at = (size_t)y * e->view->width + (size_t)xa;
  const size_t r = svgf_level_out_row(e->level, y) + (size_t)xa;
  const float *const in[3] = {e->level->plane[SVGF_R] + r, e->level->plane[SVGF_G] + r,
                              e->level->plane[SVGF_B] + r};
  const float *alb[3], *add[3];
  hush__export_remodulated_span(in, hush__planar_at3(e->albedo, at, alb),
                                hush__planar_at3(e->add, at, add),
                                e->add_rows && e->add_rows[y] == 0.0f, e->view, (uint32_t)y,
                                (uint32_t)xa, (uint32_t)(xb - xa));
}

/* The emission's history blended with this frame's (svgf_state.eh), with
 * the first component's ages after its blend; the planes to add back. */
static const hush_planar *emission_history(svgf_state *st, float alpha_min, int holes,
                                           int threads) {
  return hush__emission_accumulate_holes(&st->eh, &st->rp.plan,
                                         hush__accum_age(&st->comp[0].acc)->plane[0], alpha_min,
                                         &st->emission, holes ? st->spp.plane[0] : NULL, threads);
}

/* Accumulation, variance and a-trous of one component: c->result. */
static void filter_component(const frame_ctx *fc, svgf_component *c, int export_variance) {
  hush_filter f = fc->f;
  svgf_state *st = fc->st;
  const int threads = fc->threads, W = (int)f->width;
  const int demodulated = fc->demod_fused || (fc->demod_emission && c == &st->comp[0]);
  if (fc->demod && !demodulated) hush__demodulate(&c->color, &st->albedo, threads);
  /* the history before the blend writes the other buffer set */
  const float *prev[6] = {NULL};
  const int had_history = c->acc.has_history;
  if (fc->holes && had_history) {
    for (int k = 0; k < 3; k++) prev[k] = hush__accum_color(&c->acc)->plane[k];
    for (int k = 0; k < 2; k++) prev[3 + k] = hush__accum_moments(&c->acc)->plane[k];
    prev[5] = hush__accum_age(&c->acc)->plane[0];
  }
  hush__accum_blend(&c->acc, &st->rp.plan, (const float *const *)c->color.plane, &fc->ap,
                    st->var.plane[0], threads);
  if (fc->ad)
    svgf_adaptive_history(fc->ad, &c->acc, had_history, (const float *const *)c->color.plane,
                          &fc->ap, st->var.plane[0], threads);
  if (fc->holes) {
    float *const cur[6] = {
        hush__accum_color(&c->acc)->plane[0],   hush__accum_color(&c->acc)->plane[1],
        hush__accum_color(&c->acc)->plane[2],   hush__accum_moments(&c->acc)->plane[0],
        hush__accum_moments(&c->acc)->plane[1], hush__accum_age(&c->acc)->plane[0]};
    svgf_forward_state(&st->prog, st->spp.plane[0], had_history ? prev : NULL, cur,
                       fc->ap.alpha_min, fc->ap.alpha_moments_min, threads);
    /* the variance of the state as it now is */
    const long long n = (long long)hush__planar_pixels(&st->var);
    float *restrict v = st->var.plane[0];
#pragma omp parallel for simd schedule(static) num_threads(threads)
    for (long long i = 0; i < n; i++) {
      const float d = cur[4][i] - cur[3][i] * cur[3][i];
      v[i] = d > 0.0f ? d : 0.0f;
    }
  }
  /* the emission's history, when its rows go out with the last level's:
   * its blend needs the ages just made, nothing the a-trous writes */
  const hush_planar *emission = NULL;
  if (fc->out_emission) emission = emission_history(st, fc->ap.alpha_min, fc->holes, threads);
  hush__filter_timing_stage(f, "accumulate");

  /* the history behind each pixel's moments, in samples (frames at 1 spp) */
  const float *samples = hush__accum_age(&c->acc)->plane[0];
  if (fc->merge) {
    svgf_samples sm;
    sm.spp = st->spp.plane[0];
    sm.variance = st->sample_var.plane[0];
    sm.color = &c->color;
    sm.albedo = fc->demod ? &st->albedo : NULL;
    sm.alpha_moments_min = fc->ap.alpha_moments_min;
    svgf_merge_samples(&sm, hush__accum_moments(&c->acc), samples, st->var.plane[0],
                       st->samples.plane[0], threads);
    samples = st->samples.plane[0];
  }
  const int min_age = hush__param_i(f, P_SPATIAL_VARIANCE_FRAMES);
  if (min_age > 1) {
    const hush_planar *m = hush__accum_moments(&c->acc);
    svgf_spatial_variance(fc->gd, (const float *const *)m->plane, samples, (float)min_age,
                          st->var.plane[0], hush__param_i(f, P_NORMAL_WEIGHT) == 0,
                          hush__param_i(f, P_WEIGHT_EXP) == 1,
                          /* samples 0: a hole, or a pixel without samples */
                          fc->holes || fc->merge, threads);
  }
  /* with the merge the moments are per sample; else they see only the
   * frame-to-frame spread of the pixel means, already per frame value */
  if (fc->merge)
    svgf_variance_per_frame(st->spp.plane[0], st->var.plane[0], hush__planar_pixels(&st->var),
                            threads);
  const hush_image_view *var_view = hush__filter_view(f, I_VARIANCE_ESTIMATE);
  if (var_view && export_variance) hush__view_export(&st->var, var_view, threads);
  const float *age = hush__accum_age(&c->acc)->plane[0];
  /* the a-trous's first input */
  /* each signal's pads only as wide as the next level's taps reach (the
   * planes keep room for the widest): fewer lines written */
  const int radius = fc->kernel->radius;
  first_signal fs = {hush__accum_color(&c->acc), st->var.plane[0], age, fc->holes,
                     &st->signal[0],
                     fc->iterations > 0 ? radius * level_step(fc->order, 0, fc->iterations) : 0};
  first_signal_pass(&fs, threads);
  hush__filter_timing_stage(f, "variance");

  svgf_level_params lp;
  lp.kernel = fc->kernel;
  lp.sigma_l = hush__param_f(f, P_SIGMA_L);
  lp.eps_l = NULL;
  lp.validity = fc->holes;
  lp.normal_exp = hush__param_i(f, P_NORMAL_WEIGHT) == 0;
  lp.fast_exp = hush__param_i(f, P_WEIGHT_EXP) == 1;
  lp.portable = 0;
  lp.vectors = 0;
  if (fc->holes) {
    svgf_progressive_epsilon(samples, hush__param_f(f, P_PROGRESSIVE_EPSILON), st->eps.plane[0],
                             hush__planar_pixels(&st->eps), threads);
    lp.eps_l = st->eps.plane[0];
  }
  int cur = 0;
  svgf_level_out last;
  last.plane[SVGF_R] = c->result.plane[0];
  last.plane[SVGF_G] = c->result.plane[1];
  last.plane[SVGF_B] = c->result.plane[2];
  last.plane[SVGF_VAR] = last.plane[SVGF_LUM] = last.plane[SVGF_VALID] = NULL;
  last.stride = (size_t)W;
  last.pad = 0;
  last.ring = 0;
  last.also[0] = last.also[1] = last.also[2] = NULL;
  last.span_done = NULL;
  last.span_ctx = NULL;
  row_export rx;
  if (fc->out_view) {
    const size_t ring = (size_t)SVGF_WAVEFRONT_RING * (size_t)W;
    rx.level = &last;
    rx.albedo = fc->out_albedo;
    rx.add = emission;
    rx.add_rows = emission ? hush__emission_rows_of(&st->eh) : NULL;
    rx.view = fc->out_view;
    last.plane[SVGF_R] = st->line;
    last.plane[SVGF_G] = st->line + ring;
    last.plane[SVGF_B] = st->line + 2 * ring;
    last.ring = SVGF_WAVEFRONT_RING;
    last.span_done = export_span;
    last.span_ctx = &rx;
  }
  /* the first level's colour written straight into the colour history as
   * well (with holes only where the age allows: copy_color_where) */
  const int feedback = hush__param_i(f, P_FEEDBACK_FIRST_LEVEL);
  const int feedback_direct = feedback && !fc->holes;
  if (fc->iterations == 0) {
    const svgf_level_out accumulated = svgf_level_out_padded(&st->signal[0]);
    copy_color(&accumulated, &c->result, threads);
  }
  /* the history keeps some spatial filtering (Schied 2017 §4.4; Dundr
   * §4.1.4.6: the first level run): less noise is fed back, at the cost
   * of a little extra blur over time. With holes the first level's copy
   * into it is a pass of its own after that level (copy_color_where), so
   * the level runs alone; the others run as one wavefront. */
  const int alone = feedback && fc->holes && fc->iterations > 0 ? 1 : 0;
  svgf_level_params lps[SVGF_MAX_ITERATIONS];
  svgf_level_out outs[SVGF_MAX_ITERATIONS];
  const svgf_padded *ins[SVGF_MAX_ITERATIONS];
  const svgf_level_out *outp[SVGF_MAX_ITERATIONS];
  for (int i = 0; i < fc->iterations; i++) {
    outs[i] = i == fc->iterations - 1 ? last : svgf_level_out_padded(&st->signal[1 - cur]);
    if (i < fc->iterations - 1)
      outs[i].pad = radius * level_step(fc->order, i + 1, fc->iterations);
    if (i == 0 && feedback_direct)
      for (int k = 0; k < 3; k++) outs[i].also[k] = hush__accum_color(&c->acc)->plane[k];
    lps[i] = lp;
    lps[i].step = level_step(fc->order, i, fc->iterations);
    ins[i] = &st->signal[cur];
    outp[i] = &outs[i];
    cur = 1 - cur;
  }
  if (alone) {
    svgf_atrous_level(fc->gd, &lps[0], ins[0], outp[0], threads);
    copy_color_where(outp[0], hush__accum_color(&c->acc), age, threads);
  }
  svgf_atrous_levels(fc->gd, lps + alone, ins + alone, outp + alone, fc->iterations - alone,
                     threads);
  hush__filter_timing_stage(f, "atrous");
}

/* a += b, 3 planes. */
static void add_planes(hush_planar *a, const hush_planar *b, int threads) {
  const long long n = (long long)hush__planar_pixels(a);
  for (int c = 0; c < 3; c++) {
    float *restrict x = a->plane[c];
    const float *restrict y = b->plane[c];
#pragma omp parallel for simd schedule(static) num_threads(threads)
    for (long long i = 0; i < n; i++) x[i] += y[i];
  }
}

hush_status svgf_run(hush_filter f, void *state, const hush_frame_info *info, svgf_adaptive *ad) {
  svgf_state *st = state;
  const int threads = st->threads;
  const int W = (int)f->width, H = (int)f->height;
  hush_status s;
  hush__filter_timing_begin(f);

  const int has_dgrad = hush__filter_view(f, I_DEPTH_GRADIENT) != NULL;
  const int demod = hush__param_i(f, P_DEMODULATE) && hush__filter_view(f, I_ALBEDO);
  const int with_taa = hush__param_i(f, P_TAA);
  const int emis = hush__filter_view(f, I_EMISSION) != NULL && hush__param_i(f, P_EMISSION_BYPASS);
  const int iterations = hush__param_i(f, P_ITERATIONS);
  const svgf_kernel *kernel = hush__param_i(f, P_KERNEL) ? &svgf_kernel_3x3 : &svgf_kernel_5x5;
  const int split = hush__filter_view(f, I_DIRECT) && hush__filter_view(f, I_INDIRECT);
  if (!with_taa) st->taa.has_history = 0; /* switched back on later: start over */

  /* ---- import: nothing of the history changes until every input is read */
  const int pad = needed_pad(kernel, iterations);
  if ((s = svgf_padded_ensure(f->device, &st->zn, 4, W, H, pad))) return s;
  for (int i = 0; i < 2; i++)
    if ((s = svgf_padded_ensure(f->device, &st->signal[i], SVGF_SIGNAL_CHANNELS, W, H, pad)))
      return s;
  const int has_spp = hush__filter_view(f, I_SPP) != NULL;
  const int has_svar = hush__filter_view(f, I_SAMPLE_VARIANCE) != NULL;
  if (has_svar && !has_spp)
    return hush__fail(f->device, HUSH_ERROR_INVALID_OPERATION,
                      "svgf: image 'variance' (per-sample variance) needs 'spp' bound too");
  if (split && !st->comp[1].color.plane[0] &&
      (s = component_init(f->device, &st->comp[1], f->width, f->height)))
    return s;
  if (demod && (s = hush__filter_scratch(f, &st->albedo, 3))) return s;
  if (!emis) st->eh.valid = 0; /* bound again later: start over */
  if (emis && ((s = hush__filter_scratch(f, &st->emission, 3)) ||
               (s = hush__filter_scratch(f, &st->eh.hist[0], 3)) ||
               (s = hush__filter_scratch(f, &st->eh.hist[1], 3)) ||
               (s = hush__emission_history_rows(f->device, &st->eh, f->height))))
    return s;
  if (has_spp && (s = hush__filter_scratch(f, &st->spp, 1))) return s;
  if (has_svar && (s = hush__filter_scratch(f, &st->sample_var, 1))) return s;
  if (with_taa && !st->taa.current.plane[0] &&
      (s = hush__taa_init(f->device, &st->taa, f->width, f->height)))
    return s;
  static const hush_gbuffer_images gimages = {I_DEPTH, I_NORMAL, I_POSITION, I_ID, I_MOTION};
  /* the colour demodulated as it is imported (one pass less), unless the
   * emission comes off first, holes may change the albedo, or asvgf's
   * gradient samples need the radiance itself */
  const int demod_fused = demod && !emis && !has_spp && !ad;
  const int color_image = split ? I_DIRECT : I_COLOR;
  if (!demod_fused && (s = hush__filter_import(f, color_image, &st->comp[0].color))) return s;
  if (!demod_fused && split && (s = hush__filter_import(f, I_INDIRECT, &st->comp[1].color)))
    return s;
  if ((s = hush__gbuffer_import(f, &gimages, hush__param_i(f, P_USE_ID), info, &st->rp, &st->gin)))
    return s;
  if (has_dgrad && (s = hush__filter_import(f, I_DEPTH_GRADIENT, &st->grad))) return s;
  if (demod_fused) {
    if ((s = hush__filter_import_albedo_demodulated(f, I_ALBEDO, color_image, &st->albedo,
                                                    &st->comp[0].color)) ||
        (split && (s = hush__filter_import_demodulated(f, I_INDIRECT, &st->albedo,
                                                       &st->comp[1].color))))
      return s;
  } else if (demod && (s = hush__filter_import(f, I_ALBEDO, &st->albedo))) {
    return s;
  }
  if (emis && (s = hush__filter_import(f, I_EMISSION, &st->emission))) return s;
  if (has_spp && (s = hush__filter_import(f, I_SPP, &st->spp))) return s;
  if (has_svar && (s = hush__filter_import(f, I_SAMPLE_VARIANCE, &st->sample_var))) return s;
  if (ad && (s = svgf_adaptive_import(f, ad))) return s;
  const size_t npix = (size_t)W * H;
  const int holes = has_spp && hush__param_i(f, P_PROGRESSIVE) &&
                    svgf_has_holes(st->spp.plane[0], npix, threads);
  if (holes && !st->gin.has_position)
    return hush__fail(f->device, HUSH_ERROR_INVALID_OPERATION,
                      "svgf: frames with holes (spp 0) need 'position' (progressive mode; or set "
                      "progressive=false)");
  if (holes && !st->prog.src &&
      ((s = svgf_progressive_init(f->device, &st->prog, f->width, f->height)) ||
       (s = hush__filter_scratch(f, &st->eps, 1))))
    return s;
  /* light seen directly is all direct light: with the split it comes off
   * 'direct'; demodulated in the same pass unless holes may change the
   * albedo first or asvgf's gradient samples need the radiance itself */
  const int demod_emission = emis && demod && !holes && !ad;
  if (emis)
    hush__emission_subtract_demodulate(&st->comp[0].color, &st->emission,
                                       demod_emission ? &st->albedo : NULL, &st->eh, threads);
  hush__filter_timing_stage(f, "import");

  /* ---- progressive: the G-buffer holes filled (Dundr §4.2.1) */
  hush_gbuffer_store *next = hush__reprojector_next(&st->rp);
  if (holes) {
    memcpy(st->prog.depth.plane[0], next->depth.plane[0], npix * sizeof(float));
    float *planes[SVGF_PYRAMID_MAX_PLANES];
    int count = 0;
    planes[count++] = next->depth.plane[0];
    for (int k = 0; k < 3; k++) planes[count++] = next->normal.plane[k];
    for (int k = 0; k < 3; k++) planes[count++] = st->gin.position.plane[k];
    if (demod)
      for (int k = 0; k < 3; k++) planes[count++] = st->albedo.plane[k];
    if (emis) /* the lamps too (docs/holes.md) */
      for (int k = 0; k < 3; k++) planes[count++] = st->emission.plane[k];
    svgf_fill_holes(&st->prog, st->spp.plane[0], planes, count, threads);
    if (emis) hush__emission_rows_stale(&st->eh); /* filled after the subtraction */
    svgf_split_background(&st->prog, st->spp.plane[0], planes, 7, threads); /* docs/holes.md */
    hush__holes_normalize_normals(st->spp.plane[0], next->depth.plane[0], next->normal.plane, npix,
                                  threads);
  }
  /* a frame without holes carries no positions; a reset forgets them */
  if (!holes || info->history == HUSH_HISTORY_RESET) st->prog.has_pos = 0;

  /* ---- reproject */
  hush_reproject_params rp;
  rp.depth_tolerance = hush__param_f(f, P_DEPTH_TOLERANCE);
  rp.depth_gradient = hush__param_f(f, P_DEPTH_GRADIENT);
  rp.normal_threshold = hush__param_f(f, P_NORMAL_THRESHOLD);
  rp.use_id = hush__param_i(f, P_USE_ID);
  rp.fallback_3x3 = hush__param_i(f, P_FALLBACK_3X3);
  if (emis) hush__emission_wildcard_ids(&st->rp, &st->emission, threads);
  if ((s = hush__gbuffer_reproject(f, &st->rp, &st->gin, info, &rp, threads))) return s;
  if (split != st->split) {
    /* the first component's history was of the other signal */
    hush__accum_reset(&st->comp[0].acc);
    hush__accum_reset(&st->comp[1].acc);
    st->split = split;
  }

  /* ---- guide */
  const hush_gbuffer_store *gb = hush__reprojector_latest(&st->rp);
  svgf_guide_import(&st->zn, gb->depth.plane[0], (const float *const *)gb->normal.plane, threads);
  /* with holes the imported gradient is 0 there: take the filled depth's */
  svgf_guide_gradient(&st->zn, has_dgrad && !holes, &st->grad, st->zon.plane[0],
                      hush__param_f(f, P_DEPTH_STEEP), threads);
  svgf_guide gd;
  gd.width = W;
  gd.height = H;
  gd.zn = &st->zn;
  gd.gx = st->grad.plane[0];
  gd.gy = st->grad.plane[1];
  gd.zon = st->zon.plane[0];
  gd.sigma_z = hush__param_f(f, P_SIGMA_Z);
  gd.np = svgf_normal_power_of(hush__param_f(f, P_SIGMA_N));
  /* progressive: the previous state scattered forwards (Dundr §4.2.4-4.2.5) */
  if (holes)
    svgf_forward_scatter(&st->prog, st->spp.plane[0],
                         st->comp[0].acc.has_history ? hush__accum_age(&st->comp[0].acc)->plane[0]
                                                     : NULL,
                         info, threads);
  hush__filter_timing_stage(f, "reproject");

  /* ---- asvgf: lambda from the gradient samples */
  if (ad) {
    svgf_adaptive_lambda(ad, gb->depth.plane[0], (const float *const *)gb->normal.plane,
                         st->grad.plane[0], st->grad.plane[1],
                         (const float *const *)st->comp[0].color.plane,
                         split ? (const float *const *)st->comp[1].color.plane : NULL, threads);
    hush__filter_timing_stage(f, "gradient");
  }

  /* ---- per component: accumulate, variance, a-trous */
  frame_ctx fc;
  fc.f = f;
  fc.st = st;
  fc.gd = &gd;
  fc.ap.alpha_min = hush__param_f(f, P_ALPHA);
  fc.ap.alpha_moments_min = hush__param_f(f, P_ALPHA_MOMENTS);
  fc.ap.max_age = hush__param_i(f, P_MAX_AGE);
  fc.demod = demod;
  fc.demod_fused = demod_fused;
  fc.demod_emission = demod_emission;
  /* the renderer's sample variance is of the whole radiance: not split */
  fc.merge = has_svar && !split && hush__param_i(f, P_SAMPLE_VARIANCE);
  fc.iterations = iterations;
  fc.order = hush__param_i(f, P_ORDER);
  fc.kernel = kernel;
  fc.threads = threads;
  fc.holes = holes;
  fc.ad = ad;
  /* the output written as the last level finishes its rows (one pass over
   * the frame less), when nothing comes after the a-trous but the
   * remodulation and the emission's addition: no TAA or second component,
   * a last level whose rows nothing reads again (with holes and the
   * feedback, a single level is copied into the history afterwards), and
   * the wavefront, whose threads share a ring of rows
   * (SVGF_WAVEFRONT_RING). The emission's history is then accumulated
   * before the a-trous (filter_component). */
  const int feedback_alone =
      hush__param_i(f, P_FEEDBACK_FIRST_LEVEL) && holes && iterations == 1;
  fc.out_view = NULL;
  fc.out_albedo = demod ? &st->albedo : NULL;
  fc.out_emission = 0;
  if (!with_taa && !split && iterations > 0 && !feedback_alone &&
      svgf_atrous_levels_wavefront(W, H)) {
    fc.out_view = hush__filter_view(f, I_OUTPUT);
    fc.out_emission = emis;
  }
  filter_component(&fc, &st->comp[0], 1);
  if (split) {
    filter_component(&fc, &st->comp[1], 0);
    add_planes(&st->comp[0].result, &st->comp[1].result, threads);
  }
  if (holes)
    svgf_carry_positions(&st->prog, st->spp.plane[0],
                         (const float *const *)st->gin.position.plane, gb->depth.plane[0],
                         threads);

  /* ---- export */
  const hush_planar *result = &st->comp[0].result;
  const hush_image_view *age_view = hush__filter_view(f, I_HISTORY_LENGTH);
  const hush_planar *e = NULL; /* the emission to add back (done with out_view) */
  if (emis && !fc.out_emission) e = emission_history(st, fc.ap.alpha_min, holes, threads);
  if (fc.out_view) {
    if (age_view) hush__view_export(hush__accum_age(&st->comp[0].acc), age_view, threads);
    hush__filter_timing_stage(f, "export");
    return HUSH_OK;
  }
  if ((demod || emis) && !with_taa) {
    /* nothing else needs the remodulated planes: one pass */
    hush__export_remodulated(result, demod ? &st->albedo : NULL, e,
                             e ? hush__emission_rows_of(&st->eh) : NULL,
                             hush__filter_view(f, I_OUTPUT), threads);
    if (age_view) hush__view_export(hush__accum_age(&st->comp[0].acc), age_view, threads);
    hush__filter_timing_stage(f, "export");
    return HUSH_OK;
  }
  if (demod) {
    hush__remodulate(&st->albedo, result, threads);
    result = &st->albedo;
  }
  hush_planar rgb = {{result->plane[0], result->plane[1], result->plane[2]}, 3, f->width,
                     f->height};
  if (with_taa) {
    /* the paper's order: remodulate, then TAA on the final radiance */
    hush_taa_params tp;
    tp.alpha = hush__param_f(f, P_TAA_ALPHA);
    tp.box = HUSH_TAA_CLAMP;
    tp.tonemap = 1;
    tp.out_view = NULL;
    if (holes && hush__param_i(f, P_PROGRESSIVE_TAA)) /* the filtered frame is whole */
      hush__taa_resolve_holes(&st->taa, &st->rp.plan, (const float *const *)rgb.plane,
                              st->spp.plane[0], 1, &tp, st->prog.scratch.plane[0], threads);
    else
      hush__taa_resolve(&st->taa, &st->rp.plan, (const float *const *)rgb.plane, &tp, threads);
    rgb = *hush__taa_output(&st->taa);
  }
  /* the emission after TAA: its history has already averaged the lights'
   * edges over frames, and TAA's tone-mapped blend would darken them */
  if (e)
    hush__export_remodulated(&rgb, NULL, e, hush__emission_rows_of(&st->eh),
                             hush__filter_view(f, I_OUTPUT), threads);
  else
    hush__view_export(&rgb, hush__filter_view(f, I_OUTPUT), threads);
  if (age_view) hush__view_export(hush__accum_age(&st->comp[0].acc), age_view, threads);
  hush__filter_timing_stage(f, "export");
  return HUSH_OK;
}

static hush_status svgf_execute(hush_filter f, void *state, const hush_frame_info *info) {
  return svgf_run(f, state, info, NULL);
}

const hush_filter_class hush__filter_svgf = {
    &svgf_info,
    svgf_create,
    svgf_destroy,
    svgf_execute,
};
