/*
 * test_lag.c — the lag measures of eval/lag.h on synthetic frames whose
 * answer is known: the box average keeps a constant and spreads an impulse
 * evenly (clipped at the edges); the changed region is exactly the pixels that stepped;
 * an exponential moving average with weight a after a step is within 10%
 * after the frames 0.6 (1 - a)^(k+1) <= 0.1 * 0.2 predicts, no history
 * gives 0 and a filter that never follows gives -1; split by sign, the
 * brightened and darkened parts are exactly the pixels that stepped up and
 * down, and where one part brightens as much as another darkens (a light
 * that jumps) a trailing filter reads 0 unsigned but its EMA lag by sign;
 * the shift lag finds an
 * integer delay exactly, a half-frame blend at k + 0.5, keeps it under
 * noise, and an exponential moving average on a steady ramp trails it by
 * (1 - a) / a frames; the shift region chosen once over the run reads 0
 * for an output with no history where one chosen per frame reads more.
 */
#include "check.h"

#include "core/rng.h"
#include "eval/lag.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define W 64
#define H 48
#define N (W * H)
#define FRAMES 24

static float prev[N], cur[N], mask[N];

/* Lit square: pixels with 16 <= x < 40, 8 <= y < 30. */
static int lit(int i) {
  const int x = i % W, y = i / W;
  return x >= 16 && x < 40 && y >= 8 && y < 30;
}

/* The box average: a constant stays, an impulse spreads 1/(2r+1)^2 over
 * the box inside and more where the box is clipped at an edge. */
static void test_box(void) {
  static float in[N], tmp[N], out[N];
  for (int i = 0; i < N; i++) in[i] = 0.25f;
  hush__lag_box(in, W, H, 3, tmp, out);
  int same = 1;
  for (int i = 0; i < N; i++) same &= fabsf(out[i] - 0.25f) < 1e-6f;
  CHECK(same);
  memset(in, 0, sizeof in);
  in[20 * W + 30] = 49.0f;
  hush__lag_box(in, W, H, 3, tmp, out);
  CHECK_NEAR(out[20 * W + 30], 1.0, 1e-6);
  CHECK_NEAR(out[23 * W + 27], 1.0, 1e-6);
  CHECK(out[24 * W + 30] == 0.0f && out[20 * W + 34] == 0.0f);
  memset(in, 0, sizeof in);
  in[0] = 16.0f; /* the corner's box holds 4 x 4 pixels */
  hush__lag_box(in, W, H, 3, tmp, out);
  CHECK_NEAR(out[0], 1.0, 1e-6);
}

/* A saturated pixel marks its box, and only its box, NaN; NaN is never in
 * a region. */
static void test_saturated(void) {
  static float y[N], tmp[N], ind[N], boxed[N], other[N], m[N];
  for (int i = 0; i < N; i++) y[i] = boxed[i] = 0.5f, other[i] = 0.0f;
  y[20 * W + 30] = 1.0f;
  hush__lag_mark_saturated(y, W, H, 2, tmp, ind, boxed);
  int marked = 0, right = 1;
  for (int i = 0; i < N; i++) {
    const int near = abs(i % W - 30) <= 2 && abs(i / W - 20) <= 2;
    marked += isnan(boxed[i]);
    right &= near ? isnan(boxed[i]) : boxed[i] == 0.5f;
  }
  CHECK(marked == 25 && right);
  CHECK(hush__lag_region(other, boxed, N, HUSH_LAG_THRESHOLD, m) == (size_t)(N - 25));
}

static void test_region(void) {
  for (int i = 0; i < N; i++) {
    const float noise = 0.016f * (hush_rng_float(3, 0, (uint32_t)i) - 0.5f);
    prev[i] = (lit(i) ? 0.8f : 0.2f) + noise;
    cur[i] = 0.2f - noise;
  }
  const size_t count = hush__lag_region(prev, cur, N, HUSH_LAG_THRESHOLD, mask);
  CHECK(count == 24 * 22);
  int same = 1;
  for (int i = 0; i < N; i++) same &= (mask[i] == 1.0f) == lit(i);
  CHECK(same);
  /* the region mean is over the region only */
  CHECK_NEAR(hush__lag_region_mean(prev, mask, N), 0.8, 0.02);
  memset(mask, 0, sizeof mask);
  CHECK(isnan(hush__lag_region_mean(prev, mask, N)));
}

