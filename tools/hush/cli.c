/*
 * cli.c — option parsing, value parsers, device creation and one-line error
 * reporting shared by the `hush` subcommands (see cli.h).
 */
#include "cli.h"

#include "io/exr.h"

#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

/* ---- messages ----------------------------------------------------------- */

/* Writes "hush <cmd>: <message>\n" as one line: a newline inside the message
 * (say, from a library message) would break tools that read stderr by line. */
static void vreport(const char *cmd, const char *fmt, va_list ap) {
  char text[2048];
  vsnprintf(text, sizeof text, fmt, ap);
  for (char *c = text; *c; c++)
    if (*c == '\n' || *c == '\r') *c = ' ';
  fprintf(stderr, "hush %s: %s\n", cmd, text);
}

void cli_usage_error(const char *cmd, const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  vreport(cmd, fmt, ap);
  va_end(ap);
  exit(CLI_EXIT_USAGE);
}

int cli_error(const char *cmd, const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  vreport(cmd, fmt, ap);
  va_end(ap);
  return CLI_EXIT_RUNTIME;
}

int cli_device_error(const char *cmd, hush_device device, hush_status status,
                     const char *context) {
  const char *message = "";
  const hush_status first = hush_device_get_error(device, &message);
  char text[2048];
  if (first != HUSH_OK)
    snprintf(text, sizeof text, "%s", message);
  else
    snprintf(text, sizeof text, "%s", hush_status_name(status));
  /* Later errors are consequences of the first; drop them so the device
   * starts clean if the caller goes on. */
  while (hush_device_get_error(device, NULL) != HUSH_OK) {
  }
  /* IO messages usually name their file already: no "a.exr: a.exr: ..." */
  if (context && *context && !strstr(text, context))
    return cli_error(cmd, "%s: %s", context, text);
  return cli_error(cmd, "%s", text);
}

/* ---- argument walk ------------------------------------------------------ */

void cli_args_init(cli_args *a, const char *cmd, int argc, char **argv) {
  a->cmd = cmd;
  a->argc = argc;
  a->argv = argv;
  a->next = 1; /* argv[0] is the subcommand */
  a->only_positional = 0;
}

int cli_next(cli_args *a, const char **arg) {
  while (a->next < a->argc) {
    const char *s = a->argv[a->next++];
    if (!a->only_positional && strcmp(s, "--") == 0) {
      a->only_positional = 1;
      continue;
    }
    *arg = s;
    return 1;
  }
  return 0;
}

int cli_is_positional(const cli_args *a, const char *arg) {
  return a->only_positional || arg[0] != '-' || arg[1] == '\0';
}

int cli_option(cli_args *a, const char *arg, const char *flag, const char **value) {
  if (a->only_positional) return 0;
  const size_t n = strlen(flag);
  if (strncmp(arg, flag, n) != 0) return 0;
  if (arg[n] == '=') {
    *value = arg + n + 1;
    return 1;
  }
  if (arg[n] != '\0') return 0;
  if (a->next >= a->argc) cli_usage_error(a->cmd, "%s needs a value (see hush %s --help)", flag, a->cmd);
  *value = a->argv[a->next++];
  return 1;
}

int cli_switch(cli_args *a, const char *arg, const char *flag) {
  if (a->only_positional) return 0;
  const size_t n = strlen(flag);
  if (strncmp(arg, flag, n) != 0) return 0;
  if (arg[n] == '=') cli_usage_error(a->cmd, "%s takes no value", flag);
  return arg[n] == '\0';
}

int cli_is_help(const char *arg) { return strcmp(arg, "-h") == 0 || strcmp(arg, "--help") == 0; }

void cli_unknown_option(const cli_args *a, const char *arg) {
  cli_usage_error(a->cmd, "unknown option '%s' (see hush %s --help)", arg, a->cmd);
}

/* ---- values ------------------------------------------------------------- */

/* Parses a whole-string unsigned decimal; 0 if it is not one. */
static int parse_u64(const char *text, unsigned long long *out) {
  if (!text || !isdigit((unsigned char)text[0])) return 0;
  char *end;
  errno = 0;
  const unsigned long long v = strtoull(text, &end, 10);
  if (errno || *end != '\0') return 0;
  *out = v;
  return 1;
}

