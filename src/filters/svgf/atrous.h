/*
 * atrous.h — the levels of the edge-avoiding a-trous wavelet filter of SVGF
 * (Dundr 2018 §4.1.4.6; Schied et al. 2017 in papers/NOTES.md): a B-spline
 * kernel with taps 2^i pixels apart, every tap weighted by weights.h, the
 * colour normalised by the sum of weights and the variance filtered along
 * with the squared weights, var' = sum(h^2 w^2 var) / (sum h w)^2. The
 * luminance weight's variance is the 3x3 Gaussian of the input variance
 * (fused into the level; Dundr §4.1.3.1).
 *
 * Per row of a level, per vector of pixels, every tap with the sums in
 * registers (mirrored tap pairs share the depth-gradient denominator);
 * borders handled by the input's row padding (x) and one row clamp per tap
 * row (y). AVX-512 intrinsics where the build has them, else AVX2 + FMA
 * intrinsics (x86-64-v3 builds), else a portable loop the compiler
 * vectorises (docs/svgf-speed.md). A frame's levels run
 * one after the other or, on larger frames, together as a wavefront down
 * the rows (svgf_atrous_levels). Every pixel is computed on its own: the
 * result depends neither on the thread count nor on the schedule.
 */
#ifndef HUSH_FILTERS_SVGF_ATROUS_H
#define HUSH_FILTERS_SVGF_ATROUS_H

#include "filters/svgf/guide.h"
#include "filters/svgf/padded.h"

/* Separable kernel h[radius + i], i in [-radius, radius]. */
typedef struct svgf_kernel {
  int radius;
  float h[5];
} svgf_kernel;

extern const svgf_kernel svgf_kernel_5x5; /* B3 spline (1, 4, 6, 4, 1) / 16 (Schied 2017) */
extern const svgf_kernel svgf_kernel_3x3; /* (1, 2, 1) / 4 (Dundr 2018 §4.1.4.6) */

/* Channels of the a-trous signal planes. */
/* VALID: 1 where the pixel holds data, 0 for a hole nothing reached yet
 * (read only with svgf_level_params.validity). */
enum { SVGF_R = 0, SVGF_G, SVGF_B, SVGF_VAR, SVGF_LUM, SVGF_VALID, SVGF_SIGNAL_CHANNELS };

/* Where a level writes: SVGF_SIGNAL_CHANNELS planes at pixel (0, 0) with a
 * row stride; var and lum may be NULL (the last level needs neither); with
 * pad > 0 every written row's pad of that many pixels is filled too. ring
 * 0: the planes hold the frame; ring > 0: they hold that many rows, row y
 * at y % ring (see svgf_atrous_levels_wavefront). */
typedef struct svgf_level_out {
  float *plane[SVGF_SIGNAL_CHANNELS];
  size_t stride;
  int pad;
  int ring;
  /* optional (NULL: none): the colour also into these 3 unpadded planes
   * of width floats a row (svgf's feedback of the first level into the
   * colour history, without a copy pass) */
  float *also[3];
  /* optional (NULL: none): called by the thread that wrote pixels [xa, xb)
   * of row y, right after (svgf's export of the last level's rows while
   * they are in cache, from a ring of rows) */
  void (*span_done)(void *ctx, int y, int xa, int xb);
  void *span_ctx;
} svgf_level_out;

static inline svgf_level_out svgf_level_out_padded(svgf_padded *p) {
  svgf_level_out o;
  for (int c = 0; c < SVGF_SIGNAL_CHANNELS; c++) o.plane[c] = p->plane[c];
  o.stride = p->stride;
  o.pad = p->pad;
  o.ring = 0;
  o.also[0] = o.also[1] = o.also[2] = NULL;
  o.span_done = NULL;
  o.span_ctx = NULL;
  return o;
}

