/*
 * report.c — REPORT_DIR/report.html from what `hush eval` wrote (report.h).
 *
 * Steps: read eval.json, metrics.csv, status.csv, timings.csv and
 * summary.md; for each frame shown side by side, load every column's
 * "color" layer (noisy, each filter, reference), apply one display
 * transform to all, pick inset regions where the noisy frame is furthest
 * from the reference, and write the pictures, insets and error heat maps to
 * img/; draw the per-frame metric plots as inline SVG; optionally encode a
 * side-by-side video with ffmpeg; then write the page through a temporary
 * file. The page has no scripts and no external resources.
 */
#include "eval/report.h"

#include "core/device.h"
#include "eval/svg.h"
#include "io/atomic_file.h"
#include "io/frame.h"
#include "io/png.h"
#include "io/tonemap.h"

#include <cjson/cJSON.h>
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <spawn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

extern char **environ;

#define NAME_MAX_LEN 64
#define MAX_SHOWN 16
#define CROP_COUNT 2
#define VIDEO_GAP 4 /* black pixels between the columns of a video strip */

/* ------------------------------------------------------------------------ */
/* Data read from the report directory                                      */
/* ------------------------------------------------------------------------ */

enum {
  M_RMSE,
  M_REL_MSE,
  M_PSNR,
  M_SSIM,
  M_TEMPORAL,
  M_REF_TEMPORAL,
  M_MS,
  METRIC_COUNT
};
static const char *const metric_columns[METRIC_COUNT] = {
    "rmse", "rel_mse", "psnr", "ssim", "temporal_error", "ref_temporal_error", "ms"};

typedef struct metric_row {
  uint32_t frame;
  double v[METRIC_COUNT];
} metric_row;

typedef struct report_filter {
  char name[NAME_MAX_LEN];
  const char *color; /* of its plot lines */
  int failed;
  char *message;     /* status.csv's message when failed */
  metric_row *rows;
  uint32_t row_count, row_cap;
} report_filter;

typedef struct csv_row {
  char **field;
  uint32_t count;
  uint32_t line;
} csv_row;

typedef struct csv_file {
  char path[HUSH_PATH_MAX];
  char *text;
  csv_row *rows; /* rows[0] is the header */
  uint32_t row_count;
} csv_file;

typedef struct report {
  hush_device device;
  const char *dir;
  hush_report_options opt;
  char seq[HUSH_PATH_MAX], ref[HUSH_PATH_MAX];
  uint32_t first, last; /* frames [first, last) */
  uint32_t width, height;
  hush_strbuf command;
  report_filter *filters; /* filters[0] is "noisy" */
  uint32_t filter_count;
  csv_file timings;
  char *summary;    /* summary.md, NULL when missing */
  int have_status;  /* status.csv was there */
  int have_timings; /* timings.csv was there */
  uint32_t shown[MAX_SHOWN];
  uint32_t shown_count;
  hush_strbuf html;
} report;

/* Tableau 10 without its grey, which "noisy" gets. */
static const char *const palette[] = {"#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd",
                                      "#8c564b", "#e377c2", "#bcbd22", "#17becf"};
#define NOISY_COLOR "#8a8a8a"
static const uint8_t crop_rgb[CROP_COUNT][3] = {{255, 140, 0}, {0, 200, 255}};
static const char *const crop_css[CROP_COUNT] = {"#ff8c00", "#00c8ff"};

/* ------------------------------------------------------------------------ */
/* Small helpers                                                            */
/* ------------------------------------------------------------------------ */

static hush_status path_printf(hush_device device, char out[HUSH_PATH_MAX], const char *fmt, ...)
    HUSH_PRINTF(3, 4);

static hush_status path_printf(hush_device device, char out[HUSH_PATH_MAX], const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  const int n = vsnprintf(out, HUSH_PATH_MAX, fmt, ap);
  va_end(ap);
  if (n < 0 || n >= HUSH_PATH_MAX)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "report: a path is too long (%s)", out);
  return HUSH_OK;
}

static int file_exists(const char *path) {
  struct stat st;
  return stat(path, &st) == 0 && S_ISREG(st.st_mode);
}

static int dir_exists(const char *path) {
  struct stat st;
  return stat(path, &st) == 0 && S_ISDIR(st.st_mode);
}

/* Reads a whole file. A missing file with `missing` not NULL is not an
 * error: *missing is set and *text is NULL. */
static hush_status read_text(hush_device device, const char *path, char **text, int *missing) {
  *text = NULL;
  if (missing) *missing = 0;
  FILE *f = fopen(path, "rb");
  if (!f) {
    if (errno == ENOENT && missing) {
      *missing = 1;
      return HUSH_OK;
    }
    return hush__fail(device, errno == ENOENT ? HUSH_ERROR_NOT_FOUND : HUSH_ERROR_IO,
                      "cannot open '%s': %s", path, strerror(errno));
  }
  hush_strbuf b = {0};
  char chunk[8192];
  size_t n;
  while ((n = fread(chunk, 1, sizeof chunk - 1, f)) > 0) {
    chunk[n] = '\0';
    if (memchr(chunk, '\0', n)) {
      fclose(f);
      hush__strbuf_free(&b);
      return hush__fail(device, HUSH_ERROR_CORRUPT, "'%s' is not a text file", path);
    }
    hush__strbuf_append(&b, chunk);
  }
  const int failed = ferror(f);
  fclose(f);
  if (failed || b.failed) {
    hush__strbuf_free(&b);
    return hush__fail(device, failed ? HUSH_ERROR_IO : HUSH_ERROR_OUT_OF_MEMORY,
                      "cannot read '%s'", path);
  }
  if (!b.data) hush__strbuf_append(&b, ""); /* an empty file is "" */
  if (b.failed) return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "cannot read '%s'", path);
  *text = b.data;
  return HUSH_OK;
}

static hush_status write_text(hush_device device, const char *path, const hush_strbuf *b) {
  if (b->failed) return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory writing '%s'", path);
  char tmp[HUSH_PATH_MAX];
  FILE *f = hush__atomic_open(device, path, tmp);
  if (!f) return HUSH_ERROR_IO;
  if (b->len && fwrite(b->data, 1, b->len, f) != b->len) {
    const int err = errno;
    hush__atomic_abort(f, tmp);
    return hush__fail(device, HUSH_ERROR_IO, "cannot write '%s': %s", path, strerror(err));
  }
  return hush__atomic_commit(device, f, tmp, path);
}

/* A number, or NaN for an empty field; "nan", "inf" as strtod reads them. */
static int parse_number(const char *s, double *v) {
  while (*s == ' ') s++;
  if (!*s) {
    *v = NAN;
    return 1;
  }
  char *end;
  *v = strtod(s, &end);
  while (*end == ' ') end++;
  return end != s && *end == '\0';
}

static int parse_frame(const char *s, uint32_t *v) {
  if (*s < '0' || *s > '9') return 0;
  char *end;
  errno = 0;
  const unsigned long n = strtoul(s, &end, 10);
  if (errno || *end || n > UINT32_MAX) return 0;
  *v = (uint32_t)n;
  return 1;
}

/* Filter names become directory and file names; keep them plain. */
static int plain_name(const char *s) {
  if (!*s || strlen(s) >= NAME_MAX_LEN || strcmp(s, ".") == 0 || strcmp(s, "..") == 0) return 0;
  for (const char *p = s; *p; p++)
    if (!((*p >= 'a' && *p <= 'z') || (*p >= 'A' && *p <= 'Z') || (*p >= '0' && *p <= '9') ||
          *p == '_' || *p == '-' || *p == '.' || *p == '+'))
      return 0;
  return 1;
}

/* ------------------------------------------------------------------------ */
/* CSV                                                                      */
/* ------------------------------------------------------------------------ */

static void csv_free(csv_file *csv) {
  for (uint32_t i = 0; i < csv->row_count; i++) free(csv->rows[i].field);
  free(csv->rows);
  free(csv->text);
  csv->rows = NULL;
  csv->text = NULL;
  csv->row_count = 0;
}

static int csv_push_field(csv_row *row, char *field) {
  char **f = realloc(row->field, (row->count + 1) * sizeof *f);
  if (!f) return 0;
  f[row->count++] = field;
  row->field = f;
  return 1;
}

static int csv_push_row(csv_file *csv, const csv_row *row) {
  csv_row *rows = realloc(csv->rows, (csv->row_count + 1) * sizeof *rows);
  if (!rows) return 0;
  rows[csv->row_count++] = *row;
  csv->rows = rows;
  return 1;
}

