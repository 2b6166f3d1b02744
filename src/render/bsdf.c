/*
 * bsdf.c — Lambert, plastic (coat over Lambert, after Mitsuba 0.5's
 * plastic / roughplastic), GGX conductor and smooth dielectric (see
 * bsdf.h). Microfacet sampling draws visible normals (Heitz 2018, "Sampling
 * the GGX Distribution of Visible Normals"), so the sample weight of a
 * reflection is F * G2 / G1 and never explodes at grazing angles.
 * Everything is done in a local frame with the shading normal on +z.
 */
#include "render/bsdf.h"
#include "render/fminmax.h"

#include <math.h>
#include <string.h>

#define BSDF_PI 3.14159265358979f
#define INV_PI 0.318309886183791f
#define MIN_ALPHA 1e-3f

/* ---- helpers ---------------------------------------------------------------- */

void hush__onb(hush_vec3 n, hush_vec3 *t, hush_vec3 *b) {
  /* Duff et al. 2017, "Building an Orthonormal Basis, Revisited" */
  const float sign = copysignf(1.0f, n.z);
  const float a = -1.0f / (sign + n.z);
  const float c = n.x * n.y * a;
  *t = hush_v3(1.0f + sign * n.x * n.x * a, sign * c, -sign * n.x);
  *b = hush_v3(c, sign + n.y * n.y * a, -n.y);
}

float hush__fresnel_dielectric(float cos_i, float eta) {
  cos_i = hush_fminf(fabsf(cos_i), 1.0f);
  const float sin_t2 = (1.0f - cos_i * cos_i) / (eta * eta);
  if (sin_t2 >= 1.0f) return 1.0f;
  const float cos_t = sqrtf(1.0f - sin_t2);
  const float rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
  const float rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
  return 0.5f * (rs * rs + rp * rp);
}

static float schlick(float f0, float cos_i) {
  const float m = 1.0f - hush_fminf(hush_fmaxf(cos_i, 0.0f), 1.0f);
  const float m2 = m * m;
  return f0 + (1.0f - f0) * m2 * m2 * m;
}

/* Mitsuba 0.5's fit of the hemispherical Fresnel reflectance (eta < 1:
 * Egan and Hilgeman 1973; else d'Eon and Irving 2011). */
static float fresnel_diffuse_reflectance(float eta) {
  if (eta < 1.0f) return -1.4399f * eta * eta + 0.7099f * eta + 0.6681f + 0.0636f / eta;
  return -0.4399f + 0.7099f / eta - 0.3319f / (eta * eta) + 0.0636f / (eta * eta * eta);
}

static float lum3(const float c[3]) {
  return hush_luminance(c[0], c[1], c[2]);
}

static hush_vec3 to_local(const hush_bsdf *b, hush_vec3 w) {
  return hush_v3(hush_v3_dot(w, b->t), hush_v3_dot(w, b->b), hush_v3_dot(w, b->n));
}

static hush_vec3 to_world(const hush_bsdf *b, hush_vec3 w) {
  return hush_v3_add(hush_v3_add(hush_v3_scale(b->t, w.x), hush_v3_scale(b->b, w.y)),
                     hush_v3_scale(b->n, w.z));
}

static void set3(float out[3], float r, float g, float bl) {
  out[0] = r;
  out[1] = g;
  out[2] = bl;
}

/* ---- GGX -------------------------------------------------------------------------- */

static float ggx_d(float alpha, hush_vec3 h) {
  if (h.z <= 0.0f) return 0.0f;
  const float a2 = alpha * alpha;
  const float c2 = h.z * h.z;
  const float d = c2 * (a2 - 1.0f) + 1.0f;
  return a2 / (BSDF_PI * d * d);
}

static float ggx_lambda(float alpha, hush_vec3 w) {
  const float c2 = w.z * w.z;
  if (c2 <= 0.0f) return 0.0f;
  const float t2 = hush_fmaxf(0.0f, 1.0f - c2) / c2;
  return 0.5f * (-1.0f + sqrtf(1.0f + alpha * alpha * t2));
}

static float ggx_g1(float alpha, hush_vec3 w) {
  return 1.0f / (1.0f + ggx_lambda(alpha, w));
}

static float ggx_g2(float alpha, hush_vec3 wo, hush_vec3 wi) {
  return 1.0f / (1.0f + ggx_lambda(alpha, wo) + ggx_lambda(alpha, wi));
}

