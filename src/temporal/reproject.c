/*
 * reproject.c — back-projection into the previous frame, per-tap
 * consistency (depth, normal, id), the 2x2 bilinear footprint with a 3x3
 * fallback, and gathering history buffers through the resulting plan.
 *
 * Follows Higginson 2023 §1.3.1 (bilinear filter of the valid taps,
 * renormalised; 3x3 "bilinear grid" with kernel k; else the new sample),
 * Koskela et al. 2019 §3.2 (per-tap discard, weights renormalised over the
 * accepted taps) and Dundr 2018 §4.1.3 (motion vectors or camera matrices,
 * disocclusion by depth). See reproject.h for the conventions.
 */
#include "temporal/reproject.h"

#include "core/device.h"
#include "core/hmath.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

const float hush__reproject_k3x3[9] = {0.0778f, 0.1233f, 0.0778f, 0.1233f, 0.1953f,
                                       0.1233f, 0.0778f, 0.1233f, 0.0778f};

void hush__reproject_params_default(hush_reproject_params *p) {
  p->depth_tolerance = 0.1f;
  p->depth_gradient = 1.0f;
  p->normal_threshold = 0.9f;
  p->use_id = 1;
  p->fallback_3x3 = 1;
}

/* ---- plan ---------------------------------------------------------------- */

hush_status hush__reproject_plan_init(hush_device device, hush_reproject_plan *plan,
                                      uint32_t width, uint32_t height) {
  memset(plan, 0, sizeof *plan);
  const size_t n = (size_t)width * height;
  if (n == 0)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "reprojection plan of size %ux%u",
                      width, height);
  plan->origin = calloc(n, sizeof *plan->origin);
  plan->mask = calloc(n, sizeof *plan->mask);
  plan->kind = calloc(n, sizeof *plan->kind);
  plan->fx = hush__alloc_floats(n);
  plan->fy = hush__alloc_floats(n);
  if (!plan->origin || !plan->mask || !plan->kind || !plan->fx || !plan->fy) {
    hush__reproject_plan_free(plan);
    return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY,
                      "out of memory for a %ux%u reprojection plan", width, height);
  }
  plan->width = width;
  plan->height = height;
  plan->blocks = width >= 2 && height >= 2;
  return HUSH_OK;
}

void hush__reproject_plan_free(hush_reproject_plan *plan) {
  free(plan->origin);
  free(plan->mask);
  free(plan->kind);
  hush__free_floats(plan->fx);
  hush__free_floats(plan->fy);
  memset(plan, 0, sizeof *plan);
}

void hush__reproject_plan_clear(hush_reproject_plan *plan, int threads) {
  const int H = (int)plan->height;
  const size_t W = plan->width;
  if (threads < 1) threads = 1;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < H; y++) {
    const size_t row = (size_t)y * W;
    memset(plan->origin + row, 0, W * sizeof *plan->origin);
    memset(plan->mask + row, 0, W * sizeof *plan->mask);
    memset(plan->kind + row, 0, W * sizeof *plan->kind);
    memset(plan->fx + row, 0, W * sizeof *plan->fx);
    memset(plan->fy + row, 0, W * sizeof *plan->fy);
  }
}

/* ---- building ------------------------------------------------------------ */

/* Everything the per-pixel loop needs, resolved once per frame. */
typedef struct build_ctx {
  const hush_reproject_input *in;
  const hush_gbuffer *prev;
  int W, H;
  int vectors;      /* HUSH_MOTION_VECTORS */
  int has_position; /* in->position usable */
  int inv_ok;       /* the current camera can be inverted */
  int std_proj;     /* view_to_clip's z and w rows depend on view z only */
  int use_id;       /* both frames have ids and the test is on */
  int fallback;
  float tol, grad, cos_min;
  float jx, jy;
  /* std_proj: clip = (nx w, ny w, p10 (-z) + p14, w), w = p11 (-z) + p15 */
  float p10, p11, p14, p15;
  float cur_to_prev[16]; /* prev_vp * inverse(view_to_clip * world_to_view) */
  float cur_to_prev_view_z[4]; /* row 2 of prev_world_to_view * that inverse */
  /* generic projections */
  float inv_v2c[16], inv_w2v[16];
  float prev_vp[16];  /* prev_view_to_clip * prev_world_to_view */
  float prev_w2v[16]; /* for the expected depth */
} build_ctx;