/* Splits csv->text in place into rows of fields (RFC 4180: commas, fields
 * in double quotes may hold commas, newlines and doubled quotes). Blank
 * lines are skipped. */
static hush_status csv_split(hush_device device, csv_file *csv) {
  char *p = csv->text;
  uint32_t line = 1;
  while (*p) {
    if (*p == '\n' || (*p == '\r' && p[1] == '\n')) {
      p += *p == '\r' ? 2 : 1;
      line++;
      continue;
    }
    csv_row row = {NULL, 0, line};
    for (;;) {
      char *field = p, *w = p;
      if (*p == '"') {
        p++;
        for (;;) {
          if (!*p) {
            free(row.field);
            return hush__fail(device, HUSH_ERROR_CORRUPT, "'%s' line %u: a quote is never closed",
                              csv->path, row.line);
          }
          if (*p == '"' && p[1] == '"') {
            *w++ = '"';
            p += 2;
          } else if (*p == '"') {
            p++;
            break;
          } else {
            if (*p == '\n') line++;
            *w++ = *p++;
          }
        }
        if (*p && *p != ',' && *p != '\n' && *p != '\r') {
          free(row.field);
          return hush__fail(device, HUSH_ERROR_CORRUPT, "'%s' line %u: text after a closing quote",
                            csv->path, line);
        }
      } else {
        while (*p && *p != ',' && *p != '\n' && *p != '\r') *w++ = *p++;
      }
      const char sep = *p; /* read before the terminator may overwrite it */
      *w = '\0';
      if (!csv_push_field(&row, field)) {
        free(row.field);
        return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory reading '%s'", csv->path);
      }
      if (sep == ',') {
        p++;
        continue;
      }
      /* the terminator may have replaced sep: step over it by what it was */
      if (sep == '\r') {
        p++;
        if (*p == '\n') p++;
        line++;
      } else if (sep == '\n') {
        p++;
        line++;
      }
      break;
    }
    if (!csv_push_row(csv, &row)) {
      free(row.field);
      return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory reading '%s'", csv->path);
    }
  }
  return HUSH_OK;
}

/* Reads dir/name into csv: header and rows, every row as wide as the
 * header. *missing (if not NULL) says the file was not there. */
static hush_status csv_read(hush_device device, const char *dir, const char *name, csv_file *csv,
                            int *missing) {
  memset(csv, 0, sizeof *csv);
  hush_status status = path_printf(device, csv->path, "%s/%s", dir, name);
  if (status != HUSH_OK) return status;
  status = read_text(device, csv->path, &csv->text, missing);
  if (status != HUSH_OK || !csv->text) return status;
  status = csv_split(device, csv);
  if (status != HUSH_OK) return status;
  if (csv->row_count == 0)
    return hush__fail(device, HUSH_ERROR_CORRUPT, "'%s' is empty: no header line", csv->path);
  const csv_row *header = &csv->rows[0];
  for (uint32_t i = 1; i < csv->row_count; i++)
    if (csv->rows[i].count != header->count)
      return hush__fail(device, HUSH_ERROR_CORRUPT, "'%s' line %u: %u fields, the header has %u",
                        csv->path, csv->rows[i].line, csv->rows[i].count, header->count);
  return HUSH_OK;
}

/* Index of a header column; reports an error naming the file when absent. */
static hush_status csv_column(hush_device device, const csv_file *csv, const char *name,
                              uint32_t *index) {
  const csv_row *header = &csv->rows[0];
  for (uint32_t i = 0; i < header->count; i++) {
    if (strcmp(header->field[i], name) == 0) {
      *index = i;
      return HUSH_OK;
    }
  }
  return hush__fail(device, HUSH_ERROR_CORRUPT, "'%s' line %u: the header has no column '%s'",
                    csv->path, header->line, name);
}

static hush_status csv_number(hush_device device, const csv_file *csv, const csv_row *row,
                              uint32_t column, double *v) {
  if (parse_number(row->field[column], v)) return HUSH_OK;
  return hush__fail(device, HUSH_ERROR_CORRUPT, "'%s' line %u: %s '%s' is not a number", csv->path,
                    row->line, csv->rows[0].field[column], row->field[column]);
}

/* ------------------------------------------------------------------------ */
/* Filters                                                                  */
/* ------------------------------------------------------------------------ */

static void filters_free(report *r) {
  for (uint32_t i = 0; i < r->filter_count; i++) {
    free(r->filters[i].rows);
    free(r->filters[i].message);
  }
  free(r->filters);
}

/* The filter named `name`, added at the end when new. `where` names the
 * file and line for an error about the name. */
