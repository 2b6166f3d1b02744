/*
 * train.c — loss, backpropagation through the iterations and Adam for the
 * nca model (Higginson 2023 §2.4.2, loss eq. 2.18 with L_g of eq. 2.1).
 *
 * Forward: the states s^0..s^K and the sigmoid outputs of every step are
 * kept; the perception is recomputed in the backward pass (cheap: 3x3
 * filters). Backward, per step t from K-1 down to 0, with g = dL/ds^{t+1}:
 *   dL/ds^t  = g + perception^T (W dz),   dz = g * sig * (1 - sig)
 *   dL/dW   += p^T dz,   dL/dbias += sum over pixels of g
 * where perception^T applies the adjoint of each clamp-to-edge 3x3 filter
 * (a scatter to the clamped taps).
 * The MSE term compares in the space the loss weights name (the state's
 * colour, radiance, or radiance relative to the reference or to the
 * prediction; the last holds its weight constant in the derivative, so its
 * "gradient" is that of the weighted MSE frozen at the current prediction). L_g compares forward differences of the Gaussian-blurred
 * prediction and reference colour of the state with an L1 norm; its
 * derivative uses sign(), 0 at 0.
 */
#include "filters/nca/train.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

typedef struct image_dims {
  long w, h, n;
} image_dims;

static long clampl(long v, long lo, long hi) { return v < lo ? lo : v > hi ? hi : v; }

/* out = k (*) in with clamp-to-edge borders. */
static void conv3x3(const float k[9], const double *in, double *out, image_dims d) {
  for (long y = 0; y < d.h; y++) {
    const double *r[3] = {in + clampl(y - 1, 0, d.h - 1) * d.w, in + y * d.w,
                          in + clampl(y + 1, 0, d.h - 1) * d.w};
    for (long x = 0; x < d.w; x++) {
      const long xs[3] = {clampl(x - 1, 0, d.w - 1), x, clampl(x + 1, 0, d.w - 1)};
      double acc = 0.0;
      for (int a = 0; a < 3; a++)
        for (int b = 0; b < 3; b++) acc += (double)k[a * 3 + b] * r[a][xs[b]];
      out[y * d.w + x] = acc;
    }
  }
}

/* dst += adjoint of (k (*) .) applied to g: each output's gradient goes
 * back to the (clamped) taps that produced it. */
static void conv3x3_adjoint_add(const float k[9], const double *g, double *dst, image_dims d) {
  for (long y = 0; y < d.h; y++) {
    const long ys[3] = {clampl(y - 1, 0, d.h - 1), y, clampl(y + 1, 0, d.h - 1)};
    for (long x = 0; x < d.w; x++) {
      const long xs[3] = {clampl(x - 1, 0, d.w - 1), x, clampl(x + 1, 0, d.w - 1)};
      const double gv = g[y * d.w + x];
      for (int a = 0; a < 3; a++)
        for (int b = 0; b < 3; b++) dst[ys[a] * d.w + xs[b]] += (double)k[a * 3 + b] * gv;
    }
  }
}

/* The 39 perception planes of a 9-channel state (model.h layout). */
static void perceive(double *const s[HUSH_NCA_CHANNELS], double *p, image_dims d) {
  for (int c = 0; c < HUSH_NCA_CHANNELS; c++) {
    memcpy(p + (size_t)(HUSH_NCA_P_STATE + c) * d.n, s[c], (size_t)d.n * sizeof(double));
    if (c < 3) conv3x3(hush__nca_kernel_gauss, s[c], p + (size_t)(HUSH_NCA_P_GAUSS + c) * d.n, d);
    conv3x3(hush__nca_kernel_laplace, s[c], p + (size_t)(HUSH_NCA_P_LAPLACE + c) * d.n, d);
    conv3x3(hush__nca_kernel_sobel_x, s[c], p + (size_t)(HUSH_NCA_P_SOBEL_X + c) * d.n, d);
    conv3x3(hush__nca_kernel_sobel_y, s[c], p + (size_t)(HUSH_NCA_P_SOBEL_Y + c) * d.n, d);
  }
}

