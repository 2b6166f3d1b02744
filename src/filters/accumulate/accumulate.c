/*
 * accumulate.c — the "accumulate" filter: temporal accumulation only.
 * Reprojects the history (camera matrices or motion vectors), tests each
 * tap for consistency (depth, normal, id), blends with
 * alpha = max(alpha_min, 1/age) and outputs the accumulated colour, the
 * luminance variance from the accumulated moments and the history length.
 * Optionally demodulates by the albedo before accumulating and remodulates
 * after.
 *
 * Follows Dundr 2018 §4.1.3, Koskela et al. 2019 §3.2 and Higginson 2023
 * §1.3 / §1.3.1; the work is done by src/temporal/ (reproject.h,
 * accumulation.h), which the later filters share.
 */
#include "filters/albedo.h"
#include "filters/emission.h"
#include "filters/filter.h"
#include "filters/gbuffer.h"
#include "filters/holes.h"
#include "temporal/accumulation.h"
#include "temporal/reproject.h"

#include <stdlib.h>
#include <string.h>

/* Albedo below this is clamped before dividing (demodulation). */

enum {
  P_NONFINITE = 0,
  P_ALPHA_MIN,
  P_ALPHA_MOMENTS_MIN,
  P_MAX_AGE,
  P_DEPTH_TOLERANCE,
  P_DEPTH_GRADIENT,
  P_NORMAL_THRESHOLD,
  P_USE_ID,
  P_FALLBACK_3X3,
  P_DEMODULATE,
  P_EMISSION_BYPASS,
  P_COUNT
};

static const hush_param_info accumulate_params[P_COUNT] = {
    HUSH_PARAM_NONFINITE_ENTRY,
    {"alpha_min", HUSH_PARAM_FLOAT, 0.2, 0.0, 1.0,
     "minimum weight of the new frame in the colour blend: alpha = max(alpha_min, 1/age)", NULL},
    {"alpha_moments_min", HUSH_PARAM_FLOAT, 0.2, 0.0, 1.0,
     "minimum weight of the new frame in the luminance-moment blend", NULL},
    {"max_age", HUSH_PARAM_INT, 256, 1, 65535,
     "history length cap in frames (256: with alpha_min 0, a plain average of up to 256 frames)",
     NULL},
    {"depth_tolerance", HUSH_PARAM_FLOAT, 0.1, 0.0, 1e6,
     "a history tap is kept when |z_prev - z_expected| <= depth_tolerance * z_expected + "
     "depth_gradient * |grad z . tap offset|",
     NULL},
    {"depth_gradient", HUSH_PARAM_FLOAT, 1.0, 0.0, 1e3,
     "weight of the screen-space depth gradient in the depth test (keeps grazing surfaces; "
     "0: relative test only)",
     NULL},
    {"normal_threshold", HUSH_PARAM_FLOAT, 0.9, -1.0, 1.0,
     "a history tap is kept when dot(normal, previous normal) >= this cosine (-1: off)", NULL},
    HUSH_PARAM_USE_ID_ENTRY,
    {"fallback_3x3", HUSH_PARAM_BOOL, 1, 0, 1,
     "search the 3x3 neighbourhood when no tap of the bilinear footprint is consistent", NULL},
    {"demodulate", HUSH_PARAM_BOOL, 1, 0, 1,
     "with 'albedo' bound: accumulate color / max(albedo, 0.02), multiply back after", NULL},
    {"emission_bypass", HUSH_PARAM_BOOL, 1, 0, 1,
     "with 'emission' bound: accumulate color minus emission and add the emission back", NULL},
};

enum {
  I_COLOR = 0,
  I_DEPTH,
  I_NORMAL,
  I_POSITION,
  I_ID,
  I_MOTION,
  I_ALBEDO,
  I_EMISSION,
  I_SPP,
  I_OUTPUT,
  I_VARIANCE,
  I_HISTORY_LENGTH,
  I_COUNT
};

static const hush_image_info accumulate_images[I_COUNT] = {
    HUSH_IMAGE_COLOR_ENTRY,
    {"depth", HUSH_IMAGE_INPUT, 1, 1, "linear view depth (0: background)"},
    HUSH_IMAGE_NORMAL_ENTRY,
    {"position", HUSH_IMAGE_INPUT, 0, 3,
     "world-space position (camera reprojection; else reconstructed from depth)"},
    HUSH_IMAGE_ID_ENTRY,
    HUSH_IMAGE_MOTION_ENTRY,
    {"albedo", HUSH_IMAGE_INPUT, 0, 3, "first-hit albedo, for demodulation"},
    {"emission", HUSH_IMAGE_INPUT, 0, 3,
     "radiance the camera sees directly at the first hit (lights, sky): kept out of the "
     "accumulation (color - emission), added back to the output"},
    {"spp", HUSH_IMAGE_INPUT, 0, 1,
     "samples per pixel; 0 marks a hole (`hush render --spp-fraction`): it keeps its history "
     "(age not increased), never sampled it is filled from around (docs/holes.md)"},
    {"output", HUSH_IMAGE_OUTPUT, 1, 3, "accumulated radiance"},
    {"variance", HUSH_IMAGE_OUTPUT, 0, 1,
     "luminance variance from the accumulated moments (of the demodulated signal when "
     "demodulating)"},
    {"history_length", HUSH_IMAGE_OUTPUT, 0, 1,
     "frames accumulated per pixel (1: no history was reused; 0: a hole never sampled)"},
};