static hush_status filter_find_or_add(report *r, const char *name, const char *where,
                                      report_filter **out) {
  for (uint32_t i = 0; i < r->filter_count; i++) {
    if (strcmp(r->filters[i].name, name) == 0) {
      *out = &r->filters[i];
      return HUSH_OK;
    }
  }
  if (!plain_name(name) || strcmp(name, "reference") == 0)
    return hush__fail(r->device, HUSH_ERROR_CORRUPT,
                      "%s: '%s' cannot be a filter name (letters, digits, '_', '-', '.', '+'; not "
                      "\"reference\")",
                      where, name);
  report_filter *f = realloc(r->filters, (r->filter_count + 1) * sizeof *f);
  if (!f) return hush__fail(r->device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory");
  r->filters = f;
  f = &r->filters[r->filter_count];
  memset(f, 0, sizeof *f);
  snprintf(f->name, sizeof f->name, "%s", name);
  f->color = r->filter_count == 0 ? NOISY_COLOR
                                  : palette[(r->filter_count - 1) % (sizeof palette / sizeof *palette)];
  r->filter_count++;
  *out = f;
  return HUSH_OK;
}

static hush_status filter_add_row(report *r, report_filter *f, const metric_row *row) {
  if (f->row_count == f->row_cap) {
    const uint32_t cap = f->row_cap ? f->row_cap * 2 : 64;
    metric_row *rows = realloc(f->rows, cap * sizeof *rows);
    if (!rows) return hush__fail(r->device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory");
    f->rows = rows;
    f->row_cap = cap;
  }
  f->rows[f->row_count++] = *row;
  return HUSH_OK;
}

static const metric_row *filter_row_at(const report_filter *f, uint32_t frame) {
  for (uint32_t i = 0; i < f->row_count; i++)
    if (f->rows[i].frame == frame) return &f->rows[i];
  return NULL;
}

/* ------------------------------------------------------------------------ */
/* Reading the files                                                        */
/* ------------------------------------------------------------------------ */

static hush_status json_string(report *r, const char *path, const cJSON *root, const char *key,
                               char *out, size_t size) {
  const cJSON *item = cJSON_GetObjectItemCaseSensitive(root, key);
  if (!cJSON_IsString(item))
    return hush__fail(r->device, HUSH_ERROR_CORRUPT, "'%s': \"%s\" is missing or not a string",
                      path, key);
  snprintf(out, size, "%s", item->valuestring);
  return HUSH_OK;
}

static hush_status json_uint(report *r, const char *path, const cJSON *item, const char *what,
                             uint32_t *out) {
  if (!cJSON_IsNumber(item) || item->valuedouble < 0 || item->valuedouble > UINT32_MAX ||
      item->valuedouble != floor(item->valuedouble))
    return hush__fail(r->device, HUSH_ERROR_CORRUPT,
                      "'%s': %s is missing or not a whole number >= 0", path, what);
  *out = (uint32_t)item->valuedouble;
  return HUSH_OK;
}

/* Appends the arguments of "command", quoting those a shell would split. */
static void json_command(report *r, const cJSON *root) {
  const cJSON *cmd = cJSON_GetObjectItemCaseSensitive(root, "command");
  const cJSON *arg;
  cJSON_ArrayForEach(arg, cmd) {
    if (!cJSON_IsString(arg)) continue;
    if (r->command.len) hush__strbuf_append(&r->command, " ");
    const char *s = arg->valuestring;
    if (*s && !strpbrk(s, " \t\"'$\\"))
      hush__strbuf_append(&r->command, s);
    else
      hush__strbuf_printf(&r->command, "'%s'", s);
  }
}

static hush_status json_parse(report *r, const char *path, const cJSON *root) {
  hush_status status = json_string(r, path, root, "seq", r->seq, sizeof r->seq);
  if (status == HUSH_OK) status = json_string(r, path, root, "ref", r->ref, sizeof r->ref);
  if (status != HUSH_OK) return status;
  const cJSON *frames = cJSON_GetObjectItemCaseSensitive(root, "frames");
  if (!cJSON_IsArray(frames) || cJSON_GetArraySize(frames) != 2)
    return hush__fail(r->device, HUSH_ERROR_CORRUPT, "'%s': \"frames\" must be [first, last]",
                      path);
  status = json_uint(r, path, cJSON_GetArrayItem(frames, 0), "frames[0]", &r->first);
  if (status == HUSH_OK) status = json_uint(r, path, cJSON_GetArrayItem(frames, 1), "frames[1]", &r->last);
  if (status == HUSH_OK)
    status = json_uint(r, path, cJSON_GetObjectItemCaseSensitive(root, "width"), "\"width\"", &r->width);
  if (status == HUSH_OK)
    status = json_uint(r, path, cJSON_GetObjectItemCaseSensitive(root, "height"), "\"height\"", &r->height);
  if (status != HUSH_OK) return status;
  if (r->last <= r->first)
    return hush__fail(r->device, HUSH_ERROR_CORRUPT, "'%s': \"frames\" [%u, %u) is empty", path,
                      r->first, r->last);
  if (r->width == 0 || r->height == 0 || r->width > 16384 || r->height > 16384)
    return hush__fail(r->device, HUSH_ERROR_CORRUPT, "'%s': the size %ux%u is not 1..16384",
                      path, r->width, r->height);

  const cJSON *filters = cJSON_GetObjectItemCaseSensitive(root, "filters");
  if (!cJSON_IsArray(filters))
    return hush__fail(r->device, HUSH_ERROR_CORRUPT, "'%s': \"filters\" is missing or not an array",
                      path);
  const cJSON *item;
  cJSON_ArrayForEach(item, filters) {
    if (!cJSON_IsString(item))
      return hush__fail(r->device, HUSH_ERROR_CORRUPT, "'%s': \"filters\" holds a non-string",
                        path);
    report_filter *f;
    status = filter_find_or_add(r, item->valuestring, path, &f);
    if (status != HUSH_OK) return status;
  }
  json_command(r, root);
  return HUSH_OK;
}

static hush_status read_eval_json(report *r) {
  char path[HUSH_PATH_MAX];
  hush_status status = path_printf(r->device, path, "%s/eval.json", r->dir);
  char *text = NULL;
  if (status == HUSH_OK) status = read_text(r->device, path, &text, NULL);
  if (status != HUSH_OK) return status;
  cJSON *root = cJSON_Parse(text);
  free(text);
  if (!cJSON_IsObject(root)) {
    cJSON_Delete(root);
    return hush__fail(r->device, HUSH_ERROR_CORRUPT, "'%s' is not a JSON object", path);
  }
  status = json_parse(r, path, root);
  cJSON_Delete(root);
  return status;
}

static hush_status read_metrics(report *r) {
  csv_file csv;
  hush_status status = csv_read(r->device, r->dir, "metrics.csv", &csv, NULL);
  uint32_t col_filter = 0, col_frame = 0, col[METRIC_COUNT] = {0};
  if (status == HUSH_OK) status = csv_column(r->device, &csv, "filter", &col_filter);
  if (status == HUSH_OK) status = csv_column(r->device, &csv, "frame", &col_frame);
  for (int m = 0; m < METRIC_COUNT && status == HUSH_OK; m++)
    status = csv_column(r->device, &csv, metric_columns[m], &col[m]);
  for (uint32_t i = 1; i < csv.row_count && status == HUSH_OK; i++) {
    const csv_row *row = &csv.rows[i];
    metric_row m = {0};
    if (!parse_frame(row->field[col_frame], &m.frame)) {
      status = hush__fail(r->device, HUSH_ERROR_CORRUPT, "'%s' line %u: frame '%s' is not a frame number",
                          csv.path, row->line, row->field[col_frame]);
      break;
    }
    for (int k = 0; k < METRIC_COUNT && status == HUSH_OK; k++)
      status = csv_number(r->device, &csv, row, col[k], &m.v[k]);
    char where[HUSH_PATH_MAX + 32];
    snprintf(where, sizeof where, "'%s' line %u", csv.path, row->line);
    report_filter *f = NULL;
    if (status == HUSH_OK) status = filter_find_or_add(r, row->field[col_filter], where, &f);
    if (status == HUSH_OK) status = filter_add_row(r, f, &m);
  }
  csv_free(&csv);
  return status;
}

static hush_status read_status(report *r) {
  csv_file csv;
  int missing = 0;
  hush_status status = csv_read(r->device, r->dir, "status.csv", &csv, &missing);
  r->have_status = status == HUSH_OK && !missing;
  uint32_t col_filter = 0, col_status = 0, col_message = 0;
  if (r->have_status) status = csv_column(r->device, &csv, "filter", &col_filter);
  if (r->have_status && status == HUSH_OK) status = csv_column(r->device, &csv, "status", &col_status);
  if (r->have_status && status == HUSH_OK) status = csv_column(r->device, &csv, "message", &col_message);
  for (uint32_t i = 1; r->have_status && i < csv.row_count && status == HUSH_OK; i++) {
    const csv_row *row = &csv.rows[i];
    const char *st = row->field[col_status];
    if (strcmp(st, "ok") != 0 && strcmp(st, "failed") != 0) {
      status = hush__fail(r->device, HUSH_ERROR_CORRUPT,
                          "'%s' line %u: status '%s' is neither \"ok\" nor \"failed\"", csv.path,
                          row->line, st);
      break;
    }
    char where[HUSH_PATH_MAX + 32];
    snprintf(where, sizeof where, "'%s' line %u", csv.path, row->line);
    report_filter *f;
    status = filter_find_or_add(r, row->field[col_filter], where, &f);
    if (status != HUSH_OK || strcmp(st, "failed") != 0) continue;
    f->failed = 1;
    free(f->message);
    f->message = strdup(row->field[col_message]);
    if (!f->message) status = hush__fail(r->device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory");
  }
  csv_free(&csv);
  return status;
}

/* timings.csv stays in r->timings; its numbers are checked here. */
static hush_status read_timings(report *r) {
  int missing = 0;
  hush_status status = csv_read(r->device, r->dir, "timings.csv", &r->timings, &missing);
  if (status != HUSH_OK || missing) return status;
  r->have_timings = 1;
  static const char *const columns[] = {"filter", "stage", "median_ms", "p5_ms", "p95_ms"};
  for (int c = 0; c < 5; c++) {
    uint32_t index = 0;
    status = csv_column(r->device, &r->timings, columns[c], &index);
    if (status != HUSH_OK) return status;
    /* the header must be in this order: the table prints columns by index */
    if (index != (uint32_t)c)
      return hush__fail(r->device, HUSH_ERROR_CORRUPT,
                        "'%s' line 1: expected the columns filter,stage,median_ms,p5_ms,p95_ms",
                        r->timings.path);
  }
  for (uint32_t i = 1; i < r->timings.row_count; i++) {
    for (uint32_t c = 2; c < 5; c++) {
      double v;
      status = csv_number(r->device, &r->timings, &r->timings.rows[i], c, &v);
      if (status != HUSH_OK) return status;
    }
  }
  return HUSH_OK;
}

static hush_status read_inputs(report *r) {
  report_filter *noisy;
  hush_status status = filter_find_or_add(r, "noisy", "report", &noisy);
  if (status == HUSH_OK) status = read_eval_json(r);
  if (status == HUSH_OK) status = read_metrics(r);
  if (status == HUSH_OK) status = read_status(r);
  if (status == HUSH_OK) status = read_timings(r);
  if (status != HUSH_OK) return status;
  char path[HUSH_PATH_MAX];
  status = path_printf(r->device, path, "%s/summary.md", r->dir);
  int missing;
  if (status == HUSH_OK) status = read_text(r->device, path, &r->summary, &missing);
  return status;
}

/* The frames shown side by side: the caller's, or first, middle and last. */
static hush_status choose_frames(report *r) {
  if (r->opt.frame_count > 0) {
    if (r->opt.frame_count > MAX_SHOWN)
      return hush__fail(r->device, HUSH_ERROR_INVALID_ARGUMENT,
                        "report: %u frames to show, at most %d", r->opt.frame_count, MAX_SHOWN);
    for (uint32_t i = 0; i < r->opt.frame_count; i++) {
      const uint32_t f = r->opt.frames[i];
      if (f < r->first || f >= r->last)
        return hush__fail(r->device, HUSH_ERROR_OUT_OF_RANGE,
                          "report: frame %u is not one of the evaluated frames [%u, %u)", f,
                          r->first, r->last);
      r->shown[r->shown_count++] = f;
    }
    return HUSH_OK;
  }
  const uint32_t pick[3] = {r->first, r->first + (r->last - 1 - r->first) / 2, r->last - 1};
  for (int i = 0; i < 3; i++)
    if (r->shown_count == 0 || r->shown[r->shown_count - 1] != pick[i])
      r->shown[r->shown_count++] = pick[i];
  return HUSH_OK;
}

/* ------------------------------------------------------------------------ */
/* Pictures                                                                 */
/* ------------------------------------------------------------------------ */

/* One column of one frame, after the display transform. */
typedef struct picture {
  int present;
  uint8_t *rgb; /* width * height * 3 */
  float *luma;  /* display luma in [0, 1], for the error maps */
} picture;

static void picture_free(picture *p) {
  free(p->rgb);
  free(p->luma);
  memset(p, 0, sizeof *p);
}

static hush_status column_path(report *r, const char *column, uint32_t frame,
                               char out[HUSH_PATH_MAX]) {
  return path_printf(r->device, out, "%s/frames/%s/frame_%04u.exr", r->dir, column, frame);
}

/* Loads frames/<column>/frame_NNNN.exr's color layer and applies the
 * display transform. A missing file leaves p->present 0 unless required.
 * Non-finite pixels are shown magenta (and count as the largest error) so
 * a broken filter is visible instead of failing the report. */
static hush_status picture_load(report *r, const char *column, uint32_t frame, int required,
                                picture *p) {
  memset(p, 0, sizeof *p);
  char path[HUSH_PATH_MAX];
  hush_status status = column_path(r, column, frame, path);
  if (status != HUSH_OK) return status;
  if (!file_exists(path)) {
    if (!required) return HUSH_OK;
    return hush__fail(r->device, HUSH_ERROR_NOT_FOUND, "report: '%s' is missing", path);
  }
  hush_frame frame_data = NULL;
  status = hush_frame_read_exr(r->device, path, &frame_data);
  if (status != HUSH_OK) return status;
  const hush_layer *color = hush__frame_find(frame_data, "color");
  if (!color || (color->channels != 1 && color->channels < 3)) {
    hush_frame_release(frame_data);
    return hush__fail(r->device, HUSH_ERROR_CORRUPT, "report: '%s' has no RGB \"color\" layer", path);
  }
  if (frame_data->width != r->width || frame_data->height != r->height) {
    status = hush__fail(r->device, HUSH_ERROR_CORRUPT, "report: '%s' is %ux%u, eval.json says %ux%u",
                        path, frame_data->width, frame_data->height, r->width, r->height);
    hush_frame_release(frame_data);
    return status;
  }
  const size_t n = (size_t)r->width * r->height;
  p->rgb = malloc(n * 3);
  p->luma = malloc(n * sizeof *p->luma);
  if (!p->rgb || !p->luma) {
    picture_free(p);
    hush_frame_release(frame_data);
    return hush__fail(r->device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory reading '%s'", path);
  }
  const float scale = exp2f(r->opt.exposure);
  const int ch = color->channels;
  for (size_t i = 0; i < n; i++) {
    const float *px = color->pixels + i * (size_t)ch;
    const float rgb[3] = {px[0], px[ch >= 3 ? 1 : 0], px[ch >= 3 ? 2 : 0]};
    if (!isfinite(rgb[0]) || !isfinite(rgb[1]) || !isfinite(rgb[2])) {
      p->rgb[i * 3 + 0] = 255, p->rgb[i * 3 + 1] = 0, p->rgb[i * 3 + 2] = 255;
      p->luma[i] = NAN;
      continue;
    }
    float d[3];
    for (int c = 0; c < 3; c++) {
      d[c] = hush__srgb_encode(hush__tonemap(rgb[c] * scale, r->opt.tonemap));
      p->rgb[i * 3 + c] = hush__quantize8(d[c]);
    }
    p->luma[i] = 0.2126f * d[0] + 0.7152f * d[1] + 0.0722f * d[2];
  }
  hush_frame_release(frame_data);
  p->present = 1;
  return HUSH_OK;
}

static float abs_error(const picture *a, const picture *ref, size_t i) {
  const float e = fabsf(a->luma[i] - ref->luma[i]);
  return isfinite(e) ? e : 1.0f;
}

typedef struct crop {
  uint32_t x, y, size;
} crop;

/* Picks up to CROP_COUNT non-overlapping square regions where the noisy
 * frame's error is largest (a summed-area table gives each window's sum):
 * that is where a filter has the most to do and differences show most. */
static uint32_t choose_crops(const report *r, const picture *noisy, const picture *ref,
                             crop out[CROP_COUNT]) {
  const uint32_t w = r->width, h = r->height;
  const uint32_t min_side = w < h ? w : h;
  uint32_t size = min_side / 5;
  if (size < 4) size = min_side < 4 ? min_side : 4;
  double *sat = calloc((size_t)(w + 1) * (h + 1), sizeof *sat);
  if (!sat) return 0;
  for (uint32_t y = 0; y < h; y++) {
    double row = 0.0;
    for (uint32_t x = 0; x < w; x++) {
      row += abs_error(noisy, ref, (size_t)y * w + x);
      sat[(size_t)(y + 1) * (w + 1) + x + 1] = sat[(size_t)y * (w + 1) + x + 1] + row;
    }
  }
  uint32_t count = 0;
  for (int k = 0; k < CROP_COUNT; k++) {
    double best = -1.0;
    crop c = {0, 0, size};
    for (uint32_t y = 0; y + size <= h; y++) {
      for (uint32_t x = 0; x + size <= w; x++) {
        int overlaps = 0;
        for (uint32_t j = 0; j < count; j++)
          if (x < out[j].x + size && out[j].x < x + size && y < out[j].y + size && out[j].y < y + size)
            overlaps = 1;
        if (overlaps) continue;
        const size_t W = w + 1;
        const double s = sat[(y + size) * W + x + size] - sat[(size_t)y * W + x + size] -
                         sat[(y + size) * W + x] + sat[(size_t)y * W + x];
        if (s > best) {
          best = s;
          c.x = x;
          c.y = y;
        }
      }
    }
    if (best < 0.0) break;
    out[count++] = c;
  }
  free(sat);
  return count;
}

/* Nearest-neighbour enlargement of a crop, so single pixels stay crisp. */
static uint32_t inset_scale(const crop *c) {
  const uint32_t k = 192 / c->size;
  return k < 2 ? 2 : k;
}

static hush_status write_inset(report *r, const picture *p, const crop *c, const char *path) {
  const uint32_t k = inset_scale(c), side = c->size * k;
  uint8_t *px = malloc((size_t)side * side * 3);
  if (!px) return hush__fail(r->device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory writing '%s'", path);
  for (uint32_t y = 0; y < side; y++) {
    for (uint32_t x = 0; x < side; x++) {
      const size_t src = ((size_t)(c->y + y / k) * r->width + c->x + x / k) * 3;
      memcpy(px + ((size_t)y * side + x) * 3, p->rgb + src, 3);
    }
  }
  const hush_status status = hush__png_write8(r->device, path, px, side, side, 3);
  free(px);
  return status;
}

/* Outlines a crop on the full picture, just inside its border. */
static void draw_outline(const report *r, uint8_t *rgb, const crop *c, const uint8_t color[3]) {
  const uint32_t t = r->width >= 640 ? 3 : r->width >= 200 ? 2 : 1;
  for (uint32_t y = c->y; y < c->y + c->size; y++) {
    for (uint32_t x = c->x; x < c->x + c->size; x++) {
      const int edge = x < c->x + t || y < c->y + t || x + t >= c->x + c->size ||
                       y + t >= c->y + c->size;
      if (edge) memcpy(rgb + ((size_t)y * r->width + x) * 3, color, 3);
    }
  }
}

/* Viridis (matplotlib's perceptually uniform map) at nine even steps,
 * interpolated linearly between them. */
static const uint8_t viridis[9][3] = {{68, 1, 84},    {71, 45, 123},  {59, 82, 139},
                                      {44, 114, 142}, {33, 144, 140}, {39, 173, 129},
                                      {93, 200, 99},  {170, 220, 50}, {253, 231, 37}};

static void viridis_rgb(float t, uint8_t out[3]) {
  if (!(t > 0.0f)) t = 0.0f;
  if (t > 1.0f) t = 1.0f;
  const float s = t * 8.0f;
  int i = (int)s;
  if (i > 7) i = 7;
  const float f = s - (float)i;
  for (int c = 0; c < 3; c++)
    out[c] = (uint8_t)lrintf(viridis[i][c] + f * (viridis[i + 1][c] - viridis[i][c]));
}

static hush_status write_heat_map(report *r, const picture *p, const picture *ref, float scale,
                                  const char *path) {
  const size_t n = (size_t)r->width * r->height;
  uint8_t *px = malloc(n * 3);
  if (!px) return hush__fail(r->device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory writing '%s'", path);
  for (size_t i = 0; i < n; i++) viridis_rgb(abs_error(p, ref, i) / scale, px + i * 3);
  const hush_status status = hush__png_write8(r->device, path, px, r->width, r->height, 3);
  free(px);
  return status;
}

static int compare_floats(const void *a, const void *b) {
  const float x = *(const float *)a, y = *(const float *)b;
  return (x > y) - (x < y);
}

/* The error that maps to the top of the colour scale: the 99th percentile
 * of the filters' errors (the noisy input's would make every filter look
 * black), rounded up to 1, 2 or 5 times a power of ten for the legend. */
static float heat_scale(const report *r, const picture *pics, const picture *ref) {
  const size_t n = (size_t)r->width * r->height;
  uint32_t users = 0;
  for (uint32_t f = 1; f < r->filter_count; f++) users += pics[f].present;
  const int noisy_only = users == 0;
  float *all = malloc(n * (noisy_only ? 1 : users) * sizeof *all);
  if (!all) return 0.1f;
  size_t count = 0;
  for (uint32_t f = noisy_only ? 0 : 1; f < (noisy_only ? 1u : r->filter_count); f++) {
    if (!pics[f].present) continue;
    for (size_t i = 0; i < n; i++) all[count++] = abs_error(&pics[f], ref, i);
  }
  float p99 = 0.0f;
  if (count) {
    qsort(all, count, sizeof *all, compare_floats);
    p99 = all[(size_t)((double)(count - 1) * 0.99)];
  }
  free(all);
  if (p99 < 0.01f) p99 = 0.01f;
  const double mag = pow(10.0, floor(log10(p99)));
  const double f = p99 / mag;
  return (float)((f <= 1.0 ? 1.0 : f <= 2.0 ? 2.0 : f <= 5.0 ? 5.0 : 10.0) * mag);
}

/* ------------------------------------------------------------------------ */
/* The page                                                                 */
/* ------------------------------------------------------------------------ */

static const char *const page_style =
    "body{font:14px/1.45 system-ui,-apple-system,'Segoe UI',sans-serif;margin:24px auto;"
    "max-width:1700px;padding:0 16px;color:#1d1d1d;background:#fafafa}\n"
    "h1{font-size:24px;margin-bottom:4px}\n"
    "h2{font-size:19px;border-bottom:1px solid #ccc;padding-bottom:4px;margin-top:36px}\n"
    "h3{font-size:16px;margin:20px 0 8px}\n"
    "table{border-collapse:collapse;margin:8px 0;background:#fff}\n"
    "th,td{border:1px solid #d0d0d0;padding:3px 9px;text-align:right;"
    "font-variant-numeric:tabular-nums}\n"
    "th{background:#eee}\n"
    "td:first-child,th:first-child,table.meta td{text-align:left}\n"
    "table.meta th{text-align:left;background:none;border:none;padding-right:16px}\n"
    "table.meta td{border:none}\n"
    "code{background:#eee;padding:1px 4px;border-radius:3px;font-size:13px}\n"
    ".grid{display:flex;flex-wrap:wrap;gap:14px;align-items:flex-start}\n"
    ".cell{width:400px;background:#fff;border:1px solid #ddd;padding:6px}\n"
    ".cell .name{font-weight:600}\n"
    ".cell .nums{color:#555;font-size:12px;margin-bottom:4px}\n"
    ".cell img{display:block;width:100%}\n"
    ".insets{display:flex;gap:6px;margin:6px 0}\n"
    ".insets img{width:calc(50% - 7px);image-rendering:pixelated;border:2px solid}\n"
    ".heat{image-rendering:pixelated}\n"
    ".missing{display:flex;align-items:center;justify-content:center;aspect-ratio:16/9;"
    "background:#eee;color:#b00020;text-align:center;padding:8px}\n"
    ".failed{color:#b00020}\n"
    ".box{background:#fff3f3;border:1px solid #e0b4b4;padding:8px 12px;margin:12px 0}\n"
    ".legend{display:flex;align-items:center;gap:8px;margin:6px 0 10px;font-size:13px}\n"
    ".plots{display:flex;flex-wrap:wrap;gap:16px}\n"
    ".plots svg{background:#fff;border:1px solid #ddd}\n"
    ".note{color:#555;font-size:13px}\n";

static const char *tonemap_name(hush_tonemap op) {
  return op == HUSH_TONEMAP_CLAMP ? "clamp" : op == HUSH_TONEMAP_REINHARD ? "reinhard" : "aces";
}

static void html_head(report *r) {
  hush_strbuf *h = &r->html;
  hush__strbuf_append(h, "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
                         "<title>hush eval: ");
  hush__strbuf_escape(h, r->seq);
  hush__strbuf_printf(h, "</title>\n<style>\n%s</style>\n</head>\n<body>\n<h1>hush eval report</h1>\n",
                      page_style);
  hush__strbuf_append(h, "<table class=\"meta\">\n<tr><th>noisy sequence</th><td><code>");
  hush__strbuf_escape(h, r->seq);
  hush__strbuf_append(h, "</code></td></tr>\n<tr><th>reference</th><td><code>");
  hush__strbuf_escape(h, r->ref);
  hush__strbuf_printf(h,
                      "</code></td></tr>\n<tr><th>frames</th><td>%u to %u (%u frames), %u x %u "
                      "pixels</td></tr>\n<tr><th>filters</th><td>",
                      r->first, r->last - 1, r->last - r->first, r->width, r->height);
  for (uint32_t i = 0; i < r->filter_count; i++) {
    hush__strbuf_append(h, i ? ", " : "");
    if (r->filters[i].failed) hush__strbuf_append(h, "<span class=\"failed\">");
    hush__strbuf_escape(h, r->filters[i].name);
    if (r->filters[i].failed) hush__strbuf_append(h, " (failed)</span>");
  }
  hush__strbuf_printf(h,
                      "</td></tr>\n<tr><th>pictures</th><td>exposure %+g stops, %s tone mapping, "
                      "sRGB</td></tr>\n",
                      (double)r->opt.exposure, tonemap_name(r->opt.tonemap));
  if (r->command.len) {
    hush__strbuf_append(h, "<tr><th>command</th><td><code>");
    hush__strbuf_escape(h, r->command.data);
    hush__strbuf_append(h, "</code></td></tr>\n");
  }
  hush__strbuf_append(h, "</table>\n");
}

static void html_failed(report *r) {
  int any = 0;
  for (uint32_t i = 0; i < r->filter_count; i++) any |= r->filters[i].failed;
  if (!any) return;
  hush_strbuf *h = &r->html;
  hush__strbuf_append(h, "<div class=\"box\"><b class=\"failed\">Failed filters</b>\n<ul>\n");
  for (uint32_t i = 0; i < r->filter_count; i++) {
    if (!r->filters[i].failed) continue;
    hush__strbuf_append(h, "<li><b>");
    hush__strbuf_escape(h, r->filters[i].name);
    hush__strbuf_append(h, "</b>: ");
    hush__strbuf_escape(h, r->filters[i].message ? r->filters[i].message : "");
    hush__strbuf_append(h, "</li>\n");
  }
  hush__strbuf_append(h, "</ul>\nThe other filters completed; a failed filter's rows cover only the "
                         "frames it finished.</div>\n");
}

/* Text with Markdown `code` spans as <code>, the rest escaped. */
static void markdown_inline(hush_strbuf *h, const char *text) {
  int in_code = 0;
  for (const char *p = text; *p;) {
    const char *tick = strchr(p, '`');
    const size_t n = tick ? (size_t)(tick - p) : strlen(p);
    char part[1024];
    snprintf(part, sizeof part, "%.*s", (int)(n < sizeof part ? n : sizeof part - 1), p);
    hush__strbuf_escape(h, part);
    if (!tick) break;
    /* an unpaired backtick stays a backtick */
    if (!in_code && !strchr(tick + 1, '`')) {
      hush__strbuf_append(h, "`");
    } else {
      hush__strbuf_append(h, in_code ? "</code>" : "<code>");
      in_code = !in_code;
    }
    p = tick + 1;
  }
  if (in_code) hush__strbuf_append(h, "</code>");
}

/* A Markdown pipe-table line ("| a | b |") split into cells. */
static void markdown_row(hush_strbuf *h, const char *line, size_t len, const char *tag) {
  hush__strbuf_append(h, "<tr>");
  size_t i = 0;
  if (i < len && line[i] == '|') i++;
  while (i < len) {
    size_t j = i;
    while (j < len && line[j] != '|') j++;
    if (j == len && i < len && strspn(line + i, " \t") >= len - i) break; /* after the last | */
    size_t a = i, b = j;
    while (a < b && (line[a] == ' ' || line[a] == '\t')) a++;
    while (b > a && (line[b - 1] == ' ' || line[b - 1] == '\t')) b--;
    char cell[512];
    snprintf(cell, sizeof cell, "%.*s", (int)(b - a), line + a);
    hush__strbuf_printf(h, "<%s>", tag);
    markdown_inline(h, cell);
    hush__strbuf_printf(h, "</%s>", tag);
    i = j + 1;
  }
  hush__strbuf_append(h, "</tr>\n");
}

/* summary.md as HTML: pipe tables become tables, headings headings, other
 * lines paragraphs. That is all summary.md uses. */
static void html_summary(report *r) {
  hush_strbuf *h = &r->html;
  hush__strbuf_append(h, "<h2 id=\"summary\">Summary</h2>\n");
  if (!r->summary) {
    hush__strbuf_append(h, "<p class=\"note\">summary.md is missing.</p>\n");
    return;
  }
  int in_table = 0, header_done = 0;
  for (const char *line = r->summary; *line;) {
    const char *end = strchr(line, '\n');
    const size_t len = end ? (size_t)(end - line) : strlen(line);
    size_t l = len;
    if (l && line[l - 1] == '\r') l--;
    const int is_row = l > 0 && line[0] == '|';
    if (!is_row && in_table) {
      hush__strbuf_append(h, "</table>\n");
      in_table = 0;
    }
    if (is_row) {
      if (!in_table) hush__strbuf_append(h, "<table>\n");
      in_table = 1;
      if (strspn(line, "|-: \t") >= l) {
        header_done = 1; /* the |---|---| separator */
      } else {
        markdown_row(h, line, l, header_done || in_table > 1 ? "td" : "th");
        in_table++;
      }
    } else if (l > 0) {
      char text[1024];
      size_t hashes = strspn(line, "#");
      const int heading = hashes > 0 && hashes < l && line[hashes] == ' ';
      const size_t skip = heading ? hashes + 1 : 0;
      snprintf(text, sizeof text, "%.*s", (int)(l - skip), line + skip);
      hush__strbuf_append(h, heading ? "<h3>" : "<p>");
      markdown_inline(h, text);
      hush__strbuf_append(h, heading ? "</h3>\n" : "</p>\n");
      header_done = 0;
    }
    if (!in_table) header_done = 0;
    line += end ? len + 1 : len;
  }
  if (in_table) hush__strbuf_append(h, "</table>\n");
}

static void html_numbers(hush_strbuf *h, const report_filter *f, uint32_t frame) {
  const metric_row *m = f ? filter_row_at(f, frame) : NULL;
  if (!m) {
    hush__strbuf_append(h, "<div class=\"nums\">&nbsp;</div>\n");
    return;
  }
  hush__strbuf_printf(h, "<div class=\"nums\">RMSE %.4g &middot; SSIM %.4f &middot; PSNR %.2f dB",
                      m->v[M_RMSE], m->v[M_SSIM], m->v[M_PSNR]);
  if (isfinite(m->v[M_MS])) hush__strbuf_printf(h, " &middot; %.2f ms", m->v[M_MS]);
  hush__strbuf_append(h, "</div>\n");
}

/* A colour bar of the heat-map scale, as inline SVG. */
static void html_legend(hush_strbuf *h, float scale) {
  hush__strbuf_append(h, "<div class=\"legend\">error maps: |output &minus; reference| of the "
                         "displayed luma, 0 <svg width=\"220\" height=\"14\"><defs>"
                         "<linearGradient id=\"viridis\">");
  for (int i = 0; i < 9; i++)
    hush__strbuf_printf(h, "<stop offset=\"%d%%\" stop-color=\"rgb(%u,%u,%u)\"/>", i * 100 / 8,
                        viridis[i][0], viridis[i][1], viridis[i][2]);
  hush__strbuf_printf(h, "</linearGradient></defs><rect width=\"220\" height=\"14\" "
                         "fill=\"url(#viridis)\"/></svg> %g and above</div>\n",
                      (double)scale);
}

static void html_cell(report *r, const char *title, const report_filter *f, uint32_t frame,
                      const picture *p, uint32_t crop_count, int heat) {
  hush_strbuf *h = &r->html;
  const char *file = f ? f->name : "reference";
  hush__strbuf_append(h, "<div class=\"cell\"><div class=\"name\">");
  hush__strbuf_escape(h, title);
  hush__strbuf_append(h, "</div>\n");
  if (!p->present) {
    hush__strbuf_append(h, "<div class=\"nums\">&nbsp;</div><div class=\"missing\">");
    if (f && f->failed) {
      hush__strbuf_append(h, "failed: ");
      hush__strbuf_escape(h, f->message ? f->message : "");
    } else {
      hush__strbuf_printf(h, "no output for frame %u", frame);
    }
    hush__strbuf_append(h, "</div></div>\n");
    return;
  }
  html_numbers(h, f, frame);
  hush__strbuf_printf(h, "<img src=\"img/f%04u_%s.png\" alt=\"", frame, file);
  hush__strbuf_escape(h, title);
  hush__strbuf_printf(h, ", frame %u\">\n<div class=\"insets\">", frame);
  for (uint32_t k = 0; k < crop_count; k++)
    hush__strbuf_printf(h, "<img src=\"img/f%04u_%s_crop%u.png\" style=\"border-color:%s\" alt=\"inset %u\">",
                        frame, file, k, crop_css[k], k + 1);
  hush__strbuf_append(h, "</div>\n");
  if (heat)
    hush__strbuf_printf(h, "<img class=\"heat\" src=\"img/f%04u_%s_err.png\" alt=\"error map\">\n",
                        frame, file);
  hush__strbuf_append(h, "</div>\n");
}

/* Writes one column's picture, insets and (not for the reference) heat map. */
static hush_status write_column(report *r, const char *file, uint32_t frame, picture *p,
                                const picture *ref, const crop *crops, uint32_t crop_count,
                                float scale, int heat) {
  char path[HUSH_PATH_MAX];
  hush_status status = HUSH_OK;
  for (uint32_t k = 0; k < crop_count && status == HUSH_OK; k++) {
    status = path_printf(r->device, path, "%s/img/f%04u_%s_crop%u.png", r->dir, frame, file, k);
    if (status == HUSH_OK) status = write_inset(r, p, &crops[k], path);
  }
  if (status == HUSH_OK && heat) {
    status = path_printf(r->device, path, "%s/img/f%04u_%s_err.png", r->dir, frame, file);
    if (status == HUSH_OK) status = write_heat_map(r, p, ref, scale, path);
  }
  for (uint32_t k = 0; k < crop_count; k++) draw_outline(r, p->rgb, &crops[k], crop_rgb[k]);
  if (status == HUSH_OK) status = path_printf(r->device, path, "%s/img/f%04u_%s.png", r->dir, frame, file);
  if (status == HUSH_OK) status = hush__png_write8(r->device, path, p->rgb, r->width, r->height, 3);
  return status;
}

static hush_status frame_section(report *r, uint32_t frame) {
  picture *pics = calloc(r->filter_count, sizeof *pics);
  picture ref = {0};
  if (!pics) return hush__fail(r->device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory");
  hush_status status = picture_load(r, "reference", frame, 1, &ref);
  for (uint32_t f = 0; f < r->filter_count && status == HUSH_OK; f++)
    status = picture_load(r, r->filters[f].name, frame, f == 0, &pics[f]);

  crop crops[CROP_COUNT];
  uint32_t crop_count = 0;
  float scale = 1.0f;
  if (status == HUSH_OK) {
    crop_count = choose_crops(r, &pics[0], &ref, crops);
    scale = heat_scale(r, pics, &ref);
  }
  for (uint32_t f = 0; f < r->filter_count && status == HUSH_OK; f++)
    if (pics[f].present)
      status = write_column(r, r->filters[f].name, frame, &pics[f], &ref, crops, crop_count, scale, 1);
  if (status == HUSH_OK)
    status = write_column(r, "reference", frame, &ref, &ref, crops, crop_count, scale, 0);

  if (status == HUSH_OK) {
    hush_strbuf *h = &r->html;
    hush__strbuf_printf(h, "<h3>Frame %u</h3>\n", frame);
    html_legend(h, scale);
    hush__strbuf_append(h, "<div class=\"grid\">\n");
    for (uint32_t f = 0; f < r->filter_count; f++)
      html_cell(r, r->filters[f].name, &r->filters[f], frame, &pics[f], crop_count, 1);
    html_cell(r, "reference", NULL, frame, &ref, crop_count, 0);
    hush__strbuf_append(h, "</div>\n");
  }
  for (uint32_t f = 0; f < r->filter_count; f++) picture_free(&pics[f]);
  free(pics);
  picture_free(&ref);
  return status;
}

static hush_status html_frames(report *r) {
  hush__strbuf_append(&r->html,
                      "<h2>Side by side</h2>\n<p class=\"note\">noisy input | each filter | "
                      "reference, with one display transform. The insets (nearest-neighbour "
                      "enlargements of the outlined squares) are where the noisy input is furthest "
                      "from the reference. Below each picture, its error map.</p>\n");
  for (uint32_t i = 0; i < r->shown_count; i++) {
    const hush_status status = frame_section(r, r->shown[i]);
    if (status != HUSH_OK) return status;
  }
  return HUSH_OK;
}

/* ------------------------------------------------------------------------ */
/* Plots                                                                    */
/* ------------------------------------------------------------------------ */

/* Log scale when the series span more than a factor of 30 (the noisy
 * input's error would otherwise flatten every filter onto the axis). */
static int wants_log(const hush_svg_series *s, uint32_t count) {
  double lo = INFINITY, hi = 0.0;
  for (uint32_t i = 0; i < count; i++)
    for (uint32_t j = 0; j < s[i].count; j++)
      if (isfinite(s[i].y[j]) && s[i].y[j] > 0.0) {
        lo = fmin(lo, s[i].y[j]);
        hi = fmax(hi, s[i].y[j]);
      }
  return hi > 0.0 && hi / lo > 30.0;
}

static hush_status html_plot(report *r, int metric, const char *title, const char *y_label,
                             int allow_log) {
  const uint32_t n = r->last - r->first;
  const uint32_t series_max = r->filter_count + 1;
  hush_svg_series *series = calloc(series_max, sizeof *series);
  double *x = malloc(n * sizeof *x);
  double *y = malloc((size_t)n * series_max * sizeof *y);
  if (!series || !x || !y) {
    free(series), free(x), free(y);
    return hush__fail(r->device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory");
  }
  for (uint32_t i = 0; i < n; i++) x[i] = r->first + i;
  uint32_t count = 0;
  for (uint32_t f = 0; f < r->filter_count; f++) {
    if (r->filters[f].row_count == 0) continue;
    double *ys = y + (size_t)count * n;
    for (uint32_t i = 0; i < n; i++) {
      const metric_row *m = filter_row_at(&r->filters[f], r->first + i);
      ys[i] = m ? m->v[metric] : NAN;
    }
    series[count++] = (hush_svg_series){r->filters[f].name, x, ys, n, r->filters[f].color, 0};
  }
  if (metric == M_TEMPORAL) {
    /* the reference's own flicker: the floor a filter can reach */
    double *ys = y + (size_t)count * n;
    for (uint32_t i = 0; i < n; i++) {
      ys[i] = NAN;
      for (uint32_t f = 0; f < r->filter_count && isnan(ys[i]); f++) {
        const metric_row *m = filter_row_at(&r->filters[f], r->first + i);
        if (m && isfinite(m->v[M_REF_TEMPORAL])) ys[i] = m->v[M_REF_TEMPORAL];
      }
    }
    series[count++] = (hush_svg_series){"reference", x, ys, n, "#000000", 1};
  }
  const hush_svg_plot plot = {title, "frame", y_label, 620, 300,
                              allow_log && wants_log(series, count), series, count};
  hush__svg_line_plot(&r->html, &plot);
  free(series), free(x), free(y);
  return HUSH_OK;
}

static hush_status html_plots(report *r) {
  hush__strbuf_append(&r->html, "<h2 id=\"plots\">Per frame</h2>\n<div class=\"plots\">\n");
  hush_status status = html_plot(r, M_RMSE, "RMSE against the reference", "RMSE", 1);
  if (status == HUSH_OK) status = html_plot(r, M_SSIM, "SSIM against the reference", "SSIM", 0);
  if (status == HUSH_OK)
    status = html_plot(r, M_TEMPORAL, "Temporal error (dashed: the reference's own)",
                       "mean |luminance change|", 1);
  if (status == HUSH_OK) status = html_plot(r, M_MS, "Filter time per frame", "ms", 0);
  hush__strbuf_append(&r->html, "</div>\n");
  return status;
}

static void html_timings(report *r) {
  hush_strbuf *h = &r->html;
  hush__strbuf_append(h, "<h2 id=\"timings\">Timings</h2>\n");
  if (!r->have_timings) {
    hush__strbuf_append(h, "<p class=\"note\">timings.csv is missing.</p>\n");
    return;
  }
  hush__strbuf_append(h, "<table>\n<tr><th>filter</th><th style=\"text-align:left\">stage</th><th>median ms</th>"
                         "<th>5th percentile ms</th><th>95th percentile ms</th></tr>\n");
  for (uint32_t i = 1; i < r->timings.row_count; i++) {
    char *const *f = r->timings.rows[i].field;
    const int total = strcmp(f[1], "total") == 0;
    hush__strbuf_append(h, total ? "<tr style=\"font-weight:600\"><td>" : "<tr><td>");
    hush__strbuf_escape(h, f[0]);
    hush__strbuf_append(h, "</td><td style=\"text-align:left\">");
    hush__strbuf_escape(h, f[1]);
    hush__strbuf_append(h, "</td>");
    for (int c = 2; c < 5; c++) {
      double v;
      parse_number(f[c], &v);
      hush__strbuf_printf(h, "<td>%.3f</td>", v);
    }
    hush__strbuf_append(h, "</tr>\n");
  }
  hush__strbuf_append(h, "</table>\n");
}

/* ------------------------------------------------------------------------ */
/* Video                                                                    */
/* ------------------------------------------------------------------------ */

/* ffmpeg's full path from PATH into out, or 0 when it is not there. */
static int find_ffmpeg(char out[HUSH_PATH_MAX]) {
  const char *path = getenv("PATH");
  if (!path) return 0;
  while (*path) {
    const size_t len = strcspn(path, ":");
    if (len > 0 && len < HUSH_PATH_MAX - 8) {
      snprintf(out, HUSH_PATH_MAX, "%.*s/ffmpeg", (int)len, path);
      if (access(out, X_OK) == 0 && file_exists(out)) return 1;
    }
    path += len;
    if (*path == ':') path++;
  }
  return 0;
}

/* Runs argv[0] with stdin from /dev/null and stdout and stderr into log,
 * without a shell. Returns its exit status, or -1 if it could not run. */
static int run_program(char *const argv[], const char *log) {
  posix_spawn_file_actions_t actions;
  if (posix_spawn_file_actions_init(&actions) != 0) return -1;
  int ok = posix_spawn_file_actions_addopen(&actions, 0, "/dev/null", O_RDONLY, 0) == 0 &&
           posix_spawn_file_actions_addopen(&actions, 1, log, O_WRONLY | O_CREAT | O_TRUNC, 0644) == 0 &&
           posix_spawn_file_actions_adddup2(&actions, 1, 2) == 0;
  pid_t pid;
  if (ok) ok = posix_spawn(&pid, argv[0], &actions, NULL, argv, environ) == 0;
  posix_spawn_file_actions_destroy(&actions);
  if (!ok) return -1;
  int wstatus;
  while (waitpid(pid, &wstatus, 0) < 0)
    if (errno != EINTR) return -1;
  return WIFEXITED(wstatus) ? WEXITSTATUS(wstatus) : -1;
}

/* The video's columns: noisy, every filter with an output directory. */
static int video_column(const report *r, uint32_t f) {
  char dir[HUSH_PATH_MAX];
  const int n = snprintf(dir, sizeof dir, "%s/frames/%s", r->dir, r->filters[f].name);
  return f == 0 || (n > 0 && n < HUSH_PATH_MAX && dir_exists(dir));
}

/* One PNG per frame: the columns side by side, a missing frame dark grey. */
static hush_status write_strip(report *r, uint32_t frame, const char *path, uint8_t *strip,
                               uint32_t strip_w, uint32_t columns) {
  memset(strip, 0, (size_t)strip_w * r->height * 3);
  uint32_t col = 0;
  hush_status status = HUSH_OK;
  for (uint32_t f = 0; f <= r->filter_count && status == HUSH_OK; f++) {
    if (f < r->filter_count && !video_column(r, f)) continue;
    picture p;
    status = picture_load(r, f < r->filter_count ? r->filters[f].name : "reference", frame,
                          f == 0 || f == r->filter_count, &p);
    if (status != HUSH_OK) break;
    const size_t x0 = (size_t)col * (r->width + VIDEO_GAP);
    for (uint32_t y = 0; y < r->height; y++) {
      uint8_t *dst = strip + ((size_t)y * strip_w + x0) * 3;
      if (p.present)
        memcpy(dst, p.rgb + (size_t)y * r->width * 3, (size_t)r->width * 3);
      else
        memset(dst, 48, (size_t)r->width * 3);
    }
    picture_free(&p);
    col++;
  }
  (void)columns;
  if (status == HUSH_OK) status = hush__png_write8(r->device, path, strip, strip_w, r->height, 3);
  return status;
}

static void remove_strips(const report *r, const char *video_dir) {
  char path[HUSH_PATH_MAX];
  for (uint32_t i = 0; i < r->last - r->first; i++) {
    if (path_printf(r->device, path, "%s/strip_%04u.png", video_dir, i) == HUSH_OK) remove(path);
  }
}

/* Encodes the strips with ffmpeg (H.264, falling back to MPEG-4 part 2 when
 * this ffmpeg lacks libx264) into a temporary file renamed to video.mp4.
 * Returns 0 and a reason in `why` when ffmpeg fails: a missing video is
 * noted on the page, it does not fail the report. */
static int encode_video(report *r, const char *ffmpeg, const char *video_dir, char *why,
                        size_t why_size) {
  char pattern[HUSH_PATH_MAX], log[HUSH_PATH_MAX], out[HUSH_PATH_MAX], tmp[HUSH_PATH_MAX];
  if (path_printf(r->device, pattern, "%s/strip_%%04d.png", video_dir) != HUSH_OK ||
      path_printf(r->device, log, "%s/ffmpeg.log", video_dir) != HUSH_OK ||
      path_printf(r->device, out, "%s/video.mp4", r->dir) != HUSH_OK ||
      hush__atomic_reserve(r->device, out, tmp) != HUSH_OK) {
    const char *message;
    hush_device_get_error(r->device, &message);
    snprintf(why, why_size, "%s", message);
    return 0;
  }
  static const char *const codecs[2][4] = {{"libx264", "-crf", "18", "yuv420p"},
                                           {"mpeg4", "-q:v", "2", "yuv420p"}};
  int code = -1;
  for (int c = 0; c < 2 && code != 0; c++) {
    const char *argv[] = {ffmpeg, "-nostdin", "-y", "-loglevel", "error", "-framerate", "24",
                          "-start_number", "0", "-i", pattern, "-vf",
                          "pad=ceil(iw/2)*2:ceil(ih/2)*2", "-c:v", codecs[c][0], codecs[c][1],
                          codecs[c][2], "-pix_fmt", codecs[c][3], "-f", "mp4", tmp, NULL};
    code = run_program((char *const *)argv, log);
  }
  if (code != 0) {
    remove(tmp);
    snprintf(why, why_size, "ffmpeg failed (%s %d; its messages are in img/video/ffmpeg.log)",
             code < 0 ? "could not run, or a signal:" : "exit status", code);
    return 0;
  }
  if (hush__atomic_commit(r->device, NULL, tmp, out) != HUSH_OK) {
    const char *message;
    hush_device_get_error(r->device, &message);
    snprintf(why, why_size, "%s", message);
    return 0;
  }
  return 1;
}

static hush_status html_video(report *r) {
  hush_strbuf *h = &r->html;
  hush__strbuf_append(h, "<h2 id=\"video\">Video</h2>\n");
  char ffmpeg[HUSH_PATH_MAX];
  if (!r->opt.video) {
    hush__strbuf_append(h, "<p class=\"note\">video: not requested.</p>\n");
    return HUSH_OK;
  }
  if (!find_ffmpeg(ffmpeg)) {
    hush__strbuf_append(h, "<p class=\"note\">video: ffmpeg is not installed (it is looked for on "
                           "PATH), so there is no side-by-side video.</p>\n");
    return HUSH_OK;
  }
  char video_dir[HUSH_PATH_MAX], path[HUSH_PATH_MAX];
  hush_status status = path_printf(r->device, video_dir, "%s/img/video", r->dir);
  if (status == HUSH_OK) status = hush__make_dirs(r->device, video_dir);
  if (status != HUSH_OK) return status;

  uint32_t columns = 1;
  for (uint32_t f = 0; f < r->filter_count; f++) columns += video_column(r, f);
  const uint32_t strip_w = columns * r->width + (columns - 1) * VIDEO_GAP;
  uint8_t *strip = malloc((size_t)strip_w * r->height * 3);
  if (!strip) return hush__fail(r->device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory");
  for (uint32_t i = 0; i < r->last - r->first && status == HUSH_OK; i++) {
    status = path_printf(r->device, path, "%s/strip_%04u.png", video_dir, i);
    if (status == HUSH_OK) status = write_strip(r, r->first + i, path, strip, strip_w, columns);
  }
  free(strip);
  if (status != HUSH_OK) return status;

  char why[HUSH_MESSAGE_MAX] = "";
  if (!encode_video(r, ffmpeg, video_dir, why, sizeof why)) {
    hush__strbuf_append(h, "<p class=\"failed\">video: ");
    hush__strbuf_escape(h, why);
    hush__strbuf_append(h, "</p>\n");
    return HUSH_OK;
  }
  remove_strips(r, video_dir);
  hush__strbuf_append(h, "<p class=\"note\">The whole sequence at 24 frames per second, left to "
                         "right: ");
  for (uint32_t f = 0; f < r->filter_count; f++) {
    if (!video_column(r, f)) continue;
    hush__strbuf_escape(h, r->filters[f].name);
    hush__strbuf_append(h, " | ");
  }
  hush__strbuf_append(h, "reference.</p>\n<video src=\"video.mp4\" controls loop muted "
                         "style=\"max-width:100%\"></video>\n");
  return HUSH_OK;
}

static void html_tail(report *r) {
  hush__strbuf_append(&r->html,
                      "<h2>Files</h2>\n<p class=\"note\"><a href=\"metrics.csv\">metrics.csv</a> "
                      "(per filter and frame) &middot; <a href=\"timings.csv\">timings.csv</a> "
                      "&middot; <a href=\"summary.md\">summary.md</a> &middot; <a "
                      "href=\"status.csv\">status.csv</a> &middot; <a "
                      "href=\"eval.json\">eval.json</a> &middot; frames/&lt;filter&gt;/ (EXR). "
                      "Metrics: RMSE and PSNR on linear radiance; temporal error: mean absolute "
                      "luminance change between consecutive frames (Schied et al. 2017).</p>\n"
                      "</body>\n</html>\n");
}

/* ------------------------------------------------------------------------ */
/* Entry point                                                              */
/* ------------------------------------------------------------------------ */

static hush_status report_run(report *r) {
  hush_status status = read_inputs(r);
  if (status == HUSH_OK) status = choose_frames(r);
  char path[HUSH_PATH_MAX];
  if (status == HUSH_OK) status = path_printf(r->device, path, "%s/img", r->dir);
  if (status == HUSH_OK) status = hush__make_dirs(r->device, path);
  if (status != HUSH_OK) return status;

  html_head(r);
  html_failed(r);
  html_summary(r);
  status = html_frames(r);
  if (status == HUSH_OK) status = html_plots(r);
  if (status != HUSH_OK) return status;
  html_timings(r);
  status = html_video(r);
  if (status != HUSH_OK) return status;
  html_tail(r);
  status = path_printf(r->device, path, "%s/report.html", r->dir);
  if (status == HUSH_OK) status = write_text(r->device, path, &r->html);
  return status;
}

hush_status hush__report_write(hush_device device, const char *report_dir,
                               const hush_report_options *opt) {
  if (!device)
    return hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT, "hush__report_write: device is NULL");
  if (!report_dir || !*report_dir)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "report: no report directory");
  report r;
  memset(&r, 0, sizeof r);
  r.device = device;
  r.dir = report_dir;
  if (opt) {
    r.opt = *opt;
  } else {
    r.opt.tonemap = HUSH_TONEMAP_ACES;
    r.opt.video = 1;
  }
  if (!isfinite(r.opt.exposure) || !hush__tonemap_valid(r.opt.tonemap))
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "report: bad exposure or tone mapping");
  if (r.opt.frame_count > 0 && !r.opt.frames)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "report: frame_count without frames");

  const hush_status status = report_run(&r);
  filters_free(&r);
  csv_free(&r.timings);
  free(r.summary);
  hush__strbuf_free(&r.command);
  hush__strbuf_free(&r.html);
  return status;
}