/* ds += perception^T dp. */
static void perceive_adjoint_add(const double *dp, double *const ds[HUSH_NCA_CHANNELS],
                                 image_dims d) {
  for (int c = 0; c < HUSH_NCA_CHANNELS; c++) {
    const double *dpc = dp + (size_t)(HUSH_NCA_P_STATE + c) * d.n;
    for (long i = 0; i < d.n; i++) ds[c][i] += dpc[i];
    if (c < 3)
      conv3x3_adjoint_add(hush__nca_kernel_gauss, dp + (size_t)(HUSH_NCA_P_GAUSS + c) * d.n,
                          ds[c], d);
    conv3x3_adjoint_add(hush__nca_kernel_laplace, dp + (size_t)(HUSH_NCA_P_LAPLACE + c) * d.n,
                        ds[c], d);
    conv3x3_adjoint_add(hush__nca_kernel_sobel_x, dp + (size_t)(HUSH_NCA_P_SOBEL_X + c) * d.n,
                        ds[c], d);
    conv3x3_adjoint_add(hush__nca_kernel_sobel_y, dp + (size_t)(HUSH_NCA_P_SOBEL_Y + c) * d.n,
                        ds[c], d);
  }
}

/* One step: next = s + sigmoid(p W) + bias; the sigmoid into sig. */
static void step_forward(const double *params, double *const s[HUSH_NCA_CHANNELS],
                         double *const next[HUSH_NCA_CHANNELS], double *const sig[HUSH_NCA_CHANNELS],
                         double *p, image_dims d) {
  perceive(s, p, d);
  for (int j = 0; j < HUSH_NCA_CHANNELS; j++) {
    for (long i = 0; i < d.n; i++) {
      double z = 0.0;
      for (int k = 0; k < HUSH_NCA_PERCEPTION; k++)
        z += params[k * HUSH_NCA_CHANNELS + j] * p[(size_t)k * d.n + i];
      const double sg = 1.0 / (1.0 + exp(-z));
      sig[j][i] = sg;
      next[j][i] = s[j][i] + sg + params[HUSH_NCA_P_BIAS + j];
    }
  }
}

/* Memory of a forward/backward pass: K + 1 states, K sigmoid outputs,
 * perception, and gradient buffers. */
typedef struct pass {
  image_dims d;
  int iterations;
  double *block;
  double *state;   /* (K + 1) * 9 planes */
  double *sig;     /* K * 9 planes */
  double *p, *dp;  /* 39 planes each */
  double *g, *gn;  /* 9 planes each: dL/ds^{t+1}, dL/ds^t */
  double *blur[2]; /* loss: blurred prediction and reference */
} pass;

static double *plane(const pass *ps, double *base, long index) {
  return base + (size_t)index * (size_t)ps->d.n;
}

static int pass_init(pass *ps, const hush_nca_sample *sample, int iterations) {
  ps->d.w = sample->width;
  ps->d.h = sample->height;
  ps->d.n = ps->d.w * ps->d.h;
  ps->iterations = iterations;
  const size_t planes = (size_t)(iterations + 1) * HUSH_NCA_CHANNELS +
                        (size_t)iterations * HUSH_NCA_CHANNELS + 2 * HUSH_NCA_PERCEPTION +
                        2 * HUSH_NCA_CHANNELS + 2;
  ps->block = calloc(planes * (size_t)ps->d.n, sizeof(double));
  if (!ps->block) return -1;
  ps->state = ps->block;
  ps->sig = plane(ps, ps->state, (long)(iterations + 1) * HUSH_NCA_CHANNELS);
  ps->p = plane(ps, ps->sig, (long)iterations * HUSH_NCA_CHANNELS);
  ps->dp = plane(ps, ps->p, HUSH_NCA_PERCEPTION);
  ps->g = plane(ps, ps->dp, HUSH_NCA_PERCEPTION);
  ps->gn = plane(ps, ps->g, HUSH_NCA_CHANNELS);
  ps->blur[0] = plane(ps, ps->gn, HUSH_NCA_CHANNELS);
  ps->blur[1] = plane(ps, ps->blur[0], 1);
  return 0;
}

static void state_planes(const pass *ps, double *base, int t, double *out[HUSH_NCA_CHANNELS]) {
  for (int c = 0; c < HUSH_NCA_CHANNELS; c++)
    out[c] = plane(ps, base, (long)t * HUSH_NCA_CHANNELS + c);
}

static void run_forward(const double *params, const hush_nca_sample *sample, pass *ps) {
  double *s0[HUSH_NCA_CHANNELS];
  state_planes(ps, ps->state, 0, s0);
  for (int c = 0; c < HUSH_NCA_CHANNELS; c++)
    for (long i = 0; i < ps->d.n; i++) s0[c][i] = (double)sample->state[c][i];
  for (int t = 0; t < ps->iterations; t++) {
    double *s[HUSH_NCA_CHANNELS], *next[HUSH_NCA_CHANNELS], *sig[HUSH_NCA_CHANNELS];
    state_planes(ps, ps->state, t, s);
    state_planes(ps, ps->state, t + 1, next);
    state_planes(ps, ps->sig, t, sig);
    step_forward(params, s, next, sig, ps->p, ps->d);
  }
}