typedef struct svgf_level_params {
  const svgf_kernel *kernel;
  int step;       /* tap spacing in pixels; kernel radius * step <= the pads */
  float sigma_l;
  const float *eps_l; /* per-pixel luminance epsilon (unpadded), or NULL: SVGF_EPS_L */
  int validity;       /* taps and centre weighted by VALID (progressive, Dundr §4.2) */
  int normal_exp;     /* normal weight 2^(-sigma_n log2 e (1 - dot)), else max(0, dot)^sigma_n */
  int fast_exp;       /* with normal_exp: svgf's weight_exp=fast (weights.h, svgf_exp2_neg_fast) */
  int portable;       /* 1: never the intrinsic (AVX-512 or AVX2) loop (tests compare the two) */
  int vectors;        /* AVX-512 loop: 0 this CPU's choice, 1 or 2 vectors of pixels at a time */
} svgf_level_params;

/* in (padded, SVGF_SIGNAL_CHANNELS planes) -> out. in and out must not
 * overlap. */
void svgf_atrous_level(const svgf_guide *g, const svgf_level_params *lp, const svgf_padded *in,
                       const svgf_level_out *out, int threads);

/* Levels run together in one wavefront (more are run in groups). */
#define SVGF_WAVEFRONT_LEVELS 8
/* Smaller frames run one level at a time: their planes stay in cache
 * anyway, and the wavefront's synchronisation per row and its interleaving of
 * levels cost more than they save (docs/svgf-speed.md, eighth round:
 * slower at 320x180 and 480x270, faster from 640x360 on). */
#define SVGF_WAVEFRONT_MIN_PIXELS 200000

/*
 * n levels in a row, level k from in[k] to out[k] with lp[k]: the same
 * outputs as svgf_atrous_level on each in turn, but in one pass down the
 * rows (a wavefront), each level a few rows behind the one before, so that
 * the rows a level reads were written moments ago and are still in cache
 * (one level at a time streams every plane of the frame through memory
 * per level). in[k] must be out[k-1]'s planes for k > 0, and out[k] may
 * be in[k-1]'s planes (the ping-pong of svgf.c): the lags keep every read
 * of a row before its overwrite. No output may be read by anything else
 * during the call (svgf.c copies the first level into the history itself
 * only where nothing overwrites it).
 */
void svgf_atrous_levels(const svgf_guide *g, const svgf_level_params *lp,
                        const svgf_padded *const *in, const svgf_level_out *const *out, int n,
                        int threads);

/* The offset of row y in a level's output planes. */
static inline size_t svgf_level_out_row(const svgf_level_out *o, int y) {
  return (size_t)(o->ring > 0 ? y % o->ring : y) * o->stride;
}

/* Times (rows of every level) a thread runs level by level before it
 * moves on: each level's 45 tap streams (9 planes x 5 rows) then run on
 * for this many rows before the next level's take over the cache and the
 * prefetchers. */
#define SVGF_WAVEFRONT_BLOCK 4
/* How many times apart the wavefront's threads can be: a thread starts a
 * block once every other has finished the time this many before the
 * block's last. One block and three rows: a thread can be a whole block
 * behind without the other waiting. */
#define SVGF_WAVEFRONT_SLACK (2 * SVGF_WAVEFRONT_BLOCK - 1)
/* The rows of an output ring that the wavefront's threads never write at
 * once (rows less than SVGF_WAVEFRONT_SLACK + 1 apart). */
#define SVGF_WAVEFRONT_RING (SVGF_WAVEFRONT_SLACK + 1)

/* Whether svgf_atrous_levels runs a width x height image as a wavefront,
 * whose threads split every row into column parts (the split moves from
 * row to row): then (only) a level's output may be a ring of at least
 * SVGF_WAVEFRONT_RING rows that its span_done empties. */
static inline int svgf_atrous_levels_wavefront(int width, int height) {
  return (long long)width * height >= SVGF_WAVEFRONT_MIN_PIXELS;
}

/* The wavefront whatever the frame's size (svgf_atrous_levels keeps one
 * level at a time below SVGF_WAVEFRONT_MIN_PIXELS); for tests. jitter 0:
 * the split between threads as in svgf_atrous_levels; else every row's
 * split drawn at random (from the seed jitter), to test that any split
 * gives the same bits. */
void svgf_atrous_wavefront(const svgf_guide *g, const svgf_level_params *lp,
                           const svgf_padded *const *in, const svgf_level_out *const *out, int n,
                           int threads, unsigned jitter);

#endif
