/*
 * check.h — the minimal test harness every test program uses: CHECK records a
 * failure with file and line and goes on; main() returns check_summary(),
 * which prints "N passed, M failed" and is non-zero on any failure.
 */
#ifndef HUSH_TESTS_CHECK_H
#define HUSH_TESTS_CHECK_H

#include <math.h>
#include <stdio.h>
#include <stdlib.h>

static int check_passed_count = 0;
static int check_failed_count = 0;

#define CHECK(cond)                                                                  \
  do {                                                                               \
    if (cond) {                                                                      \
      check_passed_count++;                                                          \
    } else {                                                                         \
      check_failed_count++;                                                          \
      fprintf(stderr, "%s:%d: CHECK failed: %s\n", __FILE__, __LINE__, #cond);       \
    }                                                                                \
  } while (0)

#define CHECK_MSG(cond, ...)                                                         \
  do {                                                                               \
    if (cond) {                                                                      \
      check_passed_count++;                                                          \
    } else {                                                                         \
      check_failed_count++;                                                          \
      fprintf(stderr, "%s:%d: CHECK failed: %s: ", __FILE__, __LINE__, #cond);       \
      fprintf(stderr, __VA_ARGS__);                                                  \
      fprintf(stderr, "\n");                                                         \
    }                                                                                \
  } while (0)

#define CHECK_NEAR(a, b, tol)                                                        \
  CHECK_MSG(fabs((double)(a) - (double)(b)) <= (double)(tol), "%s = %.9g, %s = %.9g", \
            #a, (double)(a), #b, (double)(b))

/* Fails and stops the program: for set-up steps the rest depends on. */
#define REQUIRE(cond)                                                                \
  do {                                                                               \
    if (!(cond)) {                                                                   \
      fprintf(stderr, "%s:%d: REQUIRE failed: %s\n", __FILE__, __LINE__, #cond);     \
      exit(1);                                                                       \
    }                                                                                \
    check_passed_count++;                                                            \
  } while (0)

static inline int check_summary(void) {
  printf("%d passed, %d failed\n", check_passed_count, check_failed_count);
  return check_failed_count ? 1 : 0;
}

#endif