/* A visible normal for wo (wo.z > 0). */
static hush_vec3 ggx_sample_vndf(float alpha, hush_vec3 wo, float u1, float u2) {
  const hush_vec3 vh = hush_v3_normalize(hush_v3(alpha * wo.x, alpha * wo.y, wo.z));
  const float len2 = vh.x * vh.x + vh.y * vh.y;
  const hush_vec3 t1 = len2 > 0.0f ? hush_v3_scale(hush_v3(-vh.y, vh.x, 0.0f), 1.0f / sqrtf(len2))
                                   : hush_v3(1.0f, 0.0f, 0.0f);
  const hush_vec3 t2 = hush_v3_cross(vh, t1);
  const float r = sqrtf(u1), phi = 2.0f * BSDF_PI * u2;
  const float p1 = r * cosf(phi);
  float p2 = r * sinf(phi);
  const float s = 0.5f * (1.0f + vh.z);
  p2 = (1.0f - s) * sqrtf(hush_fmaxf(0.0f, 1.0f - p1 * p1)) + s * p2;
  const float p3 = sqrtf(hush_fmaxf(0.0f, 1.0f - p1 * p1 - p2 * p2));
  const hush_vec3 nh =
      hush_v3_add(hush_v3_add(hush_v3_scale(t1, p1), hush_v3_scale(t2, p2)), hush_v3_scale(vh, p3));
  return hush_v3_normalize(hush_v3(alpha * nh.x, alpha * nh.y, hush_fmaxf(1e-6f, nh.z)));
}

/* Density of wi = reflect(wo, h) under VNDF sampling. */
static float ggx_pdf(float alpha, hush_vec3 wo, hush_vec3 h) {
  return ggx_g1(alpha, wo) * ggx_d(alpha, h) / (4.0f * wo.z);
}

static hush_vec3 reflect_local(hush_vec3 wo, hush_vec3 h) {
  return hush_v3_sub(hush_v3_scale(h, 2.0f * hush_v3_dot(wo, h)), wo);
}

static hush_vec3 cosine_hemisphere(float u1, float u2) {
  const float r = sqrtf(u1), phi = 2.0f * BSDF_PI * u2;
  return hush_v3(r * cosf(phi), r * sinf(phi), sqrtf(hush_fmaxf(0.0f, 1.0f - u1)));
}

/* ---- set-up ---------------------------------------------------------------------- */

static float material_ior(const hush_material *m) { return m->ior > 0.0f ? m->ior : 1.5f; }

/* Fresnel reflectance at normal incidence. */
static float coat_f0(float ior) { return ((ior - 1.0f) * (ior - 1.0f)) / ((ior + 1.0f) * (ior + 1.0f)); }

void hush__bsdf_setup(hush_bsdf *b, const hush_material *m, const hush_surface *s, hush_vec3 wo) {
  memset(b, 0, sizeof *b);
  b->type = m->type;
  memcpy(b->diffuse, s->albedo, sizeof b->diffuse);
  memcpy(b->specular, m->specular, sizeof b->specular);
  b->alpha = m->roughness > 0.0f ? hush_fmaxf(m->roughness, MIN_ALPHA) : 0.0f;
  const float ior = material_ior(m);
  b->eta = ior;
  b->n = s->ns;
  b->ng = s->ng;
  if (hush_v3_dot(wo, b->ng) < 0.0f) {
    /* the scene turns two-sided surfaces to the viewer already, so only a
     * one-sided surface can be seen from behind; glass has two sides anyway */
    b->black = m->type != HUSH_MAT_DIELECTRIC;
    b->n = hush_v3_scale(b->n, -1.0f);
    b->ng = hush_v3_scale(b->ng, -1.0f);
  }
  if (hush_v3_dot(b->n, b->ng) < 0.0f) b->n = b->ng;
  if (m->type == HUSH_MAT_DIELECTRIC) b->eta = s->back_face ? 1.0f / ior : ior;
  if (m->type == HUSH_MAT_PLASTIC) {
    /* Ks is the coat's normal-incidence reflectance: Fresnel(ior) scaled to it */
    const float f0 = coat_f0(ior);
    for (int k = 0; k < 3; k++) b->specular[k] = hush_fminf(1.0f, hush_fmaxf(0.0f, m->specular[k] / f0));
    b->fdr_int = fresnel_diffuse_reflectance(1.0f / ior);
  }
  hush__onb(b->n, &b->t, &b->b);
}

int hush__bsdf_has_smooth(const hush_bsdf *b) {
  if (b->black) return 0;
  switch (b->type) {
  case HUSH_MAT_DIFFUSE:
  case HUSH_MAT_PLASTIC:
    return 1;
  case HUSH_MAT_CONDUCTOR:
    return b->alpha > 0.0f;
  default:
    return 0;
  }
}

