/*
 * fminmax.h — fmaxf and fminf as inline code for the renderer's hot paths.
 * Without -ffinite-math-only the compiler calls libm's fmaxf/fminf through
 * the PLT (their NaN rule does not match maxss/minss), ~3% of a 1 spp
 * render. These follow the same rule (a NaN argument yields the other
 * one), so results are bit-identical; only the sign of a zero may differ
 * when comparing -0 with +0, which C leaves unspecified as well.
 */
#ifndef HUSH_RENDER_FMINMAX_H
#define HUSH_RENDER_FMINMAX_H

static inline float hush_fmaxf(float a, float b) {
  return (a > b || b != b) ? a : b;
}

static inline float hush_fminf(float a, float b) {
  return (a < b || b != b) ? a : b;
}

#endif
