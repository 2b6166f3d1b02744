/*
 * filter.c — the generic hush_filter object: creation by class name,
 * parameters by name validated against the class table, image bindings,
 * commit-time checks, execute dispatch and stage timings. Filter classes
 * (src/filters/<method>/) implement only their algorithm.
 */
#include "filters/filter.h"

#include "core/timer.h"
#include "filters/albedo.h"

#include <errno.h>
#include <stddef.h>
#include <stdio.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

const char *const hush__nonfinite_names[] = {"error", "replace"};

/* ---- classes ------------------------------------------------------------ */

uint32_t hush_filter_class_count(void) { return hush__filter_class_count; }

const hush_filter_class_info *hush_filter_class_at(uint32_t index) {
  return index < hush__filter_class_count ? hush__filter_classes[index]->info : NULL;
}

static const hush_filter_class *find_class(const char *name) {
  if (!name) return NULL;
  for (uint32_t i = 0; i < hush__filter_class_count; i++)
    if (strcmp(hush__filter_classes[i]->info->name, name) == 0) return hush__filter_classes[i];
  return NULL;
}

const hush_filter_class_info *hush_filter_class_find(const char *name) {
  const hush_filter_class *c = find_class(name);
  return c ? c->info : NULL;
}

/* ---- lifetime ----------------------------------------------------------- */

static void list_class_names(char *buf, size_t size) {
  buf[0] = '\0';
  for (uint32_t i = 0; i < hush__filter_class_count; i++) {
    const size_t len = strlen(buf);
    snprintf(buf + len, size - len, "%s%s", i ? ", " : "", hush__filter_classes[i]->info->name);
  }
}

hush_filter hush_filter_new(hush_device device, const char *class_name) {
  if (!device) {
    hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT, "hush_filter_new: device is NULL");
    return NULL;
  }
  const hush_filter_class *cls = find_class(class_name);
  if (!cls) {
    char names[512];
    list_class_names(names, sizeof names);
    hush__fail(device, HUSH_ERROR_NOT_FOUND, "unknown filter '%s' (known: %s)",
               class_name ? class_name : "(null)", names);
    return NULL;
  }
  hush_filter f = calloc(1, sizeof *f);
  const uint32_t np = cls->info->param_count;
  double *params = calloc(np ? np : 1, sizeof *params);
  if (!f || !params) {
    free(f);
    free(params);
    hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory creating filter '%s'", class_name);
    return NULL;
  }
  for (uint32_t i = 0; i < np; i++) params[i] = cls->info->params[i].default_value;
  f->refcount = 1;
  f->device = device;
  f->cls = cls;
  f->params = params;
  hush_device_retain(device);
  return f;
}

void hush_filter_retain(hush_filter filter) {
  if (filter) filter->refcount++;
}

void hush_filter_release(hush_filter filter) {
  if (!filter || --filter->refcount > 0) return;
  if (filter->state) filter->cls->destroy(filter->state);
  free(filter->class_data);
  free(filter->params);
  hush_device_release(filter->device);
  free(filter);
}

const hush_filter_class_info *hush_filter_get_class(hush_filter filter) {
  return filter ? filter->cls->info : NULL;
}

/* ---- parameters --------------------------------------------------------- */

static const char *type_name(hush_param_type t) {
  switch (t) {
  case HUSH_PARAM_BOOL: return "bool";
  case HUSH_PARAM_INT: return "int";
  case HUSH_PARAM_FLOAT: return "float";
  case HUSH_PARAM_ENUM: return "enum";
  }
  return "?";
}

