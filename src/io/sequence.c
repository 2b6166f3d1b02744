/*
 * sequence.c — frame sequences on disk: a directory with one EXR per frame
 * and cameras.json ("hush-cameras/1") describing resolution, frame count,
 * motion source and each frame's matrices and jitter. The reader checks
 * every field and names the file and the field in its messages; the writer
 * writes the JSON by hand (one frame per few lines, floats in their
 * shortest exact form) through a temporary file.
 */
#include "io/sequence.h"

#include "core/device.h"
#include "io/atomic_file.h"
#include "io/frame.h"

#include <cjson/cJSON.h>

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#define CAMERAS_FILE "cameras.json"
#define CAMERAS_FORMAT "hush-cameras/1"
#define CAMERAS_MAX_BYTES ((long long)256 << 20)
#define SEQUENCE_MAX_SIZE 65536
#define SEQUENCE_MAX_FRAMES (1 << 24)
#define FILE_NAME_MAX 255

/* A frame file is a plain name inside the sequence directory. Quotes,
 * backslashes and control characters are refused too, so that names need
 * no escaping in JSON. */
static int is_plain_file_name(const char *name) {
  const size_t len = strlen(name);
  if (len == 0 || len > FILE_NAME_MAX || strstr(name, "..")) return 0;
  for (const unsigned char *p = (const unsigned char *)name; *p; p++)
    if (*p == '/' || *p == '\\' || *p == '"' || *p < 0x20 || *p == 0x7f) return 0;
  return 1;
}

static hush_status join_path(hush_device device, const char *dir, const char *name, char *buf,
                             size_t size) {
  const int n = snprintf(buf, size, "%s/%s", dir, name);
  if (n < 0 || (size_t)n >= size)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "path '%s/%s' is too long", dir, name);
  return HUSH_OK;
}

static void identity(float m[16]) {
  for (int i = 0; i < 16; i++) m[i] = i % 5 == 0 ? 1.0f : 0.0f;
}

void hush__sequence_free(hush_sequence *seq) {
  if (!seq) return;
  if (seq->files)
    for (uint32_t i = 0; i < seq->frame_count; i++) free(seq->files[i]);
  free(seq->files);
  free(seq->cameras);
  free(seq->dir);
  memset(seq, 0, sizeof *seq);
}

/* Allocates dir, files (all NULL) and cameras (identity, no jitter). */
static hush_status sequence_alloc(hush_device device, hush_sequence *seq, const char *dir,
                                  uint32_t frame_count) {
  seq->dir = strdup(dir);
  seq->files = calloc(frame_count, sizeof *seq->files);
  seq->cameras = calloc(frame_count, sizeof *seq->cameras);
  if (!seq->dir || !seq->files || !seq->cameras)
    return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory for a sequence of %u frames",
                      frame_count);
  seq->frame_count = frame_count;
  for (uint32_t i = 0; i < frame_count; i++) {
    identity(seq->cameras[i].world_to_view);
    identity(seq->cameras[i].view_to_clip);
  }
  return HUSH_OK;
}

/* ------------------------------------------------------------------------ */
/* Reading cameras.json                                                     */
/* ------------------------------------------------------------------------ */

typedef struct json_source {
  hush_device device;
  const char *path; /* dir/cameras.json, for messages */
} json_source;

static hush_status field_error(const json_source *js, hush_status status, const char *field,
                               const char *fmt, ...) HUSH_PRINTF(4, 5);

static hush_status field_error(const json_source *js, hush_status status, const char *field,
                               const char *fmt, ...) {
  char detail[512];
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(detail, sizeof detail, fmt, ap);
  va_end(ap);
  return hush__fail(js->device, status, "%s: %s: %s", js->path, field, detail);
}

static const char *json_kind(const cJSON *item) {
  if (cJSON_IsString(item)) return "a string";
  if (cJSON_IsNumber(item)) return "a number";
  if (cJSON_IsArray(item)) return "an array";
  if (cJSON_IsObject(item)) return "an object";
  if (cJSON_IsBool(item)) return "a boolean";
  if (cJSON_IsNull(item)) return "null";
  return "invalid";
}

