/*
 * lag.h — how many frames a filter's output trails a change of the lighting
 * (issue 7, A-SVGF; realtime-denoising-comparison-higginson-2023.md §2.3 and
 * papers/NOTES.md: temporal accumulation reacts to a change only as fast as
 * its history weight lets it). Two measures, both on the lag luminance Y:
 * the Rec. 709 luminance of the linear radiance clamped to [0, 1], so that
 * a light seen directly does not outweigh the rest, and linear below 1, so
 * that the mean of a noisy image (a 1 spp input, a reference of a few
 * dozen samples) is not biased, as the mean of sRGB-encoded values would
 * be. Both are defined by the references alone and are the same for every
 * filter (docs/eval.md "Lag"):
 *
 *   event lag  a change at frame K (a light switched off, a light that
 *              jumps): the changed region R is the set of pixels whose
 *              reference luminance, averaged over a (2 HUSH_LAG_RADIUS +
 *              1)^2 box, changes by more than HUSH_LAG_THRESHOLD between
 *              frames K-1 and K (the box keeps the references' own noise
 *              out: a region chosen where a noisy reference happens to
 *              change would favour bright noise in it). R is split by the
 *              sign of the change into the brightened part R+ and the
 *              darkened part R- (where a light jumps, a filter that keeps
 *              the old lighting is too dark in R+ and too bright in R-, and
 *              over all of R the two cancel). Each part that covers at
 *              least HUSH_LAG_MIN_PART of the frame is lagged: the number
 *              of frames after K until the filter's mean luminance over it
 *              is within HUSH_LAG_TOLERANCE (10%) of the reference's mean
 *              over it (0: already at K); the event lag is the larger.
 *   shift lag  continuous change (a moving light): the shift k, 0..S-1, of
 *              the reference sequence that the filter's output matches
 *              best, argmin_k of the sum over frames t and the pixels of
 *              the shift region of (Y_out(t) - Y_ref(t - k))^2, refined to
 *              a fraction of a frame by the parabola through the minimum
 *              and its two neighbours. The shift region is one set for the
 *              whole run: the pixels whose box-averaged reference ranges
 *              over more than HUSH_LAG_THRESHOLD across the frames (max -
 *              min), less those within the box of a saturated pixel, Y = 1,
 *              in any frame (a light seen directly moves with the motion
 *              vectors, which every filter follows, and its clamped edges
 *              would outweigh the shading whose history the lag is about).
 *              One region, not one per frame: a region chosen per frame t
 *              from references t and t - S + 1 is chosen where their noise
 *              happens to exaggerate the change, so those two shifts match
 *              worse than the others and an output with no history at all
 *              read a lag of 1 (tests/test_lag.c); over the whole run every
 *              reference frame's noise weighs on every shift alike. A filter that trails the reference by L frames
 *              on a steady change minimises it at k = L: the error is
 *              exactly quadratic in k - L for a linear ramp, and the
 *              noise adds the same constant to every k.
 *
 * Pure functions on caller-owned planes; deterministic.
 */
#ifndef HUSH_EVAL_LAG_H
#define HUSH_EVAL_LAG_H

#include <stddef.h>
#include <stdint.h>

/* Change of the box-averaged lag luminance that puts a pixel in the region
 * (radiance 1 is display white: 0.02 is a visible change in a dim scene). */
#define HUSH_LAG_THRESHOLD 0.02f
#define HUSH_LAG_RADIUS 3
/* "Within 10% of the reference". */
#define HUSH_LAG_TOLERANCE 0.1
/* An event needs at least this fraction of the frame to change. */
#define HUSH_LAG_MIN_REGION 0.05
/* A part of the event region (brightened, darkened) is lagged when it
 * covers at least this fraction of the frame. */
#define HUSH_LAG_MIN_PART 0.01
/* Largest shift the shift lag tries. */
#define HUSH_LAG_MAX_SHIFT 8u

/* The lag luminance of `count` interleaved RGB pixels into the plane y:
 * min(max(0.2126 R + 0.7152 G + 0.0722 B, 0), 1), NaN counts as 0. */
void hush__lag_luminance(const float *rgb, size_t count, float *y);

