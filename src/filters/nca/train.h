/*
 * train.h — training of the nca model (Higginson 2023 §2.4.2): loss
 * w1 * MSE + w2 * L_g (the gradient term of §2.1.2, eq. 2.1), the gradient
 * of that loss with respect to W and bias by backpropagation through the K
 * iterations written out by hand, and Adam. In double precision, on the
 * straightforward (unblocked) form of the model in model.h, so that the
 * finite-difference check of tests/test_nca.c is tight; `hush train-nca`
 * drives it and the float filter (model.c) runs the result.
 */
#ifndef HUSH_FILTERS_NCA_TRAIN_H
#define HUSH_FILTERS_NCA_TRAIN_H

#include "filters/nca/model.h"

/* Parameters as one vector: W (k * 9 + j) then bias. */
#define HUSH_NCA_P_BIAS HUSH_NCA_WEIGHT_COUNT

/* One training crop, planar, width x height (>= 2 each). Not owned. */
typedef struct hush_nca_sample {
  uint32_t width, height;
  const float *state[HUSH_NCA_CHANNELS]; /* initial state, colour already transformed */
  const float *target[3];                /* reference colour, same transform */
} hush_nca_sample;

/* Where the MSE term compares prediction and reference. The gradient term
 * always works on the state's colour (log space for log1p weights). */
typedef enum hush_nca_mse_space {
  HUSH_NCA_MSE_STATE = 0,    /* the state's colour as is (log1p: log space; darkens, docs/nca.md) */
  HUSH_NCA_MSE_LINEAR = 1,   /* radiance: unbiased, dominated by the brightest pixels */
  HUSH_NCA_MSE_RELATIVE = 2, /* radiance, each error over reference^2 + 0.01 (hush eval's relMSE;
                                its minimiser is biased dark, docs/nca.md) */
  HUSH_NCA_MSE_RELATIVE_PREDICTED = 3, /* radiance, each error over prediction^2 + 0.01 with
                                          that weight held constant in the derivative (Lehtinen
                                          2018's HDR loss): as balanced over brightness as
                                          relMSE, and its fixed point is the mean */
  HUSH_NCA_MSE_WEIGHTED = 4  /* radiance, each error times weight[c][i] (the frozen form of
                                RELATIVE_PREDICTED, for its gradient check) */
} hush_nca_mse_space;

typedef struct hush_nca_loss_weights {
  double mse;      /* w1 */
  double gradient; /* w2 */
  hush_nca_mse_space space;
  hush_nca_transform transform;     /* of the sample's state and target colour */
  const double *const *weight;      /* HUSH_NCA_MSE_WEIGHTED: 3 planes; not owned */
} hush_nca_loss_weights;

/*
 * Runs `iterations` steps of the model with params (HUSH_NCA_PARAM_COUNT
 * doubles) on the sample and returns the loss of the final colour. When
 * grad is not NULL, adds dLoss/dparams to it. Returns a negative value when
 * out of memory.
 */
double hush__nca_loss(const double *params, int iterations, const hush_nca_sample *sample,
                      const hush_nca_loss_weights *lw, double *grad);

/* Forward pass only, the final state into out (9 planes of width*height
 * doubles); for comparing the training model with the float filter. */
int hush__nca_forward_double(const double *params, int iterations,
                             const hush_nca_sample *sample, double *const out[HUSH_NCA_CHANNELS]);

typedef struct hush_nca_adam {
  double lr, beta1, beta2, eps;
  double m[HUSH_NCA_PARAM_COUNT], v[HUSH_NCA_PARAM_COUNT];
  long t;
} hush_nca_adam;

/* Kingma and Ba 2015 defaults (beta 0.9, 0.999, eps 1e-8) with rate lr. */
void hush__nca_adam_init(hush_nca_adam *adam, double lr);
/* One Adam step of params along grad. */
void hush__nca_adam_step(hush_nca_adam *adam, double *params, const double *grad);

/* Conversions between the parameter vector and the weights struct. */
void hush__nca_params_from_weights(const hush_nca_weights *w, double *params);
void hush__nca_weights_from_params(const double *params, hush_nca_weights *w);

#endif