static hush_status get_integer(const json_source *js, const cJSON *obj, const char *key, double min,
                               double max, uint32_t *out) {
  const cJSON *item = cJSON_GetObjectItemCaseSensitive(obj, key);
  if (!item) return field_error(js, HUSH_ERROR_CORRUPT, key, "missing");
  if (!cJSON_IsNumber(item))
    return field_error(js, HUSH_ERROR_CORRUPT, key, "expected an integer, got %s", json_kind(item));
  const double v = item->valuedouble;
  if (!(v >= min && v <= max) || v != floor(v))
    return field_error(js, HUSH_ERROR_CORRUPT, key, "expected an integer in %.0f..%.0f, got %g",
                       min, max, v);
  *out = (uint32_t)v;
  return HUSH_OK;
}

static hush_status get_string(const json_source *js, const cJSON *obj, const char *key,
                              const char *field, const char **out) {
  const cJSON *item = cJSON_GetObjectItemCaseSensitive(obj, key);
  if (!item) return field_error(js, HUSH_ERROR_CORRUPT, field, "missing");
  if (!cJSON_IsString(item) || !item->valuestring)
    return field_error(js, HUSH_ERROR_CORRUPT, field, "expected a string, got %s", json_kind(item));
  *out = item->valuestring;
  return HUSH_OK;
}

/* An array of exactly n numbers that are finite as floats. */
static hush_status get_floats(const json_source *js, const cJSON *obj, const char *key,
                              const char *field, int n, float *out) {
  const cJSON *item = cJSON_GetObjectItemCaseSensitive(obj, key);
  if (!item) return field_error(js, HUSH_ERROR_CORRUPT, field, "missing");
  if (!cJSON_IsArray(item))
    return field_error(js, HUSH_ERROR_CORRUPT, field, "expected an array of %d numbers, got %s", n,
                       json_kind(item));
  const int size = cJSON_GetArraySize(item);
  if (size != n)
    return field_error(js, HUSH_ERROR_CORRUPT, field, "expected %d numbers, got %d", n, size);
  int i = 0;
  const cJSON *e;
  cJSON_ArrayForEach(e, item) {
    if (!cJSON_IsNumber(e))
      return field_error(js, HUSH_ERROR_CORRUPT, field, "element %d is %s, expected a number", i,
                         json_kind(e));
    const float v = (float)e->valuedouble;
    if (!isfinite(v))
      return field_error(js, HUSH_ERROR_CORRUPT, field, "element %d (%g) is not a finite float", i,
                         e->valuedouble);
    out[i++] = v;
  }
  return HUSH_OK;
}