/* The point at view depth z (w = 1) or, for background, the direction
 * (w = 0) on the ray through the CENTRE of pixel (x, y), in world space, for
 * any invertible projection. (std_proj cameras use the cheaper clip-space
 * form in back_project_span.) Using the centre ray rather than the jittered one
 * makes the result exact for any camera rotation; under translation the only
 * error is the parallax of the depth difference between the jittered sample
 * and the centre. Returns 0 when it cannot be reconstructed. */
static int reconstruct(const build_ctx *c, float nx, float ny, float z, int bg, hush_vec4 *out) {
  hush_vec4 a = hush_m4_mul_v4(c->inv_v2c, nx, ny, -1.0f, 1.0f);
  hush_vec4 b = hush_m4_mul_v4(c->inv_v2c, nx, ny, 1.0f, 1.0f);
  if (a.w == 0.0f || b.w == 0.0f) return 0;
  const float ia = 1.0f / a.w, ib = 1.0f / b.w;
  const float ax = a.x * ia, ay = a.y * ia, az = a.z * ia;
  const float dx = b.x * ib - ax, dy = b.y * ib - ay, dz = b.z * ib - az;
  if (bg) {
    *out = hush_m4_mul_v4(c->inv_w2v, dx, dy, dz, 0.0f);
    out->w = 0.0f;
    return isfinite(out->x) && isfinite(out->y) && isfinite(out->z);
  }
  if (dz == 0.0f) return 0;
  const float t = (-z - az) / dz;
  *out = hush_m4_mul_v4(c->inv_w2v, ax + t * dx, ay + t * dy, az + t * dz, 1.0f);
  out->w = 1.0f;
  return isfinite(out->x) && isfinite(out->y) && isfinite(out->z);
}

/* View depth of world point p in the previous camera. */
static inline float prev_depth(const build_ctx *c, hush_vec4 p) {
  const float *m = c->prev_w2v;
  return -(m[2] * p.x + m[6] * p.y + m[10] * p.z + m[14] * p.w);
}

/* Marks a pixel with no previous location in the span buffers. */
#define NO_LOCATION (-1e30f)

#if defined(__GNUC__)
#  define HUSH_ALWAYS_INLINE inline __attribute__((always_inline))
#else
#  define HUSH_ALWAYS_INLINE inline
#endif

/* The span arrays of back_project_span. */
typedef struct span_out {
  float *px, *py, *ze;
} span_out;

/* HUSH_MOTION_VECTORS, std_proj: the motion gives the location; the
 * expected depth is the point's view depth in the previous camera.
 * use_pos is a constant at each call, so each loop is branch-free. */
