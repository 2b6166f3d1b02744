/*
 * device.c — hush_device: configuration string, reference counting, the
 * first-unread-error slot with its message, and the error and log callbacks.
 * The library never prints; everything goes through here.
 */
#include "core/device.h"

#include <errno.h>
#include <limits.h>
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* The error of a failed hush_device_new() (no device to hold it), per thread
 * as in Open Image Denoise's oidnGetDeviceError(NULL). */
static _Thread_local hush_status thread_error = HUSH_OK;
static _Thread_local char thread_message[HUSH_MESSAGE_MAX];
static _Thread_local char thread_read_message[HUSH_MESSAGE_MAX];

const char *hush_version(void) { return HUSH_VERSION_STRING; }

const char *hush_status_name(hush_status status) {
  switch (status) {
  case HUSH_OK: return "HUSH_OK";
  case HUSH_ERROR_UNKNOWN: return "HUSH_ERROR_UNKNOWN";
  case HUSH_ERROR_INVALID_ARGUMENT: return "HUSH_ERROR_INVALID_ARGUMENT";
  case HUSH_ERROR_INVALID_OPERATION: return "HUSH_ERROR_INVALID_OPERATION";
  case HUSH_ERROR_OUT_OF_MEMORY: return "HUSH_ERROR_OUT_OF_MEMORY";
  case HUSH_ERROR_NOT_FOUND: return "HUSH_ERROR_NOT_FOUND";
  case HUSH_ERROR_OUT_OF_RANGE: return "HUSH_ERROR_OUT_OF_RANGE";
  case HUSH_ERROR_TYPE_MISMATCH: return "HUSH_ERROR_TYPE_MISMATCH";
  case HUSH_ERROR_NONFINITE: return "HUSH_ERROR_NONFINITE";
  case HUSH_ERROR_IO: return "HUSH_ERROR_IO";
  case HUSH_ERROR_CORRUPT: return "HUSH_ERROR_CORRUPT";
  case HUSH_ERROR_UNSUPPORTED: return "HUSH_ERROR_UNSUPPORTED";
  }
  return "HUSH_ERROR_UNKNOWN";
}

hush_status hush__vfail(hush_device device, hush_status status, const char *fmt, va_list ap) {
  char text[HUSH_MESSAGE_MAX];
  vsnprintf(text, sizeof text, fmt, ap);
  if (!device) {
    if (thread_error == HUSH_OK) {
      thread_error = status;
      memcpy(thread_message, text, sizeof text);
    }
    return status;
  }
  if (device->error == HUSH_OK) {
    device->error = status;
    memcpy(device->message, text, sizeof text);
  }
  if (device->error_fn) device->error_fn(device->error_user, status, text);
  return status;
}

hush_status hush__fail(hush_device device, hush_status status, const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  hush__vfail(device, status, fmt, ap);
  va_end(ap);
  return status;
}

void hush__log(hush_device device, int level, const char *fmt, ...) {
  if (!device || !device->log_fn || device->verbose < level) return;
  char text[HUSH_MESSAGE_MAX];
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(text, sizeof text, fmt, ap);
  va_end(ap);
  device->log_fn(device->log_user, level, text);
}

/* Parses a non-negative decimal integer that must fill [s, end). */
static int parse_int(const char *s, size_t len, int *out) {
  if (len == 0 || len > 9) return 0;
  int v = 0;
  for (size_t i = 0; i < len; i++) {
    if (s[i] < '0' || s[i] > '9') return 0;
    v = v * 10 + (s[i] - '0');
  }
  *out = v;
  return 1;
}