static hush_status parse_frame(const json_source *js, hush_sequence *seq, const cJSON *frame,
                               uint32_t i) {
  char field[64];
  snprintf(field, sizeof field, "frames[%u]", i);
  if (!cJSON_IsObject(frame))
    return field_error(js, HUSH_ERROR_CORRUPT, field, "expected an object, got %s",
                       json_kind(frame));

  const char *file = NULL;
  snprintf(field, sizeof field, "frames[%u].file", i);
  hush_status status = get_string(js, frame, "file", field, &file);
  if (status != HUSH_OK) return status;
  if (!is_plain_file_name(file))
    return field_error(js, HUSH_ERROR_CORRUPT, field,
                       "'%.80s' is not a plain file name (no '/', '..', quotes or control "
                       "characters)",
                       file);
  char path[HUSH_PATH_MAX];
  status = join_path(js->device, seq->dir, file, path, sizeof path);
  if (status != HUSH_OK) return status;
  struct stat st;
  if (stat(path, &st) != 0)
    return field_error(js, HUSH_ERROR_IO, field, "cannot open '%s': %s", path, strerror(errno));
  if (!S_ISREG(st.st_mode))
    return field_error(js, HUSH_ERROR_IO, field, "'%s' is not a regular file", path);
  seq->files[i] = strdup(file);
  if (!seq->files[i]) return hush__fail(js->device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory");

  hush_camera *cam = &seq->cameras[i];
  snprintf(field, sizeof field, "frames[%u].world_to_view", i);
  status = get_floats(js, frame, "world_to_view", field, 16, cam->world_to_view);
  if (status != HUSH_OK) return status;
  snprintf(field, sizeof field, "frames[%u].view_to_clip", i);
  status = get_floats(js, frame, "view_to_clip", field, 16, cam->view_to_clip);
  if (status != HUSH_OK) return status;
  snprintf(field, sizeof field, "frames[%u].jitter", i);
  return get_floats(js, frame, "jitter", field, 2, cam->jitter);
}

static hush_status parse_cameras(const json_source *js, const cJSON *root, const char *dir,
                                 hush_sequence *seq) {
  if (!cJSON_IsObject(root))
    return hush__fail(js->device, HUSH_ERROR_CORRUPT, "%s: expected a JSON object, got %s",
                      js->path, json_kind(root));
  const char *format = NULL;
  hush_status status = get_string(js, root, "format", "format", &format);
  if (status != HUSH_OK) return status;
  if (strcmp(format, CAMERAS_FORMAT) != 0)
    return field_error(js, HUSH_ERROR_UNSUPPORTED, "format", "'%.80s' is not '%s'", format,
                       CAMERAS_FORMAT);
  uint32_t width = 0, height = 0, count = 0;
  status = get_integer(js, root, "width", 1, SEQUENCE_MAX_SIZE, &width);
  if (status == HUSH_OK) status = get_integer(js, root, "height", 1, SEQUENCE_MAX_SIZE, &height);
  if (status == HUSH_OK)
    status = get_integer(js, root, "frame_count", 1, SEQUENCE_MAX_FRAMES, &count);
  if (status != HUSH_OK) return status;

  const char *motion = NULL;
  status = get_string(js, root, "motion", "motion", &motion);
  if (status != HUSH_OK) return status;
  if (strcmp(motion, "camera") != 0 && strcmp(motion, "vectors") != 0)
    return field_error(js, HUSH_ERROR_CORRUPT, "motion",
                       "'%.80s' is neither 'camera' nor 'vectors'", motion);

  const cJSON *frames = cJSON_GetObjectItemCaseSensitive(root, "frames");
  if (!frames) return field_error(js, HUSH_ERROR_CORRUPT, "frames", "missing");
  if (!cJSON_IsArray(frames))
    return field_error(js, HUSH_ERROR_CORRUPT, "frames", "expected an array, got %s",
                       json_kind(frames));
  const int entries = cJSON_GetArraySize(frames);
  if (entries < 0 || (uint32_t)entries != count)
    return field_error(js, HUSH_ERROR_CORRUPT, "frame_count", "is %u but frames has %d entries",
                       count, entries);

  status = sequence_alloc(js->device, seq, dir, count);
  if (status != HUSH_OK) return status;
  seq->width = width;
  seq->height = height;
  seq->motion = strcmp(motion, "vectors") == 0 ? HUSH_MOTION_VECTORS : HUSH_MOTION_CAMERA;
  uint32_t i = 0;
  const cJSON *frame;
  cJSON_ArrayForEach(frame, frames) {
    status = parse_frame(js, seq, frame, i++);
    if (status != HUSH_OK) return status;
  }
  return HUSH_OK;
}

/* The whole file as a string; *len excludes the terminating NUL. */
static hush_status read_text(hush_device device, const char *path, char **text, size_t *len) {
  *text = NULL;
  FILE *f = fopen(path, "rb");
  if (!f) return hush__fail(device, HUSH_ERROR_IO, "cannot open '%s': %s", path, strerror(errno));
  struct stat st;
  if (fstat(fileno(f), &st) != 0 || !S_ISREG(st.st_mode)) {
    fclose(f);
    return hush__fail(device, HUSH_ERROR_IO, "cannot read '%s': not a regular file", path);
  }
  if ((long long)st.st_size > CAMERAS_MAX_BYTES) {
    fclose(f);
    return hush__fail(device, HUSH_ERROR_UNSUPPORTED, "'%s' is larger than %lld bytes", path,
                      CAMERAS_MAX_BYTES);
  }
  const size_t size = (size_t)st.st_size;
  char *buf = malloc(size + 1);
  if (!buf) {
    fclose(f);
    return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory reading '%s'", path);
  }
  const size_t got = fread(buf, 1, size, f);
  const int failed = ferror(f);
  const int err = errno;
  fclose(f);
  if (failed || got != size) {
    free(buf);
    return hush__fail(device, HUSH_ERROR_IO, "cannot read '%s': %s", path,
                      failed ? strerror(err) : "file changed while reading");
  }
  buf[size] = '\0';
  *text = buf;
  *len = size;
  return HUSH_OK;
}

hush_status hush__sequence_read(hush_device device, const char *dir, hush_sequence *seq) {
  if (!device)
    return hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT, "hush__sequence_read: device is NULL");
  if (!dir || !*dir || !seq)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "hush__sequence_read: bad argument");
  memset(seq, 0, sizeof *seq);
  char path[HUSH_PATH_MAX];
  hush_status status = join_path(device, dir, CAMERAS_FILE, path, sizeof path);
  if (status != HUSH_OK) return status;
  char *text = NULL;
  size_t len = 0;
  status = read_text(device, path, &text, &len);
  if (status != HUSH_OK) return status;

  /* The length includes the terminating NUL, which cJSON wants to see
   * right after the value (and its trailing whitespace). */
  const char *end = NULL;
  cJSON *root = cJSON_ParseWithLengthOpts(text, len + 1, &end, 1);
  if (!root) {
    const size_t at = end && end >= text && end <= text + len ? (size_t)(end - text) : len;
    free(text);
    return hush__fail(device, HUSH_ERROR_CORRUPT, "%s: not valid JSON (error at byte %zu)", path,
                      at);
  }
  const json_source js = {device, path};
  status = parse_cameras(&js, root, dir, seq);
  cJSON_Delete(root);
  free(text);
  if (status != HUSH_OK) hush__sequence_free(seq);
  return status;
}

