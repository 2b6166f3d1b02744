/*
 * taa.c — the "taa" filter: temporal anti-aliasing on its own. The
 * previous output is reprojected with the shared plan (camera matrices or
 * motion vectors, with the depth/normal/id consistency tests), clamped or
 * clipped to the current 3x3 neighbourhood in YCoCg and blended with a
 * constant weight (src/temporal/taa.h).
 *
 * Follows Karis 2014 as summarised in papers/NOTES.md ("TAA"); the
 * reprojection is Dundr 2018 §4.1.3 / Higginson 2023 §1.3.1 (reproject.h).
 */
#include "filters/filter.h"
#include "filters/gbuffer.h"
#include "filters/holes.h"
#include "temporal/reproject.h"
#include "temporal/taa.h"

#include <stdlib.h>

static const char *const taa_box_names[] = {"clamp", "clip"};

enum {
  P_NONFINITE = 0,
  P_ALPHA,
  P_BOX,
  P_TONEMAP,
  P_DEPTH_TOLERANCE,
  P_NORMAL_THRESHOLD,
  P_USE_ID,
  P_COUNT
};

static const hush_param_info taa_params[P_COUNT] = {
    HUSH_PARAM_NONFINITE_ENTRY,
    {"alpha", HUSH_PARAM_FLOAT, 0.1, 0.01, 1.0, "weight of the current frame in the blend", NULL},
    {"box", HUSH_PARAM_ENUM, 0, 0, 1,
     "history limited to the 3x3 neighbourhood's YCoCg box: clamp (per component) or clip "
     "(towards the box centre)",
     taa_box_names},
    {"tonemap", HUSH_PARAM_BOOL, 1, 0, 1,
     "resolve on tone-mapped values c / (1 + luma), inverted after", NULL},
    {"depth_tolerance", HUSH_PARAM_FLOAT, 0.1, 0.0, 1e6,
     "reprojection: relative depth tolerance of a history tap", NULL},
    {"normal_threshold", HUSH_PARAM_FLOAT, -1.0, -1.0, 1.0,
     "reprojection: minimum dot(normal, previous normal) of a history tap (-1: off)", NULL},
    HUSH_PARAM_USE_ID_ENTRY,
};

enum { I_COLOR = 0, I_DEPTH, I_NORMAL, I_POSITION, I_ID, I_MOTION, I_SPP, I_OUTPUT, I_COUNT };

static const hush_image_info taa_images[I_COUNT] = {
    {"color", HUSH_IMAGE_INPUT, 1, 3, "radiance of this frame (e.g. a denoiser's output)"},
    {"depth", HUSH_IMAGE_INPUT, 1, 1, "linear view depth (0: background)"},
    {"normal", HUSH_IMAGE_INPUT, 0, 3, "world-space shading normal (for the normal test)"},
    {"position", HUSH_IMAGE_INPUT, 0, 3,
     "world-space position (camera reprojection; else reconstructed from depth)"},
    HUSH_IMAGE_ID_ENTRY,
    HUSH_IMAGE_MOTION_ENTRY,
    {"spp", HUSH_IMAGE_INPUT, 0, 1,
     "samples per pixel; 0 marks a hole (`hush render --spp-fraction`): only traced pixels "
     "update the history and form the box, a hole keeps its history (docs/holes.md)"},
    {"output", HUSH_IMAGE_OUTPUT, 1, 3, "anti-aliased radiance"},
};

static const hush_filter_class_info taa_info = {
    "taa",
    "temporal anti-aliasing: reprojected history clamped to the 3x3 YCoCg box, constant blend",
    "Karis 2014 (papers/NOTES.md, TAA); Dundr 2018 §4.1.3 (reprojection)",
    taa_params,
    P_COUNT,
    taa_images,
    I_COUNT,
};

typedef struct taa_state {
  hush_reprojector rp;
  hush_taa taa;
  hush_planar color;
  hush_gbuffer_inputs gin; /* position and motion between import and build */
  hush_planar valid;       /* 1, frames with holes: the output pixels that have data */
} taa_state;