static HUSH_ALWAYS_INLINE void span_vectors(const build_ctx *c, int y, int x_begin, int n,
                                            span_out o, const int use_pos) {
  const hush_reproject_input *in = c->in;
  const size_t row = (size_t)y * (size_t)c->W + (size_t)x_begin;
  const float *zr = in->cur.depth + row;
  const float *mx = in->motion[0] + row, *my = in->motion[1] + row;
  /* unread without use_pos: any valid pointer (no arithmetic on NULL) */
  const float *X = use_pos ? in->position[0] + row : zr;
  const float *Y = use_pos ? in->position[1] + row : zr;
  const float *Z = use_pos ? in->position[2] + row : zr;
  const float ny = 1.0f - 2.0f * ((float)y + 0.5f) / (float)c->H;
  const float sxf = 2.0f / (float)c->W;
  const float p10 = c->p10, p11 = c->p11, p14 = c->p14, p15 = c->p15;
  const float r0 = c->cur_to_prev_view_z[0], r1 = c->cur_to_prev_view_z[1];
  const float r2 = c->cur_to_prev_view_z[2], r3 = c->cur_to_prev_view_z[3];
  const float v2 = c->prev_w2v[2], v6 = c->prev_w2v[6], v10 = c->prev_w2v[10];
  const float v14 = c->prev_w2v[14];
  float *restrict pxo = o.px, *restrict pyo = o.py, *restrict zeo = o.ze;
  for (int k = 0; k < n; k++) {
    const float z = zr[k];
    pxo[k] = (float)(x_begin + k) + 0.5f + mx[k];
    pyo[k] = (float)y + 0.5f + my[k];
    float d, w = 1.0f;
    if (use_pos) {
      d = -(v2 * X[k] + v6 * Y[k] + v10 * Z[k] + v14);
    } else {
      const float nx = ((float)(x_begin + k) + 0.5f) * sxf - 1.0f;
      w = p15 - p11 * z;
      const float c2 = p14 - p10 * z;
      d = -(r0 * (nx * w) + r1 * (ny * w) + r2 * c2 + r3 * w);
    }
    zeo[k] = (z > 0.0f && w > 0.0f && d > 0.0f) ? d : z;
  }
}

/* HUSH_MOTION_CAMERA, std_proj: the pixel's homogeneous clip vector (the
 * point at depth z on the centre ray, or for background the direction at
 * infinity) taken to the previous clip space by one matrix; with use_pos,
 * surfaces project their position instead. */
static HUSH_ALWAYS_INLINE void span_camera(const build_ctx *c, int y, int x_begin, int n,
                                           span_out o, const int use_pos) {
  const hush_reproject_input *in = c->in;
  const size_t row = (size_t)y * (size_t)c->W + (size_t)x_begin;
  const float *zr = in->cur.depth + row;
  /* unread without use_pos: any valid pointer (no arithmetic on NULL) */
  const float *X = use_pos ? in->position[0] + row : zr;
  const float *Y = use_pos ? in->position[1] + row : zr;
  const float *Z = use_pos ? in->position[2] + row : zr;
  const float Wf = (float)c->W, Hf = (float)c->H;
  const float ny = 1.0f - 2.0f * ((float)y + 0.5f) / Hf;
  const float sxf = 2.0f / Wf;
  const float p10 = c->p10, p11 = c->p11, p14 = c->p14, p15 = c->p15;
  float M[16], R[4], P[16], V[4];
  memcpy(M, c->cur_to_prev, sizeof M);
  memcpy(R, c->cur_to_prev_view_z, sizeof R);
  memcpy(P, c->prev_vp, sizeof P);
  for (int k = 0; k < 4; k++) V[k] = c->prev_w2v[k * 4 + 2];
  const float jx = c->jx, jy = c->jy;
  float *restrict pxo = o.px, *restrict pyo = o.py, *restrict zeo = o.ze;
  for (int k = 0; k < n; k++) {
    const float z = zr[k];
    const int bg = !(z > 0.0f);
    const float nx = ((float)(x_begin + k) + 0.5f) * sxf - 1.0f;
    const float w = bg ? -p11 : p15 - p11 * z;
    const float c0 = nx * w, c1 = ny * w, c2 = bg ? -p10 : p14 - p10 * z;
    float qx = M[0] * c0 + M[4] * c1 + M[8] * c2 + M[12] * w;
    float qy = M[1] * c0 + M[5] * c1 + M[9] * c2 + M[13] * w;
    float qw = M[3] * c0 + M[7] * c1 + M[11] * c2 + M[15] * w;
    float ze = -(R[0] * c0 + R[1] * c1 + R[2] * c2 + R[3] * w);
    int ok = (w > 0.0f) | (bg & (w == 0.0f));
    float sjx = 0.0f, sjy = 0.0f;
    if (use_pos) {
      /* a surface's "position" is its jittered sample's hit point: its
       * previous coordinate minus this frame's jitter estimates the
       * centre's (first order) */
      const int sp = !bg;
      const float x3 = X[k], y3 = Y[k], z3 = Z[k];
      qx = sp ? P[0] * x3 + P[4] * y3 + P[8] * z3 + P[12] : qx;
      qy = sp ? P[1] * x3 + P[5] * y3 + P[9] * z3 + P[13] : qy;
      qw = sp ? P[3] * x3 + P[7] * y3 + P[11] * z3 + P[15] : qw;
      ze = sp ? -(V[0] * x3 + V[1] * y3 + V[2] * z3 + V[3]) : ze;
      ok = sp | ok;
      sjx = sp ? jx : 0.0f;
      sjy = sp ? jy : 0.0f;
    }
    ok &= (qw > 0.0f) & (bg | (ze > 0.0f));
    const float iw = 1.0f / qw;
    const float px = (qx * iw + 1.0f) * 0.5f * Wf - sjx;
    const float py = (1.0f - qy * iw) * 0.5f * Hf - sjy;
    pxo[k] = ok ? px : NO_LOCATION;
    pyo[k] = ok ? py : NO_LOCATION;
    zeo[k] = ze;
  }
}

