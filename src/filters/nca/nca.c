/*
 * nca.c — the "nca" filter: the tiny neural cellular automaton denoiser of
 * Higginson 2023 §2.4 ("TNND"), single frame, no temporal input.
 *
 * The state (colour, normal, albedo: 9 planar channels) is iterated K times
 * with model.c's step (perception 39 -> sigmoid(p W) + bias added to the
 * state); the colour channels are the output. Weights are the built-in
 * ones (default_weights.c, trained by `hush train-nca`) unless a file was
 * loaded with hush_nca_load_weights (weights.c checks it).
 */
#include "filters/emission.h"
#include "filters/filter.h"
#include "filters/gbuffer.h"
#include "filters/nca/model.h"
#include "filters/nca/weights.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Largest log-space colour turned back into radiance: exp(30) stays finite
 * in float and is far above any real pixel. */
#define NCA_LOG_MAX 30.0f

enum { P_NONFINITE = 0, P_ITERATIONS, P_EMISSION_BYPASS, P_COUNT };

static const hush_param_info nca_params[P_COUNT] = {
    HUSH_PARAM_NONFINITE_ENTRY,
    {"iterations", HUSH_PARAM_INT, 0, 0, HUSH_NCA_MAX_ITERATIONS,
     "cellular automaton iterations K (0: the count the weights were trained for)", NULL},
    {"emission_bypass", HUSH_PARAM_BOOL, 1, 0, 1,
     "with 'emission' bound: the automaton sees color minus emission, which is added back to "
     "its output (lamps seen directly keep their radiance and do not bloom)",
     NULL},
};

enum { I_COLOR = 0, I_NORMAL, I_ALBEDO, I_EMISSION, I_OUTPUT, I_COUNT };

static const hush_image_info nca_images[I_COUNT] = {
    HUSH_IMAGE_COLOR_ENTRY,
    HUSH_IMAGE_NORMAL_ENTRY,
    {"albedo", HUSH_IMAGE_INPUT, 1, 3, "first-hit albedo"},
    {"emission", HUSH_IMAGE_INPUT, 0, 3,
     "radiance the camera sees directly at the first hit (lights, sky): kept out of the "
     "automaton (color - emission), added back to the output"},
    {"output", HUSH_IMAGE_OUTPUT, 1, 3, "denoised radiance"},
};

static const hush_filter_class_info nca_info = {
    "nca",
    "tiny neural cellular automaton: K learned update steps on colour, normal and albedo",
    "Higginson 2023 §2.4, §3.1",
    nca_params,
    P_COUNT,
    nca_images,
    I_COUNT,
};

typedef struct nca_state {
  hush_planar color, normal, albedo; /* imported inputs: the state at even steps */
  hush_planar emission;              /* imported with emission_bypass (emission.h) */
  float *odd[HUSH_NCA_CHANNELS];     /* the state at odd steps, one block */
  float *scratch;                    /* hush__nca_scratch_floats */
  int scratch_threads;
} nca_state;

static void nca_destroy(void *state) {
  nca_state *st = state;
  if (!st) return;
  hush__planar_free(&st->color);
  hush__planar_free(&st->normal);
  hush__planar_free(&st->albedo);
  hush__planar_free(&st->emission);
  hush__free_floats(st->odd[0]);
  hush__free_floats(st->scratch);
  free(st);
}

static hush_status nca_create(hush_filter f, void **state) {
  nca_state *st = calloc(1, sizeof *st);
  if (!st) return hush__fail(f->device, HUSH_ERROR_OUT_OF_MEMORY, "nca: out of memory");
  const size_t n = (size_t)f->width * f->height;
  const int threads = hush__filter_threads(f);
  hush_status s = hush__planar_init(f->device, &st->color, 3, f->width, f->height);
  if (!s) s = hush__planar_init(f->device, &st->normal, 3, f->width, f->height);
  if (!s) s = hush__planar_init(f->device, &st->albedo, 3, f->width, f->height);
  if (!s) {
    st->odd[0] = hush__alloc_floats(n * HUSH_NCA_CHANNELS);
    st->scratch = hush__alloc_floats(hush__nca_scratch_floats(f->width, threads));
    st->scratch_threads = threads;
    if (!st->odd[0] || !st->scratch)
      s = hush__fail(f->device, HUSH_ERROR_OUT_OF_MEMORY, "nca: out of memory");
    else /* the padding lanes after the last pixel of a row read it */
      memset(st->scratch, 0, hush__nca_scratch_floats(f->width, threads) * sizeof(float));
  }
  if (s) {
    nca_destroy(st);
    return s;
  }
  for (int c = 1; c < HUSH_NCA_CHANNELS; c++) st->odd[c] = st->odd[0] + n * (size_t)c;
  *state = st;
  return HUSH_OK;
}

/* Colour into the state: log(1 + max(c, 0)) or max(c, 0). The vectorisable
 * log and exp of model.h: libm's log1pf and expm1f cost as much as a few
 * iterations at 1280x720. */
