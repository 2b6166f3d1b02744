/*
 * filter.h — the contract between the generic filter object (filter.c:
 * handles, parameters by name, image bindings, commit checks, timings) and
 * each filter class (one folder per method under src/filters/).
 *
 * A class provides a static hush_filter_class: its public info (parameter
 * and image tables, declared once) and four functions. Parameter values are
 * stored by filter.c as doubles in table order; a class reads them by index
 * with hush__param(). By convention parameter 0 of every class is
 * HUSH_PARAM_NONFINITE ("nonfinite": error | replace).
 */
#ifndef HUSH_FILTERS_FILTER_H
#define HUSH_FILTERS_FILTER_H

#include "hush.h"
#include "core/device.h"
#include "core/image.h"

#define HUSH_MAX_STAGES 16
#define HUSH_MAX_IMAGES 24

typedef struct hush_filter_class {
  const hush_filter_class_info *info;
  /* Allocates the class state (history, scratch) for filter->width/height.
   * Called by commit; the previous state, if any, was destroyed first. */
  hush_status (*create)(hush_filter filter, void **state);
  void (*destroy)(void *state);
  /* Runs one frame. Bindings were validated by filter.c: every required
   * image is bound and all bound images have the committed size. */
  hush_status (*execute)(hush_filter filter, void *state, const hush_frame_info *info);
} hush_filter_class;

struct hush_filter_t {
  int refcount;
  hush_device device;
  const hush_filter_class *cls;
  double *params;                        /* cls->info->param_count values */
  hush_image_view views[HUSH_MAX_IMAGES]; /* by image index */
  int bound[HUSH_MAX_IMAGES];
  uint32_t width, height;                /* committed size, 0 before commit */
  int committed;                         /* 0 until commit, or after a binding changed size */
  size_t memory_left; /* of the device's memory limit, after what commit and execute allocated */
  void *state;
  /* Class data that outlives commits, freed with free() at release (nca:
   * weights loaded with hush_nca_load_weights); NULL until a class sets it. */
  void *class_data;
  /* timings of the last execute */
  const char *stage_names[HUSH_MAX_STAGES];
  double stage_ms[HUSH_MAX_STAGES];
  uint32_t stage_count;
  double stage_start;
};

/* The common first parameter of every class table. */
#define HUSH_PARAM_NONFINITE_ENTRY                                                            \
  {"nonfinite", HUSH_PARAM_ENUM, 0, 0, 1,                                                    \
   "NaN/Inf input values (or beyond +-1e15): error (fail the frame) or replace (use 0)",   \
   hush__nonfinite_names}
extern const char *const hush__nonfinite_names[];

/* Table entries several filters share word for word (the same meaning and
 * default everywhere they appear; docs/filters.md shows them per filter). */
#define HUSH_IMAGE_COLOR_ENTRY \
  {"color", HUSH_IMAGE_INPUT, 1, 3, "noisy radiance of this frame"}
#define HUSH_IMAGE_NORMAL_ENTRY \
  {"normal", HUSH_IMAGE_INPUT, 1, 3, "world-space shading normal"}
#define HUSH_IMAGE_ID_ENTRY \
  {"id", HUSH_IMAGE_INPUT, 0, 1, \
  "mesh or material id: history only from the same id (where the emission is bypassed, a " \
  "pixel that sees a light matches any id, so light edges average over frames)"}
#define HUSH_IMAGE_MOTION_ENTRY \
  {"motion", HUSH_IMAGE_INPUT, 0, 2, \
  "motion in pixels, previous minus current (required with HUSH_MOTION_VECTORS)"}
#define HUSH_PARAM_DEPTH_TOLERANCE_ENTRY \
  {"depth_tolerance", HUSH_PARAM_FLOAT, 0.1, 0.0, 1e6, \
  "reprojection: a history tap is kept when its depth is within this fraction (plus the " \
  "gradient term)", \
  NULL}
#define HUSH_PARAM_DEPTH_GRADIENT_ENTRY \
  {"depth_gradient", HUSH_PARAM_FLOAT, 1.0, 0.0, 1e3, \
  "reprojection: weight of the screen-space depth gradient in the depth test", NULL}