uint32_t cli_parse_uint(const char *cmd, const char *flag, const char *text, uint32_t min,
                        uint32_t max) {
  unsigned long long v;
  if (!parse_u64(text, &v))
    cli_usage_error(cmd, "%s: expected a whole number, got '%s'", flag, text);
  if (v < min || v > max)
    cli_usage_error(cmd, "%s: %s is outside [%u, %u]", flag, text, min, max);
  return (uint32_t)v;
}

float cli_parse_float(const char *cmd, const char *flag, const char *text, float min, float max) {
  char *end;
  errno = 0;
  const double v = strtod(text, &end);
  if (!*text || errno || *end != '\0' || !isfinite(v))
    cli_usage_error(cmd, "%s: expected a number, got '%s'", flag, text);
  if (v < (double)min || v > (double)max)
    cli_usage_error(cmd, "%s: %s is outside [%g, %g]", flag, text, (double)min, (double)max);
  return (float)v;
}

void cli_parse_size(const char *cmd, const char *flag, const char *text, uint32_t *width,
                    uint32_t *height) {
  const char *x = strchr(text, 'x');
  char w[32];
  unsigned long long vw, vh;
  if (!x || (size_t)(x - text) >= sizeof w)
    cli_usage_error(cmd, "%s: expected WIDTHxHEIGHT such as 320x180, got '%s'", flag, text);
  memcpy(w, text, (size_t)(x - text));
  w[x - text] = '\0';
  if (!parse_u64(w, &vw) || !parse_u64(x + 1, &vh))
    cli_usage_error(cmd, "%s: expected WIDTHxHEIGHT such as 320x180, got '%s'", flag, text);
  if (vw < 1 || vh < 1 || vw > 16384 || vh > 16384)
    cli_usage_error(cmd, "%s: %s is outside 1x1 .. 16384x16384", flag, text);
  *width = (uint32_t)vw;
  *height = (uint32_t)vh;
}

void cli_parse_range(const char *cmd, const char *flag, const char *text, uint32_t *first,
                     uint32_t *last) {
  const char *colon = strchr(text, ':');
  unsigned long long a = 0, b = UINT32_MAX;
  char left[32];
  if (!colon) {
    if (!parse_u64(text, &a) || a >= UINT32_MAX)
      cli_usage_error(cmd, "%s: expected A:B or A, got '%s'", flag, text);
    *first = (uint32_t)a;
    *last = (uint32_t)a + 1;
    return;
  }
  if ((size_t)(colon - text) >= sizeof left)
    cli_usage_error(cmd, "%s: expected A:B, got '%s'", flag, text);
  memcpy(left, text, (size_t)(colon - text));
  left[colon - text] = '\0';
  if ((left[0] && !parse_u64(left, &a)) || (colon[1] && !parse_u64(colon + 1, &b)) ||
      a > UINT32_MAX || b > UINT32_MAX)
    cli_usage_error(cmd, "%s: expected A:B (frames A to B-1), got '%s'", flag, text);
  if (b <= a) cli_usage_error(cmd, "%s: %s selects no frames (B must be greater than A)", flag, text);
  *first = (uint32_t)a;
  *last = (uint32_t)b;
}

hush_tonemap cli_parse_tonemap(const char *cmd, const char *flag, const char *text) {
  if (strcmp(text, "clamp") == 0) return HUSH_TONEMAP_CLAMP;
  if (strcmp(text, "reinhard") == 0) return HUSH_TONEMAP_REINHARD;
  if (strcmp(text, "aces") == 0) return HUSH_TONEMAP_ACES;
  cli_usage_error(cmd, "%s: unknown tone mapping '%s' (one of: clamp, reinhard, aces)", flag, text);
}

/* ---- device and files --------------------------------------------------- */

hush_device cli_device_new(const char *cmd, uint32_t threads) {
  char config[64];
  snprintf(config, sizeof config, "threads=%u", threads);
  hush_device device = hush_device_new(config);
  if (!device) cli_device_error(cmd, NULL, HUSH_ERROR_UNKNOWN, "cannot create a device");
  return device;
}

