/*
 * features.h — BMFR's multi-order feature set (bmfr-koskela-2019.md §3.3,
 * eq. 1, and §5, eq. 8): T = [1, F_{n_2}^{g_2}, ..., F_{n_M}^{g_M}], built
 * per block from the noise-free G-buffer channels.
 *
 * The set is described by exponents per source (normal, world position,
 * depth, albedo, and the block-local x/y gradients of §5): each source has
 * up to two exponents, 0 meaning "not used"; every channel of a source is
 * added with each of its exponents (§5: "every channel of each feature
 * buffer was added at once"). The default [1, n, w, w^2] is eq. 8.
 *
 * Per block, each base channel f is first min-max scaled to s in [-1, 1]
 * over the block's valid pixels; a feature is then s^g (sign-preserving
 * |s|^g sign(s) for a non-integer g), scaled to [-1, 1] again (§3.4: "T
 * within every block is scaled to be in range [-1, 1]"). Scaling before the
 * power keeps float32 well conditioned (world coordinates of 100 squared
 * would leave w and w^2 nearly collinear); for integer exponents that come
 * with the lower orders, as in eq. 8, the span of the features, hence the
 * fit, is the same as with the paper's F^g.
 */
#ifndef HUSH_FILTERS_BMFR_FEATURES_H
#define HUSH_FILTERS_BMFR_FEATURES_H

#include <stddef.h>

/* Base channels a block gathers (column index in the block's base buffer). */
enum {
  BMFR_BASE_NORMAL = 0,   /* 3: world-space shading normal */
  BMFR_BASE_POSITION = 3, /* 3: world-space position */
  BMFR_BASE_DEPTH = 6,    /* 1: linear view depth */
  BMFR_BASE_ALBEDO = 7,   /* 3: first-hit albedo */
  BMFR_BASE_GRADIENT = 10, /* 2: block-local column and row (computed, not gathered) */
  BMFR_BASE_COUNT = 12
};

/* Sources, in the order their features enter T. */
enum { BMFR_SRC_NORMAL = 0, BMFR_SRC_POSITION, BMFR_SRC_DEPTH, BMFR_SRC_ALBEDO, BMFR_SRC_COUNT };

/* At most: 1 + 2 * (3 + 3 + 1 + 3) + 2. */
#define BMFR_MAX_FEATURES 23

typedef struct bmfr_feature {
  int base;       /* BMFR_BASE_* channel; -1 for the constant feature */
  float exponent; /* > 0; 1 takes the scaled channel as it is */
} bmfr_feature;

typedef struct bmfr_feature_set {
  int count; /* M, including the constant feature 0 */
  bmfr_feature f[BMFR_MAX_FEATURES];
  unsigned needs; /* bit BMFR_SRC_*: the set reads that source */
  int gradients;  /* the two gradient features are in the set */
} bmfr_feature_set;

/* Builds the set from exponents[source][0..1] (0: unused) and the gradient
 * switch. */
void hush__bmfr_features_build(bmfr_feature_set *set, const float exponents[BMFR_SRC_COUNT][2],
                               int gradients);

/*
 * Computes the noise-free feature columns of one block:
 *   base   BMFR_BASE_COUNT columns of ld floats: the gathered channels (only
 *          those the set uses are read; gradient columns included);
 *   mask   1 for a valid pixel (a surface hit), 0 for a hole, n entries;
 *   T      out, set->count columns of ld floats: column 0 is the mask (the
 *          constant feature on valid pixels), every column is 0 on holes.
 * scratch: ld floats. Rows n..ld-1 are set to 0.
 */
void hush__bmfr_features_block(const bmfr_feature_set *set, const float *base, const float *mask,
                               int n, size_t ld, float *T, float *scratch);

#endif