/* out = in averaged over the box of radius `radius` (clipped at the
 * edges) on a width x height plane; tmp: width x height floats. */
void hush__lag_box(const float *in, uint32_t width, uint32_t height, int radius, float *tmp,
                   float *out);

/* boxed[i] = NaN where a pixel within the box of radius `radius` around i
 * has y >= 1 (saturated); tmp and ind: width x height floats of scratch. */
void hush__lag_mark_saturated(const float *y, uint32_t width, uint32_t height, int radius,
                              float *tmp, float *ind, float *boxed);

/* mask[i] = 1 where |cur[i] - prev[i]| > threshold, else 0 (also where
 * either is NaN); returns the number of ones. */
size_t hush__lag_region(const float *prev, const float *cur, size_t n, float threshold,
                        float *mask);

/* The event region by sign: mask[i] = +1 where cur[i] - prev[i] >
 * threshold (brightened), -1 where it is < -threshold (darkened), else 0
 * (also where either is NaN). count[0]: the brightened pixels, count[1]:
 * the darkened ones; returns their sum. */
size_t hush__lag_region_signed(const float *prev, const float *cur, size_t n, float threshold,
                               float *mask, size_t count[2]);

/* Mean of y over the pixels where mask is 1 (NaN for an empty mask). */
double hush__lag_region_mean(const float *y, const float *mask, size_t n);

/* Mean of y over the pixels where mask equals `value` (+1, -1; NaN when
 * there are none). */
double hush__lag_region_mean_of(const float *y, const float *mask, float value, size_t n);

/*
 * Event lag: out_mean[k] and ref_mean[k] are the region means at frame
 * K + k, k < count. Returns the first k with |out - ref| <= tolerance *
 * |ref|, or -1 when no frame is within it.
 */
int hush__lag_event(const double *out_mean, const double *ref_mean, uint32_t count,
                    double tolerance);

/*
 * Event lag by sign: out_mean[s][k], ref_mean[s][k] as for hush__lag_event
 * for part s (0: brightened, 1: darkened); a part is lagged when use[s] is
 * non-zero. Returns the larger of the parts' lags, -1 when a lagged part
 * never comes within the tolerance, -2 when no part is used.
 */
int hush__lag_event_signed(const double *const out_mean[2], const double *const ref_mean[2],
                           const int use[2], uint32_t count, double tolerance);

/* Shift lag, per frame: sse[k] += sum over pixels of mask (out - ref[k])^2
 * for k < shifts, ref[k] the reference k frames before out's frame; mask
 * NULL: every pixel. */
void hush__lag_shift_add(const float *out, const float *const *ref, const float *mask,
                         uint32_t shifts, size_t n, double *sse);

/* Shift lag, per pixel: sse[i * shifts + k] += (out[i] - ref[k][i])^2 for
 * k < shifts (ref[k]: the reference k frames before out's); the region is
 * applied at the end (hush__lag_shift_sum). Float: a pixel's sum has one
 * term in [0, 1] per frame, and the memory is pixels x shifts per filter. */
void hush__lag_shift_add_pixels(const float *out, const float *const *ref, uint32_t shifts,
                                size_t n, float *sse);

/* The range of a box-averaged reference over the frames: lo = min, hi =
 * max, start them at +inf and -inf; a NaN (near a saturated pixel) makes
 * both NaN for good. */
void hush__lag_range_add(const float *boxed, size_t n, float *lo, float *hi);

/* The shift region: mask[i] = 1 where hi[i] - lo[i] > threshold, else 0
 * (NaN: 0); returns the number of ones. */
size_t hush__lag_range_region(const float *lo, const float *hi, size_t n, float threshold,
                              float *mask);

/* sse[k] = sum over i of mask[i] * pixels[i * shifts + k], k < shifts. */
void hush__lag_shift_sum(const float *pixels, const float *mask, uint32_t shifts, size_t n,
                         double *sse);

/* The shift lag from the sums of hush__lag_shift_add (shifts >= 1): the
 * argmin (the smallest on a tie), refined by the parabola through it and
 * its neighbours when it is inside. NaN when shifts is 0. */
double hush__lag_shift(const double *sse, uint32_t shifts);

#endif