static hush_status find_param(hush_filter f, const char *name, const hush_param_info **info,
                              int *index) {
  const hush_filter_class_info *ci = f->cls->info;
  if (!name) return hush__fail(f->device, HUSH_ERROR_INVALID_ARGUMENT, "parameter name is NULL");
  for (uint32_t i = 0; i < ci->param_count; i++)
    if (strcmp(ci->params[i].name, name) == 0) {
      *info = &ci->params[i];
      *index = (int)i;
      return HUSH_OK;
    }
  char names[1024] = "";
  for (uint32_t i = 0; i < ci->param_count; i++) {
    const size_t len = strlen(names);
    snprintf(names + len, sizeof names - len, "%s%s", i ? ", " : "", ci->params[i].name);
  }
  return hush__fail(f->device, HUSH_ERROR_NOT_FOUND,
                    "filter '%s' has no parameter '%s' (it has: %s)", ci->name, name, names);
}

/* Stores value after the range check shared by every setter. */
static hush_status store_param(hush_filter f, const hush_param_info *p, int index, double value) {
  if (!isfinite(value))
    return hush__fail(f->device, HUSH_ERROR_OUT_OF_RANGE, "%s.%s: value is not finite",
                      f->cls->info->name, p->name);
  if (p->type == HUSH_PARAM_BOOL) {
    if (value != 0.0 && value != 1.0)
      return hush__fail(f->device, HUSH_ERROR_OUT_OF_RANGE, "%s.%s: a bool is 0 or 1, got %g",
                        f->cls->info->name, p->name, value);
  } else if (value < p->min_value || value > p->max_value) {
    return hush__fail(f->device, HUSH_ERROR_OUT_OF_RANGE, "%s.%s = %g is outside [%g, %g]",
                      f->cls->info->name, p->name, value, p->min_value, p->max_value);
  }
  f->params[index] = value;
  return HUSH_OK;
}

static hush_status type_mismatch(hush_filter f, const hush_param_info *p, const char *given) {
  return hush__fail(f->device, HUSH_ERROR_TYPE_MISMATCH, "%s.%s is a %s parameter, not %s",
                    f->cls->info->name, p->name, type_name(p->type), given);
}

hush_status hush_filter_set_bool(hush_filter filter, const char *name, int value) {
  if (!filter) return hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT, "filter is NULL");
  const hush_param_info *p;
  int i;
  hush_status s = find_param(filter, name, &p, &i);
  if (s) return s;
  if (p->type != HUSH_PARAM_BOOL) return type_mismatch(filter, p, "bool");
  return store_param(filter, p, i, value ? 1.0 : 0.0);
}

hush_status hush_filter_set_int(hush_filter filter, const char *name, int value) {
  if (!filter) return hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT, "filter is NULL");
  const hush_param_info *p;
  int i;
  hush_status s = find_param(filter, name, &p, &i);
  if (s) return s;
  if (p->type == HUSH_PARAM_FLOAT) return type_mismatch(filter, p, "int");
  return store_param(filter, p, i, (double)value);
}

hush_status hush_filter_set_float(hush_filter filter, const char *name, float value) {
  if (!filter) return hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT, "filter is NULL");
  const hush_param_info *p;
  int i;
  hush_status s = find_param(filter, name, &p, &i);
  if (s) return s;
  if (p->type == HUSH_PARAM_BOOL || p->type == HUSH_PARAM_ENUM)
    return type_mismatch(filter, p, "float");
  if (p->type == HUSH_PARAM_INT && (double)value != floor((double)value))
    return hush__fail(filter->device, HUSH_ERROR_TYPE_MISMATCH,
                      "%s.%s is an int parameter, got %g", filter->cls->info->name, p->name,
                      (double)value);
  return store_param(filter, p, i, (double)value);
}

/* Parses a whole-string number; 0 if the text is not one. */
static int parse_number(const char *text, double *out) {
  if (!text || !*text) return 0;
  char *end;
  errno = 0;
  const double v = strtod(text, &end);
  if (errno || *end != '\0') return 0;
  *out = v;
  return 1;
}

