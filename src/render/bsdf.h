/*
 * bsdf.h — the renderer's materials as BSDFs, for the path tracer's
 * importance-sampled secondary rays and next-event estimation
 * (bmfr-koskela-2019.md §3.1: "the direction of the secondary ray is decided
 * based on importance sampling", with multiple importance sampling).
 *
 *   DIFFUSE     Lambert.
 *   PLASTIC     a dielectric coat (Fresnel of ior, scaled by Ks / F0(ior))
 *               over a Lambert base; smooth coat (alpha 0) is a delta lobe,
 *               else GGX. The base follows Mitsuba 0.5's "nonlinear"
 *               plastic (and Tungsten's):
 *               Kd / (1 - Kd Fdr_int) (1 - Fi)(1 - Fo) / eta^2 / pi.
 *   CONDUCTOR   GGX with Schlick's Fresnel, F0 = Ks; alpha 0 is a mirror.
 *   DIELECTRIC  smooth glass: delta reflection / refraction chosen by Fresnel.
 *
 * Every function works with world-space unit directions pointing away from
 * the surface (wo towards the viewer, wi towards the light) and returns
 * f * |cos(wi, n)|, so a path's throughput is multiplied by eval / pdf or by
 * a sample's weight. Sampled delta lobes have pdf = the lobe's discrete
 * probability and are never returned by eval.
 */
#ifndef HUSH_RENDER_BSDF_H
#define HUSH_RENDER_BSDF_H

#include "core/hmath.h"
#include "render/scene.h"

typedef struct hush_bsdf {
  hush_material_type type;
  float diffuse[3];
  float specular[3];   /* plastic: coat tint (Ks / F0); conductor: F0 */
  float alpha;         /* GGX alpha; 0: smooth */
  float eta;           /* plastic: ior; dielectric: ior on wo's side -> the other side */
  float fdr_int;       /* plastic: internal diffuse Fresnel reflectance */
  hush_vec3 t, b, n;   /* shading frame; n on wo's side */
  hush_vec3 ng;        /* geometric normal on n's side */
  int black;           /* seen from behind (one-sided): reflects nothing */
} hush_bsdf;

typedef struct hush_bsdf_sample {
  hush_vec3 wi;
  float weight[3];     /* f * |cos| / pdf */
  float pdf;           /* solid-angle density, or the lobe's probability for delta */
  int delta;
} hush_bsdf_sample;

/* Sets up the BSDF of material m at surface s seen from direction wo. */
void hush__bsdf_setup(hush_bsdf *b, const hush_material *m, const hush_surface *s, hush_vec3 wo);

/* Whether eval can return anything (some non-delta lobe): next-event
 * estimation is skipped otherwise. */
int hush__bsdf_has_smooth(const hush_bsdf *b);

/* f * |cos(wi)| of the non-delta lobes into f[3]; *pdf the solid-angle
 * density with which hush__bsdf_sample returns wi (delta lobes excluded). */
void hush__bsdf_eval(const hush_bsdf *b, hush_vec3 wo, hush_vec3 wi, float f[3], float *pdf);

/* The same split by lobe, for the diffuse / specular layers: fd the
 * diffuse lobe (Lambert, the plastic's base), fs the glossy one (rough
 * conductor, the plastic's rough coat); fd + fs is hush__bsdf_eval's f,
 * bit for bit. Delta lobes (mirror, smooth coat, glass) are specular. */
void hush__bsdf_eval_lobes(const hush_bsdf *b, hush_vec3 wo, hush_vec3 wi, float fd[3],
                           float fs[3], float *pdf);

/* Draws wi from u in [0,1)^3. Returns 0 when no direction was produced. */
int hush__bsdf_sample(const hush_bsdf *b, hush_vec3 wo, const float u[3], hush_bsdf_sample *s);

/* The demodulation albedo of a first hit (see docs/renderer.md). */
void hush__bsdf_albedo(const hush_material *m, const hush_surface *s, float out[3]);

/* Helpers shared with tests and lights. */
float hush__fresnel_dielectric(float cos_i, float eta);
void hush__onb(hush_vec3 n, hush_vec3 *t, hush_vec3 *b);

#endif
