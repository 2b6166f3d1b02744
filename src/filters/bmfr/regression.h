/*
 * regression.h — BMFR's per-block least-squares fit
 * (bmfr-koskela-2019.md §3.3-3.4, eqs. 2-7): stochastic regularisation of
 * the features, Householder QR of the augmented matrix [T + N, z_r, z_g,
 * z_b] computing only R, one R for the three colour channels, back
 * substitution, and the weighted sum with the noise-free features.
 *
 * Layout: column-major, one contiguous column of ld floats per feature (ld
 * a multiple of 16, rows n..ld-1 zero), so the Householder dot products
 * and updates are plain vectorised loops over the block's rows, and the
 * whole augmented matrix of a 32x32 block (1024 x 13 floats, 52 KiB) stays
 * in the core's cache.
 */
#ifndef HUSH_FILTERS_BMFR_REGRESSION_H
#define HUSH_FILTERS_BMFR_REGRESSION_H

#include "filters/bmfr/features.h"

#include <stddef.h>
#include <stdint.h>

/* Colour channels fitted with the one R. */
#define BMFR_CHANNELS 3

/*
 * The stochastic regularisation noise of a frame (§3.4, eq. 7): for
 * feature m >= 1 and block row i, uniform in [-eps, eps] from a hash of
 * (i, m, frame), so it is deterministic per frame and the same in every
 * block (as the published code). Each column is then shifted to mean 0
 * exactly over the n rows, so a block whose features are all flat fits
 * exactly the block mean. Column 0 (the constant) gets none.
 * table: count columns of ld floats.
 */
void hush__bmfr_noise_table(float *table, int count, int n, size_t ld, uint64_t frame, float eps);

/*
 * Fits one block. T: the set's `count` noise-free columns (features.h:
 * column 0 is the 0/1 validity mask, all columns 0 on holes); z:
 * BMFR_CHANNELS columns of ld floats, the block's (accumulated) radiance
 * (rows n..ld-1 finite: they are read, weighted by the mask's 0); mask: ld
 * floats, 0 from row n on; noise: the
 * frame's table; nvalid: how many rows are valid (when below n the noise
 * is re-centred over the valid rows, and holes get none). A is the
 * (count + 3) x ld scratch the QR works in. refine: steps of iterative
 * refinement of the weights towards the noise-free least-squares solution
 * (0: the paper's plain solve).
 * Writes coef[c][m], the fitted weights of channel c; a feature whose pivot
 * vanished (rank deficiency that the noise did not cure, or a block with no
 * valid pixel) gets weight 0, so the result is always finite.
 */
void hush__bmfr_fit(const float *T, int count, const float *const z[BMFR_CHANNELS],
                    const float *noise, const float *mask, int n, int nvalid, size_t ld, float *A,
                    int refine, float coef[BMFR_CHANNELS][BMFR_MAX_FEATURES]);

/* y[c][i] = sum_m coef[c][m] T_m[i] (eq. 6), clamped below at 0 as the
 * published code does (radiance is not negative); y: columns of ld floats,
 * all written (rows n..ld-1 get 0). */
void hush__bmfr_synthesize(const float *T, int count, int n, size_t ld,
                           const float coef[BMFR_CHANNELS][BMFR_MAX_FEATURES],
                           float *const y[BMFR_CHANNELS]);

/* The fit of rows r0..r1-1 of a B x B block (B a multiple of two vectors)
 * straight into an image: out[c][(r - r0) stride + x] = mask ? y : z[c],
 * y as hush__bmfr_synthesize's (the same bits), z[c] the block's columns
 * (what a pixel out of the fit keeps). */
void hush__bmfr_synthesize_rows(const float *T, int count, size_t ld, int B,
                                const float coef[BMFR_CHANNELS][BMFR_MAX_FEATURES],
                                const float *mask, const float *const z[BMFR_CHANNELS], int r0,
                                int r1, float *const out[BMFR_CHANNELS], size_t stride);

#endif