static void taa_destroy(void *state) {
  taa_state *st = state;
  if (!st) return;
  hush__reprojector_free(&st->rp);
  hush__taa_free(&st->taa);
  hush__planar_free(&st->color);
  hush__gbuffer_inputs_free(&st->gin);
  hush__planar_free(&st->valid);
  free(st);
}

static hush_status taa_create(hush_filter f, void **state) {
  taa_state *st = calloc(1, sizeof *st);
  if (!st) return hush__fail(f->device, HUSH_ERROR_OUT_OF_MEMORY, "taa: out of memory");
  hush_status s = hush__reprojector_init(f->device, &st->rp, f->width, f->height);
  if (!s) s = hush__taa_init(f->device, &st->taa, f->width, f->height);
  if (!s) s = hush__planar_init(f->device, &st->color, 3, f->width, f->height);
  if (s) {
    taa_destroy(st);
    return s;
  }
  *state = st;
  return HUSH_OK;
}

static hush_status taa_execute(hush_filter f, void *state, const hush_frame_info *info) {
  taa_state *st = state;
  const int threads = hush__filter_threads(f);
  hush_status s;
  hush__filter_timing_begin(f);

  static const hush_gbuffer_images gimages = {I_DEPTH, I_NORMAL, I_POSITION, I_ID, I_MOTION};
  if ((s = hush__filter_import(f, I_COLOR, &st->color))) return s;
  if ((s = hush__gbuffer_import(f, &gimages, hush__param_i(f, P_USE_ID), info, &st->rp, &st->gin)))
    return s;
  if ((s = hush__gbuffer_fill_holes(f, I_SPP, &st->rp, &st->gin, NULL, 0, info, threads))) return s;
  if (st->gin.has_holes && (s = hush__filter_scratch(f, &st->valid, 1))) return s;
  hush__filter_timing_stage(f, "import");

  hush_reproject_params rp;
  hush__reproject_params_default(&rp);
  rp.depth_tolerance = hush__param_f(f, P_DEPTH_TOLERANCE);
  rp.normal_threshold = hush__param_f(f, P_NORMAL_THRESHOLD);
  rp.use_id = hush__param_i(f, P_USE_ID);
  if ((s = hush__gbuffer_reproject(f, &st->rp, &st->gin, info, &rp, threads))) return s;
  hush__filter_timing_stage(f, "reproject");

  hush_taa_params tp;
  tp.alpha = hush__param_f(f, P_ALPHA);
  tp.box = (hush_taa_box)hush__param_i(f, P_BOX);
  tp.tonemap = hush__param_i(f, P_TONEMAP);
  tp.out_view = NULL;
  if (st->gin.has_holes) {
    /* only the traced pixels update; pixels with nothing at all (no
     * history, no traced neighbour) are filled from around */
    hush_taa *t = &st->taa;
    if (hush__taa_resolve_holes(t, &st->rp.plan, (const float *const *)st->color.plane,
                                st->gin.spp.plane[0], 0, &tp, st->valid.plane[0], threads))
      hush__holes_fill(st->gin.holes.pyramid, f->width, f->height, st->valid.plane[0],
                       t->history[t->latest].plane, 3, threads);
  } else {
    /* the output written as each row is resolved */
    tp.out_view = hush__filter_view(f, I_OUTPUT);
    hush__taa_resolve(&st->taa, &st->rp.plan, (const float *const *)st->color.plane, &tp,
                      threads);
  }
  hush__filter_timing_stage(f, "resolve");

  if (!tp.out_view)
    hush__view_export(hush__taa_output(&st->taa), hush__filter_view(f, I_OUTPUT), threads);
  hush__filter_timing_stage(f, "export");
  return HUSH_OK;
}

const hush_filter_class hush__filter_taa = {
    &taa_info,
    taa_create,
    taa_destroy,
    taa_execute,
};