int cli_is_dir(const char *path) {
  struct stat sb;
  return stat(path, &sb) == 0 && S_ISDIR(sb.st_mode);
}

void cli_extension(const char *path, char *buf, size_t size) {
  const char *base = cli_basename(path);
  const char *dot = strrchr(base, '.');
  size_t n = 0;
  if (dot && dot != base)
    for (const char *c = dot + 1; *c && n + 1 < size; c++) buf[n++] = (char)tolower((unsigned char)*c);
  if (size) buf[n] = '\0';
}

const char *cli_basename(const char *path) {
  const char *slash = strrchr(path, '/');
  return slash ? slash + 1 : path;
}

void cli_layer_channels(const char *layer, int channels, char *buf, size_t size) {
  buf[0] = '\0';
  for (int c = 0; c < channels && c < 4; c++) {
    char name[HUSH_EXR_NAME_MAX];
    hush__exr_channel_name(layer, channels, c, name);
    const size_t len = strlen(buf);
    snprintf(buf + len, size - len, "%s%s", c ? ", " : "", name);
  }
}

/* Whether the frame has layer `name`, without hush_frame_get_layer's
 * error: the device keeps its first error, so a missing optional layer
 * must not leave one behind to mask a later, real failure. */
static int frame_has_layer(hush_frame frame, const char *name) {
  for (uint32_t i = 0; i < hush_frame_layer_count(frame); i++)
    if (strcmp(hush_frame_layer_name(frame, i), name) == 0) return 1;
  return 0;
}

static int is_nca_weights(hush_filter filter, const char *key) {
  return strcmp(key, "weights") == 0 && strcmp(hush_filter_get_class(filter)->name, "nca") == 0;
}

hush_status cli_filter_set(hush_filter filter, const char *key, const char *value) {
  if (is_nca_weights(filter, key))
    return hush_nca_load_weights(filter, strcmp(value, "builtin") == 0 ? NULL : value);
  return hush_filter_set_string(filter, key, value);
}

int cli_filter_has_param(hush_filter filter, const char *key) {
  if (is_nca_weights(filter, key)) return 1;
  const hush_filter_class_info *cls = hush_filter_get_class(filter);
  for (uint32_t k = 0; k < cls->param_count; k++)
    if (strcmp(cls->params[k].name, key) == 0) return 1;
  return 0;
}

int cli_bind_inputs(const char *cmd, hush_device device, hush_filter filter, hush_frame frame,
                    const char *file) {
  const hush_filter_class_info *cls = hush_filter_get_class(filter);
  for (uint32_t i = 0; i < cls->image_count; i++) {
    const hush_image_info *im = &cls->images[i];
    if (im->role != HUSH_IMAGE_INPUT) continue;
    hush_image_view view;
    if (!frame_has_layer(frame, im->name) ||
        hush_frame_get_layer(frame, im->name, &view) != HUSH_OK) {
      if (im->required) {
        char channels[128];
        cli_layer_channels(im->name, im->channels, channels, sizeof channels);
        return cli_error(cmd, "%s has no '%s' layer (channels %s), which filter '%s' requires",
                         file, im->name, channels, cls->name);
      }
      /* a view into the previous frame must not outlive it */
      hush_filter_unset_image(filter, im->name);
      continue;
    }
    const int have = hush_format_channels(view.format);
    if (have < im->channels)
      return cli_error(cmd, "%s: layer '%s' has %d channel%s, filter '%s' needs %d", file,
                       im->name, have, have == 1 ? "" : "s", cls->name, im->channels);
    const hush_status st = hush_filter_set_image(filter, im->name, &view);
    if (st != HUSH_OK) return cli_device_error(cmd, device, st, file);
  }
  return 0;
}

void cli_json_string(FILE *f, const char *s) {
  fputc('"', f);
  for (; *s; s++) {
    const unsigned char c = (unsigned char)*s;
    if (c == '"' || c == '\\')
      fprintf(f, "\\%c", c);
    else if (c < 0x20)
      fprintf(f, "\\u%04x", c);
    else
      fputc(c, f);
  }
  fputc('"', f);
}
