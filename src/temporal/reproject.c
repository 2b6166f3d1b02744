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
/* With AVX-512, tuned for a core whose gathers are fast (vgatherdps: ~9
 * cycles per 16 floats here): under the default -mtune=generic gcc emulates
 * the tap loads of chunks whose footprints do not follow each other with
 * scalar loads and inserts at 4 lanes (most of the build's time under camera
 * motion). Tuning changes no result (no -ffast-math; contraction as before). */
#if defined(__GNUC__) && !defined(__clang__) && defined(__AVX512F__)
#  pragma GCC target("tune=cooperlake", "prefer-vector-width=512")
#endif
#include "temporal/reproject.h"

#include "core/device.h"
#include "core/hmath.h"
#include "core/stream.h"

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
  plan->origin = hush__alloc_counted(n, sizeof *plan->origin);
  plan->mask = hush__alloc_counted(n, sizeof *plan->mask);
  plan->kind = hush__alloc_counted(n, sizeof *plan->kind);
  int ok = plan->origin && plan->mask && plan->kind;
  for (int t = 0; t < 4; t++) {
    plan->w[t] = hush__alloc_floats(n);
    ok = ok && plan->w[t];
  }
  if (!ok) {
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
  for (int t = 0; t < 4; t++) hush__free_floats(plan->w[t]);
  memset(plan, 0, sizeof *plan);
}

/* Rows y0..y1-1 of the plan: NONE. */
static void clear_rows(hush_reproject_plan *plan, int y0, int y1) {
  const size_t W = plan->width;
  for (int y = y0; y < y1; y++) {
    const size_t row = (size_t)y * W;
    memset(plan->origin + row, 0, W * sizeof *plan->origin);
    memset(plan->mask + row, 0, W * sizeof *plan->mask);
    memset(plan->kind + row, 0, W * sizeof *plan->kind);
    for (int t = 0; t < 4; t++) memset(plan->w[t] + row, 0, W * sizeof *plan->w[t]);
  }
}

void hush__reproject_plan_clear(hush_reproject_plan *plan, int threads) {
  const int H = (int)plan->height;
  if (threads < 1) threads = 1;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < H; y++) clear_rows(plan, y, y + 1);
}

/* ---- building ------------------------------------------------------------ */

/* Everything the per-pixel loop needs, resolved once per frame
 * (reproject.h). */
typedef hush_reproject_job build_ctx;

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


/* The span arrays of back_project_span. span_vectors and span_camera take
 * them as restrict parameters, not as this struct: gcc ignores restrict on
 * local pointers, and with position planes a loop needs more run-time alias
 * checks than it versions for (10), so it stayed scalar. */
typedef struct span_out {
  float *px, *py, *ze;
} span_out;

/* HUSH_MOTION_VECTORS, std_proj: the motion gives the location; the
 * expected depth is the point's view depth in the previous camera.
 * use_pos is a constant at each call, so each loop is branch-free. */
