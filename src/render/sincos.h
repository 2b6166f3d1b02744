/*
 * sincos.h — sine and cosine of one angle at once, inline, for the
 * direction samplers (cone of the sun and of sphere lights, env-map and sky
 * texels, cosine hemisphere, GGX visible normals). libm's sincosf was ~3% of
 * the classroom render: a call through the PLT per sample plus its checks
 * for huge and non-finite arguments, which the samplers never pass (their
 * angles lie in [0, 2 pi]).
 *
 * Method: Cody-Waite reduction by pi/2 in three parts, then the minimax
 * polynomials of Cephes' sinf/cosf on [-pi/4, pi/4] (Moshier 1989); within
 * 2.5e-7 of libm for |x| <= 8 (tested). Only the last bits differ from
 * libm, so images change by rounding only (docs/renderer.md, speed).
 */
#ifndef HUSH_RENDER_SINCOS_H
#define HUSH_RENDER_SINCOS_H

/* *s = sin(x), *c = cos(x), for finite |x| up to ~1e4 (beyond that the
 * reduction loses bits; the samplers stay below 2 pi). */
static inline void hush_sincosf(float x, float *s, float *c) {
  /* the nearest multiple q of pi/2, without rintf (a libm call without SSE4.1) */
  const int q = (int)(x * 0.636619772367581f + (x >= 0.0f ? 0.5f : -0.5f));
  const float k = (float)q;
  /* r = x - k pi/2 in three steps; k * 1.5703125f is exact */
  float r = x - k * 1.5703125f;
  r = r - k * 4.837512969970703125e-4f;
  r = r - k * 7.549789954891882e-8f;
  const float z = r * r;
  const float sp = r + r * z * (-1.6666654611e-1f + z * (8.3321608736e-3f + z * -1.9515295891e-4f));
  const float cp = 1.0f - 0.5f * z +
                   z * z * (4.166664568298827e-2f + z * (-1.388731625493765e-3f + z * 2.443315711809948e-5f));
  /* quadrant q mod 4: (sin, cos) = (sp, cp), (cp, -sp), (-sp, -cp), (-cp, sp) */
  const int odd = q & 1, neg_s = q & 2, neg_c = (q + 1) & 2;
  const float ss = odd ? cp : sp, cc = odd ? sp : cp;
  *s = neg_s ? -ss : ss;
  *c = neg_c ? -cc : cc;
}

#endif