/* An EMA of weight a follows a step 0.8 -> 0.2 at frame 0 of the series:
 * out(k) = 0.2 + 0.6 (1 - a)^(k + 1). */
static int ema_event_lag(double a) {
  double out[FRAMES], ref[FRAMES];
  double y = 0.8;
  for (int k = 0; k < FRAMES; k++) {
    y = (1.0 - a) * y + a * 0.2;
    for (int i = 0; i < N; i++) cur[i] = lit(i) ? (float)y : 0.2f;
    out[k] = hush__lag_region_mean(cur, mask, N);
    ref[k] = 0.2;
  }
  return hush__lag_event(out, ref, FRAMES, HUSH_LAG_TOLERANCE);
}

static void test_event(void) {
  for (int i = 0; i < N; i++) mask[i] = lit(i) ? 1.0f : 0.0f;
  /* within 10% of 0.2: 0.6 (1 - a)^(k + 1) <= 0.02 */
  const double alphas[] = {0.2, 0.3, 0.5};
  for (int j = 0; j < 3; j++) {
    const double a = alphas[j];
    const int expected = (int)ceil(log(0.02 / 0.6) / log(1.0 - a) - 1.0 - 1e-9);
    CHECK_MSG(ema_event_lag(a) == expected, "alpha %g: lag %d, expected %d", a, ema_event_lag(a),
              expected);
  }
  CHECK(ema_event_lag(0.2) >= 5); /* svgf's alpha trails by 5 frames or more */
  CHECK(ema_event_lag(1.0) == 0); /* no history: at the reference at once */
  CHECK(ema_event_lag(0.0) == -1); /* never follows */
}

/* Signed region: the lit square darkens, the band below it (y >= 34)
 * brightens, the rest stays; NaN is in neither part. */
static void test_region_signed(void) {
  static float m[N];
  for (int i = 0; i < N; i++) {
    const int band = i / W >= 34;
    prev[i] = lit(i) ? 0.8f : 0.2f;
    cur[i] = lit(i) ? 0.2f : band ? 0.6f : 0.2f;
  }
  prev[0] = NAN;
  size_t part[2];
  const size_t c = hush__lag_region_signed(prev, cur, N, HUSH_LAG_THRESHOLD, m, part);
  CHECK(part[0] == (size_t)(14 * W) && part[1] == 24 * 22 && c == part[0] + part[1]);
  int right = 1;
  for (int i = 0; i < N; i++)
    right &= m[i] == (lit(i) ? -1.0f : i / W >= 34 ? 1.0f : 0.0f);
  CHECK(right);
  CHECK_NEAR(hush__lag_region_mean_of(cur, m, 1.0f, N), 0.6, 1e-6);
  CHECK_NEAR(hush__lag_region_mean_of(cur, m, -1.0f, N), 0.2, 1e-6);
  memset(m, 0, sizeof m);
  CHECK(isnan(hush__lag_region_mean_of(cur, m, 1.0f, N)));
}

/* A light that jumps: one region of equal size goes 0.2 -> 0.6, another
 * 0.6 -> 0.2, and a filter that keeps history (an EMA of weight 0.2)
 * trails both. Over the whole changed region the two errors cancel
 * exactly, so the unsigned event lag reads 0; by sign it is the EMA's lag
 * on a step of 0.4 towards 0.2: 0.4 (0.8)^(k+1) <= 0.02, k = 13 (the
 * brightened part, 0.6, is within 10% sooner: 0.4 (0.8)^(k+1) <= 0.06). */