static void back_project_general(const build_ctx *c, int x, int y, size_t i, float *pxo,
                                 float *pyo, float *zeo);

/*
 * Back-projection of pixels x_begin .. x_begin + n - 1 of row y: the
 * continuous previous-frame coordinate of each pixel centre (NO_LOCATION
 * when there is none) and, for surfaces, the expected previous view depth.
 * Perspective and orthographic cameras (std_proj) take the branch-free
 * loops above, which the compiler vectorises; other projections the general
 * per-pixel path.
 */
static void back_project_span(const build_ctx *c, int y, int x_begin, int n, span_out o) {
  if (!c->std_proj || !c->inv_ok) {
    const size_t row = (size_t)y * (size_t)c->W + (size_t)x_begin;
    for (int k = 0; k < n; k++)
      back_project_general(c, x_begin + k, y, row + (size_t)k, &o.px[k], &o.py[k], &o.ze[k]);
  } else if (c->vectors) {
    if (c->has_position)
      span_vectors(c, y, x_begin, n, o, 1);
    else
      span_vectors(c, y, x_begin, n, o, 0);
  } else {
    if (c->has_position)
      span_camera(c, y, x_begin, n, o, 1);
    else
      span_camera(c, y, x_begin, n, o, 0);
  }
}

/* One pixel, any invertible projection (or none, with position/motion). */
static void back_project_general(const build_ctx *c, int x, int y, size_t i, float *pxo,
                                 float *pyo, float *zeo) {
  const hush_reproject_input *in = c->in;
  const float z = in->cur.depth[i];
  const int bg = !(z > 0.0f);
  const float nx = 2.0f * ((float)x + 0.5f) / (float)c->W - 1.0f;
  const float ny = 1.0f - 2.0f * ((float)y + 0.5f) / (float)c->H;
  const int use_position = !bg && c->has_position;
  *pxo = *pyo = NO_LOCATION;
  *zeo = z;
  hush_vec4 p = {0.0f, 0.0f, 0.0f, 0.0f};
  int have_point = 0;
  if (use_position) {
    p.x = in->position[0][i];
    p.y = in->position[1][i];
    p.z = in->position[2][i];
    p.w = 1.0f;
    have_point = 1;
  } else if (c->inv_ok) {
    have_point = reconstruct(c, nx, ny, z, bg, &p);
  }
  if (c->vectors) {
    *pxo = (float)x + 0.5f + in->motion[0][i];
    *pyo = (float)y + 0.5f + in->motion[1][i];
    if (!bg && have_point) {
      const float d = prev_depth(c, p);
      if (d > 0.0f) *zeo = d; /* else keep this frame's depth */
    }
    return;
  }
  if (!have_point) return;
  const hush_vec4 q = hush_m4_mul_v4(c->prev_vp, p.x, p.y, p.z, p.w);
  if (!(q.w > 0.0f)) return; /* behind the previous camera */
  if (!bg) {
    *zeo = prev_depth(c, p);
    if (!(*zeo > 0.0f)) return;
  }
  const float jx = use_position ? c->jx : 0.0f, jy = use_position ? c->jy : 0.0f;
  const float iw = 1.0f / q.w;
  *pxo = (q.x * iw + 1.0f) * 0.5f * (float)c->W - jx;
  *pyo = (1.0f - q.y * iw) * 0.5f * (float)c->H - jy;
}