static HUSH_ALWAYS_INLINE void span_vectors(const build_ctx *c, int y, int x_begin, int n,
                                            float *restrict pxo, float *restrict pyo,
                                            float *restrict zeo, const int use_pos) {
  const hush_reproject_input *in = &c->in;
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

/* span_camera's use_pos: the centre ray only, positions for surfaces, or
 * a span without background (the common case), where every pixel projects
 * its position and the centre-ray transform (whose result the mixed mode
 * computes and then discards for surfaces) is skipped: half the arithmetic
 * of the loop, the same expressions and results. */
enum { POS_NONE = 0, POS_SURFACES = 1, POS_ALL = 2 };

/* HUSH_MOTION_CAMERA, std_proj: the pixel's homogeneous clip vector (the
 * point at depth z on the centre ray, or for background the direction at
 * infinity) taken to the previous clip space by one matrix; with use_pos,
 * surfaces project their position instead. */
static HUSH_ALWAYS_INLINE void span_camera(const build_ctx *c, int y, int x_begin, int n,
                                           float *restrict pxo, float *restrict pyo,
                                           float *restrict zeo, const int use_pos) {
  const hush_reproject_input *in = &c->in;
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
  float M[16], R[4];
  memcpy(M, c->cur_to_prev, sizeof M);
  memcpy(R, c->cur_to_prev_view_z, sizeof R);
  /* the rows of prev_vp and prev_w2v use_pos needs, as scalars (gcc does
   * not vectorise the loop with them in a local array) */
  const float *P = c->prev_vp;
  const float P0 = P[0], P4 = P[4], P8 = P[8], P12 = P[12];
  const float P1 = P[1], P5 = P[5], P9 = P[9], P13 = P[13];
  const float P3 = P[3], P7 = P[7], P11 = P[11], P15 = P[15];
  const float V0 = c->prev_w2v[2], V1 = c->prev_w2v[6], V2 = c->prev_w2v[10];
  const float V3 = c->prev_w2v[14];
  const float jx = c->jx, jy = c->jy;
  for (int k = 0; k < n; k++) {
    float qx, qy, qw, ze, sjx = 0.0f, sjy = 0.0f;
    int ok, bg = 0;
    /* a surface's "position" is its jittered sample's hit point: its
     * previous coordinate minus this frame's jitter estimates the centre's
     * (first order) */
    const float x3 = X[k], y3 = Y[k], z3 = Z[k];
    if (use_pos == POS_ALL) {
      qx = P0 * x3 + P4 * y3 + P8 * z3 + P12;
      qy = P1 * x3 + P5 * y3 + P9 * z3 + P13;
      qw = P3 * x3 + P7 * y3 + P11 * z3 + P15;
      ze = -(V0 * x3 + V1 * y3 + V2 * z3 + V3);
      ok = 1;
      sjx = jx;
      sjy = jy;
    } else {
      const float z = zr[k];
      bg = !(z > 0.0f);
      const float nx = ((float)(x_begin + k) + 0.5f) * sxf - 1.0f;
      const float w = bg ? -p11 : p15 - p11 * z;
      const float c0 = nx * w, c1 = ny * w, c2 = bg ? -p10 : p14 - p10 * z;
      qx = M[0] * c0 + M[4] * c1 + M[8] * c2 + M[12] * w;
      qy = M[1] * c0 + M[5] * c1 + M[9] * c2 + M[13] * w;
      qw = M[3] * c0 + M[7] * c1 + M[11] * c2 + M[15] * w;
      ze = -(R[0] * c0 + R[1] * c1 + R[2] * c2 + R[3] * w);
      ok = (w > 0.0f) | (bg & (w == 0.0f));
      if (use_pos == POS_SURFACES) {
        const int sp = !bg;
        qx = sp ? P0 * x3 + P4 * y3 + P8 * z3 + P12 : qx;
        qy = sp ? P1 * x3 + P5 * y3 + P9 * z3 + P13 : qy;
        qw = sp ? P3 * x3 + P7 * y3 + P11 * z3 + P15 : qw;
        ze = sp ? -(V0 * x3 + V1 * y3 + V2 * z3 + V3) : ze;
        ok = sp | ok;
        sjx = sp ? jx : 0.0f;
        sjy = sp ? jy : 0.0f;
      }
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

/* Whether pixels x_begin .. x_begin + n - 1 of row y are all surfaces. */
static int span_all_surface(const build_ctx *c, int y, int x_begin, int n) {
  const float *z = c->in.cur.depth + (size_t)y * (size_t)c->W + (size_t)x_begin;
  int bg = 0;
  for (int k = 0; k < n; k++) bg |= !(z[k] > 0.0f);
  return !bg;
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
      span_vectors(c, y, x_begin, n, o.px, o.py, o.ze, 1);
    else
      span_vectors(c, y, x_begin, n, o.px, o.py, o.ze, 0);
  } else {
    if (c->has_position && span_all_surface(c, y, x_begin, n))
      span_camera(c, y, x_begin, n, o.px, o.py, o.ze, POS_ALL);
    else if (c->has_position)
      span_camera(c, y, x_begin, n, o.px, o.py, o.ze, POS_SURFACES);
    else
      span_camera(c, y, x_begin, n, o.px, o.py, o.ze, POS_NONE);
  }
}

/* One pixel, any invertible projection (or none, with position/motion). */
static void back_project_general(const build_ctx *c, int x, int y, size_t i, float *pxo,
                                 float *pyo, float *zeo) {
  const hush_reproject_input *in = &c->in;
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

/* Whether a neighbour (depth zj, normal nj, id idj) of a pixel (normal ni,
 * id idi) of this frame is on the same surface (a surface, normal within
 * the threshold, same id): only those give the depth slope, so a crease or
 * an edge does not distort it. Branch-free, for the span loops too. */
static inline int same_surface_v(float zj, float ni0, float ni1, float ni2, float nj0, float nj1,
                                 float nj2, float idi, float idj, float cos_min, int use_id) {
  const float d = ni0 * nj0 + ni1 * nj1 + ni2 * nj2;
  return (zj > 0.0f) & ((d < cos_min) == 0) & ((use_id == 0) | hush__id_match(idi, idj));
}

static inline int same_surface(const build_ctx *c, size_t i, size_t j) {
  const hush_gbuffer *g = &c->in.cur;
  const float idi = c->use_id ? g->id[i] : 0.0f, idj = c->use_id ? g->id[j] : 0.0f;
  return same_surface_v(g->depth[j], g->normal[0][i], g->normal[1][i], g->normal[2][i],
                        g->normal[0][j], g->normal[1][j], g->normal[2][j], idi, idj, c->cos_min,
                        c->use_id);
}

/* The smaller one-sided |dz| of a pixel at depth z from its neighbours at
 * za (counted when a_ok) and zb (when b_ok); 0 with neither. */
static inline float min_slope(float z, float za, float zb, int a_ok, int b_ok) {
  const float da = fabsf(z - za), db = fabsf(zb - z);
  float d = hush__select_bits(a_ok, da, HUGE_VALF);
  d = hush__select_bits(b_ok & (db < d), db, d);
  return hush__select_bits(d < HUGE_VALF, d, 0.0f);
}

/* |dz| per pixel of pixel i along one axis, from its neighbours i - step
 * (when has_a) and i + step (when has_b) on the same surface: the smaller
 * one-sided difference; 0 without such a neighbour. */
static float depth_slope(const build_ctx *c, size_t i, size_t step, int has_a, int has_b) {
  const float *z = c->in.cur.depth;
  const int a_ok = has_a && same_surface(c, i, i - step);
  const int b_ok = has_b && same_surface(c, i, i + step);
  return min_slope(z[i], a_ok ? z[i - step] : 0.0f, b_ok ? z[i + step] : 0.0f, a_ok, b_ok);
}

/* Tap j of the previous frame, at offset (ox, oy) pixels from the
 * back-projected point. */
static inline int tap_ok(const build_ctx *c, pixel_ref *r, int32_t j, float ox, float oy) {
  const hush_gbuffer *p = &c->prev;
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
  if (c->use_id && !hush__id_match(p->id[j], r->id)) return 0;
  return 1;
}

/*
 * A superset of the 3x3 fallback's taps (bit t: tap (cx - 1 + t % 3,
 * cy - 1 + t / 3)) that tap_ok passes, from their depths alone, for a pixel
 * whose depth slopes are given (or the gradient test is off): on-screen,
 * background or not as the pixel is, and for a surface within the depth
 * tolerance or the gradient's, the latter widened by 1e-4 of itself so
 * that no rounding of tap_ok's own sum can pass a tap this leaves out.
 * Most open pixels are disocclusions whose every tap fails on its depth:
 * one branch-free pass over 9 depths, and tap_ok only for the few
 * candidates (classroom frames, one thread: the reprojection 21.4 -> 20.9
 * ms).
 */
static unsigned fallback_depths(const build_ctx *c, const pixel_ref *r, int cx, int cy, float sx,
                                float sy) {
  const float *pz = c->prev.depth;
  const int W = c->W, H = c->H;
  const float gx = r->slopes ? r->gx : 0.0f, gy = r->slopes ? r->gy : 0.0f;
  unsigned pass = 0;
  for (int t = 0; t < 9; t++) {
    const int xt = cx - 1 + t % 3, yt = cy - 1 + t / 3;
    const int in = (xt >= 0) & (xt < W) & (yt >= 0) & (yt < H);
    const float zt = pz[(yt * W + xt) & -(int32_t)in]; /* off-screen: any tap, ignored */
    const float dz = fabsf(zt - r->ze);
    const float tol = r->tolz + gx * fabsf((float)xt - sx) + gy * fabsf((float)yt - sy);
    const int surface = zt > 0.0f;
    /* tap_ok's plain test as it is, its gradient test widened; NaN
     * passes, as in tap_ok */
    const int near = ((dz > r->tolz) == 0) | ((dz > tol + fabsf(tol) * 1e-4f) == 0);
    const int ok = r->bg ? !surface : surface & near;
    pass |= (unsigned)(ok & in) << t;
  }
  return pass;
}

/*
 * The full per-pixel rule, for any pixel: the bilinear footprint of the
 * back-projected point (px, py) with each tap tested by tap_ok (the depth
 * gradient computed lazily), moved inside the image when it overhangs the
 * border; else the 3x3 fallback; else NONE. Returns the pixel's footprint.
 * build_row sends here only the pixels its span test could not settle:
 * footprints not wholly inside the image, and those with no consistent tap
 * (3x3 fallback). blocks: the plan's. have_slopes: gx, gy are tap_ok's depth
 * slopes, already computed. bilinear_empty: the span test found no
 * consistent tap in this footprint, wholly inside the image (its test is
 * tap_ok's, bit for bit), so only the 3x3 fallback is left to try.
 */
typedef struct footprint {
  int32_t origin;
  unsigned mask;
  int kind;      /* hush_footprint */
  float fx, fy;  /* BILINEAR: the fractions; else 0 */
} footprint;

static footprint plan_pixel(const build_ctx *c, int blocks, int x, int y, float px, float py,
                            float ze, int have_slopes, float gx, float gy,
                            int bilinear_empty) {
  const hush_gbuffer *cur = &c->in.cur;
  const int W = c->W, H = c->H;
  const size_t i = (size_t)y * (size_t)W + (size_t)x;
  unsigned mask = 0;
  uint8_t kind = HUSH_FOOTPRINT_NONE;
  int32_t origin = 0;
  float fx = 0.0f, fy = 0.0f;
  pixel_ref r;
  r.z = cur->depth[i];
  r.bg = !(r.z > 0.0f);
  r.ze = ze;
  if (px > -2.0f && px < (float)W + 2.0f && py > -2.0f && py < (float)H + 2.0f) {
    r.x = x;
    r.y = y;
    r.i = i;
    r.tolz = c->tol * r.ze;
    r.slopes = have_slopes; /* given: the same values tap_ok would compute */
    r.gx = gx;
    r.gy = gy;
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
    for (int t = 0; t < 4 && !bilinear_empty; t++) {
      const int xt = x0 + (t & 1), yt = y0 + (t >> 1);
      if (xt < 0 || xt >= W || yt < 0 || yt >= H || !(bw[t] >= HUSH_REPROJECT_MIN_WEIGHT))
        continue;
      if (tap_ok(c, &r, (int32_t)yt * W + xt, (float)(t & 1) - fx, (float)(t >> 1) - fy))
        mask |= 1u << t;
    }
    if (mask) {
      kind = HUSH_FOOTPRINT_BILINEAR;
      int bx = x0, by = y0;
      if (blocks) {
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
      /* The bilinear taps lie among these (x0 is cx - 1 or cx), and those
       * of them with their weight were tested above (or by the span test,
       * bit for bit) and failed: tap_ok gives the same answer here, its
       * offsets (xt - sx against (t & 1) - fx) being the same floats. On
       * rendered frames most open pixels are disocclusions that come here
       * (13 % of the classroom's). */
      unsigned failed = 0;
      for (int t = 0; t < 4; t++)
        if (bw[t] >= HUSH_REPROJECT_MIN_WEIGHT)
          failed |= 1u << ((y0 + (t >> 1) - (cy - 1)) * 3 + (x0 + (t & 1) - (cx - 1)));
      unsigned cand = 0x1ffu & ~failed;
      if (r.slopes || !(c->grad > 0.0f)) cand &= fallback_depths(c, &r, cx, cy, sx, sy);
      for (; cand; cand &= cand - 1) {
        const int t = __builtin_ctz(cand);
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
  const footprint fp = {origin, mask, kind, fx, fy};
  return fp;
}

/* Pixels per span: the back-projection and the tap tests run over spans of
 * a row held in small stack arrays (L1-resident). */
#define SPAN 256

/* The previous frame's planes, for span_tap. */
typedef struct prev_view {
  const float *depth, *normal[3], *id;
  float cos_min;
} prev_view;

/* What span_tap compares a tap with: one pixel of this frame. */
typedef struct tap_ref {
  int bg;
  float n0, n1, n2, id;
  float ze, tolz; /* expected depth, depth_tolerance * ze */
  float gx, gy;   /* depth slopes (grad_test) */
} tap_ref;

/*
 * The test of a tap (depth zt, normal nt, id idt of the previous frame)
 * with bilinear weight wt at offset (ox, oy) pixels from the back-projected
 * point, for a footprint inside the image: 1 if it is in
 * plan_pixel's mask. With grad_test (depth_gradient > 0) that is exactly
 * tap_ok, comparisons included (NaN fails or passes as there); without,
 * the plain test (tap_ok's result when the gradient retry is off). Every
 * value is loaded and computed unconditionally and combined with & and |,
 * so the span loop has no control flow (which would stop vectorisation).
 */
static HUSH_ALWAYS_INLINE unsigned span_tap(const prev_view *p, float zt, float nt0, float nt1,
                                            float nt2, float idt, float wt, float ox, float oy,
                                            const tap_ref *r, const int use_id,
                                            const int grad_test, unsigned *retry) {
  const float d = r->n0 * nt0 + r->n1 * nt1 + r->n2 * nt2;
  const float dz = fabsf(zt - r->ze);
  const int surface = zt > 0.0f;
  int surface_ok;
  if (grad_test) {
    const float tol_grad = r->tolz + r->gx * fabsf(ox) + r->gy * fabsf(oy);
    surface_ok = surface & (((dz > r->tolz) == 0) | ((dz > tol_grad) == 0)) &
                 ((d < p->cos_min) == 0);
  } else {
    surface_ok = surface & (dz <= r->tolz) & (d >= p->cos_min);
  }
  const int id_ok = (use_id == 0) | hush__id_match(idt, r->id);
  const int kind_ok = (r->bg & (surface == 0)) | ((r->bg == 0) & surface_ok); /* bg: bg taps */
  const int weight_ok = wt >= HUSH_REPROJECT_MIN_WEIGHT;
  /* without grad_test: whether the tap fails here but could pass the
   * gradient test (its depth test failed, or its normal is NaN, which
   * only the gradient test's form lets through) */
  if (!grad_test)
    *retry = (unsigned)((r->bg == 0) & surface & ((d < p->cos_min) == 0) & weight_ok & id_ok &
                        (surface_ok == 0));
  return (unsigned)(kind_ok & weight_ok & id_ok);
}

/*
 * tap_ok's depth slopes gx, gy (depth_gradient * ze / z times depth_slope
 * along x and y) of pixels x_begin .. x_begin + n - 1 of row y, for every
 * pixel (background ones are not used). Branch-free over contiguous loads:
 * the neighbours are the pixels beside and the rows above and below; the
 * first and last pixel of the image row, whose neighbour along x would lie
 * outside it, go through depth_slope.
 */
static HUSH_ALWAYS_INLINE void span_slopes(const build_ctx *c, int y, int x_begin, int n,
                                           const float *restrict sze, float *restrict gx,
                                           float *restrict gy, const int use_id) {
  const hush_gbuffer *g = &c->in.cur;
  const int W = c->W, H = c->H;
  const size_t row = (size_t)y * (size_t)W + (size_t)x_begin;
  const int has_up = y > 0, has_down = y + 1 < H;
  /* a missing row is replaced by this one (and not counted) */
  const size_t up = has_up ? row - (size_t)W : row, down = has_down ? row + (size_t)W : row;
  const float *z = g->depth + row, *zu = g->depth + up, *zd = g->depth + down;
  const float *a = g->normal[0] + row, *au = g->normal[0] + up, *ad = g->normal[0] + down;
  const float *b = g->normal[1] + row, *bu = g->normal[1] + up, *bd = g->normal[1] + down;
  const float *e = g->normal[2] + row, *eu = g->normal[2] + up, *ed = g->normal[2] + down;
  /* unread without use_id: any valid pointers */
  const float *id = use_id ? g->id + row : z, *idu = use_id ? g->id + up : zu;
  const float *idd = use_id ? g->id + down : zd;
  const float grad = c->grad, cos_min = c->cos_min;
  for (int k = 0; k < n; k++) {
    const float s = grad * sze[k] / z[k];
    const int u_ok = has_up & same_surface_v(zu[k], a[k], b[k], e[k], au[k], bu[k], eu[k], id[k],
                                             idu[k], cos_min, use_id);
    const int d_ok = has_down & same_surface_v(zd[k], a[k], b[k], e[k], ad[k], bd[k], ed[k],
                                               id[k], idd[k], cos_min, use_id);
    gy[k] = s * min_slope(z[k], zu[k], zd[k], u_ok, d_ok);
  }
  /* along x: pixels 1 .. W - 2 of the image row have both neighbours */
  const int k0 = x_begin == 0 ? 1 : 0;
  const int k1 = x_begin + n == W ? n - 1 : n;
  for (int k = k0; k < k1; k++) {
    const float s = grad * sze[k] / z[k];
    const int l_ok = same_surface_v(z[k - 1], a[k], b[k], e[k], a[k - 1], b[k - 1], e[k - 1],
                                    id[k], id[k - 1], cos_min, use_id);
    const int r_ok = same_surface_v(z[k + 1], a[k], b[k], e[k], a[k + 1], b[k + 1], e[k + 1],
                                    id[k], id[k + 1], cos_min, use_id);
    gx[k] = s * min_slope(z[k], z[k - 1], z[k + 1], l_ok, r_ok);
  }
  const int first = x_begin == 0, last = x_begin + n == W;
  if (first) gx[0] = grad * sze[0] / z[0] * depth_slope(c, row, 1, 0, W > 1);
  if (last && !(first && n == 1))
    gx[n - 1] = grad * sze[n - 1] / z[n - 1] * depth_slope(c, row + (size_t)n - 1, 1, 1, 0);
}

/* What the span test settles per pixel. */
typedef struct span_taps {
  int32_t origin[SPAN]; /* the footprint's top-left tap (0 when not inside) */
  float fx[SPAN], fy[SPAN];
  float gx[SPAN], gy[SPAN]; /* tap_ok's depth slopes (grad_test) */
  /* 32-bit flags: with bytes among its types gcc vectorised the tap tests
   * of a chunk of 16 at 128 bits (16 bytes), so 4 floats a vector */
  int32_t inside[SPAN];     /* the footprint lies wholly inside the image */
  int32_t mask[SPAN];       /* consistent taps */
  int32_t retry[SPAN];      /* the plain test: taps only the depth test failed */
  /* hush_footprint. The span test: BILINEAR where its origin, mask, fx, fy
   * are final, else NONE (plan_pixel decides and overwrites all five). */
  int32_t kind[SPAN];
} span_taps;

/* Pixels per chunk of the tap tests: a chunk whose footprints follow each
 * other (origin + 1 per pixel, as under smooth motion) loads its taps as
 * vectors; any other chunk gathers them one by one. */
#define CHUNK 16

/*
 * The span test's per-chunk questions, over pixels k0 .. k1 - 1: whether
 * every footprint is inside and follows the first (contiguous), whether
 * any pixel has a tap to retry or is left open, whether any is not
 * BILINEAR. A whole chunk with AVX-512 as compares into mask registers:
 * gcc vectorised the loops as vector ORs and ANDs folded by shuffles, a
 * chain of a dozen instructions each (13 % of the plan's samples on a
 * stand-alone build).
 */
#if defined(__AVX512F__)
_Static_assert(CHUNK == 16, "a chunk is one vector of int32");
static HUSH_ALWAYS_INLINE __m512i chunk_load(const int32_t *a) {
  return _mm512_loadu_si512((const void *)a);
}
#endif

static HUSH_ALWAYS_INLINE int chunk_contiguous(const span_taps *o, int k0, int k1) {
#if defined(__AVX512F__)
  if (k1 - k0 == CHUNK) {
    const __mmask16 run = hush__run_mask16(chunk_load(o->origin + k0), o->origin[k0]);
    const __mmask16 in = _mm512_test_epi32_mask(chunk_load(o->inside + k0),
                                                chunk_load(o->inside + k0));
    return (run & in) == 0xFFFF;
  }
#endif
  int contiguous = 1;
  for (int k = k0; k < k1; k++)
    contiguous &= o->inside[k] & (o->origin[k] == o->origin[k0] + (k - k0));
  return contiguous;
}

/* Bit 0: a tap to retry; bit 1: a pixel left open (not BILINEAR, and not
 * inside or with the 3x3 fallback on). */
static HUSH_ALWAYS_INLINE int chunk_retry_open(const span_taps *o, int k0, int k1, int fallback) {
#if defined(__AVX512F__)
  if (k1 - k0 == CHUNK) {
    const __m512i kind = chunk_load(o->kind + k0), inside = chunk_load(o->inside + k0);
    const __mmask16 not_bil =
        _mm512_cmpneq_epi32_mask(kind, _mm512_set1_epi32(HUSH_FOOTPRINT_BILINEAR));
    const __mmask16 out = fallback ? (__mmask16)0xFFFF : _mm512_testn_epi32_mask(inside, inside);
    const __mmask16 retry = _mm512_test_epi32_mask(chunk_load(o->retry + k0),
                                                   chunk_load(o->retry + k0));
    return (retry != 0) | ((not_bil & out) != 0) << 1;
  }
#endif
  int retry = 0, open = 0;
  for (int k = k0; k < k1; k++) {
    retry |= o->retry[k];
    open |= (o->kind[k] != HUSH_FOOTPRINT_BILINEAR) & (fallback | (o->inside[k] == 0));
  }
  return (retry != 0) | (open != 0) << 1;
}

/* Whether any of pixels k0 .. k1 - 1 is not BILINEAR. */
static HUSH_ALWAYS_INLINE int chunk_any_open(const span_taps *o, int k0, int k1) {
#if defined(__AVX512F__)
  if (k1 - k0 == CHUNK)
    return _mm512_cmpneq_epi32_mask(chunk_load(o->kind + k0),
                                    _mm512_set1_epi32(HUSH_FOOTPRINT_BILINEAR)) != 0;
#endif
  int open = 0;
  for (int k = k0; k < k1; k++) open |= o->kind[k] != HUSH_FOOTPRINT_BILINEAR;
  return open;
}

/* The footprint of each pixel of a span: fractions, origin (0 when not
 * wholly inside the image, so its taps are read at a safe index) and
 * whether it is inside (x0 >= 0 && x0 + 1 < W, likewise y; false for NaN
 * and NO_LOCATION). Branch-free, vectorised. */
static void span_footprints(int W, int H, const float *restrict spx, const float *restrict spy,
                            span_taps *restrict o, int n) {
  const float Wm2 = (float)(W - 2), Hm2 = (float)(H - 2);
  for (int k = 0; k < n; k++) {
    const float sx = spx[k] - 0.5f, sy = spy[k] - 0.5f;
    const float flx = hush__floorf_vec(sx), fly = hush__floorf_vec(sy);
    const int inside = (flx >= 0.0f) & (flx <= Wm2) & (fly >= 0.0f) & (fly <= Hm2);
    o->fx[k] = sx - flx;
    o->fy[k] = sy - fly;
    /* no out-of-range float is converted */
    o->origin[k] = (int32_t)hush__select_bits(inside, fly, 0.0f) * W +
                   (int32_t)hush__select_bits(inside, flx, 0.0f);
    o->inside[k] = inside;
  }
}

/* How a chunk's taps are read: gathered one by one, as vectors (the
 * footprints follow each other: base + k), from a window (reproject.h), or
 * as two vectors per tap picked per pixel (the pixels split between two
 * such bases, as where the motion carries the footprints a column or a row
 * further: reproject.h's diagonals). */
enum { TAPS_GATHER, TAPS_CONTIGUOUS, TAPS_WINDOW, TAPS_DIAGONALS };

/* The planes a window of the tap tests reads: depth, normal, id. */
#define WINDOW_PLANES 5

/*
 * plan_pixel's common case for pixels k_begin .. k_begin + len - 1 of a span,
 * without branches (vectorised): a footprint lying wholly inside the image
 * with at least one consistent tap. Then the result is final (done); else
 * plan_pixel decides (the border, the 3x3 fallback). TAPS_CONTIGUOUS: the
 * footprint of pixel k starts at base + k (plain vector loads);
 * TAPS_WINDOW: its taps were read from a window (tb[plane][tap][k -
 * k_begin], planes as WINDOW_PLANES; a pixel whose footprint is not inside
 * the image got some tap of the window, as a gather reads index 0 for it:
 * plan_pixel redoes it); TAPS_GATHER: at o->origin[k] (gathers). mode,
 * use_id and grad_test are constants at each call, so the loop has no
 * branch on them (and reads no id plane without use_id).
 */
static HUSH_ALWAYS_INLINE void test_pixels(const build_ctx *c, size_t row, int k_begin, int len,
                                           const float *restrict sze, span_taps *restrict o,
                                           int32_t base, int32_t base1, const int mode,
                                           const float (*restrict tb)[4][CHUNK], const int use_id,
                                           const int grad_test) {
  const int contiguous = mode == TAPS_CONTIGUOUS, window = mode == TAPS_WINDOW;
  const int diagonals = mode == TAPS_DIAGONALS;
  const int k_end = k_begin + len;
  const hush_gbuffer *cur = &c->in.cur, *pg = &c->prev;
  const int W = c->W;
  const float *zr = cur->depth + row;
  const float *n0 = cur->normal[0] + row, *n1 = cur->normal[1] + row, *n2 = cur->normal[2] + row;
  /* unread without use_id: any valid pointer */
  const float *idr = use_id ? cur->id + row : zr;
  const prev_view pv = {pg->depth, {pg->normal[0], pg->normal[1], pg->normal[2]},
                        use_id ? pg->id : pg->depth, c->cos_min};
  const float tol = c->tol;
  for (int k = k_begin; k < k_end; k++) {
    tap_ref r;
    r.bg = !(zr[k] > 0.0f);
    r.n0 = n0[k];
    r.n1 = n1[k];
    r.n2 = n2[k];
    r.id = idr[k];
    r.ze = sze[k];
    r.tolz = tol * r.ze;
    r.gx = grad_test ? o->gx[k] : 0.0f;
    r.gy = grad_test ? o->gy[k] : 0.0f;
    const float fx = o->fx[k], fy = o->fy[k];
    float bw[4];
    hush__reproject_bilinear(fx, fy, bw);
    const int32_t j0 = contiguous | diagonals ? base + k : o->origin[k];
    /* TAPS_DIAGONALS: the pixel's footprint on the second diagonal */
    const int second = diagonals & (o->origin[k] == base1 + k);
    const int32_t j1 = base1 + k;
    const int kk = k - k_begin;
    unsigned q0 = 0, q1 = 0, q2 = 0, q3 = 0;
    /* tap t (0..3: top left, top right, bottom left, bottom right, at
     * offset D from the footprint's origin) of the window's plane pi, or
     * of plane P: both diagonals' taps loaded, one picked */
#define TAP(P, pi, t, D)                                                                         \
  (window      ? tb[pi][t][kk]                                                                   \
   : diagonals ? hush__select_bits(second, (P)[j1 + (D)], (P)[j0 + (D)])                         \
               : (P)[j0 + (D)])
#define SPAN_TAP(t, D, ox, oy, q)                                                               \
  span_tap(&pv, TAP(pv.depth, 0, t, D), TAP(pv.normal[0], 1, t, D), TAP(pv.normal[1], 2, t, D), \
           TAP(pv.normal[2], 3, t, D), use_id ? TAP(pv.id, 4, t, D) : 0.0f, bw[t], ox, oy, &r,   \
           use_id, grad_test, q)
    const unsigned m = SPAN_TAP(0, 0, 0.0f - fx, 0.0f - fy, &q0) |
                       SPAN_TAP(1, 1, 1.0f - fx, 0.0f - fy, &q1) << 1 |
                       SPAN_TAP(2, W, 0.0f - fx, 1.0f - fy, &q2) << 2 |
                       SPAN_TAP(3, W + 1, 1.0f - fx, 1.0f - fy, &q3) << 3;
#undef SPAN_TAP
#undef TAP
    if (!grad_test) o->retry[k] = (int32_t)(q0 | q1 | q2 | q3);
    o->mask[k] = (int32_t)m;
    o->kind[k] = (o->inside[k] & (m != 0u)) ? HUSH_FOOTPRINT_BILINEAR : HUSH_FOOTPRINT_NONE;
  }
}

/* The tap tests of pixels k0..k1-1 of a span (one chunk), the taps read as
 * mode says: TAPS_CONTIGUOUS from base[0] + k, TAPS_DIAGONALS from base[0]
 * + k or base[1] + k (each pixel's own), TAPS_WINDOW from tb. */
static HUSH_ALWAYS_INLINE void test_chunk(const build_ctx *c, size_t row, int k0, int k1,
                                          const float *restrict sze, span_taps *restrict o,
                                          int mode, const int32_t base[2],
                                          const float (*restrict tb)[4][CHUNK],
                                          const int use_id, const int grad_test) {
  /* a constant length for full chunks: one vector iteration, no
   * alignment peeling or scalar epilogue */
  if (k1 - k0 < CHUNK)
    test_pixels(c, row, k0, k1 - k0, sze, o, 0, 0, TAPS_GATHER, NULL, use_id, grad_test);
  else if (mode == TAPS_CONTIGUOUS)
    test_pixels(c, row, k0, CHUNK, sze, o, base[0], 0, TAPS_CONTIGUOUS, NULL, use_id, grad_test);
  else if (mode == TAPS_DIAGONALS)
    test_pixels(c, row, k0, CHUNK, sze, o, base[0], base[1], TAPS_DIAGONALS, NULL, use_id,
                grad_test);
  else if (mode == TAPS_WINDOW)
    test_pixels(c, row, k0, CHUNK, sze, o, 0, 0, TAPS_WINDOW, tb, use_id, grad_test);
  else
    test_pixels(c, row, k0, CHUNK, sze, o, 0, 0, TAPS_GATHER, NULL, use_id, grad_test);
}

#ifdef HUSH_HAVE_WINDOW
/* hush__window_read's work for the footprints origin[0..HUSH_WINDOW_MAX-1]
 * of the pixels with use[k], in planes of W x (size / W) floats. */
static int window_read(const int32_t *origin, const uint8_t *use, int32_t W, size_t size,
                       const float *const *planes, int nplanes,
                       float (*out)[4][HUSH_WINDOW_MAX]) {
  int32_t e[HUSH_WINDOW_MAX], dy[HUSH_WINDOW_MAX], base = 0;
  const int rows = hush__reproject_window16(origin, use, W, size, &base, e, dy);
  for (int p = 0; p < nplanes && rows; p++) {
    if (!planes[p]) continue;
    if (rows == 1)
      hush__window_taps(planes[p], base, W, e, dy, 1, out[p]);
    else
      hush__window_taps(planes[p], base, W, e, dy, 2, out[p]);
  }
  return rows;
}

/* The distinct origin[k] - k of the chunk's pixels inside the image, in
 * the order of their first pixels, counted up to 3: the first two into
 * base. Two mask compares, where a loop over the pixels with a branch each
 * had taken 70 % of chunk_mode's samples (a profile of the bench frames). */
static HUSH_ALWAYS_INLINE int chunk_bases(const span_taps *o, int k0, int32_t base[2]) {
  const __m512i inside = chunk_load(o->inside + k0), origin = chunk_load(o->origin + k0);
  const __mmask16 in = _mm512_test_epi32_mask(inside, inside);
  if (!in) return 0;
  /* the pixels whose origin is base + k: a run from base + k0 */
  const int first = __builtin_ctz(in);
  base[0] = o->origin[k0 + first] - (k0 + first);
  const __mmask16 rest = in & ~hush__run_mask16(origin, base[0] + k0);
  if (!rest) return 1;
  const int second = __builtin_ctz(rest);
  base[1] = o->origin[k0 + second] - (k0 + second);
  return rest & ~hush__run_mask16(origin, base[1] + k0) ? 3 : 2;
}

/*
 * How the full chunk of pixels k0.. reads its taps, and from where (base,
 * test_chunk; base[0] is origin[k0] - k0 on entry). AVX-512 builds. The
 * footprints inside the image (plan_pixel redoes the
 * others) at base + k for one base: TAPS_CONTIGUOUS; for two:
 * TAPS_DIAGONALS, when every pixel's taps at either base lie inside the
 * planes (each tap of each plane loaded at both bases and picked per
 * pixel: one test pass where two vector passes, each pixel keeping its
 * own, had cost a chunk ~15 % less than a window's reads and tests on Zen
 * 4; the reprojection on the bench frames 3.66 -> 3.57 ms on 2 threads,
 * 6.32 -> 6.12 on one, Zen 5, the same bits); else TAPS_WINDOW when they
 * form a window, read into tb
 * (depth, normal, and the ids with use_id); else TAPS_GATHER. Out of line:
 * its code in test_span's loop would cost the common contiguous chunks
 * more than the call costs the others.
 */
static int chunk_mode(const build_ctx *c, const span_taps *o, int k0, int contiguous,
                      const int use_id, int32_t base[2], float (*tb)[4][CHUNK]) {
  if (contiguous) return TAPS_CONTIGUOUS;
  const int bases = chunk_bases(o, k0, base);
  /* taps base + k + {0, 1, W, W + 1}, k = k0 .. k0 + CHUNK - 1 */
  const int64_t last = (int64_t)c->W * c->H - (k0 + CHUNK) - c->W;
  int in_planes = bases > 0 && bases < 3;
  for (int t = 0; t < bases && t < 2; t++)
    in_planes &= (int64_t)base[t] + k0 >= 0 && (int64_t)base[t] < last;
  if (in_planes) return bases == 1 ? TAPS_CONTIGUOUS : TAPS_DIAGONALS;
  _Static_assert(CHUNK == HUSH_WINDOW_MAX, "a window is one chunk");
  uint8_t use[CHUNK];
  for (int k = 0; k < CHUNK; k++) use[k] = o->inside[k0 + k] != 0;
  const hush_gbuffer *pg = &c->prev;
  const float *const planes[WINDOW_PLANES] = {pg->depth, pg->normal[0], pg->normal[1],
                                              pg->normal[2], use_id ? pg->id : NULL};
  return window_read(o->origin + k0, use, c->W, (size_t)c->W * (size_t)c->H, planes,
                     WINDOW_PLANES, tb)
             ? TAPS_WINDOW
             : TAPS_GATHER;
}
#endif

#ifdef HUSH_HAVE_DIAGONALS
/* How a full chunk of pixels k0.. that is not contiguous reads its taps
 * (x86-64-v3 builds): from two diagonals (TAPS_DIAGONALS, base[0] and
 * base[1] relative to the span) when its footprints inside the image lie on
 * them, else gathered. */
static HUSH_ALWAYS_INLINE int span_diagonals(const build_ctx *c, const span_taps *o, int k0,
                                             int32_t base[2]) {
  _Static_assert(CHUNK == HUSH_DIAGONAL_CHUNK, "a chunk is the diagonals' chunk");
  int32_t b[2];
  const int n = hush__reproject_diagonals(o->origin + k0, NULL, o->inside + k0, c->W,
                                          (size_t)c->W * (size_t)c->H, b);
  if (!n) return TAPS_GATHER;
  base[0] = b[0] - k0;
  base[1] = b[1] - k0;
  return n == 1 ? TAPS_CONTIGUOUS : TAPS_DIAGONALS;
}
#endif

/* Pixels ahead of a chunk whose row below prefetch_inputs asks for. */
#define BELOW_AHEAD 64

/*
 * Prefetches, in this frame's planes that the back-projection and the span
 * test read, pixel `ahead` (the next span's pixel, or the next row's), so
 * that their ten sequential streams, with the history's, do not wait on
 * the hardware prefetchers: reprojection 7.75 -> 7.26 ms on 2 threads,
 * 14.4 -> 13.5 on one (1280x720, Zen 3, medians of alternated runs;
 * docs/svgf-speed.md, twenty-first round). Also pixel `i` + BELOW_AHEAD of
 * the row below in the planes span_slopes reads there (depth, normal, id):
 * that row is read for the first time by the slopes of a chunk with a pixel
 * left open or a tap to retry, and on rendered frames those are common (31
 * % of the classroom's chunks): a profile put a tenth of build_row's
 * samples on the loads of that row's normals. Reprojection on the
 * classroom's frames 23.2 -> 21.7 ms on one thread, 12.5 -> 12.1 on two;
 * the bench's frames, with few such chunks, unchanged (twenty-second
 * round). Past the frame's end the addresses lie outside the planes
 * (hush__prefetch).
 */
static HUSH_ALWAYS_INLINE void prefetch_inputs(const build_ctx *c, size_t ahead, size_t i,
                                               const int use_id) {
  const hush_gbuffer *g = &c->in.cur;
  /* the first five: what span_slopes reads */
  const float *const planes[10] = {g->depth,          g->normal[0],       g->normal[1],
                                   g->normal[2],      use_id ? g->id : NULL,
                                   c->in.motion[0],  c->in.motion[1],   c->in.position[0],
                                   c->in.position[1], c->in.position[2]};
  hush__prefetch_planes(planes, 10, (ptrdiff_t)ahead * (ptrdiff_t)sizeof(float));
  hush__prefetch_planes(planes, 5,
                        (ptrdiff_t)(i + (size_t)c->W + BELOW_AHEAD) * (ptrdiff_t)sizeof(float));
}

/* The span test: footprints, then the tap tests chunk by chunk (with the
 * depth slopes where they can matter). */
static HUSH_ALWAYS_INLINE void test_span(const build_ctx *c, int y, int x_begin, int n,
                                         const float *restrict spx, const float *restrict spy,
                                         const float *restrict sze, span_taps *restrict o,
                                         const int use_id, const int grad_test) {
  const size_t row = (size_t)y * (size_t)c->W + (size_t)x_begin;
  span_footprints(c->W, c->H, spx, spy, o, n);
  const hush_gbuffer *pg = &c->prev;
  const float *const prev_planes[WINDOW_PLANES] = {pg->depth, pg->normal[0], pg->normal[1],
                                                   pg->normal[2], use_id ? pg->id : NULL};
  for (int k0 = 0; k0 < n; k0 += CHUNK) {
    const int k1 = n - k0 < CHUNK ? n : k0 + CHUNK;
    hush__prefetch_taps(prev_planes, WINDOW_PLANES, hush__prefetch_origin(o->origin, k0, n), c->W);
    prefetch_inputs(c, row + (size_t)k0 + SPAN, row + (size_t)k0, use_id);
    const int contiguous = chunk_contiguous(o, k0, k1);
    /* the plain test first; the depth slopes only for a chunk where the
     * gradient could change a tap (one only its depth test failed) or
     * plan_pixel will need them (a pixel left open), and the test with
     * them only for the former. The gradient test passes every tap the
     * plain one does and can add only taps whose depth test alone failed,
     * so elsewhere both agree. (On the classroom's rendered frames 31 % of
     * the chunks have a pixel left open, 2 % a tap to retry.) */
    float tb[WINDOW_PLANES][4][CHUNK] __attribute__((aligned(64)));
    int32_t base[2] = {o->origin[k0] - k0, 0};
    /* (a partial chunk gathers: it is not a whole vector) */
#ifdef HUSH_HAVE_WINDOW
    const int mode =
        k1 - k0 < CHUNK ? TAPS_GATHER : chunk_mode(c, o, k0, contiguous, use_id, base, tb);
#elif defined(HUSH_HAVE_DIAGONALS)
    /* (x86-64-v3, 8-float vectors: two passes, and even a scalar search for
     * the bases, were slower than the gathers: reproject stage 16.6-16.8 ->
     * 17.3-17.4 ms with the search alone; AVX2 windows of 3 permutes per
     * tap, too: 6.9-7.1 -> 7.3-8.0 ms on the bench frames) */
    const int mode = k1 - k0 < CHUNK ? TAPS_GATHER
                     : contiguous    ? TAPS_CONTIGUOUS
                                     : span_diagonals(c, o, k0, base);
#else
    const int mode = k1 - k0 < CHUNK || !contiguous ? TAPS_GATHER : TAPS_CONTIGUOUS;
#endif
    test_chunk(c, row, k0, k1, sze, o, mode, base, (const float(*)[4][CHUNK])tb, use_id, 0);
    if (!grad_test) continue;
    /* plan_pixel needs the slopes only for the open pixels it tests again:
     * those not wholly inside, and any with the 3x3 fallback on (without
     * it an inside pixel with no consistent tap is final: build_row) */
    const int ro = chunk_retry_open(o, k0, k1, c->fallback);
    const int retry = ro & 1;
    if (!ro) continue;
    span_slopes(c, y, x_begin + k0, k1 - k0, sze + k0, o->gx + k0, o->gy + k0, use_id);
    if (retry)
      test_chunk(c, row, k0, k1, sze, o, mode, base, (const float(*)[4][CHUNK])tb, use_id, 1);
  }
}

/* A span's footprints into the plan, with their renormalised weights
 * (hush__reproject_renormalised; 0 unless BILINEAR), in one vectorised pass
 * over the span's L1-resident arrays: the fractions are not stored, so the
 * plan costs 8 bytes a pixel less to write, and the weights need no second
 * pass over the row. */
static HUSH_ALWAYS_INLINE void span_weights(const span_taps *restrict st, float *restrict w0,
                                             float *restrict w1, float *restrict w2,
                                             float *restrict w3, int n) {
  for (int k = 0; k < n; k++) {
    float w[4];
    hush__reproject_renormalised((unsigned)st->mask[k], st->fx[k], st->fy[k], w);
    const int bil = st->kind[k] == HUSH_FOOTPRINT_BILINEAR;
    w0[k] = bil ? w[0] : 0.0f;
    w1[k] = bil ? w[1] : 0.0f;
    w2[k] = bil ? w[2] : 0.0f;
    w3[k] = bil ? w[3] : 0.0f;
  }
}

/* The narrow fields, in a loop of their own: among the weights' floats,
 * the bytes had gcc vectorise that loop at 16 and 32 bytes. */
static HUSH_ALWAYS_INLINE void span_codes(const span_taps *restrict st, int32_t *restrict origin,
                                          uint16_t *restrict mask, uint8_t *restrict kind,
                                          int n) {
  for (int k = 0; k < n; k++) {
    origin[k] = st->origin[k];
    mask[k] = (uint16_t)st->mask[k];
    kind[k] = (uint8_t)st->kind[k];
  }
}

static void store_span(const span_taps *restrict st, int32_t *restrict origin,
                       uint16_t *restrict mask, uint8_t *restrict kind, float *restrict w0,
                       float *restrict w1, float *restrict w2, float *restrict w3, int n) {
  /* staged in L1, then streamed to the plan (core/stream.h): the plan is
   * read only after the whole frame's build, or after a block row's
   * (bmfr.c's fused_frame, where streaming it is still faster) */
  int32_t so[SPAN];
  uint16_t sm[SPAN];
  uint8_t sk[SPAN];
  float sw[4][SPAN] __attribute__((aligned(64)));
  span_weights(st, sw[0], sw[1], sw[2], sw[3], n);
  span_codes(st, so, sm, sk, n);
  hush__stream_copy(origin, so, (size_t)n * sizeof *origin);
  hush__stream_copy(mask, sm, (size_t)n * sizeof *mask);
  hush__stream_copy(kind, sk, (size_t)n * sizeof *kind);
  hush__stream_copy(w0, sw[0], (size_t)n * sizeof *w0);
  hush__stream_copy(w1, sw[1], (size_t)n * sizeof *w1);
  hush__stream_copy(w2, sw[2], (size_t)n * sizeof *w2);
  hush__stream_copy(w3, sw[3], (size_t)n * sizeof *w3);
}

/* Pixel k of a span takes plan_pixel's footprint. */
static inline void span_set(span_taps *st, int k, footprint fp) {
  st->origin[k] = fp.origin;
  st->mask[k] = (int32_t)fp.mask;
  st->kind[k] = fp.kind;
  st->fx[k] = fp.fx;
  st->fy[k] = fp.fy;
}

/* One row of the plan, span by span: the back-projection, the span test,
 * plan_pixel for the pixels the test left open, then the span into the
 * plan. Plans without blocks (an image 1 pixel wide or high) go through
 * plan_pixel. */
static void build_row(const build_ctx *c, hush_reproject_plan *plan, int y) {
  const int W = c->W;
  const size_t row = (size_t)y * (size_t)W;
  float span_px[SPAN], span_py[SPAN], span_ze[SPAN];
  span_taps st;
  for (int x0 = 0; x0 < W; x0 += SPAN) {
    const int n = W - x0 < SPAN ? W - x0 : SPAN;
    const span_out so = {span_px, span_py, span_ze};
    back_project_span(c, y, x0, n, so);
    if (!plan->blocks) {
      /* a 1-pixel-wide or -high image: no footprint lies inside it (and
       * the span test's taps at index 0 would not exist) */
      for (int k = 0; k < n; k++)
        span_set(&st, k,
                 plan_pixel(c, 0, x0 + k, y, span_px[k], span_py[k], span_ze[k], 0, 0.0f, 0.0f,
                            0));
    } else {
      const int grad_test = c->grad > 0.0f;
      if (c->use_id) {
        if (grad_test)
          test_span(c, y, x0, n, span_px, span_py, span_ze, &st, 1, 1);
        else
          test_span(c, y, x0, n, span_px, span_py, span_ze, &st, 1, 0);
      } else {
        if (grad_test)
          test_span(c, y, x0, n, span_px, span_py, span_ze, &st, 0, 1);
        else
          test_span(c, y, x0, n, span_px, span_py, span_ze, &st, 0, 0);
      }
      /* the open pixels are few and scattered: a vectorised test per
       * chunk skips the chunks without any (a branch per pixel cost
       * mispredictions at each one) */
      for (int k0 = 0; k0 < n; k0 += CHUNK) {
        const int k1 = n - k0 < CHUNK ? n : k0 + CHUNK;
        if (!chunk_any_open(&st, k0, k1)) continue;
        for (int k = k0; k < k1; k++) {
          if (st.kind[k] == HUSH_FOOTPRINT_BILINEAR) continue;
          if (st.inside[k] && !c->fallback) {
            /* what plan_pixel returns for it: no tap of its footprint
             * passed (the span test is tap_ok's), and no fallback; most
             * open pixels are such disocclusions */
            const footprint none = {0, 0u, HUSH_FOOTPRINT_NONE, 0.0f, 0.0f};
            span_set(&st, k, none);
            continue;
          }
          span_set(&st, k,
                   plan_pixel(c, 1, x0 + k, y, span_px[k], span_py[k], span_ze[k], grad_test,
                              grad_test ? st.gx[k] : 0.0f, grad_test ? st.gy[k] : 0.0f,
                              st.inside[k]));
        }
      }
    }
    const size_t i = row + (size_t)x0;
    store_span(&st, plan->origin + i, plan->mask + i, plan->kind + i, plan->w[0] + i,
               plan->w[1] + i, plan->w[2] + i, plan->w[3] + i, n);
  }
}

/* Rows per chunk of the parallel build (see hush__reproject_build). */
#define BUILD_ROWS 4

hush_status hush__reproject_begin(hush_device device, const hush_reproject_plan *plan,
                                  const hush_reproject_input *in, const hush_gbuffer *prev,
                                  const hush_frame_info *info, const hush_reproject_params *params,
                                  hush_reproject_job *job) {
  const int vectors = info->motion == HUSH_MOTION_VECTORS;
  if (vectors && (!in->motion[0] || !in->motion[1]))
    return hush__fail(device, HUSH_ERROR_INVALID_OPERATION,
                      "motion source is HUSH_MOTION_VECTORS but no motion image is bound");
  build_ctx c;
  memset(&c, 0, sizeof c);
  c.in = *in;
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
    c.clear = 1;
    *job = c;
    return HUSH_OK;
  }
  c.prev = *prev;
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
  *job = c;
  return HUSH_OK;
}

void hush__reproject_rows(const hush_reproject_job *job, hush_reproject_plan *plan, int y0,
                          int y1) {
  if (job->clear) {
    clear_rows(plan, y0, y1);
    return;
  }
  for (int y = y0; y < y1; y++) build_row(job, plan, y);
  hush__stream_fence();
}

/* The whole plan of a begun job, the rows shared among the threads. */
static void build_all(const hush_reproject_job *job, hush_reproject_plan *plan, int threads) {
  if (threads < 1) threads = 1;
  if (job->clear) {
    hush__reproject_plan_clear(plan, threads);
    return;
  }
  const int H = job->H;
  /* Rows cost very different amounts (a disocclusion or a border runs
   * plan_pixel's scalar path; a row whose footprints do not follow each
   * other gathers its taps), and they cluster in bands: a static split in
   * halves left one thread with ~1.4x the work of the other. Rows are
   * handed out in small chunks instead; each row is computed on its own,
   * so the plan does not depend on which thread builds it. */
#pragma omp parallel for schedule(dynamic, BUILD_ROWS) num_threads(threads)
  for (int y = 0; y < H; y++) hush__reproject_rows(job, plan, y, y + 1);
}

hush_status hush__reproject_build(hush_device device, hush_reproject_plan *plan,
                                  const hush_reproject_input *in, const hush_gbuffer *prev,
                                  const hush_frame_info *info, const hush_reproject_params *params,
                                  int threads) {
  hush_reproject_job job;
  hush_status s = hush__reproject_begin(device, plan, in, prev, info, params, &job);
  if (s) return s;
  build_all(&job, plan, threads);
  return HUSH_OK;
}

#ifdef HUSH_HAVE_WINDOW
int hush__window_read(const hush_reproject_plan *plan, size_t i, const float *const *planes,
                      int nplanes, float (*out)[4][HUSH_WINDOW_MAX]) {
  uint8_t use[HUSH_WINDOW_MAX];
  for (int k = 0; k < HUSH_WINDOW_MAX; k++) use[k] = plan->kind[i + k] == HUSH_FOOTPRINT_BILINEAR;
  return window_read(plan->origin + i, use, (int32_t)plan->width,
                     (size_t)plan->width * plan->height, planes, nplanes, out);
}
#endif

/* ---- gathering ----------------------------------------------------------- */

#define GATHER_MAX 8

void hush__reproject_gather(const hush_reproject_plan *plan, const float *const *prev,
                            int channels, float *const *out, float fill_value, int threads) {
  const int H = (int)plan->height;
  const size_t W = plan->width;
  const int32_t Wi = (int32_t)W;
  if (threads < 1) threads = 1;
  if (channels > GATHER_MAX) channels = GATHER_MAX;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int y = 0; y < H; y++) {
    const size_t row = (size_t)y * W;
    if (plan->blocks) {
      /* every pixel as a block (vectorised; NONE pixels: fill_value), then
       * the 3X3 pixels through their taps */
      for (int ch = 0; ch < channels; ch++) {
        const float *p = prev[ch];
        float *o = out[ch];
#pragma omp simd
        for (size_t i = row; i < row + W; i++) {
          const int32_t j = hush__reproject_block_origin(plan, i);
          const float h = plan->w[0][i] * p[j] + plan->w[1][i] * p[j + 1] +
                          plan->w[2][i] * p[j + Wi] + plan->w[3][i] * p[j + Wi + 1];
          o[i] = plan->kind[i] == HUSH_FOOTPRINT_BILINEAR ? h : fill_value;
        }
      }
    }
    for (size_t i = row; i < row + W; i++) {
      if (plan->blocks && plan->kind[i] != HUSH_FOOTPRINT_3X3) continue;
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

hush_status hush__reprojector_begin(hush_device device, hush_reprojector *r,
                                    const float *const *position, const float *const *motion,
                                    const hush_frame_info *info,
                                    const hush_reproject_params *params, hush_reproject_job *job) {
  hush_reproject_input in;
  memset(&in, 0, sizeof in);
  gbuffer_of(hush__reprojector_next(r), &in.cur);
  if (position)
    for (int k = 0; k < 3; k++) in.position[k] = position[k];
  if (motion)
    for (int k = 0; k < 2; k++) in.motion[k] = motion[k];
  hush_gbuffer prev;
  gbuffer_of(&r->store[r->latest], &prev);
  hush_status s = hush__reproject_begin(device, &r->plan, &in, r->has_history ? &prev : NULL,
                                        info, params, job);
  if (s) return s;
  r->latest = 1 - r->latest;
  r->has_history = 1;
  return HUSH_OK;
}

hush_status hush__reprojector_build(hush_device device, hush_reprojector *r,
                                    const float *const *position, const float *const *motion,
                                    const hush_frame_info *info,
                                    const hush_reproject_params *params, int threads) {
  hush_reproject_job job;
  hush_status s = hush__reprojector_begin(device, r, position, motion, info, params, &job);
  if (s) return s;
  build_all(&job, &r->plan, threads);
  return HUSH_OK;
}