static const hush_filter_class_info accumulate_info = {
    "accumulate",
    "temporal accumulation with reprojection, consistency tests and luminance moments",
    "Dundr 2018 §4.1.3; Koskela et al. 2019 §3.2; Higginson 2023 §1.3, §1.3.1",
    accumulate_params,
    P_COUNT,
    accumulate_images,
    I_COUNT,
};

typedef struct accumulate_state {
  hush_reprojector rp; /* previous G-buffer + plan */
  hush_accum acc;      /* colour (3), moments, age */
  hush_planar color;   /* this frame's colour, demodulated in place */
  /* allocated on first use: */
  hush_planar albedo;   /* imported albedo, then the remodulated output */
  hush_gbuffer_inputs gin; /* position and motion between import and build */
  hush_planar variance; /* 1 */
  hush_planar emission; /* imported emission, then the output (emission.h) */
  hush_emission_history eh; /* the emission added back, accumulated */
} accumulate_state;

static void accumulate_destroy(void *state) {
  accumulate_state *st = state;
  if (!st) return;
  hush__reprojector_free(&st->rp);
  hush__accum_free(&st->acc);
  hush__planar_free(&st->color);
  hush__planar_free(&st->albedo);
  hush__gbuffer_inputs_free(&st->gin);
  hush__planar_free(&st->variance);
  hush__planar_free(&st->emission);
  hush__emission_history_free(&st->eh);
  free(st);
}

static hush_status accumulate_create(hush_filter f, void **state) {
  accumulate_state *st = calloc(1, sizeof *st);
  if (!st) return hush__fail(f->device, HUSH_ERROR_OUT_OF_MEMORY, "accumulate: out of memory");
  hush_status s = hush__reprojector_init(f->device, &st->rp, f->width, f->height);
  if (!s) s = hush__accum_init(f->device, &st->acc, 3, f->width, f->height);
  if (!s) s = hush__planar_init(f->device, &st->color, 3, f->width, f->height);
  if (s) {
    accumulate_destroy(st);
    return s;
  }
  *state = st;
  return HUSH_OK;
}

/* This frame's emission blended into its history (emission.h): what goes
 * back onto the output. */
static const hush_planar *accumulated_emission(accumulate_state *st, float alpha_min,
                                               int threads) {
  return hush__emission_accumulate_holes(&st->eh, &st->rp.plan,
                                         hush__accum_age(&st->acc)->plane[0], alpha_min,
                                         &st->emission, hush__gbuffer_holes_spp(&st->gin),
                                         threads);
}

static hush_status export_result(hush_filter f, accumulate_state *st, hush_planar *result,
                                 int demod, int emis, const hush_accum_params *ap,
                                 int threads);