static hush_status apply_option(hush_device d, const char *key, size_t key_len, const char *val,
                                size_t val_len) {
  int v;
  if (key_len == 7 && memcmp(key, "threads", 7) == 0) {
    if (!parse_int(val, val_len, &v) || v > 1024)
      return hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT,
                        "device config: threads must be an integer in [0, 1024], got '%.*s'",
                        (int)val_len, val);
    d->threads = v;
    return HUSH_OK;
  }
  if (key_len == 7 && memcmp(key, "verbose", 7) == 0) {
    if (!parse_int(val, val_len, &v) || v > 2)
      return hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT,
                        "device config: verbose must be 0, 1 or 2, got '%.*s'", (int)val_len, val);
    d->verbose = v;
    return HUSH_OK;
  }
  if (key_len == 6 && memcmp(key, "memory", 6) == 0) {
    if (!parse_int(val, val_len, &v))
      return hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT,
                        "device config: memory must be a number of MiB in [0, 999999999], got "
                        "'%.*s'",
                        (int)val_len, val);
    d->memory_limit = (size_t)v << 20;
    return HUSH_OK;
  }
  return hush__fail(NULL, HUSH_ERROR_NOT_FOUND,
                    "device config: unknown option '%.*s' (known: threads, verbose, memory)",
                    (int)key_len, key);
}

static hush_status parse_config(hush_device d, const char *config) {
  const char *p = config;
  while (*p) {
    while (*p == ' ' || *p == ',') p++;
    if (!*p) break;
    const char *item = p;
    while (*p && *p != ',') p++;
    const char *item_end = p;
    while (item_end > item && item_end[-1] == ' ') item_end--;
    const char *eq = memchr(item, '=', (size_t)(item_end - item));
    if (!eq)
      return hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT,
                        "device config: expected key=value, got '%.*s'", (int)(item_end - item),
                        item);
    hush_status s = apply_option(d, item, (size_t)(eq - item), eq + 1,
                                 (size_t)(item_end - eq - 1));
    if (s != HUSH_OK) return s;
  }
  return HUSH_OK;
}

/* The machine's physical memory, or the cgroup (v2) limit of the process
 * if lower: what a filter may take before the kernel kills the process
 * (Linux grants more than it has and kills whoever touches the excess). */
static size_t machine_memory(void) {
  size_t bytes = SIZE_MAX;
  const long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGESIZE);
  if (pages > 0 && page > 0 && (unsigned long)pages <= SIZE_MAX / (unsigned long)page)
    bytes = (size_t)pages * (size_t)page;
  FILE *f = fopen("/sys/fs/cgroup/memory.max", "r"); /* "max" when unlimited */
  if (f) {
    unsigned long long limit = 0;
    if (fscanf(f, "%llu", &limit) == 1 && limit > 0 && limit < bytes) bytes = (size_t)limit;
    fclose(f);
  }
  return bytes;
}

hush_device hush_device_new(const char *config) {
  hush_device d = calloc(1, sizeof *d);
  if (!d) {
    hush__fail(NULL, HUSH_ERROR_OUT_OF_MEMORY, "out of memory creating a device");
    return NULL;
  }
  d->refcount = 1;
  if (config && parse_config(d, config) != HUSH_OK) {
    free(d);
    return NULL;
  }
  if (d->threads == 0) d->threads = omp_get_max_threads();
  if (d->threads < 1) d->threads = 1;
  if (d->memory_limit == 0) d->memory_limit = machine_memory();
  return d;
}

void hush_device_retain(hush_device device) {
  if (device) device->refcount++;
}

void hush_device_release(hush_device device) {
  if (!device) return;
  if (--device->refcount > 0) return;
  free(device);
}

hush_status hush_device_get_error(hush_device device, const char **message) {
  hush_status *slot = device ? &device->error : &thread_error;
  char *text = device ? device->message : thread_message;
  char *read_text = device ? device->read_message : thread_read_message;
  const hush_status s = *slot;
  if (s == HUSH_OK)
    read_text[0] = '\0';
  else
    memcpy(read_text, text, HUSH_MESSAGE_MAX);
  *slot = HUSH_OK;
  text[0] = '\0';
  if (message) *message = read_text;
  return s;
}

void hush_device_set_error_callback(hush_device device, hush_error_fn fn, void *user) {
  if (!device) return;
  device->error_fn = fn;
  device->error_user = user;
}

void hush_device_set_log_callback(hush_device device, hush_log_fn fn, void *user) {
  if (!device) return;
  device->log_fn = fn;
  device->log_user = user;
}

int hush_device_threads(hush_device device) { return device ? device->threads : 0; }

size_t hush__device_memory_limit(hush_device device) {
  return device ? device->memory_limit : SIZE_MAX;
}