/* This pixel's values the taps are compared with. */
typedef struct pixel_ref {
  int bg;
  int x, y;
  size_t i;
  float z;
  float ze;     /* expected previous depth */
  float tolz;   /* depth_tolerance * ze */
  int slopes;   /* gx, gy computed (lazily: only when a tap needs them) */
  float gx, gy; /* |depth slope| per pixel, times depth_gradient * ze / z */
  float n[3];
  float id;
} pixel_ref;

/* Whether neighbour j of this frame is on the same surface as pixel i
 * (surface, normal within the threshold, same id): only those give the
 * depth slope, so a crease or an edge does not distort it. */
static inline int same_surface(const build_ctx *c, size_t i, size_t j) {
  const hush_gbuffer *g = &c->in->cur;
  if (!(g->depth[j] > 0.0f)) return 0;
  const float d = g->normal[0][i] * g->normal[0][j] + g->normal[1][i] * g->normal[1][j] +
                  g->normal[2][i] * g->normal[2][j];
  if (d < c->cos_min) return 0;
  return !c->use_id || g->id[i] == g->id[j];
}

/* |dz| per pixel of pixel i along one axis, from its neighbours i - step
 * (when has_a) and i + step (when has_b) on the same surface: the smaller
 * one-sided difference; 0 without such a neighbour. */
static float depth_slope(const build_ctx *c, size_t i, size_t step, int has_a, int has_b) {
  const float *z = c->in->cur.depth;
  float d = HUGE_VALF;
  if (has_a && same_surface(c, i, i - step)) d = fabsf(z[i] - z[i - step]);
  if (has_b && same_surface(c, i, i + step)) {
    const float db = fabsf(z[i + step] - z[i]);
    if (db < d) d = db;
  }
  return d < HUGE_VALF ? d : 0.0f;
}

/* Tap j of the previous frame, at offset (ox, oy) pixels from the
 * back-projected point. */
static inline int tap_ok(const build_ctx *c, pixel_ref *r, int32_t j, float ox, float oy) {
  const hush_gbuffer *p = c->prev;
  const float zt = p->depth[j];
  if (r->bg) {
    if (zt > 0.0f) return 0;
  } else {
    if (!(zt > 0.0f)) return 0;
    const float dz = fabsf(zt - r->ze);
    if (dz > r->tolz) {
      if (!(c->grad > 0.0f)) return 0;
      if (!r->slopes) {
        const float s = c->grad * r->ze / r->z;
        r->gx = s * depth_slope(c, r->i, 1, r->x > 0, r->x + 1 < c->W);
        r->gy = s * depth_slope(c, r->i, (size_t)c->W, r->y > 0, r->y + 1 < c->H);
        r->slopes = 1;
      }
      if (dz > r->tolz + r->gx * fabsf(ox) + r->gy * fabsf(oy)) return 0;
    }
    const float d = r->n[0] * p->normal[0][j] + r->n[1] * p->normal[1][j] + r->n[2] * p->normal[2][j];
    if (d < c->cos_min) return 0;
  }
  if (c->use_id && p->id[j] != r->id) return 0;
  return 1;
}

#define SPAN 256