/* Loss of the final colour; with dpred (3 planes) its gradient there. */
static double loss_and_grad(const hush_nca_sample *sample, pass *ps,
                            const hush_nca_loss_weights *lw, double *const dpred[3]) {
  const image_dims d = ps->d;
  double *pred[HUSH_NCA_CHANNELS];
  state_planes(ps, ps->state, ps->iterations, pred);
  const double n_mse = 3.0 * (double)d.n;
  const double n_grad = 3.0 * (double)((d.w - 1) * d.h + d.w * (d.h - 1));
  double mse = 0.0, lg = 0.0;
  for (int c = 0; c < 3; c++) {
    double *bp = ps->blur[0], *bt = ps->blur[1];
    for (long i = 0; i < d.n; i++) {
      const double t = (double)sample->target[c][i];
      bt[i] = t;
      if (lw->space == HUSH_NCA_MSE_STATE) {
        const double e = pred[c][i] - t;
        mse += e * e;
        if (dpred) dpred[c][i] = lw->mse * 2.0 * e / n_mse;
        continue;
      }
      const int log1p_colour = lw->transform == HUSH_NCA_LOG1P;
      /* radiance of prediction and reference; dr the derivative of the
       * prediction's radiance by its state */
      const double dr = log1p_colour ? exp(pred[c][i]) : 1.0;
      const double rp = log1p_colour ? dr - 1.0 : pred[c][i];
      const double rt = log1p_colour ? expm1(t) : t;
      const double rp0 = rp > 0.0 ? rp : 0.0;
      const double wgt = lw->space == HUSH_NCA_MSE_RELATIVE             ? 1.0 / (rt * rt + 0.01)
                         : lw->space == HUSH_NCA_MSE_RELATIVE_PREDICTED ? 1.0 / (rp0 * rp0 + 0.01)
                         : lw->space == HUSH_NCA_MSE_WEIGHTED           ? lw->weight[c][i]
                                                                        : 1.0;
      const double e = rp - rt;
      mse += wgt * e * e;
      if (dpred) dpred[c][i] = lw->mse * 2.0 * wgt * e * dr / n_mse;
    }
    conv3x3(hush__nca_kernel_gauss, pred[c], bp, d);
    conv3x3(hush__nca_kernel_gauss, bt, ps->dp, d); /* dp as scratch */
    memcpy(bt, ps->dp, (size_t)d.n * sizeof(double));
    /* dL/dblur(prediction) accumulates in dp[1 plane] */
    double *db = ps->dp + d.n;
    memset(db, 0, (size_t)d.n * sizeof(double));
    const double scale = lw->gradient / n_grad;
    for (long y = 0; y < d.h; y++)
      for (long x = 0; x < d.w; x++) {
        const long i = y * d.w + x;
        if (x + 1 < d.w) {
          const double a = (bp[i + 1] - bp[i]) - (bt[i + 1] - bt[i]);
          lg += fabs(a);
          const double sg = (a > 0) - (a < 0);
          db[i + 1] += scale * sg;
          db[i] -= scale * sg;
        }
        if (y + 1 < d.h) {
          const double a = (bp[i + d.w] - bp[i]) - (bt[i + d.w] - bt[i]);
          lg += fabs(a);
          const double sg = (a > 0) - (a < 0);
          db[i + d.w] += scale * sg;
          db[i] -= scale * sg;
        }
      }
    if (dpred) conv3x3_adjoint_add(hush__nca_kernel_gauss, db, dpred[c], d);
  }
  return lw->mse * mse / n_mse + lw->gradient * lg / n_grad;
}