static void test_event_signed(void) {
  static float ref[N], out[N], m[N], before[N], after[N];
  /* the left half of the square brightens, the right half darkens */
  for (int i = 0; i < N; i++) {
    const int up = lit(i) && i % W < 28, down = lit(i) && i % W >= 28;
    before[i] = up ? 0.2f : down ? 0.6f : 0.4f;
    after[i] = up ? 0.6f : down ? 0.2f : 0.4f;
  }
  size_t part[2];
  hush__lag_region_signed(before, after, N, HUSH_LAG_THRESHOLD, m, part);
  CHECK(part[0] == part[1] && part[0] > 0);
  for (int i = 0; i < N; i++) mask[i] = m[i] != 0.0f ? 1.0f : 0.0f;
  double all_out[FRAMES], all_ref[FRAMES], s_out[2][FRAMES], s_ref[2][FRAMES];
  memcpy(out, before, sizeof out);
  memcpy(ref, after, sizeof ref);
  for (int k = 0; k < FRAMES; k++) {
    for (int i = 0; i < N; i++) out[i] = 0.8f * out[i] + 0.2f * ref[i];
    all_out[k] = hush__lag_region_mean(out, mask, N);
    all_ref[k] = hush__lag_region_mean(ref, mask, N);
    for (int s = 0; s < 2; s++) {
      s_out[s][k] = hush__lag_region_mean_of(out, m, s ? -1.0f : 1.0f, N);
      s_ref[s][k] = hush__lag_region_mean_of(ref, m, s ? -1.0f : 1.0f, N);
    }
  }
  CHECK(hush__lag_event(all_out, all_ref, FRAMES, HUSH_LAG_TOLERANCE) == 0);
  const double *const o2[2] = {s_out[0], s_out[1]}, *const r2[2] = {s_ref[0], s_ref[1]};
  const int both[2] = {1, 1}, up_only[2] = {1, 0}, none[2] = {0, 0};
  const int lag_down = (int)ceil(log(0.02 / 0.4) / log(0.8) - 1.0 - 1e-9);
  const int lag_up = (int)ceil(log(0.06 / 0.4) / log(0.8) - 1.0 - 1e-9);
  CHECK(lag_down == 13 && lag_up > 0 && lag_up < lag_down);
  CHECK_MSG(hush__lag_event_signed(o2, r2, both, FRAMES, HUSH_LAG_TOLERANCE) == lag_down,
            "signed lag %d, expected %d",
            hush__lag_event_signed(o2, r2, both, FRAMES, HUSH_LAG_TOLERANCE), lag_down);
  CHECK(hush__lag_event_signed(o2, r2, up_only, FRAMES, HUSH_LAG_TOLERANCE) == lag_up);
  CHECK(hush__lag_event_signed(o2, r2, none, FRAMES, HUSH_LAG_TOLERANCE) == -2);
  /* a part that never follows makes the event's lag -1 */
  for (int k = 0; k < FRAMES; k++) s_out[1][k] = 0.6;
  CHECK(hush__lag_event_signed(o2, r2, both, FRAMES, HUSH_LAG_TOLERANCE) == -1);
  /* no history: 0 */
  CHECK(hush__lag_event_signed(r2, r2, both, FRAMES, HUSH_LAG_TOLERANCE) == 0);
}

/* A pattern moving one pixel per frame: ref(t)(x) = ramp of x - t. */
static float ramp(int i, double t) {
  const double x = i % W, y = i / W;
  return (float)(0.3 + 0.004 * (x - t) + 0.002 * y);
}

static float refs[FRAMES][N];

static double shift_of(float (*out)[N], int first) {
  double sse[HUSH_LAG_MAX_SHIFT] = {0};
  const float *ring[HUSH_LAG_MAX_SHIFT];
  for (int t = first; t < FRAMES; t++) {
    for (uint32_t k = 0; k < HUSH_LAG_MAX_SHIFT; k++) ring[k] = refs[t - (int)k];
    hush__lag_shift_add(out[t], ring, NULL, HUSH_LAG_MAX_SHIFT, N, sse);
  }
  return hush__lag_shift(sse, HUSH_LAG_MAX_SHIFT);
}