static void build_row(const build_ctx *c, hush_reproject_plan *plan, int y) {
  const hush_gbuffer *cur = &c->in->cur;
  const int W = c->W, H = c->H;
  float span_px[SPAN], span_py[SPAN], span_ze[SPAN];
  for (int x = 0; x < W; x++) {
    const int k = x % SPAN;
    if (k == 0) {
      const span_out so = {span_px, span_py, span_ze};
      back_project_span(c, y, x, W - x < SPAN ? W - x : SPAN, so);
    }
    const size_t i = (size_t)y * (size_t)W + (size_t)x;
    unsigned mask = 0;
    uint8_t kind = HUSH_FOOTPRINT_NONE;
    int32_t origin = 0;
    float fx = 0.0f, fy = 0.0f;
    pixel_ref r;
    r.z = cur->depth[i];
    r.bg = !(r.z > 0.0f);
    const float px = span_px[k], py = span_py[k];
    r.ze = span_ze[k];
    if (px > -2.0f && px < (float)W + 2.0f && py > -2.0f && py < (float)H + 2.0f) {
      r.x = x;
      r.y = y;
      r.i = i;
      r.tolz = c->tol * r.ze;
      r.slopes = 0;
      r.gx = r.gy = 0.0f;
      r.n[0] = cur->normal[0][i];
      r.n[1] = cur->normal[1][i];
      r.n[2] = cur->normal[2][i];
      r.id = c->use_id ? cur->id[i] : 0.0f;
      /* 2x2 bilinear footprint around the tap-grid coordinate p - 0.5. */
      const float sx = px - 0.5f, sy = py - 0.5f;
      const float flx = floorf(sx), fly = floorf(sy);
      const int x0 = (int)flx, y0 = (int)fly;
      fx = sx - flx;
      fy = sy - fly;
      float bw[4];
      hush__reproject_bilinear(fx, fy, bw);
      if (!r.bg && x0 >= 0 && y0 >= 0 && x0 + 1 < W && y0 + 1 < H) {
        /* The common case, without branches: the plain tests on all four
         * taps, then the full test (depth gradient) on those that failed;
         * the same result as tap_ok on each. */
        const hush_gbuffer *pg = c->prev;
        const int32_t j0 = (int32_t)y0 * W + x0;
        const int32_t jj[4] = {j0, j0 + 1, j0 + W, j0 + W + 1};
        for (int t = 0; t < 4; t++) {
          const int32_t j = jj[t];
          const float zt = pg->depth[j];
          const float d = r.n[0] * pg->normal[0][j] + r.n[1] * pg->normal[1][j] +
                          r.n[2] * pg->normal[2][j];
          int ok = (zt > 0.0f) & (fabsf(zt - r.ze) <= r.tolz) & (d >= c->cos_min) &
                   (bw[t] >= HUSH_REPROJECT_MIN_WEIGHT);
          if (c->use_id) ok &= pg->id[j] == r.id;
          mask |= (unsigned)ok << t;
        }
        if (mask != 0xfu && c->grad > 0.0f)
          for (int t = 0; t < 4; t++)
            if (!(mask & (1u << t)) && bw[t] >= HUSH_REPROJECT_MIN_WEIGHT &&
                tap_ok(c, &r, jj[t], (float)(t & 1) - fx, (float)(t >> 1) - fy))
              mask |= 1u << t;
      } else {
        for (int t = 0; t < 4; t++) {
          const int xt = x0 + (t & 1), yt = y0 + (t >> 1);
          if (xt < 0 || xt >= W || yt < 0 || yt >= H || !(bw[t] >= HUSH_REPROJECT_MIN_WEIGHT))
            continue;
          if (tap_ok(c, &r, (int32_t)yt * W + xt, (float)(t & 1) - fx, (float)(t >> 1) - fy))
            mask |= 1u << t;
        }
      }
      if (mask) {
        kind = HUSH_FOOTPRINT_BILINEAR;
        int bx = x0, by = y0;
        if (plan->blocks) {
          /* move an overhanging footprint inside: same taps, same weights */
          if (bx < 0) {
            bx = 0;
            mask = (mask & 0xau) >> 1;
            fx = 0.0f;
          } else if (bx > W - 2) {
            bx = W - 2;
            mask = (mask & 0x5u) << 1;
            fx = 1.0f;
          }
          if (by < 0) {
            by = 0;
            mask = (mask & 0xcu) >> 2;
            fy = 0.0f;
          } else if (by > H - 2) {
            by = H - 2;
            mask = (mask & 0x3u) << 2;
            fy = 1.0f;
          }
        }
        origin = (int32_t)by * W + bx;
      } else if (c->fallback) {
        /* 3x3 around the pixel that contains p. */
        const int cx = (int)floorf(px), cy = (int)floorf(py);
        for (int t = 0; t < 9; t++) {
          const int xt = cx - 1 + t % 3, yt = cy - 1 + t / 3;
          if (xt < 0 || xt >= W || yt < 0 || yt >= H) continue;
          if (tap_ok(c, &r, (int32_t)yt * W + xt, (float)xt - sx, (float)yt - sy))
            mask |= 1u << t;
        }
        if (mask) {
          kind = HUSH_FOOTPRINT_3X3;
          origin = (int32_t)(cy - 1) * W + (cx - 1);
        }
      }
    }
    if (kind != HUSH_FOOTPRINT_BILINEAR) fx = fy = 0.0f;
    plan->origin[i] = origin;
    plan->mask[i] = (uint16_t)mask;
    plan->kind[i] = kind;
    plan->fx[i] = fx;
    plan->fy[i] = fy;
  }
}