hush_status hush_filter_set_string(hush_filter filter, const char *name, const char *value) {
  if (!filter) return hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT, "filter is NULL");
  const hush_param_info *p;
  int i;
  hush_status s = find_param(filter, name, &p, &i);
  if (s) return s;
  if (!value)
    return hush__fail(filter->device, HUSH_ERROR_INVALID_ARGUMENT, "%s.%s: value is NULL",
                      filter->cls->info->name, p->name);
  double v = 0.0;
  switch (p->type) {
  case HUSH_PARAM_BOOL:
    if (!strcasecmp(value, "true") || !strcmp(value, "1") || !strcasecmp(value, "on"))
      return store_param(filter, p, i, 1.0);
    if (!strcasecmp(value, "false") || !strcmp(value, "0") || !strcasecmp(value, "off"))
      return store_param(filter, p, i, 0.0);
    return hush__fail(filter->device, HUSH_ERROR_TYPE_MISMATCH,
                      "%s.%s is a bool: use true or false, got '%s'", filter->cls->info->name,
                      p->name, value);
  case HUSH_PARAM_ENUM:
    for (int k = 0; k <= (int)p->max_value; k++)
      if (!strcmp(p->enum_names[k], value)) return store_param(filter, p, i, (double)k);
    if (parse_number(value, &v) && v == floor(v)) return store_param(filter, p, i, v);
    {
      char names[256] = "";
      for (int k = 0; k <= (int)p->max_value; k++) {
        const size_t len = strlen(names);
        snprintf(names + len, sizeof names - len, "%s%s", k ? ", " : "", p->enum_names[k]);
      }
      return hush__fail(filter->device, HUSH_ERROR_OUT_OF_RANGE,
                        "%s.%s: unknown value '%s' (one of: %s)", filter->cls->info->name, p->name,
                        value, names);
    }
  case HUSH_PARAM_INT:
    if (!parse_number(value, &v) || v != floor(v))
      return hush__fail(filter->device, HUSH_ERROR_TYPE_MISMATCH,
                        "%s.%s is an int, got '%s'", filter->cls->info->name, p->name, value);
    return store_param(filter, p, i, v);
  case HUSH_PARAM_FLOAT:
    if (!parse_number(value, &v))
      return hush__fail(filter->device, HUSH_ERROR_TYPE_MISMATCH,
                        "%s.%s is a number, got '%s'", filter->cls->info->name, p->name, value);
    return store_param(filter, p, i, v);
  }
  return HUSH_ERROR_UNKNOWN;
}

static hush_status get_param(hush_filter filter, const char *name, double *value) {
  *value = 0.0;
  if (!filter) return hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT, "filter is NULL");
  const hush_param_info *p;
  int i;
  hush_status s = find_param(filter, name, &p, &i);
  if (s) return s;
  *value = filter->params[i];
  return HUSH_OK;
}

hush_status hush_filter_get_bool(hush_filter filter, const char *name, int *value) {
  double v;
  if (!value) return hush__fail(filter ? filter->device : NULL, HUSH_ERROR_INVALID_ARGUMENT, "value is NULL");
  hush_status s = get_param(filter, name, &v);
  if (!s) *value = v != 0.0;
  return s;
}

hush_status hush_filter_get_int(hush_filter filter, const char *name, int *value) {
  double v;
  if (!value) return hush__fail(filter ? filter->device : NULL, HUSH_ERROR_INVALID_ARGUMENT, "value is NULL");
  hush_status s = get_param(filter, name, &v);
  if (!s) *value = (int)v;
  return s;
}

hush_status hush_filter_get_float(hush_filter filter, const char *name, float *value) {
  double v;
  if (!value) return hush__fail(filter ? filter->device : NULL, HUSH_ERROR_INVALID_ARGUMENT, "value is NULL");
  hush_status s = get_param(filter, name, &v);
  if (!s) *value = (float)v;
  return s;
}

/* ---- images ------------------------------------------------------------- */