static hush_status accumulate_execute(hush_filter f, void *state, const hush_frame_info *info) {
  accumulate_state *st = state;
  const int threads = hush__filter_threads(f);
  hush_status s;
  hush__filter_timing_begin(f);

  const int demod = hush__param_i(f, P_DEMODULATE) && hush__filter_view(f, I_ALBEDO);
  const int emis = hush__filter_view(f, I_EMISSION) != NULL && hush__param_i(f, P_EMISSION_BYPASS);

  /* ---- import: nothing of the history changes until every input is read */
  if (demod && (s = hush__filter_scratch(f, &st->albedo, 3))) return s;
  if (!emis) st->eh.valid = 0; /* bound again later: start over */
  if (emis && ((s = hush__filter_scratch(f, &st->emission, 3)) ||
               (s = hush__filter_scratch(f, &st->eh.hist[0], 3)) ||
               (s = hush__filter_scratch(f, &st->eh.hist[1], 3)) ||
               (s = hush__emission_history_rows(f->device, &st->eh, f->height))))
    return s;
  if (hush__filter_view(f, I_VARIANCE) && (s = hush__filter_scratch(f, &st->variance, 1)))
    return s;
  static const hush_gbuffer_images gimages = {I_DEPTH, I_NORMAL, I_POSITION, I_ID, I_MOTION};
  /* the colour demodulated as it is imported (one pass less), unless the
   * emission comes off first or holes may change the albedo */
  const int fused = demod && !emis && !hush__filter_view(f, I_SPP);
  if (!fused && (s = hush__filter_import(f, I_COLOR, &st->color))) return s;
  if ((s = hush__gbuffer_import(f, &gimages, hush__param_i(f, P_USE_ID), info, &st->rp, &st->gin)))
    return s;
  if (fused) {
    if ((s = hush__filter_import_albedo_demodulated(f, I_ALBEDO, I_COLOR, &st->albedo, &st->color)))
      return s;
  } else if (demod && (s = hush__filter_import(f, I_ALBEDO, &st->albedo))) {
    return s;
  }
  if (emis && (s = hush__filter_import(f, I_EMISSION, &st->emission))) return s;
  /* holes: the G-buffer, albedo and emission filled from around */
  hush_planar *const fill[2] = {demod ? &st->albedo : NULL, emis ? &st->emission : NULL};
  if ((s = hush__gbuffer_fill_holes(f, I_SPP, &st->rp, &st->gin, fill, 2, info, threads))) return s;
  hush__filter_timing_stage(f, "import");

  /* ---- reproject */
  hush_reproject_params rp;
  rp.depth_tolerance = hush__param_f(f, P_DEPTH_TOLERANCE);
  rp.depth_gradient = hush__param_f(f, P_DEPTH_GRADIENT);
  rp.normal_threshold = hush__param_f(f, P_NORMAL_THRESHOLD);
  rp.use_id = hush__param_i(f, P_USE_ID);
  rp.fallback_3x3 = hush__param_i(f, P_FALLBACK_3X3);
  if (emis) hush__emission_wildcard_ids(&st->rp, &st->emission, threads);
  if ((s = hush__gbuffer_reproject(f, &st->rp, &st->gin, info, &rp, threads))) return s;
  hush__filter_timing_stage(f, "reproject");

  /* ---- accumulate */
  if (emis)
    hush__emission_subtract_demodulate(&st->color, &st->emission, demod ? &st->albedo : NULL,
                                       &st->eh, threads);
  else if (demod && !fused)
    hush__demodulate(&st->color, &st->albedo, threads);
  hush_accum_params ap;
  ap.alpha_min = hush__param_f(f, P_ALPHA_MIN);
  ap.alpha_moments_min = hush__param_f(f, P_ALPHA_MOMENTS_MIN);
  ap.max_age = hush__param_i(f, P_MAX_AGE);
  const hush_image_view *var_view = hush__filter_view(f, I_VARIANCE);
  hush__accum_blend_holes(&st->acc, &st->rp.plan, (const float *const *)st->color.plane,
                          hush__gbuffer_holes_spp(&st->gin), &ap,
                          var_view ? st->variance.plane[0] : NULL, threads);
  hush__filter_timing_stage(f, "accumulate");

  /* ---- export */
  hush_planar *result = hush__accum_color(&st->acc);
  if (!st->acc.empty && (demod || emis)) {
    /* nothing else needs the remodulated planes: one pass */
    const hush_planar *e = emis ? accumulated_emission(st, ap.alpha_min, threads) : NULL;
    hush__export_remodulated(result, demod ? &st->albedo : NULL, e,
                             e ? hush__emission_rows_of(&st->eh) : NULL,
                             hush__filter_view(f, I_OUTPUT), threads);
  } else if ((s = export_result(f, st, result, demod, emis, &ap, threads))) {
    return s;
  }
  if (var_view) hush__view_export(&st->variance, var_view, threads);
  const hush_image_view *age_view = hush__filter_view(f, I_HISTORY_LENGTH);
  if (age_view) hush__view_export(hush__accum_age(&st->acc), age_view, threads);
  hush__filter_timing_stage(f, "export");
  return HUSH_OK;
}

/* The output through the remodulated planes: holes filled, emission added. */
static hush_status export_result(hush_filter f, accumulate_state *st, hush_planar *result,
                                 int demod, int emis, const hush_accum_params *ap,
                                 int threads) {
  hush_status s;
  if (demod) {
    hush__remodulate(&st->albedo, result, threads);
    result = &st->albedo;
  }
  /* pixels never sampled (age 0) output the fill of those around them;
   * the accumulation ignores their colour (empty taps weigh 0). Age 0
   * comes only from spp holes, whose filling at import reserved a pyramid
   * of more planes: the reserve below allocates nothing, so it cannot fail
   * after the history has changed. */
  if (st->acc.empty) {
    if ((s = hush__holes_reserve(f->device, &st->gin.holes, f->width, f->height, 3))) return s;
    hush__holes_fill(st->gin.holes.pyramid, f->width, f->height,
                     hush__accum_age(&st->acc)->plane[0], result->plane, 3, threads);
  }
  if (emis) {
    hush__emission_add(&st->emission, accumulated_emission(st, ap->alpha_min, threads), result,
                       threads);
    result = &st->emission;
  }
  hush__view_export(result, hush__filter_view(f, I_OUTPUT), threads);
  return HUSH_OK;
}

const hush_filter_class hush__filter_accumulate = {
    &accumulate_info,
    accumulate_create,
    accumulate_destroy,
    accumulate_execute,
};
