/*
 * svgf.h — what the two classes of the SVGF pipeline share (svgf.c): "svgf"
 * and "asvgf" (asvgf.c: the same pipeline with the adaptive temporal stage
 * of A-SVGF, adaptive.h, before the temporal blend). The parameter and image
 * indices, the table rows (asvgf's tables are svgf's plus its own rows
 * after them, so these indices hold in both) and the per-frame body.
 */
#ifndef HUSH_FILTERS_SVGF_SVGF_H
#define HUSH_FILTERS_SVGF_SVGF_H

#include "filters/filter.h"

struct svgf_adaptive;


enum {
  P_NONFINITE = 0,
  P_ALPHA,
  P_ALPHA_MOMENTS,
  P_MAX_AGE,
  P_DEPTH_TOLERANCE,
  P_DEPTH_GRADIENT,
  P_NORMAL_THRESHOLD,
  P_USE_ID,
  P_FALLBACK_3X3,
  P_DEMODULATE,
  P_ITERATIONS,
  P_SIGMA_Z,
  P_SIGMA_N,
  P_SIGMA_L,
  P_SPATIAL_VARIANCE_FRAMES,
  P_FEEDBACK_FIRST_LEVEL,
  P_TAA,
  P_TAA_ALPHA,
  P_KERNEL,
  P_ORDER,
  P_DEPTH_STEEP,
  P_SAMPLE_VARIANCE,
  P_PROGRESSIVE,
  P_PROGRESSIVE_EPSILON,
  P_EMISSION_BYPASS,
  P_PROGRESSIVE_TAA,
  P_NORMAL_WEIGHT,
  P_WEIGHT_EXP,
  P_COUNT
};

extern const char *const svgf_kernel_names[];
extern const char *const svgf_order_names[];
extern const char *const svgf_normal_weight_names[];
extern const char *const svgf_weight_exp_names[];

/* the most a-trous levels (the "iterations" parameter's bound) */
#define SVGF_MAX_ITERATIONS 10