static void run_backward(const double *params, pass *ps, double *grad) {
  const image_dims d = ps->d;
  double *g[HUSH_NCA_CHANNELS], *gn[HUSH_NCA_CHANNELS];
  state_planes(ps, ps->g, 0, g);
  state_planes(ps, ps->gn, 0, gn);
  for (int t = ps->iterations - 1; t >= 0; t--) {
    double *s[HUSH_NCA_CHANNELS], *sig[HUSH_NCA_CHANNELS];
    state_planes(ps, ps->state, t, s);
    state_planes(ps, ps->sig, t, sig);
    perceive(s, ps->p, d);
    /* dz in place of g's copy: gn = g (identity path), then g becomes dz */
    for (int j = 0; j < HUSH_NCA_CHANNELS; j++) {
      double bsum = 0.0;
      for (long i = 0; i < d.n; i++) {
        gn[j][i] = g[j][i];
        bsum += g[j][i];
        g[j][i] *= sig[j][i] * (1.0 - sig[j][i]);
      }
      grad[HUSH_NCA_P_BIAS + j] += bsum;
    }
    for (int k = 0; k < HUSH_NCA_PERCEPTION; k++) {
      const double *pk = ps->p + (size_t)k * d.n;
      double *dpk = ps->dp + (size_t)k * d.n;
      for (int j = 0; j < HUSH_NCA_CHANNELS; j++) {
        double acc = 0.0;
        for (long i = 0; i < d.n; i++) acc += pk[i] * g[j][i];
        grad[k * HUSH_NCA_CHANNELS + j] += acc;
      }
      for (long i = 0; i < d.n; i++) {
        double v = 0.0;
        for (int j = 0; j < HUSH_NCA_CHANNELS; j++) v += params[k * HUSH_NCA_CHANNELS + j] * g[j][i];
        dpk[i] = v;
      }
    }
    perceive_adjoint_add(ps->dp, gn, d);
    for (int c = 0; c < HUSH_NCA_CHANNELS; c++) {
      double *tmp = g[c];
      g[c] = gn[c];
      gn[c] = tmp;
    }
  }
}

double hush__nca_loss(const double *params, int iterations, const hush_nca_sample *sample,
                      const hush_nca_loss_weights *lw, double *grad) {
  pass ps;
  if (pass_init(&ps, sample, iterations)) return -1.0;
  run_forward(params, sample, &ps);
  double *g[HUSH_NCA_CHANNELS];
  state_planes(&ps, ps.g, 0, g);
  const double loss = loss_and_grad(sample, &ps, lw, grad ? g : NULL);
  if (grad) {
    /* normals and albedo do not enter the loss directly */
    for (int c = 3; c < HUSH_NCA_CHANNELS; c++) memset(g[c], 0, (size_t)ps.d.n * sizeof(double));
    run_backward(params, &ps, grad);
  }
  free(ps.block);
  return loss;
}

int hush__nca_forward_double(const double *params, int iterations,
                             const hush_nca_sample *sample, double *const out[HUSH_NCA_CHANNELS]) {
  pass ps;
  if (pass_init(&ps, sample, iterations)) return -1;
  run_forward(params, sample, &ps);
  double *last[HUSH_NCA_CHANNELS];
  state_planes(&ps, ps.state, iterations, last);
  for (int c = 0; c < HUSH_NCA_CHANNELS; c++)
    memcpy(out[c], last[c], (size_t)ps.d.n * sizeof(double));
  free(ps.block);
  return 0;
}

void hush__nca_adam_init(hush_nca_adam *adam, double lr) {
  memset(adam, 0, sizeof *adam);
  adam->lr = lr;
  adam->beta1 = 0.9;
  adam->beta2 = 0.999;
  adam->eps = 1e-8;
}

void hush__nca_adam_step(hush_nca_adam *adam, double *params, const double *grad) {
  adam->t++;
  const double c1 = 1.0 - pow(adam->beta1, (double)adam->t);
  const double c2 = 1.0 - pow(adam->beta2, (double)adam->t);
  for (int i = 0; i < HUSH_NCA_PARAM_COUNT; i++) {
    adam->m[i] = adam->beta1 * adam->m[i] + (1.0 - adam->beta1) * grad[i];
    adam->v[i] = adam->beta2 * adam->v[i] + (1.0 - adam->beta2) * grad[i] * grad[i];
    params[i] -= adam->lr * (adam->m[i] / c1) / (sqrt(adam->v[i] / c2) + adam->eps);
  }
}

void hush__nca_params_from_weights(const hush_nca_weights *w, double *params) {
  for (int i = 0; i < HUSH_NCA_WEIGHT_COUNT; i++) params[i] = (double)w->w[i];
  for (int j = 0; j < HUSH_NCA_CHANNELS; j++) params[HUSH_NCA_P_BIAS + j] = (double)w->bias[j];
}

void hush__nca_weights_from_params(const double *params, hush_nca_weights *w) {
  for (int i = 0; i < HUSH_NCA_WEIGHT_COUNT; i++) w->w[i] = (float)params[i];
  for (int j = 0; j < HUSH_NCA_CHANNELS; j++) w->bias[j] = (float)params[HUSH_NCA_P_BIAS + j];
}
