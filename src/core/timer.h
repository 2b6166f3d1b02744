/*
 * timer.h — a monotonic wall clock in milliseconds, for stage timings, and
 * the process's CPU time.
 */
#ifndef HUSH_CORE_TIMER_H
#define HUSH_CORE_TIMER_H

#include <time.h>

static inline double hush__now_ms(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

/* CPU seconds used by the whole process (all threads): the cost of a stage
 * on a shared machine, where wall time depends on what else runs. */
static inline double hush__cpu_seconds(void) {
  struct timespec ts;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

#endif