void hush__bsdf_albedo(const hush_material *m, const hush_surface *s, float out[3]) {
  switch (m->type) {
  case HUSH_MAT_CONDUCTOR:
    memcpy(out, m->specular, 3 * sizeof(float));
    break;
  case HUSH_MAT_DIELECTRIC:
    set3(out, 1.0f, 1.0f, 1.0f);
    break;
  case HUSH_MAT_PLASTIC: {
    /* The coat reflects whatever the base's colour: with the base alone,
     * an orange frame's blue (Kd 0.001) would divide its white highlight by
     * 0.001. ks + (1 - ks) Kd: the lobes' albedos at normal incidence, ks
     * the coat's reflectance there (Ks, at most Fresnel's, as set up). */
    const float f0 = coat_f0(material_ior(m));
    for (int k = 0; k < 3; k++) {
      const float ks = hush_fminf(m->specular[k], f0);
      out[k] = ks + (1.0f - ks) * s->albedo[k];
    }
    break;
  }
  default:
    memcpy(out, s->albedo, 3 * sizeof(float));
    break;
  }
}

/* Probability of sampling the plastic coat rather than the base. */
static float plastic_spec_prob(const hush_bsdf *b, float cos_o) {
  const float fo = hush__fresnel_dielectric(cos_o, b->eta);
  const float ws = fo * lum3(b->specular);
  const float wd = (1.0f - fo) * lum3(b->diffuse);
  if (ws <= 0.0f) return 0.0f;
  if (wd <= 0.0f) return 1.0f;
  return hush_fminf(0.9f, hush_fmaxf(0.1f, ws / (ws + wd)));
}

/* ---- evaluation ---------------------------------------------------------------------- */

/* The non-delta lobes at (wo, wi), local frame: fd the diffuse one
 * (Lambert, or the plastic's base), fs the glossy one (GGX of the conductor
 * or of the plastic's coat). */
static void eval_lobes(const hush_bsdf *b, hush_vec3 wo, hush_vec3 wi, float fd[3], float fs[3],
                       float *pdf) {
  set3(fd, 0.0f, 0.0f, 0.0f);
  set3(fs, 0.0f, 0.0f, 0.0f);
  *pdf = 0.0f;
  if (wo.z <= 0.0f || wi.z <= 0.0f) return;
  if (b->type == HUSH_MAT_DIFFUSE) {
    for (int k = 0; k < 3; k++) fd[k] = b->diffuse[k] * wi.z * INV_PI;
    *pdf = wi.z * INV_PI;
    return;
  }
  const hush_vec3 h = hush_v3_normalize(hush_v3_add(wo, wi));
  if (b->type == HUSH_MAT_CONDUCTOR) {
    if (b->alpha <= 0.0f) return;
    const float dg = ggx_d(b->alpha, h) * ggx_g2(b->alpha, wo, wi) / (4.0f * wo.z);
    const float c = hush_v3_dot(wo, h);
    for (int k = 0; k < 3; k++) fs[k] = schlick(b->specular[k], c) * dg;
    *pdf = ggx_pdf(b->alpha, wo, h);
    return;
  }
  if (b->type != HUSH_MAT_PLASTIC) return;
  const float ps = plastic_spec_prob(b, wo.z);
  const float fi = hush__fresnel_dielectric(wi.z, b->eta);
  const float fo = hush__fresnel_dielectric(wo.z, b->eta);
  /* The base, light bouncing between it and the inside of the coat summed
   * as a geometric series in the albedo: Kd / (1 - Kd * Fdr_int). This is
   * Mitsuba's "nonlinear" plastic, which every plastic of the shared scenes
   * asks for, and the only form Tungsten has; the linear Kd / (1 - Fdr_int)
   * made the living room's floor and panels up to twice too bright. */
  const float base = (1.0f - fi) * (1.0f - fo) / (b->eta * b->eta) * wi.z * INV_PI;
  for (int k = 0; k < 3; k++) fd[k] = b->diffuse[k] / (1.0f - b->diffuse[k] * b->fdr_int) * base;
  *pdf = (1.0f - ps) * wi.z * INV_PI;
  if (b->alpha > 0.0f) {
    const float fr = hush__fresnel_dielectric(hush_v3_dot(wo, h), b->eta);
    const float spec = fr * ggx_d(b->alpha, h) * ggx_g2(b->alpha, wo, wi) / (4.0f * wo.z);
    for (int k = 0; k < 3; k++) fs[k] = b->specular[k] * spec;
    *pdf += ps * ggx_pdf(b->alpha, wo, h);
  }
}

/* Both lobes together: fd + fs (a lobe that is absent adds an exact 0). */
static void eval_local(const hush_bsdf *b, hush_vec3 wo, hush_vec3 wi, float f[3], float *pdf) {
  float fs[3];
  eval_lobes(b, wo, wi, f, fs, pdf);
  for (int k = 0; k < 3; k++) f[k] += fs[k];
}

void hush__bsdf_eval(const hush_bsdf *b, hush_vec3 wo, hush_vec3 wi, float f[3], float *pdf) {
  set3(f, 0.0f, 0.0f, 0.0f);
  *pdf = 0.0f;
  if (b->black || hush_v3_dot(wi, b->ng) <= 0.0f) return;
  eval_local(b, to_local(b, wo), to_local(b, wi), f, pdf);
}