#define HUSH_PARAM_NORMAL_THRESHOLD_ENTRY \
  {"normal_threshold", HUSH_PARAM_FLOAT, 0.9, -1.0, 1.0, \
  "reprojection: a history tap is kept when dot(normal, previous normal) >= this (-1: off)", \
  NULL}
#define HUSH_PARAM_USE_ID_ENTRY \
  {"use_id", HUSH_PARAM_BOOL, 1, 0, 1, \
  "reject history from a pixel with another id (when 'id' is bound)", NULL}
#define HUSH_PARAM_DEMODULATE_ENTRY \
  {"demodulate", HUSH_PARAM_BOOL, 1, 0, 1, \
  "with 'albedo' bound: filter color / max(albedo, 0.02), multiply back after", NULL}

static inline double hush__param(const struct hush_filter_t *f, int index) {
  return f->params[index];
}
static inline float hush__param_f(const struct hush_filter_t *f, int index) {
  return (float)f->params[index];
}
static inline int hush__param_i(const struct hush_filter_t *f, int index) {
  return (int)f->params[index];
}

/* Index of an image in the class table, -1 if unknown. */
int hush__filter_image_index(const struct hush_filter_t *f, const char *name);
/* Bound view of image index i, or NULL when unbound. */
static inline const hush_image_view *hush__filter_view(const struct hush_filter_t *f, int i) {
  return f->bound[i] ? &f->views[i] : NULL;
}
/* The worker threads of the filter's device (at least 1). */
static inline int hush__filter_threads(const struct hush_filter_t *f) {
  return f->device->threads > 0 ? f->device->threads : 1;
}
/* Imports bound input image i into dst (already sized), honouring the
 * "nonfinite" parameter; reports errors naming the image. */
hush_status hush__filter_import(struct hush_filter_t *f, int image, hush_planar *dst);

/* hush__filter_import of `count` (<= HUSH_IMPORT_MANY_MAX) bound images
 * images[j] into dst[j], in one parallel pass over the rows (one fork and
 * join, not one per image); the NaN/Inf policy is then applied image by
 * image in that order (the first failing one is reported). normals >= 0:
 * images[normals] is a 3-channel image of normals, and odd_rows[y] (one
 * byte per row) is set to whether row y holds one that is neither 0 nor of
 * unit length (hush__view_import_row_normals). */
#define HUSH_IMPORT_MANY_MAX 8
hush_status hush__filter_import_many(struct hush_filter_t *f, int count, const int *images,
                                    hush_planar *const *dst, int normals, uint8_t *odd_rows);

/* hush__filter_import fused with the demodulation (albedo.h): dst <- the
 * radiance image / max(albedo, eps), albedo imported already; the same
 * errors and messages. */
hush_status hush__filter_import_demodulated(struct hush_filter_t *f, int image,
                                            const hush_planar *albedo, hush_planar *dst);

/* hush__filter_import of albedo_image into albedo, then
 * hush__filter_import_demodulated of color_image by it, in one pass
 * (albedo.h's hush__import_albedo_demodulated). */
hush_status hush__filter_import_albedo_demodulated(struct hush_filter_t *f, int albedo_image,
                                                   int color_image, hush_planar *albedo,
                                                   hush_planar *dst);

/* Allocates a planar image of the filter's size the first time it is
 * needed (a no-op when img already has planes). */
hush_status hush__filter_scratch(struct hush_filter_t *f, hush_planar *img, int channels);

/* Stage timing: call begin at the start of execute, then stage(name) at the
 * end of each stage; the time since the previous mark goes to that name. */
void hush__filter_timing_begin(struct hush_filter_t *f);
void hush__filter_timing_stage(struct hush_filter_t *f, const char *name);
/* For stages run interleaved (block row by block row in the threads'
 * loop): the time since the previous mark, shared among the n names in
 * proportion to weight[k] (the threads' time in each; all 0: equally). */
void hush__filter_timing_split(struct hush_filter_t *f, const char *const *names,
                               const double *weight, int n);

/* The registry (registry.c): every class this build has. */
extern const hush_filter_class *const hush__filter_classes[];
extern const uint32_t hush__filter_class_count;

#endif