/* The parameter rows of "svgf", in P_ order. */
#define SVGF_PARAM_ROWS \
    HUSH_PARAM_NONFINITE_ENTRY, \
    {"alpha", HUSH_PARAM_FLOAT, 0.2, 0.0, 1.0, \
     "minimum weight of the new frame in the colour blend: max(alpha, 1/history_length)", NULL}, \
    {"alpha_moments", HUSH_PARAM_FLOAT, 0.2, 0.0, 1.0, \
     "minimum weight of the new frame in the luminance-moment blend", NULL}, \
    {"max_age", HUSH_PARAM_INT, 32, 1, 65535, "history length cap in frames", NULL}, \
    HUSH_PARAM_DEPTH_TOLERANCE_ENTRY, \
    HUSH_PARAM_DEPTH_GRADIENT_ENTRY, \
    HUSH_PARAM_NORMAL_THRESHOLD_ENTRY, \
    HUSH_PARAM_USE_ID_ENTRY, \
    {"fallback_3x3", HUSH_PARAM_BOOL, 1, 0, 1, \
     "search the 3x3 neighbourhood when no tap of the bilinear footprint is consistent", NULL}, \
    HUSH_PARAM_DEMODULATE_ENTRY, \
    {"iterations", HUSH_PARAM_INT, 5, 0, SVGF_MAX_ITERATIONS, \
     "a-trous levels, tap steps 1, 2, ..., 2^(iterations-1) (0: accumulation only); the thesis " \
     "uses 6 with the 3x3 kernel", \
     NULL}, \
    {"sigma_z", HUSH_PARAM_FLOAT, 1.0, 1e-6, 1e6, \
     "depth weight exp(-|z_p - z_q| / (sigma_z |grad z . (p - q)| + eps))", NULL}, \
    {"sigma_n", HUSH_PARAM_FLOAT, 128.0, 0.0, 1024.0, \
     "normal weight max(0, n_p . n_q)^sigma_n", NULL}, \
    {"sigma_l", HUSH_PARAM_FLOAT, 4.0, 1e-6, 1e6, \
     "luminance weight exp(-|l_p - l_q| / (sigma_l sqrt(g3x3(var_p)) + eps))", NULL}, \
    {"spatial_variance_frames", HUSH_PARAM_INT, 4, 0, 65535, \
     "below this history length (in samples: frames x spp) the variance is a 7x7 bilateral " \
     "spatial estimate (0: never)", \
     NULL}, \
    {"feedback_first_level", HUSH_PARAM_BOOL, 1, 0, 1, \
     "the first a-trous level becomes the next frame's colour history (else the accumulation)", \
     NULL}, \
    {"taa", HUSH_PARAM_BOOL, 0, 0, 1, \
     "finish with temporal anti-aliasing of the remodulated output (as the 'taa' filter: 3x3 " \
     "YCoCg clamp, tone-mapped); off by default so that svgf alone can be compared", \
     NULL}, \
    {"taa_alpha", HUSH_PARAM_FLOAT, 0.1, 0.01, 1.0, \
     "with taa: weight of the current frame in the TAA blend", NULL}, \
    {"kernel", HUSH_PARAM_ENUM, 0, 0, 1, \
     "a-trous kernel: 5x5 B3 spline (1 4 6 4 1)/16 (Schied 2017) or 3x3 (1 2 1)/4 (Dundr 2018 " \
     "§4.1.4.6)", \
     svgf_kernel_names}, \
    {"order", HUSH_PARAM_ENUM, 0, 0, 2, \
     "order of the tap steps: increasing (1, 2, 4, ...; Schied 2017), decreasing (largest " \
     "first) or 0-then-decreasing (1, then largest down to 2: Dundr 2018 §4.1.4.6, 'i = 0, 5, 4, " \
     "3, 2, 1'); the first level run is the one fed back (with decreasing that is the coarsest: " \
     "its bias accumulates, measured +2 % on a noisy wall after 8 frames)", \
     svgf_order_names}, \
    {"depth_steep", HUSH_PARAM_FLOAT, 0.0, 0.0, 1e6, \
     "the depth weight is 1 where |grad z| > depth_steep * z (relative slope per pixel; Dundr " \
     "2018 §4.1.4.3, a scene-dependent constant without a published value); 0: never", \
     NULL}, \
    {"sample_variance", HUSH_PARAM_BOOL, 1, 0, 1, \
     "with 'variance' and 'spp' bound: merge the within-pixel sample variance into the moments " \
     "(Dundr 2018 §4.3)", \
     NULL}, \
    {"progressive", HUSH_PARAM_BOOL, 1, 0, 1, \
     "with 'spp' bound and holes (spp 0, `hush render --spp-fraction`): fewer than 1 spp " \
     "(Dundr 2018 §4.2): G-buffer holes filled by a pyramid, forward reprojection by scatter " \
     "with a depth test, near/far rejection, holes without data weightless; needs 'position'", \
     NULL}, \
    {"progressive_epsilon", HUSH_PARAM_FLOAT, 0.05, 0.0, 1e6, \
     "progressive: the luminance weight's epsilon is 1e-4 + this / samples below 4 samples " \
     "(Dundr 2018 §4.2.3: typically 0.01 to 0.1)", \
     NULL}, \
    {"emission_bypass", HUSH_PARAM_BOOL, 1, 0, 1, \
     "with 'emission' bound: filter color minus emission and add back the emission accumulated " \
     "over frames (lights seen directly stay exact, do not bleed, and their 1 spp edges average " \
     "over frames: cornell-box RMSE 0.122 -> 0.054, relMSE 0.038 -> 0.022; docs/psf.md, One-sided lights)", \
     NULL}, \
    {"progressive_taa", HUSH_PARAM_BOOL, 0, 0, 1, \
     "progressive, with taa: only the traced pixels blend into the TAA history, a hole keeps " \
     "it clamped to its box (Dundr 2018 §4.2.6: 'only new samples would get updated'; " \
     "docs/holes.md)", \
     NULL}, \
    {"normal_weight", HUSH_PARAM_ENUM, 0, 0, 1, \
     "a-trous normal weight: exp = exp(-sigma_n (1 - n_p . n_q)), the first-order form of the " \
     "paper's max(0, n_p . n_q)^sigma_n (within 0.0021 of it at sigma_n 128, and cheaper: " \
     "docs/svgf-speed.md), or pow = that power exactly", \
     svgf_normal_weight_names}, \
    {"weight_exp", HUSH_PARAM_ENUM, 1, 0, 1, \
     "the exp of the edge-stopping weights (a-trous and 7x7 variance, with " \
     "normal_weight=exp): fast = 2^t interpolated linearly between powers of two " \
     "(Schraudolph 1999; each weight within 3 % of it, the a-trous 11-13 % faster, RMSE and " \
     "SSIM as good on three scenes: docs/svgf-speed.md, twenty-third round), accurate = a " \
     "polynomial (1e-4 relative)", \
     svgf_weight_exp_names},