static float outs[FRAMES][N];

static void test_shift(void) {
  for (int t = 0; t < FRAMES; t++)
    for (int i = 0; i < N; i++) refs[t][i] = ramp(i, t);
  const int first = (int)HUSH_LAG_MAX_SHIFT;
  /* an exact copy: 0; a copy 3 frames late: 3 */
  CHECK(shift_of(refs, first) == 0.0);
  for (int t = 0; t < FRAMES; t++)
    for (int i = 0; i < N; i++) outs[t][i] = ramp(i, t - 3);
  CHECK_NEAR(shift_of(outs, first), 3.0, 1e-9);
  /* halfway between 2 and 3 frames late */
  for (int t = 0; t < FRAMES; t++)
    for (int i = 0; i < N; i++) outs[t][i] = 0.5f * (ramp(i, t - 2) + ramp(i, t - 3));
  CHECK_NEAR(shift_of(outs, first), 2.5, 1e-3);
  /* the same under noise of 5x the per-frame change */
  for (int t = 0; t < FRAMES; t++)
    for (int i = 0; i < N; i++)
      outs[t][i] = ramp(i, t - 4) + 0.02f * (hush_rng_float(7, (uint32_t)t, (uint32_t)i) - 0.5f);
  CHECK_NEAR(shift_of(outs, first), 4.0, 0.1);
  /* EMA of weight a on the ramp trails by (1 - a) / a once settled (it
   * starts settled) */
  const double a = 0.25;
  for (int i = 0; i < N; i++) outs[0][i] = ramp(i, -(1.0 - a) / a);
  for (int t = 1; t < FRAMES; t++)
    for (int i = 0; i < N; i++)
      outs[t][i] = (float)((1.0 - a) * outs[t - 1][i] + a * refs[t][i]);
  CHECK_NEAR(shift_of(outs, first), (1.0 - a) / a, 0.1);
  /* the argmin stays inside 0..S-1 */
  double sse[3] = {3.0, 2.0, 1.0};
  CHECK(hush__lag_shift(sse, 3) == 2.0);
  CHECK(isnan(hush__lag_shift(sse, 0)));
}

/* The shift region over the run against one per frame. The truth changes
 * slowly, by 0 to 0.042 over the 8 frames the shifts span (slope x / W
 * times 0.006 per frame), across the threshold; the references add
 * independent noise (sigma about 0.06, 0.009 in the box), the outputs none
 * (a filter's own noise would only add to every shift alike). A region chosen per frame t from references t and
 * t - 7 picks the pixels where their noise exaggerates the change, so
 * shifts 0 and 7 match worse and the no-history output reads a lag; the
 * one region over the run reads 0 for it, and (1 - a) / a for an
 * exponential average of weight a. */
#define RW 192
#define RH 128
#define RN (RW * RH)

static float truth(int i, int t) {
  return (float)(0.3 + 0.006 * (double)(i % RW) / RW * t);
}

static float noisy_refs[FRAMES][RN], boxed[FRAMES][RN], routs[FRAMES][RN];

static double shift_per_frame(float (*out)[RN]) {
  double sse[HUSH_LAG_MAX_SHIFT] = {0};
  const float *ring[HUSH_LAG_MAX_SHIFT];
  static float m[RN];
  const int S = (int)HUSH_LAG_MAX_SHIFT;
  for (int t = S - 1; t < FRAMES; t++) {
    for (int k = 0; k < S; k++) ring[k] = noisy_refs[t - k];
    hush__lag_region(boxed[t - S + 1], boxed[t], RN, HUSH_LAG_THRESHOLD, m);
    hush__lag_shift_add(out[t], ring, m, (uint32_t)S, RN, sse);
  }
  return hush__lag_shift(sse, (uint32_t)S);
}