static void color_to_state(hush_planar *color, uint32_t transform, int threads) {
  const long n = (long)hush__planar_pixels(color);
  for (int c = 0; c < 3; c++) {
    float *p = color->plane[c];
#pragma omp parallel for num_threads(threads) schedule(static)
    for (long i = 0; i < n; i++) {
      const float v = p[i] > 0.0f ? p[i] : 0.0f;
      p[i] = transform == HUSH_NCA_LOG1P ? hush__nca_log1p(v) : v;
    }
  }
}

/* State colour back to radiance, never negative, never Inf. */
static void state_to_color(float *const plane[3], hush_planar *out, uint32_t transform,
                           int threads) {
  const long n = (long)hush__planar_pixels(out);
  for (int c = 0; c < 3; c++) {
    const float *s = plane[c];
    float *d = out->plane[c];
#pragma omp parallel for num_threads(threads) schedule(static)
    for (long i = 0; i < n; i++) {
      const float v = s[i] < NCA_LOG_MAX ? s[i] : NCA_LOG_MAX;
      const float r = transform == HUSH_NCA_LOG1P ? hush__nca_exp(v) - 1.0f : v;
      d[i] = r > 0.0f ? r : 0.0f;
    }
  }
}

static hush_status nca_execute(hush_filter f, void *state, const hush_frame_info *info) {
  (void)info;
  nca_state *st = state;
  int threads = hush__filter_threads(f);
  if (threads > st->scratch_threads) threads = st->scratch_threads;
  const hush_nca_weights *wt = f->class_data ? f->class_data : &hush__nca_default_weights;
  const int k_param = hush__param_i(f, P_ITERATIONS);
  const int iterations = k_param > 0 ? k_param : (int)wt->iterations;
  hush_status s;
  hush__filter_timing_begin(f);

  if ((s = hush__filter_import(f, I_COLOR, &st->color))) return s;
  if ((s = hush__filter_import(f, I_NORMAL, &st->normal))) return s;
  hush__unit_normals(&st->normal, threads); /* the features it was trained on */
  if ((s = hush__filter_import(f, I_ALBEDO, &st->albedo))) return s;
  const int emis = hush__filter_view(f, I_EMISSION) != NULL && hush__param_i(f, P_EMISSION_BYPASS);
  if (emis && ((s = hush__filter_scratch(f, &st->emission, 3)) ||
               (s = hush__filter_import(f, I_EMISSION, &st->emission))))
    return s;
  if (emis) hush__emission_subtract(&st->color, &st->emission, NULL, threads);
  color_to_state(&st->color, wt->color_transform, threads);
  hush__filter_timing_stage(f, "import");

  float *even[HUSH_NCA_CHANNELS];
  for (int c = 0; c < 3; c++) {
    even[c] = st->color.plane[c];
    even[3 + c] = st->normal.plane[c];
    even[6 + c] = st->albedo.plane[c];
  }
  for (int it = 0; it < iterations; it++) {
    float *const *src = (it & 1) ? st->odd : even;
    float *const *dst = (it & 1) ? even : st->odd;
    hush__nca_step(wt, (const float *const *)src, dst, f->width, f->height, st->scratch, threads);
  }
  hush__filter_timing_stage(f, "iterate");

  /* the final state's colour, back to radiance, into the normal planar
   * (no longer needed) as the export buffer */
  float *const *last = (iterations & 1) ? st->odd : even;
  float *result[3] = {last[0], last[1], last[2]};
  state_to_color(result, &st->normal, wt->color_transform, threads);
  if (emis) hush__emission_add(&st->normal, &st->emission, &st->normal, threads);
  hush__view_export(&st->normal, hush__filter_view(f, I_OUTPUT), threads);
  hush__filter_timing_stage(f, "export");
  return HUSH_OK;
}

const hush_filter_class hush__filter_nca = {
    &nca_info,
    nca_create,
    nca_destroy,
    nca_execute,
};

hush_status hush_nca_load_weights(hush_filter filter, const char *path) {
  if (!filter)
    return hush__fail(NULL, HUSH_ERROR_INVALID_ARGUMENT, "hush_nca_load_weights: filter is NULL");
  if (filter->cls != &hush__filter_nca)
    return hush__fail(filter->device, HUSH_ERROR_INVALID_ARGUMENT,
                      "hush_nca_load_weights: filter '%s' is not an nca filter",
                      filter->cls->info->name);
  if (!path) {
    free(filter->class_data);
    filter->class_data = NULL;
    return HUSH_OK;
  }
  hush_nca_weights *w = malloc(sizeof *w);
  if (!w) return hush__fail(filter->device, HUSH_ERROR_OUT_OF_MEMORY, "nca: out of memory");
  const hush_status s = hush__nca_weights_load(filter->device, path, w);
  if (s) {
    free(w);
    return s;
  }
  free(filter->class_data);
  filter->class_data = w;
  return HUSH_OK;
}
