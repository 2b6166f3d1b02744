/*
 * emission.h — light seen directly kept out of the filtered signal.
 *
 * A pixel whose first hit is a light (the Cornell lamp, a sphere light, the
 * sky) holds radiance its neighbours do not share; a screen-space filter
 * (bmfr-koskela-2019.md §3.3's per-block fit above all) smears it into the
 * surfaces around it. With the renderer's 'emission' layer
 * (docs/sequence-format.md) a filter filters (color - emission), clamped at
 * 0, and adds emission back after remodulation, as NRD and the papers'
 * renderers keep first-hit emission out of the denoised signal. Shared by
 * accumulate, svgf and bmfr.
 */
#ifndef HUSH_FILTERS_EMISSION_H
#define HUSH_FILTERS_EMISSION_H

#include "core/image.h"
#include "temporal/reproject.h"

typedef struct hush_emission_history hush_emission_history;

/* color[c] = max(color[c] - emission[c], 0), in place (3 channels). With h
 * (NULL: none) whose rows are allocated (hush__emission_history_rows), also
 * notes which image rows of emission are not all zero, for h's next
 * hush__emission_accumulate(_holes). */
void hush__emission_subtract(hush_planar *color, const hush_planar *emission,
                             hush_emission_history *h, int threads);
/* hush__emission_subtract followed by hush__demodulate (albedo: 3
 * planes; NULL: no demodulation), in one pass over the rows instead of two
 * over the frame (on rendered frames, where the emission is bound, about
 * 0.4 ms of a 1280x720 frame at 2 threads); the same bits. */
void hush__emission_subtract_demodulate(hush_planar *color, const hush_planar *emission,
                                        const hush_planar *albedo, hush_emission_history *h,
                                        int threads);
/* out[c] = emission[c] + filtered[c] (3 channels). out may alias either
 * input; filters write into their imported emission planes so that their
 * own result (often their history) is left untouched. */
void hush__emission_add(hush_planar *out, const hush_planar *emission, const hush_planar *filtered,
                        int threads);

/*
 * Marks this frame's ids (hush__reprojector_next(rp), before the plan is
 * built; nothing without ids) as matching any id (NaN, hush__id_match)
 * where the pixel sees a light (some emission channel > 0). With the
 * emission kept out of the filtered signal, a light's pixel and the surface
 * beside it differ only in what the emission history carries, and that
 * history must mix them: at 1 spp a light's edge pixel sees the light or
 * the surface, and only an average over frames gives its coverage. With the
 * id test both kept their own histories and the edge stayed aliased
 * (docs/psf.md, "One-sided lights"); depth and normal are still tested.
 */
void hush__emission_wildcard_ids(hush_reprojector *rp, const hush_planar *emission, int threads);

/* The emission added back, accumulated over frames through the filter's
 * own reprojection plan and ages (hush__temporal_blend): at 1 spp a light's
 * edge pixel sees the light or not, all or nothing, and the references
 * (and the filtered colour) average that coverage over samples; the
 * accumulated emission does the same over frames. The filter owns it and
 * allocates hist with hush__filter_scratch. */
struct hush_emission_history {
  hush_planar hist[2]; /* ping-pong: the blend reads one and writes the other */
  int latest;          /* index of the last result */
  int valid;           /* 0: no history (first frame, or emission was unbound) */
  /* Lights cover a few percent of a frame (the classroom's windows 5-6 %
   * of the pixels, 9-15 % of the rows at 1280x720; the Cornell lamp 0.5 %,
   * 4 %), so most rows of the accumulated emission are exactly 0 and stay
   * so: they are neither blended nor written. One value per image row
   * (`height` floats per plane, 0 or 1; NULL planes: every row is
   * blended): EMISSION_ROW_LIT, this frame's emission has a non-zero bit
   * there (hush__emission_subtract); EMISSION_ROW_HIST + b, hist[b] has one
   * there; EMISSION_ROW_NEED, the row is blended this frame. */
  hush_planar rows;
  int lit_fresh; /* rows' LIT plane is this frame's (subtract ran since the last accumulate) */
};
enum { EMISSION_ROW_LIT, EMISSION_ROW_HIST, EMISSION_ROW_NEED = EMISSION_ROW_HIST + 2 };

/* Per image row of the last accumulated emission (`height` floats): 0
 * where every value is +0; NULL without row flags. */
static inline const float *hush__emission_rows_of(const hush_emission_history *h) {
  return h->rows.plane[0] ? h->rows.plane[EMISSION_ROW_HIST + h->latest] : NULL;
}

/* The emission planes changed after hush__emission_subtract noted their
 * lit rows (holes filled from around): the next accumulate blends every
 * row. */
static inline void hush__emission_rows_stale(hush_emission_history *h) { h->lit_fresh = 0; }

/* Allocates h->rows for images of `height` rows (once; hist's contents
 * taken as unknown). */
hush_status hush__emission_history_rows(hush_device device, hush_emission_history *h,
                                        uint32_t height);
void hush__emission_history_free(hush_emission_history *h);
/* Blends this frame's emission into the history with the filter's plan,
 * ages and alpha (as its colour) and returns the accumulated emission,
 * owned by h, valid until the next call. */
const hush_planar *hush__emission_accumulate(hush_emission_history *h,
                                             const hush_reproject_plan *plan, const float *age,
                                             float alpha_min, const hush_planar *emission,
                                             int threads);

/* As hush__emission_accumulate in a frame with holes (spp not > 0; NULL:
 * none; docs/holes.md): a hole with a history keeps it (gathered through
 * the plan, no new sample); without one it takes this frame's emission,
 * which the caller filled (hush__gbuffer_fill_holes). */
const hush_planar *hush__emission_accumulate_holes(hush_emission_history *h,
                                                   const hush_reproject_plan *plan,
                                                   const float *age, float alpha_min,
                                                   const hush_planar *emission, const float *spp,
                                                   int threads);

#endif
