/*
 * gradient.h — temporal gradients of A-SVGF: from the renderer's gradient
 * samples (`hush render --gradients`, layer `gradient`) to a per-pixel
 * λ in [0, 1] ("how much did the shading change here"), and the rule that
 * turns λ into a shorter history. Shared by the "asvgf" filter and by any
 * other temporal filter that wants gradients (bmfr's temporal_gradients).
 *
 * Follows Schied, Peters, Dachsbacher 2018 §4.2-4.3 and Higginson 2023
 * §2.3.1 (papers/NOTES.md, "A-SVGF"); the design is docs/asvgf.md.
 *
 *   1. Gather the stratum grid, Ws x Hs = ceil(W/3) x ceil(H/3): per stratum,
 *      read at pixel (3sx, 3sy) of the layer: c, p and the landing index k
 *      (0..8, else no sample): delta = c - p, norm = max(c, p), valid. The
 *      guides (depth, normal, depth gradient x 3, luminance) are taken at the
 *      landing pixel, or at the stratum's centre pixel where there is none.
 *   2. Reconstruction: `iterations` a-trous levels (3x3 (1 2 1)/4 kernel, steps
 *      1, 2, 4, ...) over the grid, a normalised convolution of delta and norm
 *      with weights h * w_z * w_n * w_l * valid_q (SVGF's w_z and w_n;
 *      w_l = exp(-|l_p - l_q| / (sigma_l max(l_p, l_q) + 1e-4)), relative
 *      because no variance is known at stratum resolution).
 *   3. lambda_s = (max(0, min(|delta~| / norm~, 1) - t) / (1 - t)) ^ exponent, 0 where
 *      norm~ <= 1e-6 (t: threshold, 0 in the papers)
 *      or no valid sample reached the stratum (no evidence of change: keep
 *      the history).
 *   4. Per pixel (joint nearest-neighbour upsampling): the lambda of the
 *      stratum, among its own and the 8 around it, whose guide depth is
 *      nearest the pixel's depth (its own on ties), so that a pixel of
 *      another surface than its stratum's sample (a silhouette, sky beside
 *      a lit wall) takes the lambda of its own surface.
 *
 * Deterministic whatever the thread count; never NaN or Inf out for finite
 * input (callers import the layer with the filters' `nonfinite` policy).
 */
#ifndef HUSH_TEMPORAL_GRADIENT_H
#define HUSH_TEMPORAL_GRADIENT_H

#include <stddef.h>
#include <stdint.h>

/* Largest number of reconstruction levels (steps up to 2^(max-1)). */
#define HUSH_GRADIENT_MAX_ITERATIONS 5

typedef struct hush_gradient_params {
  int iterations; /* 0..HUSH_GRADIENT_MAX_ITERATIONS; 0: raw per-stratum lambda */
  float sigma_z;  /* depth weight, as SVGF's sigma_z (> 0) */
  float sigma_n;  /* normal weight exponent, as SVGF's sigma_n (>= 0) */
  float sigma_l;  /* relative luminance weight (> 0) */
  float exponent; /* lambda = ratio^exponent (> 0): 1 Schied 2018, 2 Higginson 2023 */
  /* noise floor in [0, 1): the ratio is first mapped to max(0, ratio - t) / (1 - t), so
   * that gradients of the size 1 spp noise gives (a glossy lobe seen from a moved camera
   * takes another path with the same numbers) keep the history; 0: none (the papers) */
  float threshold;
} hush_gradient_params;

/* The current frame's guides, W x H planar floats, borrowed for the call. */
typedef struct hush_gradient_guides {
  const float *depth;         /* linear view depth (0: background) */
  const float *normal[3];     /* world-space normal */
  const float *depth_grad[2]; /* d depth / d pixel in x, y; NULL: 0 (flat) */
  const float *luminance;     /* of this frame's colour; NULL: c of the stratum's sample */
} hush_gradient_guides;

/*
 * Floats of scratch hush__gradient_lambda needs for a W x H frame (a few
 * planes of the stratum grid). The caller owns it (any float buffer of at
 * least this size; contents need not be kept between calls).
 */
size_t hush__gradient_scratch_floats(uint32_t width, uint32_t height);

/*
 * lambda (W x H floats, caller-owned, written everywhere) <- the per-pixel
 * lambda of this frame from `gradient` (the layer's 3 planes, W x H: c, p,
 * landing index), the guides and the parameters (steps 1-3 above).
 * scratch: hush__gradient_scratch_floats(W, H) floats.
 */
void hush__gradient_lambda(const float *const gradient[3], const hush_gradient_guides *guides,
                           uint32_t width, uint32_t height, const hush_gradient_params *params,
                           float *scratch, float *lambda, int threads);

/* How lambda shortens the history (parameter `history_rule`). */
typedef enum hush_history_rule {
  HUSH_HISTORY_SCHIED = 0,   /* a = (1 - lambda) max(alpha, 1/N) + lambda */
  /* N' = min((N-1)(1 - lambda)^10 + 1, max_age), a = mix(1/N', 1, lambda) */
  HUSH_HISTORY_HIGGINSON = 1
} hush_history_rule;

/*
 * lowered[i] <- the history length of pixel i after the change lambda[i],
 * from age[i] = N, the history length including this frame (>= 1; what
 * hush__accum_blend writes). With the rule's target weight a of the new
 * frame: lowered = min(N, 1/a) where a > max(alpha, 1/N) (the blend gave the
 * new frame less weight than the rule asks), else N unchanged: lambda = 0
 * leaves N as it is, lambda = 1 gives 1. A blend with
 * a = max(alpha, 1/lowered) (hush__temporal_blend) then gives the new frame
 * the rule's weight, and the next frame sees the shortened history
 * (docs/bmfr.md "For A-SVGF", docs/asvgf.md). n pixels; lowered may alias
 * age. Returns how many pixels were lowered (0: the history is untouched).
 */
size_t hush__gradient_lower_age(const float *lambda, const float *age, float *lowered, size_t n,
                                hush_history_rule rule, float alpha, int max_age, int threads);

#endif