hush_status hush__reproject_build(hush_device device, hush_reproject_plan *plan,
                                  const hush_reproject_input *in, const hush_gbuffer *prev,
                                  const hush_frame_info *info, const hush_reproject_params *params,
                                  int threads) {
  if (threads < 1) threads = 1;
  const int vectors = info->motion == HUSH_MOTION_VECTORS;
  if (vectors && (!in->motion[0] || !in->motion[1]))
    return hush__fail(device, HUSH_ERROR_INVALID_OPERATION,
                      "motion source is HUSH_MOTION_VECTORS but no motion image is bound");
  build_ctx c;
  memset(&c, 0, sizeof c);
  c.in = in;
  c.prev = prev;
  c.W = (int)plan->width;
  c.H = (int)plan->height;
  c.vectors = vectors;
  c.has_position = in->position[0] && in->position[1] && in->position[2];
  const float *v2c = info->view_to_clip;
  float vp[16], inv_vp[16];
  hush_m4_mul(vp, v2c, info->world_to_view);
  c.inv_ok = hush_m4_invert(c.inv_v2c, v2c) && hush_m4_invert(c.inv_w2v, info->world_to_view) &&
             hush_m4_invert(inv_vp, vp);
  if (!vectors && !c.has_position && !c.inv_ok)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                      "camera reprojection without 'position' needs invertible world_to_view "
                      "and view_to_clip matrices");
  if (!prev || info->history == HUSH_HISTORY_RESET) {
    hush__reproject_plan_clear(plan, threads);
    return HUSH_OK;
  }
  c.use_id = params->use_id && in->cur.id && prev->id;
  c.fallback = params->fallback_3x3;
  c.tol = params->depth_tolerance;
  c.grad = params->depth_gradient;
  c.cos_min = params->normal_threshold;
  c.jx = info->jitter[0];
  c.jy = info->jitter[1];
  hush_m4_mul(c.prev_vp, info->prev_view_to_clip, info->prev_world_to_view);
  memcpy(c.prev_w2v, info->prev_world_to_view, sizeof c.prev_w2v);
  /* Perspective and orthographic projections: clip z and w depend on view z
   * only, so a pixel's clip vector follows from (nx, ny, depth) and one
   * matrix takes it to the previous clip space. */
  c.std_proj = v2c[2] == 0.0f && v2c[6] == 0.0f && v2c[3] == 0.0f && v2c[7] == 0.0f;
  c.p10 = v2c[10];
  c.p11 = v2c[11];
  c.p14 = v2c[14];
  c.p15 = v2c[15];
  if (c.inv_ok) {
    float m[16];
    hush_m4_mul(c.cur_to_prev, c.prev_vp, inv_vp);
    hush_m4_mul(m, info->prev_world_to_view, inv_vp);
    for (int k = 0; k < 4; k++) c.cur_to_prev_view_z[k] = m[k * 4 + 2];
  }

  const int H = c.H;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < H; y++) build_row(&c, plan, y);
  return HUSH_OK;
}

