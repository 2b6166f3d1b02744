/*
 * timer.h — a monotonic wall clock in milliseconds, for stage timings.
 */
#ifndef HUSH_CORE_TIMER_H
#define HUSH_CORE_TIMER_H

#include <time.h>

static inline double hush__now_ms(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

#endif