int hush__filter_image_index(const struct hush_filter_t *f, const char *name) {
  const hush_filter_class_info *ci = f->cls->info;
  for (uint32_t i = 0; i < ci->image_count; i++)
    if (strcmp(ci->images[i].name, name) == 0) return (int)i;
  return -1;
}

static hush_status unknown_image(hush_filter f, const char *name) {
  const hush_filter_class_info *ci = f->cls->info;
  char names[512] = "";
  for (uint32_t i = 0; i < ci->image_count; i++) {
    const size_t len = strlen(names);
    snprintf(names + len, sizeof names - len, "%s%s", i ? ", " : "", ci->images[i].name);
  }
  return hush__fail(f->device, HUSH_ERROR_NOT_FOUND, "filter '%s' has no image '%s' (it has: %s)",
                    ci->name, name, names);
}

hush_status hush_filter_set_image(hush_filter filter, const char *name, const hush_image_view *view) {
  if (!filter) return hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT, "filter is NULL");
  if (!name) return hush__fail(filter->device, HUSH_ERROR_INVALID_ARGUMENT, "image name is NULL");
  const int i = hush__filter_image_index(filter, name);
  if (i < 0) return unknown_image(filter, name);
  const hush_image_info *ii = &filter->cls->info->images[i];
  hush_status s = hush__view_validate(filter->device, view, name, ii->channels,
                                      ii->role == HUSH_IMAGE_OUTPUT);
  if (s) return s;
  filter->views[i] = *view;
  filter->bound[i] = 1;
  if (view->width != filter->width || view->height != filter->height) filter->committed = 0;
  return HUSH_OK;
}

hush_status hush_filter_unset_image(hush_filter filter, const char *name) {
  if (!filter) return hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT, "filter is NULL");
  if (!name) return hush__fail(filter->device, HUSH_ERROR_INVALID_ARGUMENT, "image name is NULL");
  const int i = hush__filter_image_index(filter, name);
  if (i < 0) return unknown_image(filter, name);
  filter->bound[i] = 0;
  return HUSH_OK;
}

/* Bytes from the first to one past the last byte a view touches. */
static void view_span(const hush_image_view *v, const char **lo, const char **hi) {
  const char *base = (const char *)v->data + v->byte_offset;
  *lo = base;
  *hi = base + (size_t)(v->height - 1) * hush__view_row_stride(v) +
        (size_t)(v->width - 1) * hush__view_pixel_stride(v) + hush_format_pixel_size(v->format);
}

static hush_status check_bindings(hush_filter f, uint32_t *width, uint32_t *height) {
  const hush_filter_class_info *ci = f->cls->info;
  int first = -1;
  for (uint32_t i = 0; i < ci->image_count; i++) {
    if (!f->bound[i]) {
      if (ci->images[i].required)
        return hush__fail(f->device, HUSH_ERROR_INVALID_OPERATION,
                          "filter '%s': required image '%s' is not bound", ci->name,
                          ci->images[i].name);
      continue;
    }
    if (first < 0) {
      first = (int)i;
      continue;
    }
    const hush_image_view *a = &f->views[first], *b = &f->views[i];
    if (a->width != b->width || a->height != b->height)
      return hush__fail(f->device, HUSH_ERROR_INVALID_ARGUMENT,
                        "filter '%s': image '%s' is %ux%u but '%s' is %ux%u", ci->name,
                        ci->images[i].name, b->width, b->height, ci->images[first].name, a->width,
                        a->height);
  }
  if (first < 0)
    return hush__fail(f->device, HUSH_ERROR_INVALID_OPERATION, "filter '%s': no image is bound",
                      ci->name);
  /* An output must not overlap any other bound image: filters read inputs
   * while writing outputs. */
  for (uint32_t i = 0; i < ci->image_count; i++) {
    if (!f->bound[i] || ci->images[i].role != HUSH_IMAGE_OUTPUT) continue;
    const char *lo, *hi;
    view_span(&f->views[i], &lo, &hi);
    for (uint32_t j = 0; j < ci->image_count; j++) {
      if (j == i || !f->bound[j]) continue;
      const char *lo2, *hi2;
      view_span(&f->views[j], &lo2, &hi2);
      if (lo < hi2 && lo2 < hi)
        return hush__fail(f->device, HUSH_ERROR_INVALID_ARGUMENT,
                          "filter '%s': output '%s' overlaps image '%s' in memory", ci->name,
                          ci->images[i].name, ci->images[j].name);
    }
  }
  *width = f->views[first].width;
  *height = f->views[first].height;
  return HUSH_OK;
}

