/*
 * asvgf.c — the "asvgf" filter: adaptive spatiotemporal variance-guided
 * filtering (Schied, Peters, Dachsbacher 2018; Higginson 2023 §2.3;
 * papers/NOTES.md "A-SVGF"; docs/asvgf.md).
 *
 * SVGF's pipeline (svgf.h) with the adaptive temporal stage (adaptive.h)
 * inserted before the temporal blend: the renderer's gradient samples
 * (`hush render --gradients`, layer `gradient`) give lambda, the amount the
 * shading changed, per pixel (src/temporal/gradient.h); lambda shortens the
 * history so that a light switched off or moved is followed within a frame
 * or two instead of lagging for 1 / alpha frames. Its tables are svgf's plus
 * the rows below, so svgf's parameter and image indices hold here too.
 */
#include "filters/filter.h"
#include "filters/svgf/adaptive.h"
#include "filters/svgf/svgf.h"

#include <stdlib.h>

enum {
  P_GRADIENT_ITERATIONS = P_COUNT,
  P_GRADIENT_SIGMA_L,
  P_GRADIENT_EXPONENT,
  P_HISTORY_RULE,
  P_GRADIENT_THRESHOLD,
  P_ASVGF_COUNT
};

static const char *const asvgf_rule_names[] = {"schied", "higginson"};

static const hush_param_info asvgf_params[P_ASVGF_COUNT] = {
    SVGF_PARAM_ROWS
    {"gradient_iterations", HUSH_PARAM_INT, 3, 0, HUSH_GRADIENT_MAX_ITERATIONS,
     "a-trous levels (3x3 (1 2 1)/4, steps 1, 2, 4, ...) reconstructing the temporal gradient "
     "on the 3x3-stratum grid, guided by depth, normal (sigma_z, sigma_n) and luminance (0: the "
     "raw per-stratum gradient; Schied 2018 §4.3)",
     NULL},
    {"gradient_sigma_l", HUSH_PARAM_FLOAT, 4.0, 1e-6, 1e6,
     "luminance weight of the gradient reconstruction, relative: exp(-|l_p - l_q| / "
     "(gradient_sigma_l max(l_p, l_q) + 1e-4))",
     NULL},
    {"gradient_exponent", HUSH_PARAM_FLOAT, 1.0, 0.01, 100.0,
     "lambda = min(|delta| / max(current, previous), 1)^exponent, of the reconstructed "
     "luminances (1: Schied 2018, the default; 2: Higginson 2023). With the renderer's "
     "diffuse-lobe gradients, exponent 1 meets issue 7's lag lines (light-jump 2 frames, 5 with "
     "2) and classroom RMSE (-0.9% against svgf); docs/results/asvgf-lag.md",
     NULL},
    {"history_rule", HUSH_PARAM_ENUM, 1, 0, 1,
     "how lambda shortens the history: schied, a = (1 - lambda) max(alpha, 1/N) + lambda; or "
     "higginson, N' = min((N - 1)(1 - lambda)^10 + 1, max_age), a = mix(1/N', 1, lambda); the "
     "history length becomes min(N, 1/a) where a exceeds the blend's weight (higginson by "
     "default: where some light remains, lambda = 1 - c/p < 1 and schied keeps that stale "
     "fraction; light-off 96x54, lit region at the change: +19% over the truth vs +1%)",
     asvgf_rule_names},
    {"gradient_threshold", HUSH_PARAM_FLOAT, 0.0, 0.0, 0.99,
     "noise floor of the relative gradient: lambda is computed from max(0, r - t) / (1 - t), "
     "r = |delta~| / max(current~, previous~), so that gradients of the size of the 1 spp "
     "noise keep the history (0: none, as the papers)",
     NULL},
};

enum { I_GRADIENT = I_COUNT, I_ASVGF_COUNT };

static const hush_image_info asvgf_images[I_ASVGF_COUNT] = {
    SVGF_IMAGE_ROWS
    {"gradient", HUSH_IMAGE_INPUT, 1, 3,
     "temporal gradient samples (`hush render --gradients`): per 3x3 stratum, read at its "
     "top-left pixel, the current and previous luminance of the re-shaded sample and its "
     "landing index 0..8 (-1: none)"},
};

static const hush_filter_class_info asvgf_info = {
    "asvgf",
    "adaptive SVGF: temporal gradients shorten the history where the shading changed, then SVGF",
    "Schied, Peters, Dachsbacher 2018; Higginson 2023 §2.3 (papers/NOTES.md); docs/asvgf.md",
    asvgf_params,
    P_ASVGF_COUNT,
    asvgf_images,
    I_ASVGF_COUNT,
};

typedef struct asvgf_state {
  void *svgf; /* svgf_create's */
  svgf_adaptive ad;
} asvgf_state;

static void asvgf_destroy(void *state) {
  asvgf_state *st = state;
  if (!st) return;
  svgf_destroy(st->svgf);
  svgf_adaptive_free(&st->ad);
  free(st);
}

static hush_status asvgf_create(hush_filter f, void **state) {
  asvgf_state *st = calloc(1, sizeof *st);
  if (!st) return hush__fail(f->device, HUSH_ERROR_OUT_OF_MEMORY, "asvgf: out of memory");
  st->ad.image = I_GRADIENT;
  const hush_status s = svgf_create(f, &st->svgf);
  if (s) {
    free(st);
    return s;
  }
  *state = st;
  return HUSH_OK;
}

static hush_status asvgf_execute(hush_filter f, void *state, const hush_frame_info *info) {
  asvgf_state *st = state;
  hush_gradient_params *gp = &st->ad.params;
  gp->iterations = hush__param_i(f, P_GRADIENT_ITERATIONS);
  gp->sigma_z = hush__param_f(f, P_SIGMA_Z);
  gp->sigma_n = hush__param_f(f, P_SIGMA_N);
  gp->sigma_l = hush__param_f(f, P_GRADIENT_SIGMA_L);
  gp->exponent = hush__param_f(f, P_GRADIENT_EXPONENT);
  gp->threshold = hush__param_f(f, P_GRADIENT_THRESHOLD);
  st->ad.rule = hush__param_i(f, P_HISTORY_RULE) ? HUSH_HISTORY_HIGGINSON : HUSH_HISTORY_SCHIED;
  return svgf_run(f, st->svgf, info, &st->ad);
}

const hush_filter_class hush__filter_asvgf = {
    &asvgf_info,
    asvgf_create,
    asvgf_destroy,
    asvgf_execute,
};