/* ------------------------------------------------------------------------ */
/* Writing                                                                  */
/* ------------------------------------------------------------------------ */

hush_status hush__sequence_init(hush_device device, hush_sequence *seq, const char *dir,
                                uint32_t width, uint32_t height, uint32_t frame_count) {
  if (!device)
    return hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT, "hush__sequence_init: device is NULL");
  if (!seq || !dir || !*dir)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "hush__sequence_init: bad argument");
  memset(seq, 0, sizeof *seq);
  if (width < 1 || height < 1 || width > SEQUENCE_MAX_SIZE || height > SEQUENCE_MAX_SIZE)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "sequence size %ux%u is outside 1..%d",
                      width, height, SEQUENCE_MAX_SIZE);
  if (frame_count < 1 || frame_count > SEQUENCE_MAX_FRAMES)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "sequence of %u frames (1..%d)",
                      frame_count, SEQUENCE_MAX_FRAMES);
  hush_status status = sequence_alloc(device, seq, dir, frame_count);
  for (uint32_t i = 0; status == HUSH_OK && i < frame_count; i++) {
    char name[32];
    snprintf(name, sizeof name, "frame_%04u.exr", i);
    seq->files[i] = strdup(name);
    if (!seq->files[i]) status = hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory");
  }
  if (status != HUSH_OK) {
    hush__sequence_free(seq);
    return status;
  }
  seq->width = width;
  seq->height = height;
  seq->motion = HUSH_MOTION_CAMERA;
  return HUSH_OK;
}

hush_status hush__sequence_frame_path(hush_device device, const hush_sequence *seq, uint32_t i,
                                      char *buf, size_t size) {
  if (!seq || !buf || size == 0 || i >= seq->frame_count || !seq->files || !seq->files[i])
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "no frame %u in the sequence", i);
  return join_path(device, seq->dir, seq->files[i], buf, size);
}

/* The shortest decimal that reads back as exactly v. */
static void format_float(char buf[32], float v) {
  for (int digits = 6; digits <= 9; digits++) {
    snprintf(buf, 32, "%.*g", digits, (double)v);
    if ((float)strtod(buf, NULL) == v) return;
  }
}

static hush_status check_floats(hush_device device, const float *v, int n, uint32_t frame,
                                const char *field) {
  for (int k = 0; k < n; k++)
    if (!isfinite(v[k]))
      return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                        "cannot write cameras: frames[%u].%s[%d] is not finite", frame, field, k);
  return HUSH_OK;
}

static hush_status check_for_writing(hush_device device, const hush_sequence *seq) {
  if (!seq->dir || !seq->files || !seq->cameras || seq->frame_count < 1 || seq->width < 1 ||
      seq->height < 1 || seq->width > SEQUENCE_MAX_SIZE || seq->height > SEQUENCE_MAX_SIZE)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                      "cannot write cameras: incomplete sequence");
  for (uint32_t i = 0; i < seq->frame_count; i++) {
    if (!seq->files[i] || !is_plain_file_name(seq->files[i]))
      return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                        "cannot write cameras: frames[%u].file is not a plain file name", i);
    const hush_camera *cam = &seq->cameras[i];
    hush_status status = check_floats(device, cam->world_to_view, 16, i, "world_to_view");
    if (status == HUSH_OK) status = check_floats(device, cam->view_to_clip, 16, i, "view_to_clip");
    if (status == HUSH_OK) status = check_floats(device, cam->jitter, 2, i, "jitter");
    if (status != HUSH_OK) return status;
  }
  return HUSH_OK;
}