/* Opens the memory cap around a class's create or execute (execute
 * allocates the buffers of the stages and images it first uses) with
 * `bytes` of the limit left; `why` (HUSH_MESSAGE_MAX) receives the refusal's
 * message and must outlive cap_close. */
static void cap_open(const struct hush_filter_t *filter, size_t bytes, char *why) {
  snprintf(why, HUSH_MESSAGE_MAX,
           "filter '%s': %ux%u images need more than the %zu MiB it may allocate (the "
           "machine's memory, or the device's memory option)",
           filter->cls->info->name, filter->width, filter->height,
           hush__device_memory_limit(filter->device) >> 20);
  hush__alloc_cap_open(filter->device, bytes, why);
}

static void cap_close(struct hush_filter_t *filter) {
  hush__alloc_cap_close();
  filter->memory_left = hush__alloc_cap_left();
}

hush_status hush_filter_commit(hush_filter filter) {
  if (!filter) return hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT, "filter is NULL");
  uint32_t w, h;
  hush_status s = check_bindings(filter, &w, &h);
  if (s) return s;
  if (filter->state && w == filter->width && h == filter->height) {
    filter->committed = 1;
    return HUSH_OK;
  }
  if (filter->state) filter->cls->destroy(filter->state);
  filter->state = NULL;
  filter->width = w;
  filter->height = h;
  char why[HUSH_MESSAGE_MAX];
  cap_open(filter, hush__device_memory_limit(filter->device), why);
  s = filter->cls->create(filter, &filter->state);
  cap_close(filter);
  if (s) {
    filter->state = NULL;
    filter->width = filter->height = 0;
    filter->committed = 0;
    return s;
  }
  filter->committed = 1;
  return HUSH_OK;
}

void hush_frame_info_init(hush_frame_info *info) {
  if (!info) return;
  memset(info, 0, sizeof *info);
  info->size = sizeof *info;
  for (int i = 0; i < 4; i++) {
    info->world_to_view[i * 5] = info->view_to_clip[i * 5] = 1.0f;
    info->prev_world_to_view[i * 5] = info->prev_view_to_clip[i * 5] = 1.0f;
  }
  info->motion = HUSH_MOTION_CAMERA;
  info->history = HUSH_HISTORY_CONTINUE;
}

static int matrix_finite(const float m[16]) {
  for (int i = 0; i < 16; i++)
    if (!isfinite(m[i])) return 0;
  return 1;
}

/* Copies the caller's info (which may be an older, smaller struct) into a
 * full one, defaults first. */