/* ---- gathering ----------------------------------------------------------- */

#define GATHER_MAX 8

void hush__reproject_gather(const hush_reproject_plan *plan, const float *const *prev,
                            int channels, float *const *out, float fill_value, int threads) {
  const int H = (int)plan->height;
  const size_t W = plan->width;
  if (threads < 1) threads = 1;
  if (channels > GATHER_MAX) channels = GATHER_MAX;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < H; y++) {
    for (size_t x = 0; x < W; x++) {
      const size_t i = (size_t)y * W + x;
      if (hush__reproject_is_block(plan, i)) {
        float w4[4];
        hush__reproject_weights4(plan, i, w4);
        const size_t o = (size_t)plan->origin[i];
        for (int ch = 0; ch < channels; ch++) out[ch][i] = hush__reproject_apply4(prev[ch], o, W, w4);
        continue;
      }
      int32_t idx[9];
      float w[9];
      const int n = hush__reproject_taps(plan, i, idx, w);
      for (int ch = 0; ch < channels; ch++)
        out[ch][i] = n ? hush__reproject_apply(prev[ch], idx, w, n) : fill_value;
    }
  }
}

/* ---- reprojector ---------------------------------------------------------- */

hush_status hush__reprojector_init(hush_device device, hush_reprojector *r, uint32_t width,
                                   uint32_t height) {
  memset(r, 0, sizeof *r);
  r->width = width;
  r->height = height;
  hush_status s = HUSH_OK;
  for (int k = 0; k < 2 && !s; k++) {
    s = hush__planar_init(device, &r->store[k].depth, 1, width, height);
    if (!s) s = hush__planar_init(device, &r->store[k].normal, 3, width, height);
  }
  if (!s) s = hush__reproject_plan_init(device, &r->plan, width, height);
  if (s) hush__reprojector_free(r);
  return s;
}

void hush__reprojector_free(hush_reprojector *r) {
  for (int k = 0; k < 2; k++) {
    hush__planar_free(&r->store[k].depth);
    hush__planar_free(&r->store[k].normal);
    hush__planar_free(&r->store[k].id);
  }
  hush__reproject_plan_free(&r->plan);
  memset(r, 0, sizeof *r);
}

void hush__reprojector_reset(hush_reprojector *r) { r->has_history = 0; }

hush_status hush__reprojector_want_id(hush_device device, hush_reprojector *r) {
  for (int k = 0; k < 2; k++) {
    if (r->store[k].id.plane[0]) continue;
    hush_status s = hush__planar_init(device, &r->store[k].id, 1, r->width, r->height);
    if (s) return s;
    r->store[k].has_id = 0;
  }
  return HUSH_OK;
}

static void gbuffer_of(const hush_gbuffer_store *st, hush_gbuffer *g) {
  g->depth = st->depth.plane[0];
  for (int k = 0; k < 3; k++) g->normal[k] = st->normal.plane[k];
  g->id = st->has_id ? st->id.plane[0] : NULL;
}

hush_status hush__reprojector_build(hush_device device, hush_reprojector *r,
                                    const float *const *position, const float *const *motion,
                                    const hush_frame_info *info,
                                    const hush_reproject_params *params, int threads) {
  hush_reproject_input in;
  memset(&in, 0, sizeof in);
  gbuffer_of(hush__reprojector_next(r), &in.cur);
  if (position)
    for (int k = 0; k < 3; k++) in.position[k] = position[k];
  if (motion)
    for (int k = 0; k < 2; k++) in.motion[k] = motion[k];
  hush_gbuffer prev;
  gbuffer_of(&r->store[r->latest], &prev);
  hush_status s = hush__reproject_build(device, &r->plan, &in, r->has_history ? &prev : NULL,
                                        info, params, threads);
  if (s) return s;
  r->latest = 1 - r->latest;
  r->has_history = 1;
  return HUSH_OK;
}