static void write_floats(FILE *f, const float *v, int n) {
  char num[32];
  fputc('[', f);
  for (int k = 0; k < n; k++) {
    format_float(num, v[k]);
    fprintf(f, "%s%s", k ? ", " : "", num);
  }
  fputc(']', f);
}

hush_status hush__sequence_write_cameras(hush_device device, const hush_sequence *seq) {
  if (!device)
    return hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT,
                      "hush__sequence_write_cameras: device is NULL");
  if (!seq)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                      "hush__sequence_write_cameras: seq is NULL");
  hush_status status = check_for_writing(device, seq);
  if (status != HUSH_OK) return status;
  char path[HUSH_PATH_MAX], tmp[HUSH_PATH_MAX];
  status = join_path(device, seq->dir, CAMERAS_FILE, path, sizeof path);
  if (status != HUSH_OK) return status;
  FILE *f = hush__atomic_open(device, path, tmp);
  if (!f) return HUSH_ERROR_IO;

  fprintf(f, "{\n  \"format\": \"%s\",\n  \"width\": %u,\n  \"height\": %u,\n", CAMERAS_FORMAT,
          seq->width, seq->height);
  fprintf(f, "  \"frame_count\": %u,\n  \"motion\": \"%s\",\n  \"frames\": [\n", seq->frame_count,
          seq->motion == HUSH_MOTION_VECTORS ? "vectors" : "camera");
  for (uint32_t i = 0; i < seq->frame_count; i++) {
    const hush_camera *cam = &seq->cameras[i];
    fprintf(f, "    {\"file\": \"%s\",\n     \"world_to_view\": ", seq->files[i]);
    write_floats(f, cam->world_to_view, 16);
    fputs(",\n     \"view_to_clip\": ", f);
    write_floats(f, cam->view_to_clip, 16);
    fputs(",\n     \"jitter\": ", f);
    write_floats(f, cam->jitter, 2);
    fputs(i + 1 < seq->frame_count ? "},\n" : "}\n", f);
  }
  fputs("  ]\n}\n", f);
  return hush__atomic_commit(device, f, tmp, path);
}

/* ------------------------------------------------------------------------ */
/* Frames                                                                   */
/* ------------------------------------------------------------------------ */

void hush__sequence_frame_info(const hush_sequence *seq, uint32_t i, hush_frame_info *info) {
  hush_frame_info_init(info);
  if (!seq || !seq->cameras || i >= seq->frame_count) return;
  const hush_camera *cur = &seq->cameras[i];
  const hush_camera *prev = i > 0 ? &seq->cameras[i - 1] : cur;
  info->frame_index = i;
  memcpy(info->world_to_view, cur->world_to_view, sizeof info->world_to_view);
  memcpy(info->view_to_clip, cur->view_to_clip, sizeof info->view_to_clip);
  memcpy(info->prev_world_to_view, prev->world_to_view, sizeof info->prev_world_to_view);
  memcpy(info->prev_view_to_clip, prev->view_to_clip, sizeof info->prev_view_to_clip);
  memcpy(info->jitter, cur->jitter, sizeof info->jitter);
  memcpy(info->prev_jitter, prev->jitter, sizeof info->prev_jitter);
  info->motion = seq->motion;
  info->history = i == 0 ? HUSH_HISTORY_RESET : HUSH_HISTORY_CONTINUE;
}

hush_status hush__sequence_read_frame(hush_device device, const hush_sequence *seq, uint32_t i,
                                      hush_frame *frame) {
  if (!device)
    return hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT,
                      "hush__sequence_read_frame: device is NULL");
  if (!frame)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                      "hush__sequence_read_frame: frame is NULL");
  *frame = NULL;
  char path[HUSH_PATH_MAX];
  hush_status status = hush__sequence_frame_path(device, seq, i, path, sizeof path);
  if (status != HUSH_OK) return status;
  hush_frame f = NULL;
  status = hush_frame_read_exr(device, path, &f);
  if (status != HUSH_OK) return status;
  if (f->width != seq->width || f->height != seq->height) {
    const uint32_t w = f->width, h = f->height;
    hush_frame_release(f);
    return hush__fail(device, HUSH_ERROR_CORRUPT, "%s is %ux%u, the sequence is %ux%u", path, w, h,
                      seq->width, seq->height);
  }
  *frame = f;
  return HUSH_OK;
}