static hush_status read_info(hush_filter f, const hush_frame_info *in, hush_frame_info *out) {
  hush_frame_info_init(out);
  if (!in) return HUSH_OK;
  if (in->size < offsetof(hush_frame_info, history) + sizeof in->history ||
      in->size > (1u << 16))
    return hush__fail(f->device, HUSH_ERROR_INVALID_ARGUMENT,
                      "hush_frame_info.size is %zu: initialise it with hush_frame_info_init()",
                      in->size);
  memcpy(out, in, sizeof *out < in->size ? sizeof *out : in->size);
  out->size = sizeof *out;
  if (!matrix_finite(out->world_to_view) || !matrix_finite(out->view_to_clip) ||
      !matrix_finite(out->prev_world_to_view) || !matrix_finite(out->prev_view_to_clip) ||
      !isfinite(out->jitter[0]) || !isfinite(out->jitter[1]) || !isfinite(out->prev_jitter[0]) ||
      !isfinite(out->prev_jitter[1]))
    return hush__fail(f->device, HUSH_ERROR_NONFINITE, "hush_frame_info: NaN/Inf in a matrix or jitter");
  if (out->motion != HUSH_MOTION_CAMERA && out->motion != HUSH_MOTION_VECTORS)
    return hush__fail(f->device, HUSH_ERROR_INVALID_ARGUMENT, "hush_frame_info.motion is %d",
                      (int)out->motion);
  if (out->history != HUSH_HISTORY_CONTINUE && out->history != HUSH_HISTORY_RESET)
    return hush__fail(f->device, HUSH_ERROR_INVALID_ARGUMENT, "hush_frame_info.history is %d",
                      (int)out->history);
  return HUSH_OK;
}

hush_status hush_filter_execute(hush_filter filter, const hush_frame_info *info) {
  if (!filter) return hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT, "filter is NULL");
  if (!filter->committed || !filter->state)
    return hush__fail(filter->device, HUSH_ERROR_INVALID_OPERATION,
                      "filter '%s': execute before commit (or a binding changed size since)",
                      filter->cls->info->name);
  uint32_t w, h;
  hush_status s = check_bindings(filter, &w, &h);
  if (s) return s;
  if (w != filter->width || h != filter->height)
    return hush__fail(filter->device, HUSH_ERROR_INVALID_OPERATION,
                      "filter '%s': images are %ux%u but it was committed at %ux%u",
                      filter->cls->info->name, w, h, filter->width, filter->height);
  hush_frame_info full;
  s = read_info(filter, info, &full);
  if (s) return s;
  filter->stage_count = 0;
  char why[HUSH_MESSAGE_MAX];
  cap_open(filter, filter->memory_left, why); /* what commit and earlier frames left */
  s = filter->cls->execute(filter, filter->state, &full);
  cap_close(filter);
  return s;
}

hush_status hush_filter_get_timings(hush_filter filter, const char *const **names, const double **ms,
                                    uint32_t *count) {
  if (!filter) return hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT, "filter is NULL");
  if (!names || !ms || !count)
    return hush__fail(filter->device, HUSH_ERROR_INVALID_ARGUMENT, "timings: NULL output pointer");
  *names = filter->stage_names;
  *ms = filter->stage_ms;
  *count = filter->stage_count;
  return HUSH_OK;
}

/* ---- helpers for filter classes ---------------------------------------- */

/* The NaN/Inf policy of the filter's `nonfinite` parameter (index 0). */
static hush_nonfinite_policy nonfinite_policy(const struct hush_filter_t *f) {
  return hush__param_i(f, 0) ? HUSH_NONFINITE_REPLACE : HUSH_NONFINITE_ERROR;
}

/* Logs that `replaced` values of image `image` were replaced (none: nothing). */
static void log_replaced(const struct hush_filter_t *f, size_t replaced, int image) {
  if (replaced)
    hush__log(f->device, 1, "%s: replaced %zu NaN/Inf value(s) in '%s' with 0",
              f->cls->info->name, replaced, f->cls->info->images[image].name);
}

hush_status hush__filter_import(struct hush_filter_t *f, int image, hush_planar *dst) {
  size_t replaced = 0;
  const hush_status s =
      hush__view_import(f->device, &f->views[image], f->cls->info->images[image].name, dst,
                        nonfinite_policy(f), &replaced);
  if (!s) log_replaced(f, replaced, image);
  return s;
}