static double shift_over_run(float (*out)[RN], size_t *region) {
  static float pixels[(size_t)RN * HUSH_LAG_MAX_SHIFT];
  static float lo[RN], hi[RN], m[RN];
  memset(pixels, 0, sizeof pixels);
  const float *ring[HUSH_LAG_MAX_SHIFT];
  const int S = (int)HUSH_LAG_MAX_SHIFT;
  for (int i = 0; i < RN; i++) lo[i] = INFINITY, hi[i] = -INFINITY;
  for (int t = 0; t < FRAMES; t++) {
    hush__lag_range_add(boxed[t], RN, lo, hi);
    if (t < S - 1) continue;
    for (int k = 0; k < S; k++) ring[k] = noisy_refs[t - k];
    hush__lag_shift_add_pixels(out[t], ring, (uint32_t)S, RN, pixels);
  }
  *region = hush__lag_range_region(lo, hi, RN, HUSH_LAG_THRESHOLD, m);
  double sse[HUSH_LAG_MAX_SHIFT];
  hush__lag_shift_sum(pixels, m, (uint32_t)S, RN, sse);
  return hush__lag_shift(sse, (uint32_t)S);
}

static float gauss(uint32_t seed, int t, int i) {
  /* sum of 4 uniforms: mean 0, sigma 0.06 */
  float g = 0.0f;
  for (uint32_t j = 0; j < 4; j++)
    g += hush_rng_float(seed + j, (uint32_t)t, (uint32_t)i) - 0.5f;
  return 0.104f * g;
}

static void test_shift_region(void) {
  static float tmp[RN];
  for (int t = 0; t < FRAMES; t++) {
    for (int i = 0; i < RN; i++) {
      /* and a firefly in one pixel of 200, as in a reference of a few
       * dozen samples */
      const float firefly = hush_rng_float(31, (uint32_t)t, (uint32_t)i) < 0.005f ? 0.6f : 0.0f;
      noisy_refs[t][i] = truth(i, t) + gauss(11, t, i) + firefly;
      routs[t][i] = truth(i, t);
    }
    hush__lag_box(noisy_refs[t], RW, RH, HUSH_LAG_RADIUS, tmp, boxed[t]);
  }
  size_t region = 0;
  const double per_frame = shift_per_frame(routs), over_run = shift_over_run(routs, &region);
  CHECK_MSG(per_frame > 0.3, "per-frame region: no history reads %g", per_frame);
  CHECK_MSG(fabs(over_run) < 0.15, "region over the run: no history reads %g", over_run);
  CHECK(region > RN / 4);
  /* an EMA of weight 0.25 of the truth, settled */
  const double a = 0.25;
  static float ema[FRAMES][RN];
  for (int t = 0; t < FRAMES; t++)
    for (int i = 0; i < RN; i++) {
      const float prev_e = t ? ema[t - 1][i] : (float)(truth(i, 0) - 4.0 * (truth(i, 1) - truth(i, 0)));
      ema[t][i] = (float)((1.0 - a) * prev_e + a * truth(i, t));
    }
  for (int t = 0; t < FRAMES; t++)
    for (int i = 0; i < RN; i++) routs[t][i] = ema[t][i];
  const double lagged = shift_over_run(routs, &region);
  CHECK_MSG(fabs(lagged - (1.0 - a) / a) < 0.5, "EMA 0.25: %g, expected 3", lagged);
  /* a saturated neighbour (NaN in the box) leaves a pixel out for good */
  float lo[2] = {INFINITY, INFINITY}, hi[2] = {-INFINITY, -INFINITY}, m[2];
  const float f0[2] = {0.1f, 0.1f}, f1[2] = {NAN, 0.5f}, f2[2] = {0.6f, 0.1f};
  hush__lag_range_add(f0, 2, lo, hi);
  hush__lag_range_add(f1, 2, lo, hi);
  hush__lag_range_add(f2, 2, lo, hi);
  CHECK(hush__lag_range_region(lo, hi, 2, HUSH_LAG_THRESHOLD, m) == 1 && m[0] == 0.0f &&
        m[1] == 1.0f);
}

int main(void) {
  test_box();
  test_saturated();
  test_region();
  test_event();
  test_region_signed();
  test_event_signed();
  test_shift();
  test_shift_region();
  return check_summary();
}
