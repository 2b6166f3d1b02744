/*
 * device.h — the device object: configuration, reference count, the first
 * unread error and the callbacks. Every library function that can fail
 * reports through hush__fail() and returns its status.
 */
#ifndef HUSH_CORE_DEVICE_H
#define HUSH_CORE_DEVICE_H

#include "hush.h"

#include <stdarg.h>

#define HUSH_MESSAGE_MAX 1024

struct hush_device_t {
  int refcount;
  int threads; /* resolved, >= 1 */
  int verbose;
  size_t memory_limit; /* bytes a filter may allocate; resolved, > 0 */
  hush_status error;           /* first unread error, HUSH_OK if none */
  char message[HUSH_MESSAGE_MAX];
  char read_message[HUSH_MESSAGE_MAX]; /* what get_error handed out last */
  hush_error_fn error_fn;
  void *error_user;
  hush_log_fn log_fn;
  void *log_user;
};

#if defined(__GNUC__)
#  define HUSH_PRINTF(a, b) __attribute__((format(printf, a, b)))
#else
#  define HUSH_PRINTF(a, b)
#endif

/*
 * Records an error on the device (kept if it is the first unread one, always
 * passed to the callback) and returns status, so callers can write
 *   return hush__fail(dev, HUSH_ERROR_INVALID_ARGUMENT, "width is 0");
 * device may be NULL: the error then goes to the calling thread's slot that
 * hush_device_get_error(NULL, ...) reads.
 */
hush_status hush__fail(hush_device device, hush_status status, const char *fmt, ...)
    HUSH_PRINTF(3, 4);
hush_status hush__vfail(hush_device device, hush_status status, const char *fmt, va_list ap);

/* The bytes a filter may allocate on device, at commit and execute together
 * (its "memory" option, else the machine's memory or its cgroup's limit). */
size_t hush__device_memory_limit(hush_device device);

/* Sends a message to the log callback when device->verbose >= level. */
void hush__log(hush_device device, int level, const char *fmt, ...) HUSH_PRINTF(3, 4);

#endif