enum {
  I_COLOR = 0,
  I_DEPTH,
  I_NORMAL,
  I_DEPTH_GRADIENT,
  I_POSITION,
  I_ID,
  I_MOTION,
  I_ALBEDO,
  I_EMISSION,
  I_SPP,
  I_SAMPLE_VARIANCE,
  I_DIRECT,
  I_INDIRECT,
  I_OUTPUT,
  I_VARIANCE_ESTIMATE,
  I_HISTORY_LENGTH,
  I_COUNT
};

/* The image rows of "svgf", in I_ order. */
#define SVGF_IMAGE_ROWS \
    HUSH_IMAGE_COLOR_ENTRY, \
    {"depth", HUSH_IMAGE_INPUT, 1, 1, "linear view depth (0: background)"}, \
    HUSH_IMAGE_NORMAL_ENTRY, \
    {"depth_gradient", HUSH_IMAGE_INPUT, 0, 2, \
     "d depth / d pixel in x and y (else the smaller one-sided difference of 'depth')"}, \
    {"position", HUSH_IMAGE_INPUT, 0, 3, \
     "world-space position (camera reprojection; else reconstructed from depth)"}, \
    HUSH_IMAGE_ID_ENTRY, \
    HUSH_IMAGE_MOTION_ENTRY, \
    {"albedo", HUSH_IMAGE_INPUT, 0, 3, "first-hit albedo, for demodulation (else 1)"}, \
    {"emission", HUSH_IMAGE_INPUT, 0, 3, \
     "radiance the camera sees directly at the first hit (lights, sky): kept out of the " \
     "filtered signal (color, or direct, minus emission), added back after TAA"}, \
    {"spp", HUSH_IMAGE_INPUT, 0, 1, \
     "samples per pixel of 'color' (else 1; `hush render --spp N`): the variance of a pixel " \
     "value is the per-sample variance / spp"}, \
    {"variance", HUSH_IMAGE_INPUT, 0, 1, \
     "per-sample luminance variance within the pixel (`hush render --spp N`, needs 'spp'), " \
     "merged into the moments (Dundr 2018 §4.3)"}, \
    {"direct", HUSH_IMAGE_INPUT, 0, 3, \
     "direct light (`hush render --split`): with 'indirect' also bound, each is filtered on its " \
     "own (own history, variance and a-trous; Schied 2017) and the output is their sum ('color' " \
     "is then not used)"}, \
    {"indirect", HUSH_IMAGE_INPUT, 0, 3, "indirect light, see 'direct'"}, \
    {"output", HUSH_IMAGE_OUTPUT, 1, 3, "filtered radiance"}, \
    {"variance_estimate", HUSH_IMAGE_OUTPUT, 0, 1, \
     "luminance variance estimate that guides the first a-trous level (demodulated)"}, \
    {"history_length", HUSH_IMAGE_OUTPUT, 0, 1, "frames accumulated per pixel"},

/* The class state of "svgf" (asvgf keeps one as part of its own). */
hush_status svgf_create(hush_filter f, void **state);
void svgf_destroy(void *state);

/*
 * One frame of the pipeline. ad == NULL: plain SVGF. Else (asvgf) the
 * gradient layer is imported with the other inputs, lambda is computed
 * after the guide (stage "gradient"), and each component's history is
 * shortened by lambda right after its temporal blend (adaptive.h).
 */
hush_status svgf_run(hush_filter f, void *state, const hush_frame_info *info,
                     struct svgf_adaptive *ad);

#endif