hush_status hush__filter_import_many(struct hush_filter_t *f, int count, const int *images,
                                    hush_planar *const *dst, int normals, uint8_t *odd_rows) {
  if (count > HUSH_IMPORT_MANY_MAX || normals >= count) return HUSH_ERROR_UNKNOWN; /* a bug */
  const int threads = hush__filter_threads(f);
  const int H = (int)f->height;
  size_t bad[HUSH_IMPORT_MANY_MAX] = {0};
  /* one parallel region for all the images, row by row */
#pragma omp parallel for schedule(static) num_threads(threads) \
    reduction(+ : bad[:HUSH_IMPORT_MANY_MAX])
  for (int y = 0; y < H; y++)
    for (int j = 0; j < count; j++) {
      const hush_image_view *v = &f->views[images[j]];
      if (j == normals) {
        int odd = 0;
        bad[j] += hush__view_import_row_normals(v, (uint32_t)y, dst[j], &odd);
        odd_rows[y] = (uint8_t)odd;
      } else {
        bad[j] += hush__view_import_row(v, (uint32_t)y, dst[j]);
      }
    }
  for (int j = 0; j < count; j++) {
    const hush_status s =
        hush__view_import_nonfinite(f->device, &f->views[images[j]],
                                    f->cls->info->images[images[j]].name, dst[j],
                                    nonfinite_policy(f), bad[j]);
    if (s) return s;
    log_replaced(f, bad[j], images[j]);
  }
  return HUSH_OK;
}

hush_status hush__filter_import_demodulated(struct hush_filter_t *f, int image,
                                            const hush_planar *albedo, hush_planar *dst) {
  size_t replaced = 0;
  const hush_status s =
      hush__import_demodulated(f->device, &f->views[image], f->cls->info->images[image].name, dst,
                               albedo, nonfinite_policy(f), &replaced, hush__filter_threads(f));
  if (!s) log_replaced(f, replaced, image);
  return s;
}

hush_status hush__filter_import_albedo_demodulated(struct hush_filter_t *f, int albedo_image,
                                                   int color_image, hush_planar *albedo,
                                                   hush_planar *dst) {
  size_t replaced = 0, replaced_albedo = 0;
  const hush_status s = hush__import_albedo_demodulated(
      f->device, &f->views[color_image], f->cls->info->images[color_image].name, dst,
      &f->views[albedo_image], f->cls->info->images[albedo_image].name, albedo,
      nonfinite_policy(f), &replaced, &replaced_albedo, hush__filter_threads(f));
  if (!s) {
    log_replaced(f, replaced_albedo, albedo_image);
    log_replaced(f, replaced, color_image);
  }
  return s;
}

hush_status hush__filter_scratch(struct hush_filter_t *f, hush_planar *img, int channels) {
  if (img->plane[0]) return HUSH_OK;
  return hush__planar_init(f->device, img, channels, f->width, f->height);
}

void hush__filter_timing_begin(struct hush_filter_t *f) {
  f->stage_count = 0;
  f->stage_start = hush__now_ms();
}

/* Adds ms to stage `name` (a new stage at the end). */
static void timing_add(struct hush_filter_t *f, const char *name, double ms) {
  for (uint32_t i = 0; i < f->stage_count; i++)
    if (f->stage_names[i] == name || strcmp(f->stage_names[i], name) == 0) {
      f->stage_ms[i] += ms;
      return;
    }
  if (f->stage_count < HUSH_MAX_STAGES) {
    f->stage_names[f->stage_count] = name;
    f->stage_ms[f->stage_count] = ms;
    f->stage_count++;
  }
}

void hush__filter_timing_stage(struct hush_filter_t *f, const char *name) {
  const double now = hush__now_ms();
  timing_add(f, name, now - f->stage_start);
  f->stage_start = now;
}

void hush__filter_timing_split(struct hush_filter_t *f, const char *const *names,
                               const double *weight, int n) {
  const double now = hush__now_ms(), span = now - f->stage_start;
  double total = 0.0;
  for (int k = 0; k < n; k++) total += weight[k];
  for (int k = 0; k < n; k++)
    timing_add(f, names[k], total > 0.0 ? span * weight[k] / total : span / n);
  f->stage_start = now;
}