void hush__bsdf_eval_lobes(const hush_bsdf *b, hush_vec3 wo, hush_vec3 wi, float fd[3],
                           float fs[3], float *pdf) {
  set3(fd, 0.0f, 0.0f, 0.0f);
  set3(fs, 0.0f, 0.0f, 0.0f);
  *pdf = 0.0f;
  if (b->black || hush_v3_dot(wi, b->ng) <= 0.0f) return;
  eval_lobes(b, to_local(b, wo), to_local(b, wi), fd, fs, pdf);
}

/* ---- sampling ---------------------------------------------------------------------------- */

/* Sample weight of a non-delta direction: eval / pdf over all lobes. */
static int finish_smooth(const hush_bsdf *b, hush_vec3 wo, hush_vec3 wi, hush_bsdf_sample *s) {
  float f[3], pdf;
  eval_local(b, wo, wi, f, &pdf);
  if (!(pdf > 0.0f)) return 0;
  for (int k = 0; k < 3; k++) s->weight[k] = f[k] / pdf;
  s->pdf = pdf;
  s->delta = 0;
  s->wi = wi;
  return 1;
}

static int sample_local(const hush_bsdf *b, hush_vec3 wo, const float u[3], hush_bsdf_sample *s) {
  const hush_vec3 mirror = hush_v3(-wo.x, -wo.y, wo.z);
  switch (b->type) {
  case HUSH_MAT_DIFFUSE:
    if (wo.z <= 0.0f) return 0;
    return finish_smooth(b, wo, cosine_hemisphere(u[1], u[2]), s);
  case HUSH_MAT_CONDUCTOR: {
    if (wo.z <= 0.0f) return 0;
    if (b->alpha <= 0.0f) {
      for (int k = 0; k < 3; k++) s->weight[k] = schlick(b->specular[k], wo.z);
      s->wi = mirror;
      s->pdf = 1.0f;
      s->delta = 1;
      return 1;
    }
    const hush_vec3 h = ggx_sample_vndf(b->alpha, wo, u[1], u[2]);
    const hush_vec3 wi = reflect_local(wo, h);
    if (wi.z <= 0.0f) return 0;
    return finish_smooth(b, wo, wi, s);
  }
  case HUSH_MAT_PLASTIC: {
    if (wo.z <= 0.0f) return 0;
    const float ps = plastic_spec_prob(b, wo.z);
    if (u[0] < ps) {
      if (b->alpha <= 0.0f) {
        const float fo = hush__fresnel_dielectric(wo.z, b->eta) / ps;
        for (int k = 0; k < 3; k++) s->weight[k] = b->specular[k] * fo;
        s->wi = mirror;
        s->pdf = ps;
        s->delta = 1;
        return 1;
      }
      const hush_vec3 h = ggx_sample_vndf(b->alpha, wo, u[1], u[2]);
      const hush_vec3 wi = reflect_local(wo, h);
      if (wi.z <= 0.0f) return 0;
      return finish_smooth(b, wo, wi, s);
    }
    return finish_smooth(b, wo, cosine_hemisphere(u[1], u[2]), s);
  }
  case HUSH_MAT_DIELECTRIC: {
    if (wo.z <= 0.0f) return 0;
    const float fr = hush__fresnel_dielectric(wo.z, b->eta);
    s->delta = 1;
    if (u[0] < fr) {
      set3(s->weight, 1.0f, 1.0f, 1.0f);
      s->wi = mirror;
      s->pdf = fr;
      return 1;
    }
    const float inv = 1.0f / b->eta;
    const float cos_t = sqrtf(hush_fmaxf(0.0f, 1.0f - inv * inv * (1.0f - wo.z * wo.z)));
    s->wi = hush_v3_normalize(hush_v3(-wo.x * inv, -wo.y * inv, -cos_t));
    /* radiance is compressed by (n_i / n_t)^2 on the way into the denser side */
    set3(s->weight, inv * inv, inv * inv, inv * inv);
    s->pdf = 1.0f - fr;
    return 1;
  }
  }
  return 0;
}

int hush__bsdf_sample(const hush_bsdf *b, hush_vec3 wo, const float u[3], hush_bsdf_sample *s) {
  memset(s, 0, sizeof *s);
  if (b->black) return 0;
  if (!sample_local(b, to_local(b, wo), u, s)) return 0;
  s->wi = hush_v3_normalize(to_world(b, s->wi));
  /* reflections must leave on the geometric side too; refraction crosses it */
  const int transmit = b->type == HUSH_MAT_DIELECTRIC && hush_v3_dot(s->wi, b->n) < 0.0f;
  const float side = hush_v3_dot(s->wi, b->ng);
  if (transmit ? side >= 0.0f : side <= 0.0f) return 0;
  return 1;
}
